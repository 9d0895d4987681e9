//! An independent f64 reference renderer: every visible primitive evaluated at every pixel in
//! depth order with the f64 twin of the method's functions; no tiles, no bounding boxes, no
//! tile culling; only the method's own thresholds and the blend's stopping rule.

#![allow(dead_code)]

pub mod adjoint;
pub mod checks;

use splat_methods::gs3d::Params;
use splat_runtime::glam::{Mat3, Quat, Vec2, Vec3, Vec4};
use splat_runtime::{Camera, CameraModel, Flat};

pub const T_MIN: f64 = 1e-4;

/// A generated flat f64 function (`module::twin::f`) taking and returning slices.
pub type Flat64 = fn(&[f64], &[u32]) -> (Vec<f64>, Vec<u32>);

/// A generated flat f64 adjoint (`module::twin::f_adjoint`): inputs, integer inputs and the
/// cotangent of the float results to the cotangent of the float inputs.
pub type Adjoint64 = fn(&[f64], &[u32], &[f64]) -> Vec<f64>;

/// A method's f64 twin: its flat `project`, `pixel_info` and `evaluate` and their adjoints,
/// and how many float words its tile-cull data has (every method here has float-only cull
/// and shade data) and its color channels.
pub struct Twin {
    pub project: Flat64,
    pub project_adjoint: Adjoint64,
    pub pixel_info: Option<Flat64>,
    pub pixel_info_adjoint: Option<Adjoint64>,
    pub evaluate: Flat64,
    pub evaluate_adjoint: Adjoint64,
    pub cull_words: usize,
    pub channels: usize,
}

/// `Twin` of a method module: `twin!(path::to::module, Cull)` or with `pixel_info`.
#[macro_export]
macro_rules! twin {
    (@f $($m:ident)::+, $f:ident) => {
        |x: &[f64], i: &[u32]| {
            let (a, b) = $($m)::+::twin::$f(x.try_into().unwrap(), i.try_into().unwrap());
            (a.to_vec(), b.to_vec())
        }
    };
    (@adjoint $($m:ident)::+, $f:ident) => {
        |x: &[f64], i: &[u32], d: &[f64]| {
            $($m)::+::twin::$f(x.try_into().unwrap(), i.try_into().unwrap(), d.try_into().unwrap())
                .to_vec()
        }
    };
    ($($m:ident)::+, pixel_info) => {
        $crate::common::Twin {
            project: twin!(@f $($m)::+, project),
            project_adjoint: twin!(@adjoint $($m)::+, project_adjoint),
            pixel_info: Some(twin!(@f $($m)::+, pixel_info)),
            pixel_info_adjoint: Some(twin!(@adjoint $($m)::+, pixel_info_adjoint)),
            evaluate: twin!(@f $($m)::+, evaluate),
            evaluate_adjoint: twin!(@adjoint $($m)::+, evaluate_adjoint),
            cull_words: <<$($m)::+::Method as splat_runtime::SplatMethod>::Cull as splat_runtime::Flat>::LEN,
            channels: <<$($m)::+::Method as splat_runtime::SplatMethod>::Color as splat_runtime::Flat>::LEN,
        }
    };
    ($($m:ident)::+) => {
        $crate::common::Twin {
            project: twin!(@f $($m)::+, project),
            project_adjoint: twin!(@adjoint $($m)::+, project_adjoint),
            pixel_info: None,
            pixel_info_adjoint: None,
            evaluate: twin!(@f $($m)::+, evaluate),
            evaluate_adjoint: twin!(@adjoint $($m)::+, evaluate_adjoint),
            cull_words: <<$($m)::+::Method as splat_runtime::SplatMethod>::Cull as splat_runtime::Flat>::LEN,
            channels: <<$($m)::+::Method as splat_runtime::SplatMethod>::Color as splat_runtime::Flat>::LEN,
        }
    };
}

pub fn gs3d() -> Twin {
    twin!(splat_methods::gs3d)
}

/// A camera's float slots as f64 (its model is passed separately, as the integer slot).
pub fn camera_words(c: &Camera) -> Vec<f64> {
    c.float_slots().map(f64::from).to_vec()
}

pub fn words<P: Flat>(p: &P) -> Vec<f64> {
    let mut w = vec![0.0f32; P::LEN];
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

/// Renders 3DGS `params` (flat f64 parameter words per primitive) through a pinhole `camera`
/// (its float words).
pub fn render(params: &[Vec<f64>], camera: &[f64]) -> Reference {
    render_with(&gs3d(), params, camera, CameraModel::Pinhole)
}

/// Renders `params` with the method `twin` through `camera` (float words) of `model`.
pub fn render_with(
    twin: &Twin,
    params: &[Vec<f64>],
    camera: &[f64],
    model: CameraModel,
) -> Reference {
    let (width, height) = (camera[16] as usize, camera[17] as usize);
    let ints = [model as u32];
    let mut prims: Vec<(f64, usize, Vec<f64>)> = vec![];
    for (i, p) in params.iter().enumerate() {
        let input: Vec<f64> = p.iter().chain(camera).copied().collect();
        let (f, b) = (twin.project)(&input, &ints);
        if b[0] == 0 || !f[0].is_finite() {
            continue;
        }
        prims.push((f[0], i, f[5 + twin.cull_words..].to_vec()));
    }
    prims.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let mut out = Reference {
        width,
        height,
        color: vec![],
        alpha: vec![0.0; width * height],
        depth: vec![0.0; width * height],
    };
    for y in 0..height {
        for x in 0..width {
            let mut pixel = vec![x as f64 + 0.5, y as f64 + 0.5];
            if let Some(info) = twin.pixel_info {
                pixel.extend(camera);
                pixel = info(&pixel, &ints).0;
            }
            let (mut t, mut c, mut d) = (1.0f64, vec![0.0; twin.channels], 0.0f64);
            for (depth, _, shade) in &prims {
                let input: Vec<f64> = pixel.iter().chain(shade).copied().collect();
                let (o, valid) = (twin.evaluate)(&input, &[]);
                if valid[0] == 0 {
                    continue;
                }
                let next = t * (1.0 - o[0]);
                if next <= T_MIN {
                    break;
                }
                for (ch, v) in c.iter_mut().zip(&o[1..]) {
                    *ch += o[0] * t * v;
                }
                d += o[0] * t * depth;
                t = next;
            }
            out.color.extend(&c);
            let px = y * width + x;
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

/// max |a - b| / max |b| over a group of gradients.
pub fn group_error(got: &[f64], want: &[f64]) -> f64 {
    let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-12);
    got.iter()
        .zip(want)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()))
        / scale
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
