//! Rendering methods written with `#[splat_method]`; each file reads like the paper's listing.

mod exact;
mod gaussians;
mod linear;
mod unscented;

pub use exact::geer;
pub use gaussians::{gs3d, gs3d_sh0, gs3d_sh1, gs3d_sh2};
pub use linear::linprim;
pub use unscented::gut;

/// Parameters that can be built from a Gaussian stored in an INRIA PLY file.
pub trait FromStored {
    fn from_stored(g: &splat_runtime::io::ply::StoredGaussian) -> Self;
}
