//! Rendering methods written with `#[splat_method]`; each file reads like the paper's listing.

pub mod gs3d;

pub use gs3d::gs3d as gaussians3d;
