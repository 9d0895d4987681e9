//! An independent f64 reference renderer: every visible primitive evaluated at every pixel in
//! depth order with the f64 twin of the method's functions; no tiles, no bounding boxes, no
//! tile culling; only the method's own thresholds and the blend's stopping rule.

#![allow(dead_code)]

use splat_methods::gs3d::{self, Params};
use splat_runtime::glam::{Mat3, Quat, Vec2, Vec3, Vec4};
use splat_runtime::{Camera, Flat};

pub const T_MIN: f64 = 1e-4;

/// A camera's slots in the order the compiler flattens `Camera`.
pub fn camera_words(c: &Camera) -> Vec<f64> {
    let mut w = vec![0.0f32; Camera::LEN];
    c.write_words(&mut w);
    w.into_iter().map(f64::from).collect()
}

pub fn param_words(p: &Params) -> Vec<f64> {
    let mut w = vec![0.0f32; Params::LEN];
    p.write_words(&mut w);
    w.into_iter().map(f64::from).collect()
}

pub struct Reference {
    pub width: usize,
    pub height: usize,
    pub color: Vec<f64>,
    pub alpha: Vec<f64>,
    pub depth: Vec<f64>,
}

/// Renders `params` (flat f64 parameter words per primitive) through `camera` (flat words).
pub fn render(params: &[Vec<f64>], camera: &[f64]) -> Reference {
    let (width, height) = (camera[16] as usize, camera[17] as usize);
    let mut prims: Vec<(f64, usize, [f64; 9])> = vec![];
    for (i, p) in params.iter().enumerate() {
        let mut input = [0.0; 77];
        input[..59].copy_from_slice(p);
        input[59..].copy_from_slice(camera);
        let (f, b) = gs3d::twin::project(&input, &[]);
        if b[0] == 0 || !f[0].is_finite() {
            continue;
        }
        let mut shade = [0.0; 9];
        shade.copy_from_slice(&f[11..20]);
        prims.push((f[0], i, shade));
    }
    prims.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let mut out = Reference {
        width,
        height,
        color: vec![0.0; width * height * 3],
        alpha: vec![0.0; width * height],
        depth: vec![0.0; width * height],
    };
    for y in 0..height {
        for x in 0..width {
            let (mut t, mut c, mut d) = (1.0f64, [0.0f64; 3], 0.0f64);
            for (depth, _, shade) in &prims {
                let mut input = [0.0; 11];
                input[0] = x as f64 + 0.5;
                input[1] = y as f64 + 0.5;
                input[2..].copy_from_slice(shade);
                let (o, valid) = gs3d::twin::evaluate(&input, &[]);
                if valid[0] == 0 {
                    continue;
                }
                let next = t * (1.0 - o[0]);
                if next <= T_MIN {
                    break;
                }
                for ch in 0..3 {
                    c[ch] += o[0] * t * o[1 + ch];
                }
                d += o[0] * t * depth;
                t = next;
            }
            let px = y * width + x;
            out.color[px * 3..px * 3 + 3].copy_from_slice(&c);
            out.alpha[px] = 1.0 - t;
            out.depth[px] = if t < 1.0 { d / (1.0 - t) } else { 0.0 };
        }
    }
    out
}

pub fn camera(width: u32, height: u32) -> Camera {
    Camera {
        rotation: Mat3::IDENTITY,
        translation: Vec3::ZERO,
        focal: Vec2::splat(width as f32),
        principal: Vec2::new(width as f32 / 2.0, height as f32 / 2.0),
        size: Vec2::new(width as f32, height as f32),
    }
}

/// A random Gaussian whose centre projects to `pixel` at depth `z` (camera at the origin,
/// looking down +z, as built by [`camera`]).
pub fn gaussian_at(
    rng: &mut fastrand::Rng,
    cam: &Camera,
    pixel: Vec2,
    z: f32,
    log_scale: f32,
) -> Params {
    let ndc = (pixel - cam.principal) / cam.focal;
    let q = Quat::from_xyzw(
        rng.f32() - 0.5,
        rng.f32() - 0.5,
        rng.f32() - 0.5,
        rng.f32() + 0.2,
    )
    .normalize();
    let mut sh = [Vec3::ZERO; 16];
    for c in sh.iter_mut() {
        *c = Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5) * 0.6;
    }
    Params {
        mean: Vec3::new(ndc.x * z, ndc.y * z, z),
        log_scale: Vec3::new(
            log_scale + rng.f32() * 0.6,
            log_scale + rng.f32() * 0.6,
            log_scale + rng.f32() * 0.6,
        ),
        rotation: Vec4::new(q.w, q.x, q.y, q.z),
        opacity_logit: rng.f32() * 4.0 - 1.5,
        sh,
    }
}

/// max |a - b| / max |b| over a group of gradients.
pub fn group_error(got: &[f64], want: &[f64]) -> f64 {
    let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-12);
    got.iter()
        .zip(want)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()))
        / scale
}
