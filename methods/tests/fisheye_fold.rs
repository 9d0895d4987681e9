//! A Kannala-Brandt polynomial with strong barrel distortion folds: r(θ) rises to a largest
//! radius and falls again, so a point past the fold lands on a pixel that a nearer ray also
//! reaches. `cam.can_project` stops at the fold, and every method that splats through the
//! projection (3DGS, 3DGUT) or culls by it (3DGEER) draws nothing there, on the CPU and the
//! GPU, while a Gaussian on the nearer ray to the same pixel is drawn.

use crate::common::{as_method, camera};
use splat_methods::gs3d::Params;
use splat_methods::{FromStored, geer, gs3d, gut};
use splat_runtime::glam::{Vec2, Vec3, Vec4};
use splat_runtime::gpu::adapter_or_skip;
use splat_runtime::{Camera, CameraModel, Frame, RenderOptions, SplatMethod, render};

/// r(θ) = θ - 0.25 θ³: its slope 1 - 0.75 θ² vanishes at θ = 1.155 rad (66°).
fn folding_camera() -> Camera {
    Camera {
        focal: Vec2::splat(24.0),
        distortion: Vec4::new(-0.25, 0.0, 0.0, 0.0),
        model: CameraModel::KannalaBrandt,
        ..camera(64, 48)
    }
}

/// An opaque, round Gaussian at `distance` along `dir`.
fn gaussian(dir: Vec3, distance: f32) -> Params {
    let mut sh = [Vec3::ZERO; 16];
    sh[0] = Vec3::splat(1.5);
    Params {
        mean: dir.normalize() * distance,
        log_scale: Vec3::splat(-1.2),
        rotation: Vec4::new(1.0, 0.0, 0.0, 0.0),
        opacity_logit: 3.0,
        sh,
    }
}

/// The largest alpha of `M`'s render of `scene`, and its pixel, on the CPU and (where there is
/// an adapter) the GPU.
fn peak_alpha<M: SplatMethod>(scene: &[Params], cam: &Camera) -> Vec<(&'static str, f32, Vec2)>
where
    M::Params: FromStored,
{
    let params: Vec<M::Params> = as_method(scene.to_vec());
    let opts = RenderOptions {
        alpha: true,
        ..Default::default()
    };
    let peak = |frame: Frame| {
        let alpha = frame.alpha.expect("alpha was asked for");
        let (i, a) =
            alpha.data.iter().enumerate().fold(
                (0, 0.0f32),
                |best, (i, &a)| if a > best.1 { (i, a) } else { best },
            );
        let w = alpha.width as usize;
        (a, Vec2::new((i % w) as f32 + 0.5, (i / w) as f32 + 0.5))
    };
    let (a, at) = peak(render::<M>(&params, cam, &opts).unwrap());
    let mut out = vec![("cpu", a, at)];
    if let Some(gpu) = adapter_or_skip() {
        let frame = splat_runtime::gpu::render::render::<M>(&gpu, &params, cam, &opts).unwrap();
        let (a, at) = peak(frame);
        out.push(("gpu", a, at));
    }
    out
}

fn check<M: SplatMethod>(name: &str)
where
    M::Params: FromStored,
{
    let cam = folding_camera();
    // 83° off axis, past the fold: without the cull it would land 16.5 pixels right of the
    // principal point, where the ray 47° off axis meets the image.
    let past = Vec3::new(1.45f32.sin(), 0.0, 1.45f32.cos());
    let pixel = cam.project_point(past);
    assert!((pixel.x - cam.principal.x - 16.5).abs() < 0.1, "{pixel}");
    let nearer = cam.pixel_ray(pixel);
    assert!((nearer.z.acos() - 0.826).abs() < 0.01, "{nearer}");
    for (backend, alpha, _) in peak_alpha::<M>(&[gaussian(past, 3.0)], &cam) {
        assert!(
            alpha < 1e-6,
            "{name}, {backend}: a Gaussian past the fold is drawn (alpha {alpha})"
        );
    }
    for (backend, alpha, at) in peak_alpha::<M>(&[gaussian(nearer, 3.0)], &cam) {
        assert!(
            alpha > 0.5 && at.distance(pixel) < 1.5,
            "{name}, {backend}: the Gaussian on the nearer ray peaks at {alpha} at {at}, not at {pixel}"
        );
    }
}

#[test]
fn nothing_past_the_fisheye_fold_is_drawn() {
    check::<gs3d::Method>("3dgs");
    check::<gut::Method>("3dgut");
    check::<geer::Method>("3dgeer");
}
