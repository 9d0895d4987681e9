//! The CPU pipeline's 3DGS renders against the f64 brute-force reference: within
//! 1e-5 absolute + 1% relative per element, for tile sizes 8 and 16.

use crate::common::{camera, gaussian_at};
use splat_methods::gs3d::{Method, Params};
use splat_runtime::checks::forward::forward_matches_reference;
use splat_runtime::glam::Vec2;
use splat_runtime::{Camera, RenderOptions, render};

fn compare(name: &str, params: &[Params], cam: &Camera) {
    let coverage = forward_matches_reference::<Method>(name, params, cam);
    assert!(coverage > 0.2, "{name}: the scene should cover the image");
}

#[test]
fn random_scene_with_sh_degree_3() {
    let mut rng = fastrand::Rng::with_seed(1);
    let cam = camera(64, 48);
    let params: Vec<Params> = (0..120)
        .map(|_| {
            let px = Vec2::new(rng.f32() * 80.0 - 8.0, rng.f32() * 64.0 - 8.0);
            let z = 2.0 + rng.f32() * 6.0;
            gaussian_at(&mut rng, &cam, px, z, -2.0)
        })
        .collect();
    compare("random", &params, &cam);
}

#[test]
fn overlapping_and_screen_covering_gaussians() {
    let mut rng = fastrand::Rng::with_seed(2);
    let cam = camera(48, 40);
    let mut params: Vec<Params> = (0..40)
        .map(|_| {
            let px = Vec2::new(24.0, 20.0) + (Vec2::new(rng.f32(), rng.f32()) - 0.5) * 10.0;
            let z = 3.0 + rng.f32();
            gaussian_at(&mut rng, &cam, px, z, -2.5)
        })
        .collect();
    // Larger than the image, and one behind the camera.
    params.push(gaussian_at(&mut rng, &cam, Vec2::new(10.0, 30.0), 2.0, 0.3));
    params.push(gaussian_at(&mut rng, &cam, Vec2::new(30.0, 5.0), 9.0, 1.0));
    let mut behind = gaussian_at(&mut rng, &cam, Vec2::new(20.0, 20.0), 2.0, -2.0);
    behind.mean.z = -2.0;
    params.push(behind);
    compare("overlapping", &params, &cam);
}

#[test]
fn gaussians_straddling_tile_boundaries() {
    let mut rng = fastrand::Rng::with_seed(3);
    let cam = camera(72, 40);
    let mut params = vec![];
    for ty in 0..=5 {
        for tx in 0..=9 {
            let px = Vec2::new(tx as f32 * 8.0, ty as f32 * 8.0);
            let z = 3.0 + rng.f32() * 3.0;
            params.push(gaussian_at(&mut rng, &cam, px, z, -2.3));
        }
    }
    compare("straddling", &params, &cam);
}

/// The blend's thresholds as renderer options: raised, they change the image as the reference
/// with the same rule says, on the CPU and the GPU, forward and backward; at their defaults
/// the image is bit for bit the one rendered without naming them.
#[test]
fn blend_thresholds_follow_the_reference_on_cpu_and_gpu() {
    use splat_runtime::blend::{Blend, T_MIN};
    use splat_runtime::checks::forward::{
        forward_matches_reference_with, gpu_forward_matches_cpu_with,
    };
    use splat_runtime::checks::gradients::gpu_gradients_match_cpu_with;

    let mut rng = fastrand::Rng::with_seed(4);
    let cam = camera(48, 40);
    // Dense enough that pixels reach every T-stop below and many pairs are faint.
    let params: Vec<Params> = (0..400)
        .map(|_| {
            let px = Vec2::new(rng.f32() * 56.0 - 4.0, rng.f32() * 48.0 - 4.0);
            let z = 2.0 + rng.f32() * 4.0;
            let mut g = gaussian_at(&mut rng, &cam, px, z, -2.0);
            g.opacity_logit = 1.0 + 4.0 * rng.f32();
            g
        })
        .collect();
    let opts = RenderOptions::default();
    let named = RenderOptions {
        blend: Blend {
            t_min: T_MIN,
            alpha_min: 0.0,
        },
        ..opts
    };
    assert_eq!(
        render::<Method>(&params, &cam, &opts).unwrap().color.data,
        render::<Method>(&params, &cam, &named).unwrap().color.data
    );
    let default_image = render::<Method>(&params, &cam, &opts).unwrap().color.data;
    for blend in [
        Blend {
            t_min: 0.0,
            alpha_min: 0.0,
        },
        Blend {
            t_min: 0.05,
            alpha_min: 0.0,
        },
        Blend {
            t_min: T_MIN,
            alpha_min: 0.1,
        },
    ] {
        let label = format!("{blend:?}");
        forward_matches_reference_with::<Method>(&label, &params, &cam, blend);
        gpu_forward_matches_cpu_with::<Method>(&label, &params, &cam, blend);
        gpu_gradients_match_cpu_with::<Method>(&label, &params, &cam, blend);
        let changed = RenderOptions { blend, ..opts };
        let image = render::<Method>(&params, &cam, &changed)
            .unwrap()
            .color
            .data;
        let moved = image
            .iter()
            .zip(&default_image)
            .filter(|(a, b)| a != b)
            .count();
        assert!(moved > 100, "{label}: only {moved} color values moved");
    }
    let bad = RenderOptions {
        blend: Blend {
            t_min: 1.0,
            alpha_min: 0.0,
        },
        ..opts
    };
    let Err(err) = render::<Method>(&params, &cam, &bad) else {
        panic!("t_min 1 was accepted");
    };
    let err = err.to_string();
    assert!(
        err.contains("t_min and alpha_min must be in [0, 1)"),
        "{err}"
    );
}

/// StopThePop's tile cull drops only pairs the 1/255 threshold would skip, on every camera
/// model and with anti-aliasing (whose opacity, and so its cull radius, is compensated), and
/// it drops some: elongated, turned Gaussians leave tiles of their boxes unreached.
#[test]
fn the_stop_the_pop_cull_is_conservative() {
    use crate::common::{as_method, spread_gaussians, wide_camera};
    use splat_runtime::CameraModel;
    use splat_runtime::checks::forward::tile_cull_is_conservative;
    for model in CameraModel::ALL {
        let cam = wide_camera(64, 48, model);
        let scene = spread_gaussians(&cam, 150, 41);
        let label = format!("3dgs {model}");
        let counts = tile_cull_is_conservative::<Method>(&label, &scene, &cam);
        let aa = as_method::<splat_methods::gs3d_aa::Params>(scene);
        let label = format!("3dgs-aa {model}");
        let counts_aa =
            tile_cull_is_conservative::<splat_methods::gs3d_aa::Method>(&label, &aa, &cam);
        for (with, without) in counts.into_iter().chain(counts_aa) {
            assert!(
                with < without,
                "{label}: the cull dropped nothing ({with} of {without})"
            );
        }
    }
}
