//! Hard cases stay finite and correct: needle and flat Gaussians, a zero
//! quaternion, the camera inside a Gaussian, Gaussians behind the camera and at the near
//! plane, opaque stacks (alpha clamp, transmittance underflow), huge and sub-pixel Gaussians,
//! empty scenes, NaN / Inf parameters.

use splat_runtime::checks;

use crate::common::{camera, gaussian_at};
use splat_methods::gs3d::{Method, Params};
use splat_runtime::glam::{Vec2, Vec3, Vec4};
use splat_runtime::{FrameGrad, RenderError, RenderOptions, backward, render, render_for_backward};

fn hard_scene() -> Vec<Params> {
    let mut rng = fastrand::Rng::with_seed(5);
    let cam = camera(40, 32);
    let mut ps = vec![];
    let mut needle = gaussian_at(&mut rng, &cam, Vec2::new(10.0, 10.0), 3.0, -2.0);
    needle.log_scale = Vec3::new(-1.5, (1e-7f32).ln(), -1.5);
    ps.push(needle);
    let mut flat = gaussian_at(&mut rng, &cam, Vec2::new(30.0, 10.0), 3.0, -2.0);
    flat.log_scale.z = (1e-7f32).ln();
    ps.push(flat);
    let mut zero_q = gaussian_at(&mut rng, &cam, Vec2::new(20.0, 25.0), 4.0, -2.0);
    zero_q.rotation = Vec4::ZERO;
    ps.push(zero_q);
    let mut around_camera = gaussian_at(&mut rng, &cam, Vec2::new(20.0, 16.0), 1.0, 0.5);
    around_camera.mean = Vec3::new(0.0, 0.0, 0.0);
    ps.push(around_camera);
    let mut behind = gaussian_at(&mut rng, &cam, Vec2::new(20.0, 16.0), 2.0, -1.0);
    behind.mean.z = -3.0;
    ps.push(behind);
    let mut near = gaussian_at(&mut rng, &cam, Vec2::new(5.0, 5.0), 0.01, -6.0);
    near.mean.z = 0.0100001;
    ps.push(near);
    // An opaque stack: alpha clamps at 0.99 and transmittance underflows the stopping rule.
    for k in 0..12 {
        let mut g = gaussian_at(
            &mut rng,
            &cam,
            Vec2::new(12.0, 22.0),
            2.0 + 0.1 * k as f32,
            -1.5,
        );
        g.opacity_logit = 12.0;
        ps.push(g);
    }
    // Huge and sub-pixel.
    ps.push(gaussian_at(&mut rng, &cam, Vec2::new(20.0, 16.0), 9.0, 1.5));
    ps.push(gaussian_at(
        &mut rng,
        &cam,
        Vec2::new(33.3, 27.7),
        5.0,
        -7.0,
    ));
    ps
}

#[test]
fn hard_cases_match_the_reference_and_stay_finite() {
    let cam = camera(40, 32);
    let ps = hard_scene();
    let reference = checks::reference::render::<splat_methods::gs3d::Method>(&ps, &cam);
    for tile_size in [8, 16] {
        let opts = RenderOptions {
            tile_size,
            alpha: true,
            depth: true,
            ..Default::default()
        };
        let frame = render::<Method>(&ps, &cam, &opts).unwrap();
        for (g, w) in frame.color.data.iter().zip(&reference.color) {
            assert!(g.is_finite());
            assert!((*g as f64 - w).abs() <= 1e-5 + 0.01 * w.abs(), "{g} vs {w}");
        }
        assert!(
            frame
                .alpha
                .unwrap()
                .data
                .iter()
                .all(|a| (0.0..=1.0).contains(a))
        );
        assert!(frame.depth.unwrap().data.iter().all(|d| d.is_finite()));
    }
    // Gradients stay finite too.
    let opts = RenderOptions {
        tile_size: 8,
        alpha: true,
        depth: true,
        ..Default::default()
    };
    let (_, state) = render_for_backward::<Method>(&ps, &cam, &opts).unwrap();
    let n = 40 * 32;
    let grad = FrameGrad {
        color: vec![1.0; n * 3],
        alpha: Some(vec![1.0; n]),
        depth: Some(vec![0.1; n]),
    };
    let g = backward::<Method>(&state, &ps, &cam, &grad).unwrap();
    for (i, p) in g.params.iter().enumerate() {
        assert!(splat_runtime::Flat::is_finite(p), "primitive {i}: {p:?}");
    }
    assert!(g.camera.rotation.is_finite() && g.camera.translation.is_finite());
}

#[test]
fn empty_scenes_render_black() {
    let cam = camera(17, 9);
    let frame = render::<Method>(
        &[],
        &cam,
        &RenderOptions {
            alpha: true,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(frame.color.data.len(), 17 * 9 * 3);
    assert!(frame.color.data.iter().all(|v| *v == 0.0));
    assert!(frame.alpha.unwrap().data.iter().all(|v| *v == 0.0));
}

#[test]
fn nan_and_inf_parameters_are_refused() {
    let cam = camera(16, 16);
    let mut ps = hard_scene();
    ps[3].sh[7].y = f32::NAN;
    assert_eq!(
        render::<Method>(&ps, &cam, &RenderOptions::default()).err(),
        Some(RenderError::NonFinite(3))
    );
    ps[3].sh[7].y = 0.0;
    ps[5].opacity_logit = f32::INFINITY;
    assert_eq!(
        render::<Method>(&ps, &cam, &RenderOptions::default()).err(),
        Some(RenderError::NonFinite(5))
    );
}

#[test]
fn absurd_sizes_and_options_are_refused() {
    let mut cam = camera(16, 16);
    cam.size.x = 0.0;
    assert!(matches!(
        render::<Method>(&[], &cam, &RenderOptions::default()),
        Err(RenderError::ImageSize { .. })
    ));
    cam.size.x = 1e9;
    assert!(matches!(
        render::<Method>(&[], &cam, &RenderOptions::default()),
        Err(RenderError::ImageSize { .. })
    ));
    let cam = camera(16, 16);
    let opts = RenderOptions {
        tile_size: 12,
        ..Default::default()
    };
    assert_eq!(
        render::<Method>(&[], &cam, &opts).err(),
        Some(RenderError::TileSize(12))
    );
}

/// Depth sums are kept only for a frame that renders depth: a depth gradient against any other
/// frame is refused on both backends, and the other outputs' gradients do not depend on it.
#[test]
fn a_depth_gradient_needs_the_depth_output() {
    let (cam, ps) = (camera(40, 32), hard_scene());
    let n = 40 * 32;
    let color_only = FrameGrad {
        color: vec![0.5; n * 3],
        alpha: Some(vec![0.25; n]),
        depth: None,
    };
    let with_depth = FrameGrad {
        depth: Some(vec![0.1; n]),
        ..color_only.clone()
    };
    let [plain, deep] = [false, true].map(|depth| RenderOptions {
        alpha: true,
        depth,
        ..Default::default()
    });
    let (_, state) = render_for_backward::<Method>(&ps, &cam, &plain).unwrap();
    let (_, deep_state) = render_for_backward::<Method>(&ps, &cam, &deep).unwrap();
    assert_eq!(
        deep_state.bytes() - state.bytes(),
        n * 4,
        "one f32 per pixel"
    );
    assert_eq!(
        backward::<Method>(&state, &ps, &cam, &with_depth).err(),
        Some(RenderError::DepthNotRendered)
    );
    let got = backward::<Method>(&state, &ps, &cam, &color_only).unwrap();
    let want = backward::<Method>(&deep_state, &ps, &cam, &color_only).unwrap();
    assert_eq!(got.params, want.params);

    let Some(gpu) = splat_runtime::gpu::adapter_or_skip() else {
        return;
    };
    use splat_runtime::gpu::{GpuRenderError, entries::Accumulation, render};
    let acc = Accumulation::default_for(&gpu);
    let (_, mut state) = render::render_for_backward::<Method>(&gpu, &ps, &cam, &plain).unwrap();
    assert!(matches!(
        render::backward(&mut state, &with_depth, acc),
        Err(GpuRenderError::Render(RenderError::DepthNotRendered))
    ));
    let (_, mut deep_state) =
        render::render_for_backward::<Method>(&gpu, &ps, &cam, &deep).unwrap();
    let words = |s: &render::GpuForwardState<Method>| s.renderer.state_layout().words();
    assert_eq!(words(&deep_state) - words(&state), 1);
    let got = render::backward(&mut state, &color_only, acc).unwrap();
    let want = render::backward(&mut deep_state, &color_only, acc).unwrap();
    // Atomics sum in any order: equal up to the rounding of the order.
    let all = |g: &[Params]| g.iter().map(checks::words).collect::<Vec<_>>();
    let terms = checks::adjoint::backward_for::<Method>(&ps, &cam, &color_only).gross_params;
    checks::gradients::groups_match(
        "GPU, without and with the depth state",
        &all(&got.gradients.params),
        &all(&want.gradients.params),
        Some(&terms),
        &splat_runtime::param_groups::<Method>(),
        checks::gradients::ATOMIC_ORDER,
    );
}

/// With no transmittance stop (`t_min` 0, `splat tradeoff`'s reference) a deep stack drives
/// T below f32's normal range. The pixel stops at the smallest normal T instead of walking on
/// with T stuck at a denormal, whose division back in the backward pass overflowed to inf
/// and NaN: the gradients stay finite and match the default stop's, which leaves out less
/// than 1e-4 of each pixel's color.
#[test]
fn no_transmittance_stop_keeps_the_gradients_finite() {
    use splat_runtime::blend::{Blend, T_MIN};
    let cam = camera(16, 16);
    let mut rng = fastrand::Rng::with_seed(9);
    let ps: Vec<Params> = (0..400)
        .map(|k| {
            let z = 2.0 + 0.01 * k as f32;
            let mut g = gaussian_at(&mut rng, &cam, Vec2::new(8.0, 8.0), z, -0.5);
            g.opacity_logit = 0.0;
            g
        })
        .collect();
    let gradients = |t_min: f32| {
        let opts = RenderOptions {
            blend: Blend {
                t_min,
                ..Blend::default()
            },
            ..Default::default()
        };
        let (_, state) = render_for_backward::<Method>(&ps, &cam, &opts).unwrap();
        let grad = FrameGrad {
            color: vec![1.0; 16 * 16 * 3],
            alpha: None,
            depth: None,
        };
        let g = backward::<Method>(&state, &ps, &cam, &grad).unwrap();
        g.params
            .iter()
            .flat_map(checks::words)
            .collect::<Vec<f64>>()
    };
    let (deep, stopped) = (gradients(0.0), gradients(T_MIN));
    let largest = stopped.iter().fold(0.0f64, |m, g| m.max(g.abs()));
    for (k, (d, s)) in deep.iter().zip(&stopped).enumerate() {
        assert!(d.is_finite(), "word {k}: {d}");
        assert!((d - s).abs() <= 1e-3 * largest, "word {k}: {d} vs {s}");
    }
}

/// `backward` takes the parameters and camera a second time: another count, another camera or
/// a NaN output gradient is refused by name, not indexed out of bounds or turned into NaN (or,
/// on the GPU, zero) gradients. A resident frame knows the upload it was rendered from.
#[test]
fn backward_refuses_what_the_frame_was_not_rendered_with() {
    let (cam, ps) = (camera(40, 32), hard_scene());
    let n = 40 * 32;
    let grad = FrameGrad {
        color: vec![0.5; n * 3],
        alpha: None,
        depth: None,
    };
    let opts = RenderOptions::default();
    let (_, state) = render_for_backward::<Method>(&ps, &cam, &opts).unwrap();
    assert_eq!(
        backward::<Method>(&state, &ps[1..], &cam, &grad).err(),
        Some(RenderError::ParamsCount {
            got: ps.len() - 1,
            want: ps.len()
        })
    );
    let moved = splat_runtime::Camera {
        translation: cam.translation + Vec3::X,
        ..cam
    };
    assert_eq!(
        backward::<Method>(&state, &ps, &moved, &grad).err(),
        Some(RenderError::OtherCamera)
    );
    let mut nan = grad.clone();
    nan.color[7] = f32::NAN;
    assert_eq!(
        backward::<Method>(&state, &ps, &cam, &nan).err(),
        Some(RenderError::NonFiniteGradient {
            what: "color",
            index: 7
        })
    );
    backward::<Method>(&state, &ps, &cam, &grad).unwrap();

    let Some(gpu) = splat_runtime::gpu::adapter_or_skip() else {
        return;
    };
    use splat_runtime::gpu::{GpuRenderError, GpuRenderer, GpuScene, entries::Accumulation};
    let acc = Accumulation::default_for(&gpu);
    let mut scene = GpuScene::<Method>::new(&gpu, &ps).unwrap();
    let mut renderer = GpuRenderer::<Method>::new(&gpu, &opts).unwrap();
    renderer.forward(&scene, &cam).unwrap();
    assert!(matches!(
        renderer.backward(&scene, &nan, acc),
        Err(GpuRenderError::Render(
            RenderError::NonFiniteGradient { .. }
        ))
    ));
    let other = GpuScene::<Method>::new(&gpu, &ps).unwrap();
    assert!(matches!(
        renderer.backward(&other, &grad, acc),
        Err(GpuRenderError::OtherScene)
    ));
    scene.upload(&gpu, &ps).unwrap();
    assert!(matches!(
        renderer.backward(&scene, &grad, acc),
        Err(GpuRenderError::OtherScene)
    ));
    renderer.forward(&scene, &cam).unwrap();
    renderer.backward(&scene, &grad, acc).unwrap();
}

/// A camera's rotation must be one: a scaled, sheared or mirrored matrix (a pose with a
/// scale, OpenGL axes taken as OpenCV's) is refused, as the camera reader refuses it.
#[test]
fn a_camera_rotation_must_be_a_rotation() {
    let (cam, ps) = (camera(40, 32), hard_scene());
    let opts = RenderOptions::default();
    let with = |rotation| splat_runtime::Camera { rotation, ..cam };
    let scaled = with(cam.rotation * 2.0);
    let mirrored =
        with(splat_runtime::glam::Mat3::from_diagonal(Vec3::new(1.0, 1.0, -1.0)) * cam.rotation);
    for (c, why) in [(scaled, "no scale or shear"), (mirrored, "must not mirror")] {
        let e = render::<Method>(&ps, &c, &opts).err().unwrap().to_string();
        assert!(e.contains(why), "{e}");
    }
    render::<Method>(&ps, &cam, &opts).unwrap();
}
