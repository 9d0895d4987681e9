//! A method with `pixel_info` (per-pixel rays, maximum response along the ray): CPU renders
//! against an f64 brute-force reference built from the twin of all three functions, and the
//! GPU path (pixel_info and evaluate in WGSL, the camera bound) against the CPU.

use splat_examples::rays::rays::{self, Method, Params};
use splat_runtime::glam::{Mat3, Vec2, Vec3};
use splat_runtime::{Camera, Flat, RenderOptions, render};

fn scene() -> (Camera, Vec<Params>) {
    let (w, h) = (40.0, 32.0);
    let cam = Camera {
        rotation: Mat3::from_rotation_y(0.1),
        translation: Vec3::new(0.1, -0.05, 0.2),
        focal: Vec2::splat(36.0),
        principal: Vec2::new(w / 2.0, h / 2.0),
        size: Vec2::new(w, h),
        ..Default::default()
    };
    let mut rng = fastrand::Rng::with_seed(12);
    let params = (0..40)
        .map(|_| Params {
            mean: Vec3::new(
                rng.f32() * 2.4 - 1.2,
                rng.f32() * 2.0 - 1.0,
                3.0 + 2.0 * rng.f32(),
            ),
            log_radius: -2.0 + 0.8 * rng.f32(),
            color: Vec3::new(rng.f32(), rng.f32(), rng.f32()),
            opacity_logit: rng.f32() * 3.0 - 1.0,
        })
        .collect();
    (cam, params)
}

#[test]
fn rays_match_an_f64_reference() {
    let (cam, params) = scene();
    let cw = cam.float_slots().map(f64::from);
    let mut prims = vec![];
    for p in &params {
        let mut w = vec![0.0f32; Params::LEN];
        p.write_words(&mut w);
        let mut input = [0.0f64; 8 + Camera::FLOAT_SLOTS];
        for (d, s) in input.iter_mut().zip(&w) {
            *d = *s as f64;
        }
        input[8..].copy_from_slice(&cw);
        let (out, flags) = rays::twin::project(&input, &[cam.model as u32]);
        if flags[0] != 0 {
            prims.push((out[0], out[6..14].to_vec()));
        }
    }
    prims.sort_by(|a, b| a.0.total_cmp(&b.0));
    let frame = render::<Method>(
        &params,
        &cam,
        &RenderOptions {
            tile_size: 8,
            ..Default::default()
        },
    )
    .unwrap();
    let (w, h) = (cam.size.x as usize, cam.size.y as usize);
    let mut covered = 0;
    for y in 0..h {
        for x in 0..w {
            let mut pin = [0.0f64; 2 + Camera::FLOAT_SLOTS];
            pin[0] = x as f64 + 0.5;
            pin[1] = y as f64 + 0.5;
            pin[2..].copy_from_slice(&cw);
            let (ray, _) = rays::twin::pixel_info(&pin, &[cam.model as u32]);
            let (mut t, mut c) = (1.0f64, [0.0f64; 3]);
            for (_, shade) in &prims {
                let mut input = [0.0f64; 14];
                input[..6].copy_from_slice(&ray);
                input[6..].copy_from_slice(shade);
                let (o, valid) = rays::twin::evaluate(&input, &[]);
                if valid[0] == 0 {
                    continue;
                }
                let next = t * (1.0 - o[0]);
                if next <= 1e-4 {
                    break;
                }
                for (acc, color) in c.iter_mut().zip(&o[1..4]) {
                    *acc += o[0] * t * color;
                }
                t = next;
            }
            covered += (t < 0.9) as usize;
            for (ch, want) in c.iter().enumerate() {
                let got = frame.color.data[(y * w + x) * 3 + ch] as f64;
                assert!(
                    (got - want).abs() <= 1e-5 + 0.01 * want.abs(),
                    "({x}, {y}) ch {ch}: {got} vs {want}"
                );
            }
        }
    }
    assert!(
        covered > w * h / 5,
        "the scene should cover the image ({covered} pixels)"
    );
}

#[test]
fn rays_on_the_gpu_match_the_cpu() {
    let Some(gpu) = splat_runtime::gpu::adapter_or_skip() else {
        return;
    };
    let (cam, params) = scene();
    let opts = RenderOptions {
        tile_size: 16,
        alpha: true,
        ..Default::default()
    };
    let cpu = render::<Method>(&params, &cam, &opts).unwrap();
    let g = splat_runtime::gpu::render::render::<Method>(&gpu, &params, &cam, &opts).unwrap();
    for (a, b) in cpu.color.data.iter().zip(&g.color.data) {
        assert!((a - b).abs() <= 1e-4 + 0.01 * a.abs(), "cpu {a} gpu {b}");
    }
}
