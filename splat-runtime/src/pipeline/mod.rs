//! The shared pipeline on the CPU, generic over any [`SplatMethod`]:
//!
//! 1. [`preprocess`]: `project` over all primitives, keep the visible ones (rayon over
//!    primitives); pack their shade data where it is stored in a reduced format
//!    ([`precision`]).
//! 2. [`rasterize`]: per-tile depth-sorted lists (count, prefix sum, emit, sort, ranges).
//! 3. [`shade`]: front-to-back blending per tile (rayon over tiles, 8 SIMD lanes over pixels),
//!    tiles scheduled longest list first (trip-count binning).
//! 4. [`backward`](mod@backward): the back-to-front backward blend, a per-primitive
//!    reduction, then `project`'s adjoint per primitive.

pub mod backward;
pub mod grid;
pub mod precision;
pub mod preprocess;
pub mod rasterize;
pub mod shade;

pub use backward::FrameGrad;
use grid::TileGrid;
use preprocess::Preprocessed;
use rasterize::TileLists;

use crate::flat::Flat;
use crate::method::{GradientSet, SplatMethod};
use crate::types::{Camera, Projected};
use precision::{Range, Stored};
use rayon::prelude::*;
use std::time::{Duration, Instant};

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
    pub blend: shade::Blend,
    /// How the per-pixel values (color, transmittance, depth sums) are stored: what the
    /// outputs are read from and the backward pass walks back from.
    pub precision: precision::Precision,
    /// How the shade data (`project`'s output that the blend reads for every pair) is stored
    /// between the preprocess and the blend ([`precision::PackedShade`]; CPU only).
    pub shade_precision: precision::Precision,
    /// How the backward pass holds its per-primitive gradient sums while they accumulate: f32
    /// or f16 (sums have no fixed range for a unorm format; CPU only).
    pub gradient_precision: precision::Precision,
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
            blend: shade::Blend::default(),
            precision: precision::Precision::F32,
            shade_precision: precision::Precision::F32,
            gradient_precision: precision::Precision::F32,
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
    Blend(shade::Blend),
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

/// What the backward pass needs from the forward pass; only built by [`render_for_backward`].
pub struct ForwardState<M: SplatMethod> {
    /// The camera the frame was rendered from.
    pub camera: Camera,
    pub grid: TileGrid,
    pub pre: Preprocessed<M>,
    pub lists: TileLists,
    pub p_max: Option<usize>,
    pub blend: shade::Blend,
    /// How the per-primitive gradient sums are held ([`RenderOptions::gradient_precision`]).
    pub gradient_precision: precision::Precision,
    /// The gradients the backward pass computes ([`RenderOptions::gradients`]).
    pub gradients: GradientSet,
    /// Final transmittance and sum of weight * depth per pixel (empty unless the frame
    /// rendered depth), in the frame's precision, and where each pixel's walk of its tile's
    /// list ended ([`shade::TileOutput::ends`]).
    pub transmittance: precision::Stored,
    pub depth_acc: precision::Stored,
    pub ends: Vec<u32>,
}

impl<M: SplatMethod> ForwardState<M> {
    /// The part of a tile's list that blending visits (`P_max`).
    pub fn visited(&self, tile: usize) -> &[u32] {
        let list = self.lists.list(tile);
        &list[..self.p_max.map_or(list.len(), |p| p.min(list.len()))]
    }

    /// Bytes held for the backward pass: the projected primitives (and their packed shade
    /// data), the visible set, the tile lists and the per-pixel state.
    pub fn bytes(&self) -> usize {
        fn held<T>(v: &Vec<T>) -> usize {
            v.capacity() * std::mem::size_of::<T>()
        }
        held(&self.pre.projected)
            + held(&self.pre.visible)
            + held(&self.lists.prims)
            + held(&self.lists.ranges)
            + self.transmittance.bytes()
            + self.depth_acc.bytes()
            + held(&self.ends)
            + self.pre.packed.as_ref().map_or(0, |p| p.bytes())
    }
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

pub(crate) fn check<M: SplatMethod>(
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

/// Renders the requested outputs; allocates nothing for a backward pass.
pub fn render<M: SplatMethod>(
    params: &[M::Params],
    camera: &Camera,
    opts: &RenderOptions,
) -> Result<Frame, RenderError> {
    forward::<M>(params, camera, opts, false).map(|(f, _)| f)
}

/// Renders and keeps what [`backward()`] needs.
pub fn render_for_backward<M: SplatMethod>(
    params: &[M::Params],
    camera: &Camera,
    opts: &RenderOptions,
) -> Result<(Frame, ForwardState<M>), RenderError> {
    forward::<M>(params, camera, opts, true).map(|(f, s)| (f, s.expect("state kept")))
}

fn forward<M: SplatMethod>(
    params: &[M::Params],
    camera: &Camera,
    opts: &RenderOptions,
    keep: bool,
) -> Result<(Frame, Option<ForwardState<M>>), RenderError> {
    let grid = check::<M>(camera, opts)?;
    if let Some(i) = params.par_iter().position_any(|p| !p.is_finite()) {
        return Err(RenderError::NonFinite(i));
    }
    let mut stats = Stats {
        primitives: params.len(),
        ..Stats::default()
    };
    let t0 = Instant::now();
    let pre = preprocess::preprocess::<M>(params, camera, &grid, opts.shade_precision);
    stats.visible = pre.visible.len();
    stats.preprocess = t0.elapsed();

    let lists = tile_lists(&pre, &grid, opts.tile_cull, &mut stats)?;

    let t2 = Instant::now();
    let capped = |t: usize| {
        let l = lists.list(t);
        &l[..opts.p_max.map_or(l.len(), |p| p.min(l.len()))]
    };
    // Trip-count binning: the longest lists start first so they do not finish last. One tile
    // per task: rayon's default halving gave one worker the long lists and the other the short
    // ones (1.3x on 2 threads instead of 1.9x on a trained 200x200 scene).
    let mut order: Vec<u32> = (0..grid.tile_count() as u32).collect();
    order.sort_by_key(|&t| std::cmp::Reverse(capped(t as usize).len()));
    let tiles: Vec<(u32, shade::TileOutput)> = order
        .par_iter()
        .with_max_len(1)
        .map(|&t| {
            (
                t,
                shade::shade_tile::<M>(
                    &grid,
                    camera,
                    t,
                    capped(t as usize),
                    &pre,
                    opts.depth,
                    opts.blend,
                ),
            )
        })
        .collect();
    let (w, h) = (grid.width as usize, grid.height as usize);
    let channels = M::Color::LEN;
    let mut color = vec![0.0; w * h * channels];
    let mut transmittance = vec![1.0; w * h];
    let mut ends = if keep { vec![0; w * h] } else { vec![] };
    let mut depth_acc = if opts.depth { vec![0.0; w * h] } else { vec![] };
    let s = grid.size as usize;
    for (t, out) in &tiles {
        stats.pairs += out.pairs;
        let (tx, ty) = grid.tile_xy(*t);
        for row in 0..s {
            let y = ty as usize * s + row;
            if y >= h {
                break;
            }
            let x0 = tx as usize * s;
            let n = s.min(w - x0);
            let (src, dst) = (row * s, y * w + x0);
            color[dst * channels..(dst + n) * channels]
                .copy_from_slice(&out.color[src * channels..(src + n) * channels]);
            transmittance[dst..dst + n].copy_from_slice(&out.transmittance[src..src + n]);
            if keep {
                ends[dst..dst + n].copy_from_slice(&out.ends[src..src + n]);
            }
            if opts.depth {
                depth_acc[dst..dst + n].copy_from_slice(&out.depth[src..src + n]);
            }
        }
    }
    stats.shade = t2.elapsed();

    // The per-pixel values in the frame's precision: the outputs are read from them, and the
    // backward pass walks back from the transmittance and depth sums.
    let p = opts.precision;
    let transmittance = Stored::new(p, Range::Relative, transmittance);
    let depth_acc = Stored::new(p, Range::Relative, depth_acc);
    let (alpha, depth) = alpha_and_depth(&grid, opts, &transmittance.as_f32(), &depth_acc.as_f32());
    let frame = Frame {
        color: Image {
            width: grid.width,
            height: grid.height,
            channels,
            data: Stored::new(p, Range::Unit, color).into_f32(),
        },
        alpha,
        depth,
        stats,
    };
    let state = keep.then_some(ForwardState {
        camera: *camera,
        grid,
        pre,
        lists,
        p_max: opts.p_max,
        blend: opts.blend,
        gradient_precision: opts.gradient_precision,
        gradients: opts.gradients,
        transmittance,
        depth_acc,
        ends,
    });
    Ok((frame, state))
}

/// Stage 3 with its statistics (shared by the CPU and GPU backends).
pub(crate) fn tile_lists<M: SplatMethod>(
    pre: &Preprocessed<M>,
    grid: &TileGrid,
    tile_cull: bool,
    stats: &mut Stats,
) -> Result<TileLists, RenderError> {
    let t = Instant::now();
    let lists = rasterize::rasterize::<M>(pre, grid, tile_cull)?;
    stats.intersections = lists.intersections();
    stats.longest_list = (0..grid.tile_count())
        .map(|t| lists.list(t).len())
        .max()
        .unwrap_or(0);
    stats.rasterize = t.elapsed();
    Ok(lists)
}

/// The alpha (1 - T) and expected-depth (sum w z / (1 - T)) outputs, where requested.
pub(crate) fn alpha_and_depth(
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

/// Gradients of the parameters and (unless the render's options turned it off) the camera,
/// given the gradient of each output. `params` and `camera` are those the frame was rendered
/// with (their count and the camera are checked).
pub fn backward<M: SplatMethod>(
    state: &ForwardState<M>,
    params: &[M::Params],
    camera: &Camera,
    grad: &FrameGrad,
) -> Result<Gradients<M>, RenderError> {
    let pixels = (state.grid.width * state.grid.height) as usize;
    grad.check(pixels, M::Color::LEN, state.depth_acc.len() == pixels)?;
    let n = state.pre.projected.len();
    if params.len() != n {
        return Err(RenderError::ParamsCount {
            got: params.len(),
            want: n,
        });
    }
    if *camera != state.camera {
        return Err(RenderError::OtherCamera);
    }
    let words = M::Shade::LEN;
    let t0 = Instant::now();
    // The f16 sums' loss scale; f32 sums are not scaled (and no pass over the gradient is
    // needed to say so).
    let scale = match precision::sum_format(state.gradient_precision) {
        precision::Precision::F32 => 1.0,
        held => {
            let largest = [Some(&grad.color), grad.alpha.as_ref(), grad.depth.as_ref()]
                .into_iter()
                .flatten()
                .flat_map(|g| g.iter())
                .fold(0.0f32, |m, v| m.max(v.abs()));
            precision::sum_scale(held, largest)
        }
    };
    // One dense accumulator per worker; tiles dealt round-robin, longest lists first.
    let workers = rayon::current_num_threads().max(1);
    let mut order: Vec<u32> = (0..state.grid.tile_count() as u32).collect();
    order.sort_by_key(|&t| std::cmp::Reverse(state.visited(t as usize).len()));
    let accs: Vec<backward::Accum> = (0..workers)
        .into_par_iter()
        .map(|w| {
            let mut acc = backward::Accum::new(n, words, state.gradient_precision, scale);
            for &t in order.iter().skip(w).step_by(workers) {
                backward::backward_tile::<M>(state, camera, grad, t, &mut acc);
            }
            acc
        })
        .collect();
    let blend = t0.elapsed();
    // Sum the workers' buffers.
    let t1 = Instant::now();
    // The camera's cotangent through the pixel rays (`pixel_info`), summed over the workers.
    let ray_camera = accs
        .iter()
        .fold(Camera::ZERO, |c, a| c.add_cotangent(&a.camera));
    const CHUNK: usize = 1 << 14;
    // Summed in f32, held at the gradient precision as each worker's sums were, then unscaled.
    let sum = |mut parts: Vec<Stored>| -> Vec<f32> {
        let mut out = parts.remove(0).into_f32();
        out.par_chunks_mut(CHUNK).enumerate().for_each(|(c, out)| {
            for part in &parts {
                part.add_to(c * CHUNK, out);
            }
            precision::hold_sums(state.gradient_precision, out);
            if scale != 1.0 {
                out.iter_mut().for_each(|v| *v /= scale);
            }
        });
        out
    };
    let (shades, depths) = accs.into_iter().map(|a| (a.shade, a.depth)).unzip();
    let (shade, depth) = (sum(shades), sum(depths));
    let reduce = t1.elapsed();
    let t2 = Instant::now();
    let (zero_params, zero_cull) = (M::Params::zero(), M::Cull::zero());
    let wanted = state.gradients;
    // Each gradient is written once (no zero-filled buffer first: that alone cost 0.1 s at 1M).
    let (param_grads, camera_grads) = crate::with_camera_model!(camera.model, MODEL => {
        let one = |i: usize| {
            let d_words = &shade[i * words..(i + 1) * words];
            let untouched = depth[i] == 0.0 && d_words.iter().all(|v| *v == 0.0);
            if !state.pre.projected[i].visible || untouched {
                return (zero_params, Camera::ZERO);
            }
            // Only depth and shade carry a gradient; the rest of the cotangent is zero.
            let d_out = Projected {
                visible: false,
                depth: depth[i],
                bbox_min: glam::Vec2::ZERO,
                bbox_max: glam::Vec2::ZERO,
                cull: zero_cull,
                shade: M::Shade::read_words(d_words),
            };
            M::project_adjoint_as::<MODEL>(&params[i], camera, &d_out, wanted)
        };
        match wanted.camera() {
            true => {
                let (p, c): (Vec<M::Params>, Vec<Camera>) = (0..n).into_par_iter().map(one).unzip();
                (p, Some(c))
            }
            false => ((0..n).into_par_iter().map(|i| one(i).0).collect(), None),
        }
    });
    // Summed in fixed chunks, in order: the same gradient whatever the thread count.
    let camera_grad = camera_grads
        .map_or(Camera::ZERO, |grads| {
            grads
                .par_chunks(CHUNK)
                .map(|c| c.iter().fold(Camera::ZERO, |a, b| a.add_cotangent(b)))
                .collect::<Vec<_>>()
                .iter()
                .fold(Camera::ZERO, |a, b| a.add_cotangent(b))
        })
        .add_cotangent(&ray_camera);
    let stats = BackwardStats {
        blend,
        reduce,
        project: t2.elapsed(),
    };
    Ok(Gradients {
        params: param_grads,
        shade,
        camera: camera_grad,
        stats,
    })
}
