//! A 16-channel feature method renders through the same runtime: every channel matches a
//! per-pixel f64 front-to-back blend of the method's own f64 twin.

use splat_examples::features::features::{self, Method, Params};
use splat_runtime::glam::{Mat3, Vec2, Vec3};
use splat_runtime::{Camera, Flat, RenderOptions, render};

#[test]
fn sixteen_channels_match_an_f64_blend() {
    let (w, h) = (24u32, 20u32);
    let cam = Camera {
        rotation: Mat3::IDENTITY,
        translation: Vec3::ZERO,
        focal: Vec2::splat(24.0),
        principal: Vec2::new(12.0, 10.0),
        size: Vec2::new(w as f32, h as f32),
        ..Default::default()
    };
    let mut rng = fastrand::Rng::with_seed(8);
    let params: Vec<Params> = (0..30)
        .map(|_| Params {
            mean: Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, 1.5 + rng.f32()),
            log_radius: -2.5 + rng.f32(),
            opacity_logit: rng.f32() * 3.0 - 1.0,
            feature: std::array::from_fn(|_| rng.f32()),
        })
        .collect();
    let frame = render::<Method>(
        &params,
        &cam,
        &RenderOptions {
            tile_size: 8,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(frame.color.channels, 16);

    // Reference: project every primitive with the f64 twin, sort by depth, blend per pixel.
    let cam_words = cam.float_slots().map(f64::from);
    let mut shades = vec![];
    for p in &params {
        let mut words = vec![0.0f32; Params::LEN];
        p.write_words(&mut words);
        let mut input = [0.0f64; 21 + Camera::FLOAT_SLOTS];
        for (d, s) in input.iter_mut().zip(&words) {
            *d = *s as f64;
        }
        input[21..].copy_from_slice(&cam_words);
        let (out, flags) = features::twin::project(&input, &[cam.model as u32]);
        if flags[0] != 0 {
            // Outputs: depth, bbox (4), cull (1), then the shade (20 words).
            shades.push((out[0], out[6..26].to_vec()));
        }
    }
    shades.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut worst = 0.0f64;
    for y in 0..h as usize {
        for x in 0..w as usize {
            let (mut t, mut acc) = (1.0f64, [0.0f64; 16]);
            for (_, shade) in &shades {
                let mut input = [0.0f64; 22];
                input[0] = x as f64 + 0.5;
                input[1] = y as f64 + 0.5;
                input[2..].copy_from_slice(shade);
                let (o, valid) = features::twin::evaluate(&input, &[]);
                if valid[0] == 0 {
                    continue;
                }
                let next = t * (1.0 - o[0]);
                if next <= 1e-4 {
                    break;
                }
                for (a, f) in acc.iter_mut().zip(&o[1..17]) {
                    *a += o[0] * t * f;
                }
                t = next;
            }
            for (k, want) in acc.iter().enumerate() {
                let got = frame.color.data[(y * w as usize + x) * 16 + k] as f64;
                let err = (got - want).abs();
                assert!(
                    err <= 1e-5 + 0.01 * want.abs(),
                    "pixel ({x}, {y}) channel {k}: {got} vs {want}"
                );
                worst = worst.max(err);
            }
        }
    }
    let mean: f32 = frame.color.data.iter().sum::<f32>() / frame.color.data.len() as f32;
    assert!(
        mean > 0.05,
        "the scene should cover the image (mean feature {mean})"
    );
    println!("16 channels: worst abs error {worst:.2e}");
}
