//! The scenes and cameras the checks run on, as Gaussians (a PLY's fields), so that every method
//! that reads PLY scenes (`FromStored`) gets them as its own parameters through [`as_method`]:
//! spread over the image ([`spread`], sparse or dense enough that lists end at the T-stop),
//! covering every pixel clear of the thresholds ([`covering`], for finite differences), and
//! faint, near the alpha threshold ([`faint`], for the boxes and the cull). A method with
//! parameters of its own (a shape, a second color) sets them on the result.

use splat_core::glam::{Mat3, Quat, Vec2, Vec3, Vec4};
use splat_core::method::SplatMethod;
use splat_core::types::{Camera, CameraModel};
use splat_io::ply::{FromStored, StoredGaussian};

/// A pinhole camera at the origin looking down +z (OpenCV axes), focal length `width` pixels.
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

/// [`camera`] with the given model; the fisheye and equiangular cameras see wide: past 90
/// degrees off axis in the fisheye's corners.
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

/// A random Gaussian whose centre projects to `pixel` at depth `z` through a pinhole camera at
/// the origin ([`camera`]): axis scales `exp(log_scale)` to 1.8x that, a random rotation,
/// opacity logit in [-1.5, 2.5], every SH coefficient random in [-0.3, 0.3].
pub fn gaussian_at(
    rng: &mut fastrand::Rng,
    cam: &Camera,
    pixel: Vec2,
    z: f32,
    log_scale: f32,
) -> StoredGaussian {
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
    StoredGaussian {
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

/// Like [`gaussian_at`], with the centre on `pixel`'s ray at `distance` (any camera model,
/// camera at the origin).
pub fn gaussian_toward(
    rng: &mut fastrand::Rng,
    cam: &Camera,
    pixel: Vec2,
    distance: f32,
    log_scale: f32,
) -> StoredGaussian {
    let mut g = gaussian_at(rng, cam, pixel, distance, log_scale);
    g.mean = cam.pixel_ray(pixel) * distance;
    g
}

/// `count` Gaussians spread over the whole image (and past its edges) of a camera at the
/// origin, 1.5 to 6 units away; larger on the wide cameras, which have fewer pixels per
/// radian. On a 64 x 48 pinhole 1,000 of them end lists at the T-stop and put most pairs at
/// the footprints' edges below 1/255: a realistic scene.
pub fn spread(cam: &Camera, count: usize, seed: u64) -> Vec<StoredGaussian> {
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

/// Four large Gaussians that cover a 24 x 16 image ([`camera`]) with alpha above 2/255
/// everywhere and leave the transmittance far above the T-stop: a render smooth in every
/// parameter, as finite differences need.
pub fn covering(cam: &Camera) -> Vec<StoredGaussian> {
    let mut rng = fastrand::Rng::with_seed(9);
    (0..4)
        .map(|i| {
            let px = Vec2::new(8.0 + 3.0 * i as f32, 6.0 + 1.5 * i as f32);
            let mut g = gaussian_toward(&mut rng, cam, px, 3.0 + 0.5 * i as f32, 0.4);
            g.opacity_logit = -1.0 + 0.4 * rng.f32();
            g
        })
        .collect()
}

/// [`spread`] with every opacity between 0.9 and 4 times the alpha threshold 1/255: footprints
/// whose reach is decided by the threshold alone, where a box or a tile cull that cuts too
/// tight drops a pixel.
pub fn faint(cam: &Camera, count: usize, seed: u64) -> Vec<StoredGaussian> {
    let mut rng = fastrand::Rng::with_seed(seed ^ 0xFA1E);
    let mut gaussians = spread(cam, count, seed);
    for g in &mut gaussians {
        let opacity = (0.9 + 3.1 * rng.f32()) / 255.0;
        g.opacity_logit = (opacity / (1.0 - opacity)).ln();
    }
    gaussians
}

/// Gaussians as `M`'s parameters, through the method's own `FromStored` (what the command
/// line does with a PLY scene).
pub fn as_method<M: SplatMethod>(gaussians: &[StoredGaussian]) -> Vec<M::Params>
where
    M::Params: FromStored,
{
    gaussians.iter().map(M::Params::from_stored).collect()
}
