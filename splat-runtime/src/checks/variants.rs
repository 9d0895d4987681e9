//! The kernels compiled for one camera model (what the runtime's loops call, through
//! [`with_camera_model!`](crate::with_camera_model)) against the generic ones that branch on
//! the model. Specializing only folds the model's integer comparisons, so the forward kernels
//! give the same results bit for bit; in the adjoints the generic kernel also adds the (zero)
//! cotangents of the branches not taken, and sums a value's cotangent contributions in another
//! order, so they agree to rounding: within `ADJOINT_TOLERANCE` of the cotangent's largest word.

use crate::flat::Flat;
use crate::method::SplatMethod;
use crate::types::{Camera, Projected};
use glam::Vec2;

/// How far an adjoint's word may be from the generic one, relative to the largest word of the
/// same cotangent (a few dozen f32 ulps: summation order, not a different derivative).
pub const ADJOINT_TOLERANCE: f32 = 1e-5;

/// `project` and `pixel_info` specialized to `cam`'s model equal the generic functions bit for
/// bit, and their adjoints (under a cotangent of ones) to rounding, on every primitive of
/// `params` and at every pixel centre of an 8 x 8 grid over the image.
pub fn specialized_kernels_match_generic<M: SplatMethod>(
    name: &str,
    params: &[M::Params],
    cam: &Camera,
) {
    let ones = unit_cotangent::<M>();
    crate::with_camera_model!(cam.model, MODEL => {
        for (i, p) in params.iter().enumerate() {
            let (a, b) = (M::project(p, cam), M::project_as::<MODEL>(p, cam));
            let what = format!("{name}: project of primitive {i} under the {} camera", cam.model);
            assert_eq!(a.visible, b.visible, "{what}: visible");
            same(&[a.depth, a.bbox_min.x, a.bbox_min.y, a.bbox_max.x, a.bbox_max.y],
                &[b.depth, b.bbox_min.x, b.bbox_min.y, b.bbox_max.x, b.bbox_max.y], &what);
            same(&words(&a.cull), &words(&b.cull), &what);
            same(&words(&a.shade), &words(&b.shade), &what);
            let (ga, ca) = M::project_adjoint(p, cam, &ones);
            let (gb, cb) = M::project_adjoint_as::<MODEL>(p, cam, &ones);
            close(&words(&ga), &words(&gb), &format!("{what}: adjoint"));
            close(&words(&ca), &words(&cb), &format!("{what}: camera adjoint"));
        }
        for k in 0..64 {
            let pixel = Vec2::new((k % 8) as f32 + 0.5, (k / 8) as f32 + 0.5) * cam.size / 8.0;
            let what = format!("{name}: pixel_info at {pixel} under the {} camera", cam.model);
            let (a, b) = (M::pixel_info(pixel, cam), M::pixel_info_as::<MODEL>(pixel, cam));
            same(&words(&a), &words(&b), &what);
            let d = M::Pixel::read_words(&vec![1.0; M::Pixel::LEN]);
            let (ca, cb) = (
                M::pixel_info_adjoint(pixel, cam, &d),
                M::pixel_info_adjoint_as::<MODEL>(pixel, cam, &d),
            );
            close(&words(&ca), &words(&cb), &format!("{what}: adjoint"));
        }
    });
}

/// A cotangent of `project`'s output that is one in every word that carries a gradient
/// (depth, cull and shade data): what the checks and the benches run the adjoints under.
pub fn unit_cotangent<M: SplatMethod>() -> Projected<M::Cull, M::Shade> {
    Projected {
        visible: false,
        depth: 1.0,
        bbox_min: Vec2::ZERO,
        bbox_max: Vec2::ZERO,
        cull: M::Cull::read_words(&vec![1.0; M::Cull::LEN]),
        shade: M::Shade::read_words(&vec![1.0; M::Shade::LEN]),
    }
}

fn words<T: Flat>(v: &T) -> Vec<f32> {
    let mut out = vec![0.0; T::LEN];
    v.write_words(&mut out);
    out
}

fn same(a: &[f32], b: &[f32], what: &str) {
    for (k, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(
            x.to_bits() == y.to_bits(),
            "{what}: word {k} is {y} specialized, {x} generic"
        );
    }
}

fn close(a: &[f32], b: &[f32], what: &str) {
    let scale = a.iter().fold(0.0f32, |m, x| m.max(x.abs()));
    for (k, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(
            (x - y).abs() <= ADJOINT_TOLERANCE * scale || x.to_bits() == y.to_bits(),
            "{what}: word {k} is {y} specialized, {x} generic (largest word {scale})"
        );
    }
}
