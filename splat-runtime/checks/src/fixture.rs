//! Fixtures: a scene, a camera, the images and gradients an independent reference computed for
//! them (in float64), and which pixels are clear of every threshold, as JSON. The methods are
//! held to them in `methods/tests/independent_reference.rs` (gsplat's PyTorch implementation,
//! and references written from the papers' math); a method crate of its own can hold its
//! method to a fixture of its own the same way ([`matches_fixture`]).
//!
//! The format (`methods/tests/gsplat/make_fixtures.py` writes it): `model`; `camera` (rows of
//! the world-to-camera rotation, translation, focal, principal, size, and optional
//! `distortion`); `params` (one row of words per primitive: a stored Gaussian's, or with
//! `"words": "params"` the method's own); `weights` (the random linear
//! loss on color, alpha and depth, zero off the clear pixels); `clear`; `color`, `alpha`,
//! `depth`; `gradient` (`params` in the same words, the camera's fields by name).

use super::bound::Bound;
use super::forward::{ImageBound, MOST_UNCLEAR, output_matches};
use super::gradients::{camera_matches, groups_match};
use super::{CAMERA_GROUPS, camera_words, options, words};
use glam::{Mat3, Vec2, Vec3, Vec4};
use serde_json::Value;
use splat_core::flat::Flat;
use splat_core::frame::{Frame, FrameGrad, Gradients};
use splat_core::method::SplatMethod;
use splat_core::param_groups;
use splat_core::types::{Camera, CameraModel};
use splat_cpu::{backward, render_for_backward};
use splat_io::ply::{FromStored, StoredGaussian};
use std::path::Path;

/// The index of the distortion coefficients in [`CAMERA_GROUPS`].
const DISTORTION: usize = 4;

/// A stored Gaussian's words: mean, log scale, rotation, opacity logit, 16 SH coefficients.
const STORED_WORDS: usize = 3 + 3 + 4 + 1 + 16 * 3;

/// What one backend is held to.
pub struct Bounds {
    pub image: ImageBound,
    pub gradient: Bound,
}

pub struct Fixture {
    pub name: String,
    pub camera: Camera,
    /// Each primitive's words: a stored Gaussian's (mean, log scale, rotation, opacity logit,
    /// 16 SH coefficients), which the method reads through `FromStored`, or with
    /// [`Fixture::own_words`] the method's `Params`' own.
    pub params: Vec<Vec<f64>>,
    /// The fixture says `"words": "params"`: `params` are the method's words as they are.
    pub own_words: bool,
    pub grad: FrameGrad,
    pub clear: Vec<bool>,
    pub color: Vec<f64>,
    pub alpha: Vec<f64>,
    pub depth: Vec<f64>,
    /// Each primitive's gradient in its `Params`' words (SH padded to 16 coefficients).
    pub params_gradient: Vec<Vec<f64>>,
    /// The camera's gradient in its float slots (size zero, and distortion where the camera
    /// has none).
    pub camera_gradient: Vec<f64>,
    /// Whether the camera has distortion coefficients (the fixture's distortion gradient).
    pub distortion: bool,
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .expect("an array")
        .iter()
        .map(|x| x.as_f64().expect("a number"))
        .collect()
}

fn rows(v: &Value) -> Vec<Vec<f64>> {
    v.as_array().expect("rows").iter().map(floats).collect()
}

fn vec2(v: &[f64]) -> Vec2 {
    Vec2::new(v[0] as f32, v[1] as f32)
}

fn vec3(v: &[f64]) -> Vec3 {
    Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32)
}

/// A 3x3 from rows, and the camera's word order (glam's columns).
fn matrix(rows: &[Vec<f64>]) -> Mat3 {
    Mat3::from_cols(
        Vec3::new(rows[0][0] as f32, rows[1][0] as f32, rows[2][0] as f32),
        Vec3::new(rows[0][1] as f32, rows[1][1] as f32, rows[2][1] as f32),
        Vec3::new(rows[0][2] as f32, rows[1][2] as f32, rows[2][2] as f32),
    )
}

fn column_major(rows: &[Vec<f64>]) -> Vec<f64> {
    (0..9).map(|k| rows[k % 3][k / 3]).collect()
}

/// The fixture at `path` (a JSON file in the format `methods/tests/gsplat/make_fixtures.py`
/// writes).
pub fn load(path: &Path) -> Fixture {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let name = path
        .file_stem()
        .map_or(String::new(), |s| s.to_string_lossy().into_owned());
    let v: Value = serde_json::from_str(&text).expect("fixture JSON");
    let c = &v["camera"];
    let size = floats(&c["size"]);
    let model = match v["model"].as_str() {
        Some("pinhole") => CameraModel::Pinhole,
        Some("kannala_brandt") => CameraModel::KannalaBrandt,
        Some("equiangular") => CameraModel::Equiangular,
        other => panic!("{name}: camera model {other:?}"),
    };
    let distortion = c.get("distortion").map(floats);
    let camera = Camera {
        rotation: matrix(&rows(&c["rotation_rows"])),
        translation: vec3(&floats(&c["translation"])),
        focal: vec2(&floats(&c["focal"])),
        principal: vec2(&floats(&c["principal"])),
        size: vec2(&size),
        distortion: distortion.as_ref().map_or(Vec4::ZERO, |k| {
            Vec4::new(k[0] as f32, k[1] as f32, k[2] as f32, k[3] as f32)
        }),
        model,
        ..Default::default()
    };
    let params = rows(&v["params"]);
    let f32s = |x: &Value| {
        floats(x)
            .into_iter()
            .map(|y| y as f32)
            .collect::<Vec<f32>>()
    };
    let w = &v["weights"];
    let g = &v["gradient"];
    let mut camera_gradient = column_major(&rows(&g["rotation_rows"]));
    camera_gradient.extend(floats(&g["translation"]));
    camera_gradient.extend(floats(&g["focal"]));
    camera_gradient.extend(floats(&g["principal"]));
    camera_gradient.resize(Camera::FLOAT_SLOTS, 0.0);
    if let Some(k) = g.get("distortion") {
        let slots = CAMERA_GROUPS[DISTORTION].1.clone();
        camera_gradient[slots].copy_from_slice(&floats(k));
    }
    Fixture {
        name,
        camera,
        params,
        own_words: v["words"].as_str() == Some("params"),
        grad: FrameGrad {
            color: f32s(&w["color"]),
            alpha: Some(f32s(&w["alpha"])),
            depth: Some(f32s(&w["depth"])),
        },
        clear: floats(&v["clear"]).iter().map(|c| *c != 0.0).collect(),
        color: floats(&v["color"]),
        alpha: floats(&v["alpha"]),
        depth: floats(&v["depth"]),
        params_gradient: rows(&g["params"]),
        camera_gradient,
        distortion: distortion.is_some(),
    }
}

/// The frame's color, alpha and depth against the fixture's on its clear pixels.
fn image_matches(at: &str, f: &Fixture, frame: &Frame, bounds: &Bounds) {
    let (alpha, depth) = (frame.alpha.as_ref(), frame.depth.as_ref());
    let outputs = [
        ("color", &frame.color.data, &f.color),
        ("alpha", &alpha.unwrap().data, &f.alpha),
        ("depth", &depth.unwrap().data, &f.depth),
    ];
    for (what, values, want) in outputs {
        let got: Vec<f64> = values.iter().map(|v| *v as f64).collect();
        output_matches(at, what, &got, want, &f.clear, bounds.image);
    }
}

/// The gradients against the fixture's: each of the method's parameter groups, and each
/// camera field the references differentiate (the pose and intrinsics, and the distortion
/// where the camera has it; no rolling shutter).
fn gradients_match<M: SplatMethod>(at: &str, f: &Fixture, got: &Gradients<M>, bounds: &Bounds) {
    let params: Vec<Vec<f64>> = got.params.iter().map(words).collect();
    let groups = param_groups::<M>();
    groups_match(
        at,
        &params,
        &f.params_gradient,
        None,
        &groups,
        bounds.gradient,
    );
    let camera = camera_words(&got.camera);
    let fields = &CAMERA_GROUPS[..if f.distortion {
        DISTORTION + 1
    } else {
        DISTORTION
    }];
    camera_matches(
        at,
        &camera,
        &f.camera_gradient,
        None,
        fields,
        bounds.gradient,
    );
}

/// `M`'s CPU pipeline and, where there is an adapter, its GPU pipeline against the fixture at
/// `path`, at tile sizes 8 and 16: images on the clear pixels, gradients per parameter group and
/// camera field.
pub fn matches_fixture<M: SplatMethod>(path: &Path, cpu: &Bounds, gpu: &Bounds)
where
    M::Params: FromStored,
{
    let f = load(path);
    let name = &f.name;
    let unclear = f.clear.iter().filter(|c| !**c).count();
    assert!(
        unclear as f64 <= MOST_UNCLEAR * f.clear.len() as f64,
        "{name}: {unclear} of {} pixels near a threshold",
        f.clear.len()
    );
    let params: Vec<M::Params> = f
        .params
        .iter()
        .map(|w| params_of::<M>(w, f.own_words))
        .collect();
    for tile_size in [8, 16] {
        let at = format!("{name}, CPU, tile {tile_size}");
        let (frame, state) =
            render_for_backward::<M>(&params, &f.camera, &options(tile_size)).expect("render");
        image_matches(&at, &f, &frame, cpu);
        let g = backward::<M>(&state, &params, &f.camera, &f.grad).expect("backward");
        gradients_match::<M>(&at, &f, &g, cpu);
    }
    #[cfg(feature = "gpu")]
    gpu_matches::<M>(&f, &params, gpu);
    #[cfg(not(feature = "gpu"))]
    let _ = gpu;
}

/// A primitive from its words: `M::Params`' own, or a stored Gaussian's.
fn params_of<M: SplatMethod>(w: &[f64], own_words: bool) -> M::Params
where
    M::Params: FromStored,
{
    let f: Vec<f32> = w.iter().map(|v| *v as f32).collect();
    if own_words {
        assert_eq!(f.len(), <M::Params as Flat>::LEN, "a primitive's words");
        return M::Params::read_words(&f);
    }
    assert_eq!(f.len(), STORED_WORDS, "a primitive's words");
    M::Params::from_stored(&StoredGaussian {
        mean: vec3(&w[0..3]),
        log_scale: vec3(&w[3..6]),
        rotation: Vec4::new(f[6], f[7], f[8], f[9]),
        opacity_logit: f[10],
        sh: std::array::from_fn(|k| vec3(&w[11 + 3 * k..])),
    })
}

#[cfg(feature = "gpu")]
fn gpu_matches<M: SplatMethod>(f: &Fixture, params: &[M::Params], bounds: &Bounds) {
    use splat_gpu::{adapter_or_skip, entries::Accumulation, render};
    let Some(gpu) = adapter_or_skip() else {
        return;
    };
    for tile_size in [8, 16] {
        let at = format!("{}, GPU, tile {tile_size}", f.name);
        let (frame, mut state) =
            render::render_for_backward::<M>(&gpu, params, &f.camera, &options(tile_size))
                .expect("render");
        image_matches(&at, f, &frame, bounds);
        let g = render::backward(&mut state, &f.grad, Accumulation::default_for(&gpu))
            .expect("backward");
        gradients_match::<M>(&at, f, &g.gradients, bounds);
    }
}
