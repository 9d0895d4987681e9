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

/// `FromStored` for methods whose parameters are the stored Gaussian's fields as they are.
macro_rules! from_stored_as_is {
    ($($params:path),*) => {$(
        impl FromStored for $params {
            fn from_stored(g: &splat_runtime::io::ply::StoredGaussian) -> Self {
                Self {
                    mean: g.mean,
                    log_scale: g.log_scale,
                    rotation: g.rotation,
                    opacity_logit: g.opacity_logit,
                    sh: g.sh,
                }
            }
        }
    )*};
}

from_stored_as_is!(gut::Params, geer::Params);
