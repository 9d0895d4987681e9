//! Primitives written as a user would write them in their own crate, depending only on the
//! public API of `splat-macros` and `splat-runtime`.

pub mod features;
pub mod generalized;
pub mod isotropic;
pub mod rays;
