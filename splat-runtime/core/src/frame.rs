//! What both backends agree on about a frame: the options a render takes, the errors it
//! refuses with (and the checks behind them), the outputs it returns and the gradients a
//! backward pass takes and gives.

use crate::blend::Blend;
use crate::flat::Flat;
use crate::grid::TileGrid;
use crate::method::{GradientSet, SplatMethod};
use crate::precision::{self, Precision};
use crate::types::Camera;
use rayon::prelude::*;
use std::time::Duration;

/// Largest accepted image side, in pixels.
pub const MAX_SIDE: u32 = 16384;

/// The tile sizes the CPU pipeline renders with.
pub const TILE_SIZES: [u32; 4] = [8, 16, 32, 64];

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    /// Tile side in pixels: 8, 16, 32 or 64.
    pub tile_size: u32,
    /// At most this many entries of each tile's list are blended (`None`: all).
    pub p_max: Option<usize>,
    /// Compute the alpha output.
    pub alpha: bool,
    /// Compute the expected-depth output.
    pub depth: bool,
    /// Apply the method's `tile_cull` (false keeps every tile of each bounding box: what the
    /// cull saves, and a check that it only drops pairs the alpha threshold would skip).
    pub tile_cull: bool,
    /// The blend's thresholds (transmittance stop, alpha skip).
    pub blend: Blend,
    /// How the per-pixel values (color, transmittance, depth sums) are stored: what the
    /// outputs are read from and the backward pass walks back from.
    pub precision: Precision,
    /// How the shade data (`project`'s output that the blend reads for every pair) is stored
    /// between the preprocess and the blend ([`precision::PackedShade`]; CPU only).
    pub shade_precision: Precision,
    /// How the backward pass holds its per-primitive gradient sums while they accumulate: f32
    /// or f16 (sums have no fixed range for a unorm format; CPU only).
    pub gradient_precision: Precision,
    /// The gradients the backward pass computes: the groups left out are never computed and
    /// are zero. Without the camera (training without pose refinement) the rays' share
    /// (`pixel_info`'s adjoint per pixel) is not computed either and [`Gradients::camera`] is
    /// zero.
    pub gradients: GradientSet,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            tile_size: 16,
            p_max: None,
            alpha: false,
            depth: false,
            tile_cull: true,
            blend: Blend::default(),
            precision: Precision::F32,
            shade_precision: Precision::F32,
            gradient_precision: Precision::F32,
            gradients: GradientSet::ALL,
        }
    }
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum RenderError {
    #[error(
        "image size {width}x{height} is not supported: each side must be 1..={MAX_SIDE} pixels"
    )]
    ImageSize { width: f32, height: f32 },
    #[error("tile size {0} is not supported: use 8, 16, 32 or 64")]
    TileSize(u32),
    #[error("P_max 0 would blend nothing: give at least 1, or none for whole lists")]
    PMax,
    #[error("blend thresholds {0:?} are not supported: t_min and alpha_min must be in [0, 1)")]
    Blend(Blend),
    /// What is wrong with the camera: "focal lengths must be finite and positive".
    #[error("camera {0}")]
    Camera(&'static str),
    #[error(
        "method `{method}` projects with a pinhole camera only (it never calls `cam.project_point` or `cam.pixel_ray`); the camera is {model}"
    )]
    CameraModel {
        method: &'static str,
        model: crate::types::CameraModel,
    },
    #[error(
        "method `{0}` renders global shutters only (no kernel calls `cam.shutter_time` or `cam.rotation_at`); the camera moves during its readout (shutter_turn, shutter_shift)"
    )]
    RollingShutter(&'static str),
    #[error("gradient sums have no fixed range for {0}: hold them as f32 or f16")]
    GradientPrecision(&'static str),
    #[error("primitive {0} has a NaN or infinite parameter")]
    NonFinite(usize),
    #[error(
        "{count} tile intersections exceed the limit of {limit}: lower the resolution or the number of primitives"
    )]
    TooManyIntersections { count: u64, limit: u64 },
    #[error(
        "the frame's {what} need {bytes} bytes, more than could be allocated: lower the resolution or the number of primitives"
    )]
    Memory { what: &'static str, bytes: u64 },
    #[error("gradient `{what}` has {got} values, the frame has {want}")]
    GradientSize {
        what: &'static str,
        got: usize,
        want: usize,
    },
    #[error("gradient `{what}` is NaN or infinite at value {index}")]
    NonFiniteGradient { what: &'static str, index: usize },
    #[error(
        "backward is given {got} primitives, and the frame was rendered from {want}: pass the parameters it was rendered with"
    )]
    ParamsCount { got: usize, want: usize },
    #[error("backward is given another camera than the frame was rendered with")]
    OtherCamera,
    #[error(
        "a depth gradient needs a frame rendered with the depth output (RenderOptions::depth, `--depth`)"
    )]
    DepthNotRendered,
}

/// An image of `channels` interleaved f32 values per pixel, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub channels: usize,
    pub data: Vec<f32>,
}

impl Image {
    /// Whether `data` holds one value per pixel and channel (the fields are public, so an
    /// image made by hand may not).
    pub fn fills_its_size(&self) -> bool {
        self.data.len() == self.width as usize * self.height as usize * self.channels
    }
}

#[derive(Clone, Debug, Default)]
pub struct Stats {
    pub primitives: usize,
    pub visible: usize,
    pub intersections: usize,
    /// Length of the longest tile list (before `P_max`).
    pub longest_list: usize,
    /// (pixel, primitive) evaluations on pixels still blending.
    pub pairs: u64,
    pub preprocess: Duration,
    pub rasterize: Duration,
    pub shade: Duration,
}

pub struct Frame {
    pub color: Image,
    pub alpha: Option<Image>,
    pub depth: Option<Image>,
    pub stats: Stats,
}

/// Per-primitive gradients and the camera's.
pub struct Gradients<M: SplatMethod> {
    pub params: Vec<M::Params>,
    /// The gradient of each primitive's shade data (`project`'s output that the blend reads),
    /// `M::Shade::LEN` words per primitive: what the blend sends back to `project`'s adjoint.
    pub shade: Vec<f32>,
    /// Zero when [`RenderOptions::gradients`] leaves the camera out.
    pub camera: Camera,
    pub stats: BackwardStats,
}

/// Time of each backward stage.
#[derive(Clone, Debug, Default)]
pub struct BackwardStats {
    /// The backward blend over tiles (including `evaluate`'s adjoint).
    pub blend: Duration,
    /// Summing the per-intersection gradients per primitive.
    pub reduce: Duration,
    /// `project`'s adjoint per primitive.
    pub project: Duration,
}

pub fn check<M: SplatMethod>(
    camera: &Camera,
    opts: &RenderOptions,
) -> Result<TileGrid, RenderError> {
    if camera.model != crate::types::CameraModel::Pinhole && !M::GENERIC_CAMERA {
        return Err(RenderError::CameraModel {
            method: M::NAME,
            model: camera.model,
        });
    }
    if !TILE_SIZES.contains(&opts.tile_size) {
        return Err(RenderError::TileSize(opts.tile_size));
    }
    if opts.p_max == Some(0) {
        return Err(RenderError::PMax);
    }
    let fraction = |v: f32| (0.0..1.0).contains(&v);
    if !(fraction(opts.blend.t_min) && fraction(opts.blend.alpha_min)) {
        return Err(RenderError::Blend(opts.blend));
    }
    if precision::sum_format(opts.gradient_precision) != opts.gradient_precision {
        return Err(RenderError::GradientPrecision(
            opts.gradient_precision.name(),
        ));
    }
    let size = camera.size;
    let ok = |v: f32| v.is_finite() && v >= 1.0 && v <= MAX_SIDE as f32 && v.fract() == 0.0;
    if !(ok(size.x) && ok(size.y)) {
        return Err(RenderError::ImageSize {
            width: size.x,
            height: size.y,
        });
    }
    if !(camera.focal.is_finite() && camera.focal.min_element() > 0.0) {
        return Err(RenderError::Camera(
            "focal lengths must be finite and positive",
        ));
    }
    if !camera.principal.is_finite() {
        return Err(RenderError::Camera("principal point must be finite"));
    }
    if !(camera.rotation.is_finite() && camera.translation.is_finite()) {
        return Err(RenderError::Camera("pose must be finite"));
    }
    match crate::types::rotation_defect(&camera.rotation) {
        Some(crate::types::NotRotation::Off(_)) => {
            return Err(RenderError::Camera(
                "rotation must be a rotation (R^T R = I: no scale or shear)",
            ));
        }
        Some(crate::types::NotRotation::Mirror) => {
            return Err(RenderError::Camera(
                "rotation must not mirror (a negative determinant)",
            ));
        }
        None => {}
    }
    if !camera.distortion.is_finite() {
        return Err(RenderError::Camera("distortion must be finite"));
    }
    if !(camera.shutter_turn.is_finite() && camera.shutter_shift.is_finite()) {
        return Err(RenderError::Camera("rolling shutter motion must be finite"));
    }
    if camera.has_rolling_shutter() && !M::ROLLING_SHUTTER {
        return Err(RenderError::RollingShutter(M::NAME));
    }
    Ok(TileGrid::new(size.x as u32, size.y as u32, opts.tile_size))
}

/// The alpha (1 - T) and expected-depth (sum w z / (1 - T)) outputs, where requested.
pub fn alpha_and_depth(
    grid: &TileGrid,
    opts: &RenderOptions,
    transmittance: &[f32],
    depth_acc: &[f32],
) -> (Option<Image>, Option<Image>) {
    let image = |data: Vec<f32>| Image {
        width: grid.width,
        height: grid.height,
        channels: 1,
        data,
    };
    let alpha = opts
        .alpha
        .then(|| image(transmittance.iter().map(|t| 1.0 - t).collect()));
    let depth = opts.depth.then(|| {
        let d = depth_acc
            .iter()
            .zip(transmittance)
            .map(|(d, t)| if *t < 1.0 { d / (1.0 - t) } else { 0.0 });
        image(d.collect())
    });
    (alpha, depth)
}

/// Gradient of the loss with respect to each requested output, in the layout of the frame.
#[derive(Clone, Debug)]
pub struct FrameGrad {
    /// H x W x channels.
    pub color: Vec<f32>,
    pub alpha: Option<Vec<f32>>,
    pub depth: Option<Vec<f32>>,
}

impl FrameGrad {
    /// Checks that every given gradient has one finite value per pixel (`channels` for the
    /// color), and that a depth gradient comes with a frame that rendered depth
    /// (`depth_rendered`).
    pub fn check(
        &self,
        pixels: usize,
        channels: usize,
        depth_rendered: bool,
    ) -> Result<(), RenderError> {
        if self.depth.is_some() && !depth_rendered {
            return Err(RenderError::DepthNotRendered);
        }
        let sizes = [
            ("color", Some(self.color.len()), pixels * channels),
            ("alpha", self.alpha.as_ref().map(Vec::len), pixels),
            ("depth", self.depth.as_ref().map(Vec::len), pixels),
        ];
        for (what, got, want) in sizes {
            if let Some(got) = got.filter(|g| *g != want) {
                return Err(RenderError::GradientSize { what, got, want });
            }
        }
        let given = [
            ("color", Some(&self.color)),
            ("alpha", self.alpha.as_ref()),
            ("depth", self.depth.as_ref()),
        ];
        for (what, values) in given {
            if let Some(index) = values.and_then(|v| first_not_finite(v)) {
                return Err(RenderError::NonFiniteGradient { what, index });
            }
        }
        Ok(())
    }
}

/// The index of the first value of `values` that is not finite: blocks in parallel, each
/// tested by a branch-free fold the compiler vectorizes (rayon's `position_first`, item by
/// item, took 20x as long over a 1080p color gradient).
fn first_not_finite(values: &[f32]) -> Option<usize> {
    const BLOCK: usize = 1 << 16;
    let (k, block) = values
        .par_chunks(BLOCK)
        .enumerate()
        .find_first(|(_, b)| b.iter().fold(false, |bad, g| bad | !g.is_finite()))?;
    block
        .iter()
        .position(|g| !g.is_finite())
        .map(|i| k * BLOCK + i)
}

#[cfg(test)]
mod tests {
    use super::first_not_finite;

    #[test]
    fn the_first_value_not_finite_is_found_in_any_block() {
        let n = 3 * (1 << 16) + 5;
        assert_eq!(first_not_finite(&vec![1.0; n]), None);
        assert_eq!(first_not_finite(&[]), None);
        for (at, bad) in [
            (0, f32::NAN),
            (70_000, f32::INFINITY),
            (n - 1, f32::NEG_INFINITY),
        ] {
            let mut v = vec![-2.5; n];
            v[at] = bad;
            // A later bad value in a later block does not hide the first.
            v[n - 1] = f32::NAN;
            assert_eq!(first_not_finite(&v), Some(at), "{bad} at {at}");
        }
    }
}
