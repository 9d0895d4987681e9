//! Rendering methods written with `#[splat_method]`; each file reads like the paper's listing.

mod gaussians;

pub use gaussians::gs3d;
