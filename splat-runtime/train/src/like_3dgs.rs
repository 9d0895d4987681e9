//! Training in one line for a method whose parameters are a 3DGS Gaussian's fields (`mean`,
//! `log_scale`, `rotation`, `opacity_logit`, `sh`) plus any of its own: [`like_3dgs!`] gives it
//! 3DGS's learning rates ([`gaussian_rates`]), initialization ([`gaussian_from_point`]) and
//! density control, and PLY scenes.

use crate::trainable::Rate;
use splat_core::glam::{Vec3, Vec4};
use splat_core::method::{SplatMethod, param_groups};

/// The DC term's SH basis value (constant over directions): color = c0 * sh[0] + 0.5.
const SH_C0: f32 = 0.282_094_8;

/// 3DGS's learning rate of each word of `M::Params`, by field name: positions scaled by the
/// scene's `extent` and decayed 100x over the run, log scales 5e-3, rotations 1e-3, opacity
/// logits 5e-2, the SH DC term 2.5e-3 and the higher bands 20x slower, band b trained from
/// step 1,000 b; a field of the method's own at its rate in `own`. Errs naming a field that
/// has neither.
pub fn gaussian_rates<M: SplatMethod>(
    extent: f32,
    own: &[(&str, Rate)],
) -> Result<Vec<Rate>, String> {
    let mut rates = vec![];
    for (name, words) in param_groups::<M>() {
        let n = words.len();
        let known = match name {
            "mean" => Some(Rate {
                first: 1.6e-4 * extent,
                last: 1.6e-6 * extent,
                from_step: 0,
            }),
            "log_scale" => Some(Rate::fixed(5e-3)),
            "rotation" => Some(Rate::fixed(1e-3)),
            "opacity_logit" => Some(Rate::fixed(5e-2)),
            "sh" => {
                rates.extend((0..n / 3).flat_map(|i| std::iter::repeat_n(sh_rate(i), 3)));
                continue;
            }
            _ => own.iter().find(|(o, _)| *o == name).map(|(_, rate)| *rate),
        };
        let rate = known.ok_or_else(|| {
            format!(
                "`{}` has a field `{name}` that 3DGS does not train: give its learning rate",
                M::NAME
            )
        })?;
        rates.extend(std::iter::repeat_n(rate, n));
    }
    Ok(rates)
}

/// 3DGS's rate of SH coefficient `i` (of band floor(sqrt(i))).
fn sh_rate(i: usize) -> Rate {
    let band = (i as f32).sqrt() as usize;
    match band {
        0 => Rate::fixed(2.5e-3),
        _ => Rate {
            from_step: 1000 * band,
            ..Rate::fixed(2.5e-3 / 20.0)
        },
    }
}

/// 3DGS's start at a point of the initial cloud: an isotropic Gaussian of axis scale `scale`
/// and opacity 0.1, the point's `color` as the DC term (the other SH coefficients zero). As
/// (mean, log scales, (w, x, y, z) rotation, opacity logit, DC coefficient).
pub fn gaussian_from_point(point: Vec3, color: Vec3, scale: f32) -> (Vec3, Vec3, Vec4, f32, Vec3) {
    (
        point,
        Vec3::splat(scale.max(1e-7).ln()),
        Vec4::new(1.0, 0.0, 0.0, 0.0),
        (0.1f32 / 0.9).ln(),
        (color - 0.5) / SH_C0,
    )
}

/// Makes a `#[splat_method]` module `$m`, whose `Params` holds a 3DGS Gaussian's fields
/// (`mean: Vec3`, `log_scale: Vec3`, `rotation: Vec4`, `opacity_logit: f32`,
/// `sh: [Vec3; N]`) and maybe fields of its own, train as 3DGS does (`Trainable`) and read PLY
/// scenes (`FromStored`, its own fields at their start); one without fields of its own also
/// writes them (`ToStored`: a PLY has no place for the others, and `splat fit` does not drop
/// what it trained).
///
/// ```ignore
/// splat_runtime::train::like_3dgs!(student);
/// // With a field of its own (its rate and start) and the shade field that holds the
/// // projected centre (density control grows from its gradient, as 3DGS's does):
/// splat_runtime::train::like_3dgs!(ges, own: { log_shape_half: Rate::fixed(1e-3) => 0.0 }, screen: center);
/// ```
#[macro_export]
macro_rules! like_3dgs {
    ($m:ident $(, screen: $screen:ident)? $(,)?) => {
        $crate::like_3dgs!(@read $m {});
        $crate::like_3dgs!(@train $m {} $($screen)?);

        impl $crate::__private::ToStored for $m::Params {
            fn to_stored(&self) -> $crate::__private::StoredGaussian {
                let mut sh = [$crate::__private::Vec3::ZERO; 16];
                sh[..self.sh.len()].copy_from_slice(&self.sh);
                $crate::__private::StoredGaussian {
                    mean: self.mean,
                    log_scale: self.log_scale,
                    rotation: self.rotation,
                    opacity_logit: self.opacity_logit,
                    sh,
                }
            }
        }
    };
    ($m:ident, own: { $($field:ident: $rate:expr => $init:expr),* $(,)? } $(, screen: $screen:ident)? $(,)?) => {
        $crate::like_3dgs!(@read $m { $($field: $rate => $init),* });
        $crate::like_3dgs!(@train $m { $($field: $rate => $init),* } $($screen)?);
    };
    (@read $m:ident { $($field:ident: $rate:expr => $init:expr),* }) => {
        impl $crate::__private::FromStored for $m::Params {
            #[allow(clippy::needless_update)]
            fn from_stored(g: &$crate::__private::StoredGaussian) -> Self {
                $m::Params {
                    mean: g.mean,
                    log_scale: g.log_scale,
                    rotation: g.rotation,
                    opacity_logit: g.opacity_logit,
                    sh: ::std::array::from_fn(|i| g.sh[i]),
                    $($field: $init,)*
                    ..::std::default::Default::default()
                }
            }
        }
    };
    (@train $m:ident { $($field:ident: $rate:expr => $init:expr),* } $($screen:ident)?) => {
        impl $crate::Trainable for $m::Method {
            fn learning_rates(extent: f32) -> ::std::vec::Vec<$crate::Rate> {
                let own: &[(&str, $crate::Rate)] = &[$((stringify!($field), $rate)),*];
                $crate::like_3dgs::gaussian_rates::<Self>(extent, own)
                    .unwrap_or_else(|e| panic!("{e}"))
            }

            #[allow(clippy::needless_update)]
            fn from_point(
                point: $crate::__private::Vec3,
                color: $crate::__private::Vec3,
                scale: f32,
            ) -> $m::Params {
                let (mean, log_scale, rotation, opacity_logit, dc) =
                    $crate::like_3dgs::gaussian_from_point(point, color, scale);
                let mut sh = [$crate::__private::Vec3::ZERO; _];
                sh[0] = dc;
                $m::Params {
                    mean,
                    log_scale,
                    rotation,
                    opacity_logit,
                    sh,
                    $($field: $init,)*
                    ..::std::default::Default::default()
                }
            }

            fn shape(p: &$m::Params) -> $crate::Shape {
                $crate::Shape::from_gaussian(p.mean, p.log_scale, p.rotation, p.opacity_logit)
            }

            fn with_shape(p: &$m::Params, s: &$crate::Shape) -> $m::Params {
                let (mean, log_scale, rotation, opacity_logit) = s.to_gaussian();
                $m::Params {
                    mean,
                    log_scale,
                    rotation,
                    opacity_logit,
                    ..*p
                }
            }

            fn position_gradient(g: &$m::Params) -> $crate::__private::Vec3 {
                g.mean
            }

            $(fn screen_gradient(
                g: &<$m::Method as $crate::__private::SplatMethod>::Shade,
            ) -> Option<$crate::__private::Vec2> {
                Some(g.$screen)
            })?
        }
    };
}
