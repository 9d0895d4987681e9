//! The built-in scene: a ringed planet of a few thousand Gaussians (banded sphere, tilted
//! ring, a moon, stars all around), a camera looking at it, and views of it to train on, so
//! `splat render` and `splat fit` run with no files.

use splat_methods::gs3d;
use splat_runtime::glam::{Mat3, Vec2, Vec3, Vec4};
use splat_runtime::io::dataset::{Dataset, View};
use splat_runtime::io::ply::{GaussianCloud, StoredGaussian};
use splat_runtime::{Camera, CameraModel, RenderError, RenderOptions, render};

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
    let mut gaussians = body(&mut rng);
    gaussians.extend(stars(&mut rng));
    GaussianCloud::new(1, gaussians)
}

/// The planet, its ring and its moon.
fn body(rng: &mut Lcg) -> Vec<StoredGaussian> {
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
    out
}

/// Stars on a sphere of radius 25 around the camera's target, in every direction: what a
/// wide camera sees beyond the planet (a fisheye past 180 degrees sees some behind it).
fn stars(rng: &mut Lcg) -> Vec<StoredGaussian> {
    let mut out = vec![];
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
    out
}

/// The scene and camera a command was given, or the built-in ones (a pinhole view at
/// `width` x `height`).
pub fn given_or_built_in(
    scene: Option<&std::path::Path>,
    camera: &crate::view::CameraArgs,
    (width, height): (u32, u32),
) -> anyhow::Result<(GaussianCloud, Camera)> {
    let camera = match camera.read()? {
        Some(given) => given.camera,
        None => built_in_camera(width, height, CameraModel::Pinhole)?,
    };
    let cloud = match scene {
        Some(path) => read(path)?,
        None => planet(),
    };
    Ok((cloud, camera))
}

/// The scene at `path` (any format `splat convert` knows, by its extension), with a note when
/// the reader folded Mip-Splatting's 3D filter in.
pub fn read(path: &std::path::Path) -> anyhow::Result<GaussianCloud> {
    let cloud = splat_runtime::io::formats::read(path)?;
    if cloud.folded_3d_filter {
        eprintln!(
            "note: {} holds Mip-Splatting's 3D filter (filter_3D), folded into its scales and \
             opacities; for its 2D filter, --method 3dgs-aa is gsplat's antialiased mode (it adds \
             0.3 px² to each footprint's variance, where Mip-Splatting adds 0.1)",
            path.display()
        );
    }
    Ok(cloud)
}

/// The built-in view ([`camera`]) at `width` x `height`, refused before any work when a side
/// is out of range.
pub fn built_in_camera(width: u32, height: u32, model: CameraModel) -> anyhow::Result<Camera> {
    let side = 1..=splat_runtime::frame::MAX_SIDE;
    if !side.contains(&width) || !side.contains(&height) {
        anyhow::bail!(
            "image size {width}x{height} is out of range (1..={} per side)",
            side.end()
        );
    }
    Ok(camera(width, height, model))
}

/// Looks at the origin from slightly above the ring plane, 6 units away: a pinhole with a
/// 58° horizontal field of view, a nearly equidistant fisheye seeing 183° across and 225°
/// diagonally, or a 126° equiangular camera.
pub fn camera(width: u32, height: u32, model: CameraModel) -> Camera {
    looking_from(Vec3::new(0.0, 1.5, -5.8), width, height, model)
}

/// A camera at `eye` looking at the origin (image x to the right of the world's up axis).
fn looking_from(eye: Vec3, width: u32, height: u32, model: CameraModel) -> Camera {
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
        ..Default::default()
    }
}

/// The built-in dataset's views, width and height.
pub const DATASET: (usize, u32, u32) = (32, 112, 84);

/// The built-in training dataset: the planet, its ring and its moon (no stars) rendered by
/// 3DGS on `background`, seen by `views` pinhole cameras circling it 6 units away while rising
/// and sinking through the ring plane; every 8th view (from the first) is held out.
pub fn dataset(
    views: usize,
    width: u32,
    height: u32,
    background: Vec3,
) -> Result<Dataset, RenderError> {
    let cloud = GaussianCloud::new(1, body(&mut Lcg(7)));
    let params: Vec<gs3d::Params> = cloud.params();
    let opts = RenderOptions {
        alpha: true,
        ..Default::default()
    };
    let mut data = Dataset {
        train: vec![],
        test: vec![],
        points: vec![],
    };
    for k in 0..views {
        let a = k as f32 / views as f32 * std::f32::consts::TAU;
        let eye = Vec3::new(5.8 * a.sin(), 1.5 + 1.8 * (2.0 * a).sin(), -5.8 * a.cos());
        let camera = looking_from(eye, width, height, CameraModel::Pinhole);
        let frame = render::<gs3d::Method>(&params, &camera, &opts)?;
        // Rendered on black: the color is the one composited on black.
        let coverage = frame.alpha.map(|a| a.data);
        let on_black = View::new(
            String::new(),
            camera,
            frame.color,
            coverage.clone(),
            Vec3::ZERO,
        );
        let image = on_black.on(background).into_owned();
        let view = View::new(
            format!("built-in view {k}"),
            camera,
            image,
            coverage,
            background,
        );
        match k % 8 {
            0 => data.test.push(view),
            _ => data.train.push(view),
        }
    }
    Ok(data)
}
