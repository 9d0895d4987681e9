//! The kernels compiled for one camera model (what the runtime's loops call, through
//! [`with_camera_model!`](splat_core::with_camera_model)) against the generic ones that branch on
//! the model. Specializing only folds the model's integer comparisons, so the forward kernels
//! give the same results bit for bit; in the adjoints the generic kernel also adds the (zero)
//! cotangents of the branches not taken, and sums a value's cotangent contributions in another
//! order, so they agree to rounding: within `ADJOINT_TOLERANCE` of the cotangent's largest word.
//!
//! Likewise a method's instance for a lower SH degree against the full one, whole frames and
//! gradients on both backends.

use super::forward::outputs_close;
use glam::Vec2;
use splat_core::flat::Flat;
use splat_core::frame::{Frame, Gradients};
use splat_core::method::SplatMethod;
use splat_core::types::{Camera, Projected};
use splat_cpu::{backward, render_for_backward};

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
    splat_core::with_camera_model!(cam.model, MODEL => {
        for (i, p) in params.iter().enumerate() {
            let (a, b) = (M::project(p, cam), M::project_as::<MODEL>(p, cam));
            let what = format!("{name}: project of primitive {i} under the {} camera", cam.model);
            assert_eq!(a.visible, b.visible, "{what}: visible");
            same(&[a.depth, a.bbox_min.x, a.bbox_min.y, a.bbox_max.x, a.bbox_max.y],
                &[b.depth, b.bbox_min.x, b.bbox_min.y, b.bbox_max.x, b.bbox_max.y], &what);
            same(&words(&a.cull), &words(&b.cull), &what);
            same(&words(&a.shade), &words(&b.shade), &what);
            let (ga, ca) = M::project_adjoint(p, cam, &ones, splat_core::GradientSet::ALL);
            let (gb, cb) = M::project_adjoint_as::<MODEL>(p, cam, &ones, splat_core::GradientSet::ALL);
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

/// `Low`, the instance of a method for a lower SH degree (its parameters the full instance's
/// with the SH array cut short, the SH coefficients the last words), renders `params` as `Full`
/// does when their higher-degree coefficients are zero: every output within 1e-6 + 1e-5
/// relative, the gradients of the words it has (and of the camera) within `ADJOINT_TOLERANCE`
/// of each one's largest, on the CPU and, where there is an adapter, on the GPU.
pub fn lower_sh_degree_matches_full<Full: SplatMethod, Low: SplatMethod>(
    label: &str,
    params: &[Full::Params],
    cam: &Camera,
) {
    let kept = Low::Params::LEN;
    let low: Vec<Low::Params> = params
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let w = words(p);
            assert!(
                w[kept..].iter().all(|v| *v == 0.0),
                "{label}: primitive {i} has SH coefficients beyond {}'s degree",
                std::any::type_name::<Low>()
            );
            Low::Params::read_words(&w[..kept])
        })
        .collect();
    let n = (cam.size.x * cam.size.y) as usize;
    let grad = super::frame_grad(&super::weights(n, <Full::Color as Flat>::LEN));
    let opts = super::options(16);
    let cpu = || {
        let full = render_for_backward::<Full>(params, cam, &opts).unwrap();
        let low_run = render_for_backward::<Low>(&low, cam, &opts).unwrap();
        (
            "CPU",
            outcome(
                full.0,
                &backward::<Full>(&full.1, params, cam, &grad).unwrap(),
            ),
            outcome(
                low_run.0,
                &backward::<Low>(&low_run.1, &low, cam, &grad).unwrap(),
            ),
        )
    };
    #[cfg_attr(not(feature = "gpu"), allow(unused_mut))] // the GPU run is pushed
    let mut runs = vec![cpu()];
    #[cfg(feature = "gpu")]
    if let Some(gpu) = splat_gpu::adapter_or_skip() {
        use splat_gpu::{entries::Accumulation, render};
        let acc = Accumulation::default_for(&gpu);
        let (full, mut state) =
            render::render_for_backward::<Full>(&gpu, params, cam, &opts).unwrap();
        let full = outcome(
            full,
            &render::backward(&mut state, &grad, acc).unwrap().gradients,
        );
        let (low_run, mut state) =
            render::render_for_backward::<Low>(&gpu, &low, cam, &opts).unwrap();
        let low_run = outcome(
            low_run,
            &render::backward(&mut state, &grad, acc).unwrap().gradients,
        );
        runs.push(("GPU", full, low_run));
    }
    for (backend, (full_frame, full_grad, full_cam), (low_frame, low_grad, low_cam)) in runs {
        let what = format!(
            "{label}: {} against {} on the {backend}",
            // The instances by their modules: every instance of a method shares its name.
            std::any::type_name::<Low>(),
            std::any::type_name::<Full>()
        );
        outputs_close(&what, &full_frame, &low_frame, 1e-6, 1e-5);
        let kept_grad: Vec<f32> = full_grad
            .chunks(Full::Params::LEN)
            .flat_map(|g| g[..kept].to_vec())
            .collect();
        close(
            &kept_grad,
            &low_grad,
            &format!("{what}: parameter gradients"),
        );
        close(&full_cam, &low_cam, &format!("{what}: camera gradient"));
    }
}

/// A frame with its gradients as words: the parameters', the camera's.
fn outcome<M: SplatMethod>(frame: Frame, g: &Gradients<M>) -> (Frame, Vec<f32>, Vec<f32>) {
    let params = g.params.iter().flat_map(words).collect();
    (frame, params, g.camera.float_slots().to_vec())
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
