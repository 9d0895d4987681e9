//! The forward pass on the GPU, stage by stage as on the CPU:
//!
//! 1. preprocess: `project` per primitive (generated WGSL).
//! 2. rasterize: count kept tiles per primitive (`tile_cull`), prefix sum, read back the
//!    total (to size the key buffers), emit (tile, depth) keys, radix sort, tile ranges,
//!    trip-count binning.
//! 3. shade: one workgroup per tile, batches of the list staged in workgroup memory.
//!
//! Every stage is submitted and waited for on its own so its time can be reported. A render
//! kept for the backward pass ([`render_for_backward`]) leaves its buffers on the GPU.

use super::device::dispatch;
use super::entries::{self, Layout};
use super::{Gpu, GpuError, sort};
use crate::flat::Flat;
use crate::method::SplatMethod;
use crate::pipeline::grid::TileGrid;
use crate::pipeline::rasterize::MAX_INTERSECTIONS;
use crate::pipeline::{Frame, Image, RenderError, RenderOptions, Stats};
use crate::types::Camera;
use std::marker::PhantomData;
use std::time::Instant;

#[derive(Debug, thiserror::Error)]
pub enum GpuRenderError {
    #[error(transparent)]
    Render(#[from] RenderError),
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

/// 32-bit words of a sequence of `Flat` values, in order.
pub(crate) fn words_of<T: Flat>(values: &[T]) -> Vec<u32> {
    let mut w = vec![0.0f32; T::LEN * values.len()];
    for (v, out) in values.iter().zip(w.chunks_exact_mut(T::LEN.max(1))) {
        v.write_words(out);
    }
    w.into_iter().map(f32::to_bits).collect()
}

/// What the backward pass needs, left on the GPU by [`render_for_backward`].
pub struct GpuForwardState<M: SplatMethod> {
    pub grid: TileGrid,
    pub primitives: usize,
    pub want_depth: bool,
    pub(crate) camera: wgpu::Buffer,
    pub(crate) params: wgpu::Buffer,
    pub(crate) projected: wgpu::Buffer,
    pub(crate) prims: wgpu::Buffer,
    pub(crate) ranges: wgpu::Buffer,
    pub(crate) order: wgpu::Buffer,
    /// Per pixel: color, final T, sum of weight * depth.
    pub(crate) pixels: wgpu::Buffer,
    pub(crate) p_max: u32,
    method: PhantomData<M>,
}

pub fn render<M: SplatMethod>(
    gpu: &Gpu,
    params: &[M::Params],
    camera: &Camera,
    opts: &RenderOptions,
) -> Result<Frame, GpuRenderError> {
    forward::<M>(gpu, params, camera, opts, false).map(|(f, _)| f)
}

/// Renders and keeps the GPU buffers [`super::backward::backward`] needs; the depth sums are
/// always accumulated (the backward pass replays them).
pub fn render_for_backward<M: SplatMethod>(
    gpu: &Gpu,
    params: &[M::Params],
    camera: &Camera,
    opts: &RenderOptions,
) -> Result<(Frame, GpuForwardState<M>), GpuRenderError> {
    forward::<M>(gpu, params, camera, opts, true).map(|(f, s)| (f, s.expect("state kept")))
}

/// The frame uniform shared by the tile stages (shaders/tiles.wgsl, tile_pass.wgsl).
pub(crate) fn frame_uniform(gpu: &Gpu, n: u32, grid: &TileGrid, p_max: u32) -> wgpu::Buffer {
    gpu.uniform(&[
        n,
        grid.width,
        grid.height,
        grid.size,
        grid.tiles_x,
        p_max,
        grid.tile_count() as u32,
        0,
    ])
}

fn forward<M: SplatMethod>(
    gpu: &Gpu,
    params: &[M::Params],
    camera: &Camera,
    opts: &RenderOptions,
    keep: bool,
) -> Result<(Frame, Option<GpuForwardState<M>>), GpuRenderError> {
    let grid = crate::pipeline::check::<M>(camera, opts)?;
    if ![8, 16].contains(&grid.size) {
        return Err(GpuError::TileSize(grid.size).into());
    }
    if let Some(i) = params.iter().position(|p| !p.is_finite()) {
        return Err(RenderError::NonFinite(i).into());
    }
    let layout = Layout::of::<M>();
    let n = params.len();
    let n32 = u32::try_from(n).map_err(|_| GpuError::TooLarge {
        what: "the primitive count",
        bytes: n as u64,
        limit: u32::MAX as u64,
    })?;
    let mut stats = Stats {
        primitives: n,
        ..Stats::default()
    };
    let p_max = opts
        .p_max
        .map_or(u32::MAX, |p| p.min(u32::MAX as usize) as u32);
    let tiles = grid.tile_count() as u32;
    let frame = frame_uniform(gpu, n32, &grid, p_max);
    let new_encoder = || gpu.device.create_command_encoder(&Default::default());

    // 1. project.
    let t0 = Instant::now();
    let camera_buf = gpu.buffer_from("camera", &words_of(std::slice::from_ref(camera)))?;
    let params_buf = gpu.buffer_from("parameters", &words_of(params))?;
    let projected = gpu.buffer("projected primitives", n * layout.stride)?;
    let project = gpu.pipeline(&entries::project::<M>()?, "splat_harness")?;
    let count_uniform = gpu.uniform(&[n32]);
    let mut enc = new_encoder();
    let bind = gpu.bind(
        &project,
        &[&params_buf, &camera_buf, &projected, &count_uniform],
    );
    dispatch(&mut enc, &project, &bind, n32.div_ceil(64));
    gpu.finish(enc)?;
    stats.preprocess = t0.elapsed();

    // 2. rasterize: count, scan, total.
    let t1 = Instant::now();
    let counts = gpu.buffer("tiles per primitive", n)?;
    let totals = gpu.buffer("intersection totals", 3)?;
    let count = gpu.pipeline(&entries::tiles::<M>(false, opts.tile_cull)?, "count_tiles")?;
    let mut enc = new_encoder();
    enc.clear_buffer(&totals, 0, None);
    let bind = gpu.bind(&count, &[&projected, &counts, &frame, &totals]);
    dispatch(&mut enc, &count, &bind, n32.div_ceil(256));
    sort::exclusive_scan(gpu, &mut enc, &counts, n32)?;
    gpu.finish(enc)?;
    let t = gpu.read(&totals, 3)?;
    let total = t[0] as u64 | (t[1] as u64) << 32;
    stats.visible = t[2] as usize;
    if total > MAX_INTERSECTIONS {
        return Err(RenderError::TooManyIntersections {
            count: total,
            limit: MAX_INTERSECTIONS,
        }
        .into());
    }
    let total = total as u32;
    stats.intersections = total as usize;
    // Emit, sort, ranges, bins.
    // Keys are `vec2<u32>`: a binding holds at least one, even with no intersection.
    let keys = gpu.buffer("intersection keys", 2 * total.max(1) as usize)?;
    let vals = gpu.buffer("intersection primitives", total as usize)?;
    let emit = gpu.pipeline(&entries::tiles::<M>(true, opts.tile_cull)?, "emit_tiles")?;
    let mut enc = new_encoder();
    let bind = gpu.bind(&emit, &[&projected, &counts, &frame, &keys, &vals]);
    dispatch(&mut enc, &emit, &bind, n32.div_ceil(256));
    let (keys, prims) = sort::sort_by_tile_and_depth(gpu, &mut enc, keys, vals, total, tiles)?;
    let ranges = sort::tile_ranges(gpu, &mut enc, &keys, total, tiles)?;
    let order = sort::bin_tiles(gpu, &mut enc, &ranges, tiles, p_max)?;
    gpu.finish(enc)?;
    let r = gpu.read(&ranges, 2 * tiles as usize)?;
    stats.longest_list = r.chunks_exact(2).map(|r| r[1] - r[0]).max().unwrap_or(0) as usize;
    stats.rasterize = t1.elapsed();

    // 3. shade.
    let t2 = Instant::now();
    let want_depth = opts.depth || keep;
    let channels = layout.channels;
    let pixels_n = (grid.width * grid.height) as usize;
    let pixels = gpu.buffer("pixels", pixels_n * (channels + 2))?;
    let shade = gpu.pipeline(
        &entries::shade::<M>(gpu, grid.size, want_depth)?,
        "shade_tiles",
    )?;
    let mut inputs = vec![&projected, &prims, &ranges, &order, &frame, &pixels];
    if M::HAS_PIXEL_INFO {
        inputs.push(&camera_buf);
    }
    let mut enc = new_encoder();
    dispatch(&mut enc, &shade, &gpu.bind(&shade, &inputs), tiles);
    gpu.finish(enc)?;
    let out = gpu.read(&pixels, pixels_n * (channels + 2))?;
    stats.shade = t2.elapsed();

    let f = f32::from_bits;
    let mut color = Vec::with_capacity(pixels_n * channels);
    let (mut t, mut dacc) = (Vec::with_capacity(pixels_n), Vec::with_capacity(pixels_n));
    for px in out.chunks_exact(channels + 2) {
        color.extend(px[..channels].iter().map(|w| f(*w)));
        t.push(f(px[channels]));
        dacc.push(f(px[channels + 1]));
    }
    let (alpha, depth) = crate::pipeline::alpha_and_depth(&grid, opts, &t, &dacc);
    let frame_out = Frame {
        color: Image {
            width: grid.width,
            height: grid.height,
            channels,
            data: color,
        },
        alpha,
        depth,
        stats,
    };
    let state = keep.then(|| GpuForwardState {
        grid,
        primitives: n,
        want_depth,
        camera: camera_buf,
        params: params_buf,
        projected,
        prims,
        ranges,
        order,
        pixels,
        p_max,
        method: PhantomData,
    });
    Ok((frame_out, state))
}
