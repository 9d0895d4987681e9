//! Scenes and cameras the method tests share (the checks themselves are the public
//! `splat_runtime::checks`).

#![allow(dead_code)]

use splat_methods::gs3d::Params;
use splat_methods::{FromStored, ToStored};
use splat_runtime::checks::scenes;
use splat_runtime::glam::Vec2;
use splat_runtime::io::ply::StoredGaussian;
use splat_runtime::{Camera, CameraModel};

pub use splat_runtime::checks::scenes::{camera, wide_camera};

fn as_3dgs(g: StoredGaussian) -> Params {
    Params::from_stored(&g)
}

/// [`scenes::gaussian_at`] as 3DGS.
pub fn gaussian_at(
    rng: &mut fastrand::Rng,
    cam: &Camera,
    pixel: Vec2,
    z: f32,
    log_scale: f32,
) -> Params {
    as_3dgs(scenes::gaussian_at(rng, cam, pixel, z, log_scale))
}

/// [`scenes::gaussian_toward`] as 3DGS.
pub fn gaussian_toward(
    rng: &mut fastrand::Rng,
    cam: &Camera,
    pixel: Vec2,
    distance: f32,
    log_scale: f32,
) -> Params {
    as_3dgs(scenes::gaussian_toward(
        rng, cam, pixel, distance, log_scale,
    ))
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
pub fn as_method<P: FromStored>(gaussians: Vec<Params>) -> Vec<P> {
    gaussians
        .iter()
        .map(|g| P::from_stored(&g.to_stored()))
        .collect()
}

/// [`scenes::spread`] as 3DGS.
pub fn spread_gaussians(cam: &Camera, count: usize, seed: u64) -> Vec<Params> {
    scenes::spread(cam, count, seed)
        .into_iter()
        .map(as_3dgs)
        .collect()
}

/// [`scenes::covering`] as 3DGS.
pub fn covering_gaussians(cam: &Camera) -> Vec<Params> {
    scenes::covering(cam).into_iter().map(as_3dgs).collect()
}
