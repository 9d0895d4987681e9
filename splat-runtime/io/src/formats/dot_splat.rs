//! antimatter15's `.splat`, the format many web viewers load: 32 bytes a Gaussian and no
//! header. Position (3 f32), linear scale (3 f32, the exp of the log scale), color and opacity
//! as RGBA bytes (`0.5 + SH_C0 dc` and the sigmoid, times 255), the unit rotation as 4 bytes
//! (w, x, y, z, each `q 128 + 128`). It keeps no SH beyond the DC term, no SH degree and no
//! flag; colors outside [0, 1] clamp. Written in the cloud's order (antimatter15's converter
//! sorts by size times opacity, for progressive loading; viewers sort by depth anyway), each
//! byte rounded to the nearest.

use crate::ply::{GaussianCloud, StoredGaussian};
use glam::{Vec3, Vec4};
use std::io::Write;

/// Bytes per Gaussian.
pub const RECORD: usize = 32;

/// The DC term's factor: color = 0.5 + SH_C0 dc.
const SH_C0: f32 = 0.282_094_8;

/// `bytes` as a cloud of SH degree 0; `None` with why when they are not a `.splat` file.
pub fn parse(bytes: &[u8]) -> Result<GaussianCloud, String> {
    if bytes.is_empty() || !bytes.len().is_multiple_of(RECORD) {
        return Err(format!(
            "{} bytes are not a .splat file (a whole number of {RECORD}-byte Gaussians, at least one)",
            bytes.len()
        ));
    }
    let gaussians = (bytes.chunks_exact(RECORD).enumerate())
        .map(|(i, r)| {
            let f = |k: usize| f32::from_le_bytes(r[4 * k..4 * k + 4].try_into().expect("4 bytes"));
            let mean = Vec3::new(f(0), f(1), f(2));
            let scale = Vec3::new(f(3), f(4), f(5));
            if !mean.is_finite() || !scale.is_finite() || scale.min_element() <= 0.0 {
                return Err(format!(
                    "Gaussian {i}: position {mean} and scale {scale} must be finite, the scale positive"
                ));
            }
            let byte = |k: usize| r[24 + k] as f32 / 255.0;
            let mut sh = [Vec3::ZERO; 16];
            sh[0] = (Vec3::new(byte(0), byte(1), byte(2)) - 0.5) / SH_C0;
            // Half a step in from 0 and 1, so that the logit stays finite.
            let alpha = byte(3).clamp(0.5 / 255.0, 1.0 - 0.5 / 255.0);
            let q = Vec4::from_array([28, 29, 30, 31].map(|k| (r[k] as f32 - 128.0) / 128.0));
            Ok(StoredGaussian {
                mean,
                log_scale: Vec3::new(scale.x.ln(), scale.y.ln(), scale.z.ln()),
                rotation: q.try_normalize().unwrap_or(Vec4::X),
                opacity_logit: (alpha / (1.0 - alpha)).ln(),
                sh,
            })
        })
        .collect::<Result<_, _>>()?;
    Ok(GaussianCloud::new(0, gaussians))
}

/// Writes `cloud` as `.splat` records (its SH beyond the DC term left out). Refused: a NaN or
/// infinite value.
pub fn write_to(w: &mut dyn Write, cloud: &GaussianCloud) -> std::io::Result<()> {
    let byte = |v: f32| (v * 255.0).round().clamp(0.0, 255.0) as u8;
    cloud.check_finite()?;
    for g in &cloud.gaussians {
        let mut record = [0u8; RECORD];
        let scale = g.log_scale.exp();
        for (k, v) in g
            .mean
            .to_array()
            .into_iter()
            .chain(scale.to_array())
            .enumerate()
        {
            record[4 * k..4 * k + 4].copy_from_slice(&v.to_le_bytes());
        }
        let color = g.sh[0] * SH_C0 + 0.5;
        let alpha = 1.0 / (1.0 + (-g.opacity_logit).exp());
        record[24..28].copy_from_slice(&[byte(color.x), byte(color.y), byte(color.z), byte(alpha)]);
        let q = g.rotation.try_normalize().unwrap_or(Vec4::X);
        let q = q
            .to_array()
            .map(|c| (c * 128.0 + 128.0).round().clamp(0.0, 255.0) as u8);
        record[28..32].copy_from_slice(&q);
        w.write_all(&record)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud() -> GaussianCloud {
        let mut rng = fastrand::Rng::with_seed(7);
        let mut r = |s: f32| (rng.f32() - 0.5) * 2.0 * s;
        let gaussians = (0..200)
            .map(|_| {
                let mut sh = [Vec3::ZERO; 16];
                sh[0] = Vec3::new(r(1.5), r(1.5), r(1.5));
                sh[1] = Vec3::splat(r(0.3));
                StoredGaussian {
                    mean: Vec3::new(r(10.0), r(10.0), r(10.0)),
                    log_scale: Vec3::new(r(4.0), r(4.0), r(4.0)),
                    rotation: Vec4::new(r(1.0), r(1.0), r(1.0), r(1.0)),
                    opacity_logit: r(6.0),
                    sh,
                }
            })
            .collect();
        GaussianCloud::new(1, gaussians)
    }

    #[test]
    fn a_round_trip_keeps_each_gaussian_within_a_byte_step() {
        let before = cloud();
        let mut bytes = vec![];
        write_to(&mut bytes, &before).unwrap();
        assert_eq!(bytes.len(), RECORD * before.gaussians.len());
        let after = parse(&bytes).unwrap();
        assert_eq!(after.sh_degree, 0);
        let sigmoid = |x: f32| 1.0 / (1.0 + (-x).exp());
        for (a, b) in before.gaussians.iter().zip(&after.gaussians) {
            assert_eq!(a.mean, b.mean);
            assert!((a.log_scale - b.log_scale).abs().max_element() < 1e-5);
            // Colors within half a byte step, where they are not clamped.
            let color = a.sh[0] * SH_C0 + 0.5;
            let kept = color.clamp(Vec3::ZERO, Vec3::ONE);
            let back = b.sh[0] * SH_C0 + 0.5;
            assert!(
                (kept - back).abs().max_element() <= 0.5 / 255.0 + 1e-6,
                "{kept} {back}"
            );
            let (pa, pb) = (sigmoid(a.opacity_logit), sigmoid(b.opacity_logit));
            assert!((pa.clamp(0.5 / 255.0, 1.0 - 0.5 / 255.0) - pb).abs() <= 0.5 / 255.0 + 1e-6);
            // The rotation within half a step of 1/128 per component (the same sign).
            let qa = a.rotation.normalize();
            assert!(
                (qa - b.rotation).abs().max_element() < 1.5 / 128.0,
                "{qa} {}",
                b.rotation
            );
            assert_eq!(b.sh[1], Vec3::ZERO);
        }
    }

    #[test]
    fn what_is_not_a_splat_file_is_refused() {
        assert!(parse(&[]).unwrap_err().contains("at least one"));
        assert!(parse(&[0; 33]).unwrap_err().contains("33 bytes"));
        let mut zero_scale = vec![0u8; RECORD];
        zero_scale[28] = 255;
        assert!(parse(&zero_scale).unwrap_err().contains("scale positive"));
        let mut bad = cloud();
        bad.gaussians[3].mean.x = f32::NAN;
        let err = write_to(&mut vec![], &bad).unwrap_err();
        assert!(err.to_string().contains("Gaussian 3"));
    }
}
