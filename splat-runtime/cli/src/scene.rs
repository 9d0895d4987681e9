//! The built-in scene: a ringed planet of a few thousand Gaussians (banded sphere, tilted
//! ring, a moon, stars all around), and a camera looking at it, so `splat render` runs with no
//! files.

use splat_runtime::glam::{Mat3, Vec2, Vec3, Vec4};
use splat_runtime::io::ply::{GaussianCloud, StoredGaussian};
use splat_runtime::{Camera, CameraModel};

/// SH DC coefficient for a target color (color = 0.5 + C0 * dc).
fn dc(color: Vec3) -> Vec3 {
    (color - 0.5) / 0.282_094_8
}

fn logit(p: f32) -> f32 {
    (p / (1.0 - p)).ln()
}

/// A tiny deterministic generator, so the scene is the same everywhere.
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 40) as f32) / (1u64 << 24) as f32
    }
}

fn gaussian(
    mean: Vec3,
    scale: f32,
    color: Vec3,
    opacity: f32,
    view_dependence: Vec3,
) -> StoredGaussian {
    let mut sh = [Vec3::ZERO; 16];
    sh[0] = dc(color);
    // A little view-dependent sheen along x (degree-1 term).
    sh[3] = view_dependence;
    StoredGaussian {
        mean,
        log_scale: Vec3::splat(scale.ln()),
        rotation: Vec4::new(1.0, 0.0, 0.0, 0.0),
        opacity_logit: logit(opacity),
        sh,
    }
}

pub fn planet() -> GaussianCloud {
    let mut rng = Lcg(7);
    let mut out = vec![];
    // The planet: points on a sphere, colored by latitude bands.
    let bands = [
        Vec3::new(0.85, 0.70, 0.45),
        Vec3::new(0.75, 0.50, 0.30),
        Vec3::new(0.95, 0.85, 0.65),
        Vec3::new(0.65, 0.40, 0.25),
    ];
    for _ in 0..2600 {
        let z = rng.next() * 2.0 - 1.0;
        let phi = rng.next() * std::f32::consts::TAU;
        let r = (1.0 - z * z).sqrt();
        let n = Vec3::new(r * phi.cos(), z, r * phi.sin());
        let band = ((z + 1.0) * 5.0) as usize % bands.len();
        let c = bands[band] * (0.9 + 0.2 * rng.next());
        out.push(gaussian(n, 0.07, c, 0.9, Vec3::new(-0.1, -0.1, -0.1)));
    }
    // The ring, tilted by 20 degrees.
    let tilt = Mat3::from_rotation_x(-0.35);
    for _ in 0..5000 {
        let rad = 1.45 + rng.next() * 0.7;
        let phi = rng.next() * std::f32::consts::TAU;
        let p = tilt * Vec3::new(rad * phi.cos(), 0.0, rad * phi.sin());
        let shade = 0.6 + 0.4 * ((rad - 1.45) * 9.0).sin().abs();
        let c = Vec3::new(0.9, 0.85, 0.75) * shade;
        let mut g = gaussian(p, 0.045, c, 0.5, Vec3::ZERO);
        g.log_scale = Vec3::new(0.045f32.ln(), 0.004f32.ln(), 0.045f32.ln());
        // Flat in the ring's plane: rotate the thin axis (y) by the tilt.
        let (s, c) = ((-0.175f32).sin(), (-0.175f32).cos());
        g.rotation = Vec4::new(c, s, 0.0, 0.0);
        out.push(g);
    }
    // A moon.
    for _ in 0..300 {
        let d = Vec3::new(rng.next() - 0.5, rng.next() - 0.5, rng.next() - 0.5).normalize_or_zero();
        out.push(gaussian(
            Vec3::new(2.4, 0.9, -0.6) + d * 0.22,
            0.04,
            Vec3::splat(0.8),
            0.95,
            Vec3::ZERO,
        ));
    }
    // Stars on a sphere of radius 25 around the camera's target, in every direction: what a
    // wide camera sees beyond the planet (a fisheye past 180 degrees sees some behind it).
    for _ in 0..1500 {
        let z = rng.next() * 2.0 - 1.0;
        let phi = rng.next() * std::f32::consts::TAU;
        let r = (1.0 - z * z).sqrt();
        let warm = rng.next();
        let c = Vec3::new(0.8 + 0.2 * warm, 0.85, 1.0 - 0.2 * warm);
        out.push(gaussian(
            Vec3::new(r * phi.cos(), z, r * phi.sin()) * 25.0,
            0.04 + 0.05 * rng.next(),
            c,
            0.9,
            Vec3::ZERO,
        ));
    }
    GaussianCloud {
        sh_degree: 1,
        gaussians: out,
    }
}

/// Looks at the origin from slightly above the ring plane, 6 units away: a pinhole with a
/// 58° horizontal field of view, a nearly equidistant fisheye seeing 183° across and 225°
/// diagonally, or a 126° equiangular camera.
pub fn camera(width: u32, height: u32, model: CameraModel) -> Camera {
    let eye = Vec3::new(0.0, 1.5, -5.8);
    let forward = (-eye).normalize();
    let right = Vec3::Y.cross(forward).normalize() * -1.0;
    let down = forward.cross(right);
    // Rows of the world-to-camera rotation are the camera axes (x right, y down, z forward).
    let rotation = Mat3::from_cols(right, down, forward).transpose();
    let w = width as f32;
    let (f, distortion) = match model {
        CameraModel::Pinhole => (0.9 * w, Vec4::ZERO),
        CameraModel::KannalaBrandt => (0.3 * w, Vec4::new(0.02, -0.002, 0.0002, -0.00001)),
        CameraModel::Equiangular => (0.45 * w, Vec4::ZERO),
    };
    Camera {
        rotation,
        translation: -(rotation * eye),
        focal: Vec2::splat(f),
        principal: Vec2::new(w / 2.0, height as f32 / 2.0),
        size: Vec2::new(w, height as f32),
        distortion,
        model,
    }
}
