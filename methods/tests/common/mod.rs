//! Scenes and cameras the method tests share (the checks themselves are the public
//! `splat_runtime::checks`).

#![allow(dead_code)]

use splat_methods::gs3d::Params;
use splat_runtime::glam::{Mat3, Quat, Vec2, Vec3, Vec4};
use splat_runtime::{Camera, CameraModel};

pub fn camera(width: u32, height: u32) -> Camera {
    Camera {
        rotation: Mat3::IDENTITY,
        translation: Vec3::ZERO,
        focal: Vec2::splat(width as f32),
        principal: Vec2::new(width as f32 / 2.0, height as f32 / 2.0),
        size: Vec2::new(width as f32, height as f32),
        ..Default::default()
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

/// A camera at the origin looking down +z with the given model; the fisheye and equiangular
/// cameras see wide: past 90 degrees off axis in the fisheye's corners.
pub fn wide_camera(width: u32, height: u32, model: CameraModel) -> Camera {
    let focal = match model {
        CameraModel::Pinhole => width as f32,
        CameraModel::KannalaBrandt => width as f32 / 3.2,
        CameraModel::Equiangular => width as f32 / 2.6,
    };
    Camera {
        focal: Vec2::splat(focal),
        distortion: match model {
            CameraModel::KannalaBrandt => Vec4::new(0.02, -0.002, 0.0002, -0.00001),
            _ => Vec4::ZERO,
        },
        model,
        ..camera(width, height)
    }
}

/// Like [`gaussian_at`], with the centre on `pixel`'s ray at `distance` (any camera model,
/// camera at the origin).
pub fn gaussian_toward(
    rng: &mut fastrand::Rng,
    cam: &Camera,
    pixel: Vec2,
    distance: f32,
    log_scale: f32,
) -> Params {
    let mut p = gaussian_at(rng, cam, pixel, distance, log_scale);
    p.mean = cam.pixel_ray(pixel) * distance;
    p
}

/// Parameter groups of the 3DGS-like methods (word ranges of `Params`).
pub const GAUSSIAN_GROUPS: [(&str, std::ops::Range<usize>); 5] = [
    ("mean", 0..3),
    ("log_scale", 3..6),
    ("rotation", 6..10),
    ("opacity", 10..11),
    ("sh", 11..59),
];

/// Camera groups (ranges of its float slots); distortion only matters for the fisheye.
pub const CAMERA_GROUPS: [(&str, std::ops::Range<usize>); 5] = [
    ("rotation", 0..9),
    ("translation", 9..12),
    ("focal", 12..14),
    ("principal", 14..16),
    ("distortion", 18..22),
];

/// The rolling shutter's camera groups (ranges of its float slots).
pub const SHUTTER_GROUPS: [(&str, std::ops::Range<usize>); 2] =
    [("shutter_turn", 22..25), ("shutter_shift", 25..28)];

/// The camera groups a model's gradient has: the distortion coefficients only on the fisheye.
pub fn camera_groups(model: CameraModel) -> &'static [(&'static str, std::ops::Range<usize>)] {
    if model == CameraModel::KannalaBrandt {
        &CAMERA_GROUPS[..]
    } else {
        &CAMERA_GROUPS[..4]
    }
}

/// The same Gaussians as another method's parameters, through the method's own `FromStored`
/// (what the CLI does with a PLY scene).
pub fn as_method<P: splat_methods::FromStored>(gaussians: Vec<Params>) -> Vec<P> {
    gaussians
        .into_iter()
        .map(|g| {
            P::from_stored(&splat_runtime::io::ply::StoredGaussian {
                mean: g.mean,
                log_scale: g.log_scale,
                rotation: g.rotation,
                opacity_logit: g.opacity_logit,
                sh: g.sh,
            })
        })
        .collect()
}

/// Gaussians spread over the whole image (and past its edges) of a camera at the origin, 1.5
/// to 6 units away; larger on the wide cameras, which have fewer pixels per radian.
pub fn spread_gaussians(cam: &Camera, count: usize, seed: u64) -> Vec<Params> {
    let log_scale = if cam.model == CameraModel::Pinhole {
        -2.5
    } else {
        -1.4
    };
    let mut rng = fastrand::Rng::with_seed(seed);
    (0..count)
        .map(|_| {
            let px = Vec2::new(rng.f32() * 1.2 - 0.1, rng.f32() * 1.2 - 0.1) * cam.size;
            let d = 1.5 + rng.f32() * 4.5;
            gaussian_toward(&mut rng, cam, px, d, log_scale)
        })
        .collect()
}

/// Four large Gaussians that cover a 24 x 16 image with alpha above 2/255 everywhere.
pub fn covering_gaussians(cam: &Camera) -> Vec<Params> {
    let mut rng = fastrand::Rng::with_seed(9);
    (0..4)
        .map(|i| {
            let px = Vec2::new(8.0 + 3.0 * i as f32, 6.0 + 1.5 * i as f32);
            let mut p = gaussian_toward(&mut rng, cam, px, 3.0 + 0.5 * i as f32, 0.4);
            p.opacity_logit = -1.0 + 0.4 * rng.f32();
            p
        })
        .collect()
}
