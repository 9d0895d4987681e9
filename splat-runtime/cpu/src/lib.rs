//! splat-cpu: the shared pipeline on the CPU, generic over any [`SplatMethod`]:
//!
//! 1. [`preprocess`]: `project` over all primitives, keep the visible ones (rayon over
//!    primitives); pack their shade data where it is stored in a reduced format
//!    ([`precision`]).
//! 2. [`rasterize`]: per-tile depth-sorted lists (count, prefix sum, emit, sort, ranges).
//! 3. [`shade`]: front-to-back blending per tile (rayon over tiles, 8 SIMD lanes over pixels),
//!    tiles scheduled longest list first (trip-count binning).
//! 4. [`backward`](mod@backward): the back-to-front backward blend, a per-primitive
//!    reduction, then `project`'s adjoint per primitive.
//!
//! A scene cut into slices (sharded among processes) renders the same frame, bit for bit:
//! each slice's visible records ([`project_visible`]) rendered together
//! ([`render_records_for_backward`]), the blend's gradients ([`backward_blend`]) sent back to
//! their slices for `project`'s adjoint ([`project_adjoints`]).

pub mod backward;
pub mod preprocess;
pub mod rasterize;
pub mod shade;

use preprocess::Preprocessed;
use rayon::prelude::*;
use splat_core::blend::Blend;
use splat_core::flat::Flat;
use splat_core::frame::{
    BackwardStats, Frame, FrameGrad, Gradients, Image, RenderError, RenderOptions, Stats,
    alpha_and_depth, check,
};
use splat_core::grid::{TileGrid, TileLists};
use splat_core::method::{GradientSet, SplatMethod};
use splat_core::precision::{self, Range, Stored};
use splat_core::types::{Camera, Projected};
use std::time::Instant;

/// What the backward pass needs from the forward pass; only built by [`render_for_backward`].
pub struct ForwardState<M: SplatMethod> {
    /// The camera the frame was rendered from.
    pub camera: Camera,
    pub grid: TileGrid,
    pub pre: Preprocessed<M>,
    pub lists: TileLists,
    pub p_max: Option<usize>,
    pub blend: Blend,
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
    blend_projected(pre, grid, camera, opts, keep, stats)
}

/// The primitives of a slice of a scene that reach the rasterizer through a camera, in order:
/// their indices in the slice, and `project`'s records of them.
pub struct Visible<M: SplatMethod> {
    pub index: Vec<u32>,
    pub records: Vec<Projected<M::Cull, M::Shade>>,
}

/// What of `params` (a slice of a scene) reaches the rasterizer through `camera`, for
/// [`render_records_for_backward`] to render with other slices'.
pub fn project_visible<M: SplatMethod>(
    params: &[M::Params],
    camera: &Camera,
    opts: &RenderOptions,
) -> Result<Visible<M>, RenderError> {
    let grid = check::<M>(camera, opts)?;
    if let Some(i) = params.par_iter().position_any(|p| !p.is_finite()) {
        return Err(RenderError::NonFinite(i));
    }
    let pre = preprocess::preprocess::<M>(params, camera, &grid, precision::Precision::F32);
    let index: Vec<u32> = pre.visible.iter().map(|&(i, _)| i).collect();
    let records = index.iter().map(|&i| pre.projected[i as usize]).collect();
    Ok(Visible { index, records })
}

/// Renders records `project` made elsewhere (the visible primitives of each slice of a scene
/// sharded among processes, [`preprocess::visible_records`], concatenated in the slices'
/// order) and keeps what [`backward_blend`] needs. The frame is the whole scene's, bit for bit:
/// the records keep the primitives' order, and the tile lists sort by depth, then order.
pub fn render_records_for_backward<M: SplatMethod>(
    records: Vec<Projected<M::Cull, M::Shade>>,
    camera: &Camera,
    opts: &RenderOptions,
) -> Result<(Frame, ForwardState<M>), RenderError> {
    records_forward::<M>(records, camera, opts, true).map(|(f, s)| (f, s.expect("state kept")))
}

/// [`render_records_for_backward`]'s frame alone.
pub fn render_records<M: SplatMethod>(
    records: Vec<Projected<M::Cull, M::Shade>>,
    camera: &Camera,
    opts: &RenderOptions,
) -> Result<Frame, RenderError> {
    records_forward::<M>(records, camera, opts, false).map(|(f, _)| f)
}

fn records_forward<M: SplatMethod>(
    records: Vec<Projected<M::Cull, M::Shade>>,
    camera: &Camera,
    opts: &RenderOptions,
    keep: bool,
) -> Result<(Frame, Option<ForwardState<M>>), RenderError> {
    let grid = check::<M>(camera, opts)?;
    let t0 = Instant::now();
    let pre = preprocess::from_records::<M>(records, &grid, opts.shade_precision);
    let stats = Stats {
        primitives: pre.projected.len(),
        visible: pre.visible.len(),
        preprocess: t0.elapsed(),
        ..Stats::default()
    };
    blend_projected(pre, grid, camera, opts, keep, stats)
}

/// Stages 2 and 3 from `pre`: the tile lists and the blend.
fn blend_projected<M: SplatMethod>(
    pre: Preprocessed<M>,
    grid: TileGrid,
    camera: &Camera,
    opts: &RenderOptions,
    keep: bool,
    mut stats: Stats,
) -> Result<(Frame, Option<ForwardState<M>>), RenderError> {
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

/// Gradients of the parameters and (unless the render's options turned it off) the camera,
/// given the gradient of each output. `params` and `camera` are those the frame was rendered
/// with (their count and the camera are checked).
pub fn backward<M: SplatMethod>(
    state: &ForwardState<M>,
    params: &[M::Params],
    camera: &Camera,
    grad: &FrameGrad,
) -> Result<Gradients<M>, RenderError> {
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
    let blended = backward_blend(state, grad)?;
    let t2 = Instant::now();
    let (param_grads, camera_grads) = project_adjoints::<M>(
        params,
        camera,
        &blended.shade,
        &blended.depth,
        state.gradients,
    );
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
        .add_cotangent(&blended.ray_camera);
    let stats = BackwardStats {
        blend: blended.blend,
        reduce: blended.reduce,
        project: t2.elapsed(),
    };
    Ok(Gradients {
        params: param_grads,
        shade: blended.shade,
        camera: camera_grad,
        stats,
    })
}

/// Chunks of the per-primitive sums, summed in parallel.
const CHUNK: usize = 1 << 14;

/// What the backward blend sends back to `project`'s adjoint: per record of the frame
/// (`ForwardState::pre`), the gradient of its shade data (`M::Shade::LEN` words each) and of
/// its depth; the camera's through the pixel rays; the stages' times.
pub struct BlendGradients {
    pub shade: Vec<f32>,
    pub depth: Vec<f32>,
    pub ray_camera: Camera,
    pub blend: std::time::Duration,
    pub reduce: std::time::Duration,
}

/// The backward blend of the frame `state` kept, given the gradient of each output: the
/// per-record sums [`project_adjoints`] reads (for a frame of records,
/// [`render_records_for_backward`], each goes back to the slice it came from).
pub fn backward_blend<M: SplatMethod>(
    state: &ForwardState<M>,
    grad: &FrameGrad,
) -> Result<BlendGradients, RenderError> {
    let pixels = (state.grid.width * state.grid.height) as usize;
    grad.check(pixels, M::Color::LEN, state.depth_acc.len() == pixels)?;
    let n = state.pre.projected.len();
    let camera = &state.camera;
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
    Ok(BlendGradients {
        shade,
        depth,
        ray_camera,
        blend,
        reduce,
    })
}

/// `project`'s adjoint for each of `params` through `camera`, given the gradients of its
/// shade data (`M::Shade::LEN` words each) and depth; a primitive with none (not drawn) gets
/// zero. The camera's gradient per primitive where `wanted` asks for it.
pub fn project_adjoints<M: SplatMethod>(
    params: &[M::Params],
    camera: &Camera,
    shade: &[f32],
    depth: &[f32],
    wanted: GradientSet,
) -> (Vec<M::Params>, Option<Vec<Camera>>) {
    let words = M::Shade::LEN;
    let n = params.len();
    let (zero_params, zero_cull) = (M::Params::zero(), M::Cull::zero());
    // Each gradient is written once (no zero-filled buffer first: that alone cost 0.1 s at 1M).
    splat_core::with_camera_model!(camera.model, MODEL => {
        let one = |i: usize| {
            let d_words = &shade[i * words..(i + 1) * words];
            let untouched = depth[i] == 0.0 && d_words.iter().all(|v| *v == 0.0);
            if untouched {
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
    })
}
