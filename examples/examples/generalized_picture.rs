//! The README picture of generalized exponential splats: four splats of equal size, opacity
//! and color with shape β = 1, 2 (a Gaussian), 4 and 8, left to right, rendered on the CPU.
//!
//! `cargo run --release -p splat-examples --example generalized_picture -- examples/images/generalized.png`

use splat_examples::generalized::generalized::{Method, Params};
use splat_runtime::glam::{Mat3, Vec2, Vec3, Vec4};
use splat_runtime::{Camera, RenderOptions, io::image::write_frame, render};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "generalized.png".into());
    let (w, h, focal, z) = (480.0, 160.0, 400.0, 4.0);
    let cam = Camera {
        rotation: Mat3::IDENTITY,
        translation: Vec3::ZERO,
        focal: Vec2::splat(focal),
        principal: Vec2::new(w / 2.0, h / 2.0),
        size: Vec2::new(w, h),
        ..Default::default()
    };
    // sigma = 18 px on screen; color (1.0, 0.6, 0.2) through the SH DC term (c - 0.5) / Y00.
    let (sigma_px, color) = (18.0, Vec3::new(1.0, 0.6, 0.2));
    let splats: Vec<Params> = [1.0f32, 2.0, 4.0, 8.0]
        .iter()
        .enumerate()
        .map(|(i, beta)| {
            let px = Vec2::new(60.0 + 120.0 * i as f32, h / 2.0);
            let ndc = (px - cam.principal) / cam.focal;
            let mut sh = [Vec3::ZERO; 4];
            sh[0] = (color - 0.5) / 0.282_094_8;
            Params {
                mean: Vec3::new(ndc.x * z, ndc.y * z, z),
                log_scale: Vec3::splat((sigma_px * z / focal).ln()),
                rotation: Vec4::new(1.0, 0.0, 0.0, 0.0),
                opacity_logit: (0.95f32 / 0.05).ln(),
                log_shape_half: (beta / 2.0).ln(),
                sh,
            }
        })
        .collect();
    let frame = render::<Method>(&splats, &cam, &RenderOptions::default())?;
    for path in write_frame(out.as_ref(), &frame)? {
        println!("wrote {}", path.display());
    }
    Ok(())
}
