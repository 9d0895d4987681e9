//! Rendering methods written with `#[splat_method]`; each file reads like the paper's listing.

// Each family of methods in the file of its module's name, expanded here so that its modules
// (`gs3d`, `gs3d_sh0`, ..., `gs3d_aa`) sit at the crate's root; each module's
// `#[splat_method(name = ...)]` is the name users type and see (`3dgs`, `3dgs-aa`, `3dgut`,
// `3dgeer`, `linprim`).
include!("gs3d.rs");
include!("gut.rs");
include!("geer.rs");
include!("linprim.rs");

pub use splat_runtime::io::ply::{FromStored, ToStored};

/// `FromStored` and `ToStored` for methods whose parameters are the stored Gaussian's fields as
/// they are, with the SH coefficients of their degree (the stored ones beyond it dropped,
/// written back as zeros).
macro_rules! stored_as_is {
    ($($params:path),*) => {$(
        impl FromStored for $params {
            fn from_stored(g: &splat_runtime::io::ply::StoredGaussian) -> Self {
                Self {
                    mean: g.mean,
                    log_scale: g.log_scale,
                    rotation: g.rotation,
                    opacity_logit: g.opacity_logit,
                    sh: std::array::from_fn(|i| g.sh[i]),
                }
            }
        }

        impl ToStored for $params {
            fn to_stored(&self) -> splat_runtime::io::ply::StoredGaussian {
                let mut sh = [splat_runtime::glam::Vec3::ZERO; 16];
                sh[..self.sh.len()].copy_from_slice(&self.sh);
                splat_runtime::io::ply::StoredGaussian {
                    mean: self.mean,
                    log_scale: self.log_scale,
                    rotation: self.rotation,
                    opacity_logit: self.opacity_logit,
                    sh,
                }
            }
        }
    )*};
}

stored_as_is!(
    gut::Params,
    gut_sh0::Params,
    gut_sh1::Params,
    gut_sh2::Params,
    gut_rs::Params,
    geer::Params,
    geer_sh0::Params,
    geer_sh1::Params,
    geer_sh2::Params,
    geer_rs::Params
);

/// 3DGUT, 3DGEER and LinPrim train like 3DGS (their parameters are the same Gaussian's, or
/// for LinPrim's octahedra the Gaussian they are stored as): the same learning rates and
/// initialization, and density control sees the stored Gaussian's shape. `screen: |g| ...`
/// reads where the primitive lands on the image from a shade gradient, for a method whose
/// shade data holds it (the ray-based methods' does not).
macro_rules! trained_like_3dgs {
    ($m:ident $(, screen: |$g:ident| $screen:expr)?) => {
        impl splat_runtime::train::Trainable for $m::Method {
            fn learning_rates(extent: f32) -> Vec<splat_runtime::train::Rate> {
                <gs3d::Method as splat_runtime::train::Trainable>::learning_rates(extent)
            }

            fn from_point(
                point: splat_runtime::glam::Vec3,
                color: splat_runtime::glam::Vec3,
                scale: f32,
            ) -> $m::Params {
                let g = <gs3d::Method as splat_runtime::train::Trainable>::from_point(point, color, scale);
                $m::Params::from_stored(&g.to_stored())
            }

            fn shape(p: &$m::Params) -> splat_runtime::train::Shape {
                <gs3d::Method as splat_runtime::train::Trainable>::shape(&as_3dgs(p))
            }

            fn with_shape(p: &$m::Params, s: &splat_runtime::train::Shape) -> $m::Params {
                let g = <gs3d::Method as splat_runtime::train::Trainable>::with_shape(&as_3dgs(p), s);
                $m::Params::from_stored(&g.to_stored())
            }

            fn position_gradient(g: &$m::Params) -> splat_runtime::glam::Vec3 {
                g.mean
            }

            $(fn screen_gradient($g: &$m::Shade) -> Option<splat_runtime::glam::Vec2> {
                Some($screen)
            })?
        }
    };
}

trained_like_3dgs!(gut);
trained_like_3dgs!(geer);
trained_like_3dgs!(linprim, screen: |g| g.slabs.center);

/// The 3DGS primitive with the same stored fields.
fn as_3dgs(p: &impl ToStored) -> gs3d::Params {
    gs3d::Params::from_stored(&p.to_stored())
}
