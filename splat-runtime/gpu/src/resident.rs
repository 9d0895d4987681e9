//! The device-resident GPU pipeline: a scene whose parameters live in a device buffer, and a
//! renderer whose kernels are built once and whose buffers persist across frames (grown to
//! the largest frame so far, never re-created for a steady one). A frame is one submission
//! ([`GpuRenderer::submit`]: a renderer's first reads its intersection count back between
//! two; a frame whose intersections outgrew the buffers is rendered again by
//! [`GpuRenderer::finish`]); the backward pass is one submission; images and gradients stay on
//! the device until the caller downloads them. This is the loop a trainer runs: render, loss,
//! backward, optimizer step, with no host transfer per step and no wait for the frame
//! ([`GpuRenderer::settle`] says afterwards whether it fitted).
//!
//! Stages, as on the CPU: preprocess (`project`), rasterize (depth sort of the primitives,
//! count kept tiles with `tile_cull`, prefix sum, emit tile keys front to back, radix sort on
//! the tile bits, tile ranges, trip-count binning), shade (one workgroup per tile); backward
//! blend, then `project`'s adjoint (and `pixel_info`'s for ray methods). Stage times come from GPU timestamps where the adapter has
//! them.

use super::adjoint::{Adjoint, interleave};
use super::device::{Grown, Kernel, dispatch};
use super::entries::{self, Accumulation, Layout, Reduction};
use super::front::{COUNT, Front, PROJECT, Projection, SORT};
use super::per_model::PerModel;
use super::scene::GpuScene;
use super::shade_pack::{ShadePacker, ShadePacking};
use super::sort::TileRanges;
use super::state::PixelState;
use super::timing::StageTimer;
use super::{Gpu, GpuError, GpuRenderError};
use splat_core::frame::{BackwardStats, Frame, FrameGrad, Gradients, Image, RenderOptions, Stats};
use splat_core::grid::TileGrid;
use splat_core::grid::TileLists;
use splat_core::method::SplatMethod;
use splat_core::types::{Camera, CameraModel};
use std::collections::HashMap;
use std::marker::PhantomData;
use std::time::Duration;

// The renderer's timed stages after the front's (two timestamps each).
const SHADE: u32 = 3;
/// Packing the shade data (empty at f32), part of the preprocess.
const PACK: u32 = 4;
const BLEND: u32 = 5;
const ADJOINT: u32 = 6;
const STAGES: u32 = 7;

mod records;

/// [`GpuRenderer::rendered_from`] of a frame of records: no scene's stamp.
const GIVEN: u64 = u64::MAX;

/// What the last frame was: its tile grid and sizes.
#[derive(Clone, Copy, Debug)]
pub struct FrameInfo {
    pub grid: TileGrid,
    pub primitives: usize,
    pub visible: usize,
    pub intersections: usize,
    /// Whether its intersections outgrew the room the frames before had left, so that it was
    /// rendered a second time ([`GpuRenderer::finish`]).
    pub redone: bool,
}

/// The last frame's stage times (GPU timestamps; zero on an adapter without them). The
/// backward's are the last backward pass's.
#[derive(Clone, Copy, Debug, Default)]
pub struct StageTimes {
    pub preprocess: Duration,
    /// Depth sort, count, emit, tile sort, ranges and bins.
    pub rasterize: Duration,
    pub shade: Duration,
    pub blend: Duration,
    pub project: Duration,
}

/// Gradients, plus the number of global atomic adds the backward blend issued.
pub struct GpuGradients<M: SplatMethod> {
    pub gradients: Gradients<M>,
    pub atomics: u64,
}

/// A renderer for one method and one set of options: kernels built once, buffers kept.
pub struct GpuRenderer<'g, M: SplatMethod> {
    gpu: &'g Gpu,
    opts: RenderOptions,
    layout: Layout,
    /// How the per-pixel state is stored.
    state: PixelState,
    front: Front,
    /// The shade data packed at a reduced precision (`None` at f32: the blends read `project`'s).
    packer: Option<ShadePacker>,
    /// The kernels that call the method's model-aware functions, per camera model used.
    shade: PerModel<Kernel>,
    /// The gradient sums and the adjoints after the blend.
    adjoint: Adjoint,
    /// Backward blends built on first use, per (camera model, depth gradient, accumulation).
    blends: HashMap<(CameraModel, bool, Accumulation), Kernel>,
    tiles: TileRanges,
    /// Per pixel: color, final T, sum of weight * depth.
    pixels: Grown,
    pixel_grad: Grown,
    /// The host's copy of the output gradients [`GpuRenderer::backward`] interleaves.
    pixel_grad_host: Vec<u32>,
    timer: StageTimer,
    /// The frame submitted last, until [`GpuRenderer::finish`] knows it fitted.
    pending: Option<Pending>,
    /// The last frame finished.
    frame: Option<FrameInfo>,
    /// A sharded run's compaction of records and scatter of their gradients, made on first
    /// use ([`records`]).
    exchange: Option<records::Exchange>,
    /// The stamp of the scene's upload the last frame was rendered from ([`GpuScene::upload`]).
    rendered_from: u64,
    method: PhantomData<M>,
}

/// A frame submitted and not yet finished.
#[derive(Clone, Copy)]
struct Pending {
    grid: TileGrid,
    primitives: usize,
    camera: Camera,
}

impl<'g, M: SplatMethod> GpuRenderer<'g, M> {
    /// A renderer producing the outputs `opts` asks for.
    pub fn new(gpu: &'g Gpu, opts: &RenderOptions) -> Result<Self, GpuRenderError> {
        if !super::TILE_SIZES.contains(&opts.tile_size) {
            return Err(GpuError::TileSize(opts.tile_size).into());
        }
        let layout = Layout::of::<M>();
        let state = PixelState {
            precision: opts.precision,
            channels: layout.channels,
            depth: opts.depth,
        };
        let grown = |what, words| Grown::new(gpu, what, words);
        Ok(GpuRenderer {
            gpu,
            opts: *opts,
            layout,
            state,
            front: Front::new::<M>(gpu, opts.tile_cull)?,
            packer: ShadePacking::of::<M>(opts.shade_precision)
                .map(|p| ShadePacker::new::<M>(gpu, p))
                .transpose()?,
            shade: PerModel::new(),
            adjoint: Adjoint::new::<M>(gpu, opts)?,
            blends: HashMap::new(),
            tiles: TileRanges::new(gpu)?,
            pixels: grown("pixels", 1)?,
            pixel_grad: grown("pixel gradients", 1)?,
            pixel_grad_host: Vec::new(),
            timer: StageTimer::new(gpu, STAGES),
            pending: None,
            frame: None,
            exchange: None,
            rendered_from: 0,
            method: PhantomData,
        })
    }

    /// The last frame finished, if any.
    pub fn frame(&self) -> Option<FrameInfo> {
        self.frame
    }

    /// Renders `scene` through `camera` into the renderer's buffers (download with
    /// [`GpuRenderer::download_frame`]): [`GpuRenderer::submit`], then
    /// [`GpuRenderer::finish`].
    pub fn forward(
        &mut self,
        scene: &GpuScene<M>,
        camera: &Camera,
    ) -> Result<FrameInfo, GpuRenderError> {
        self.submit(scene, camera)?;
        self.finish(scene)
    }

    /// Records and submits the frame of `scene` through `camera` without waiting for it, and
    /// says its tile grid. With the room the buffers have from the frames before, the frame is
    /// one submission (the number of keys it sorts is settled on the device); the renderer's
    /// first frame reads its intersection count back in between, to make that room.
    ///
    /// Work recorded from the submitted frame before [`GpuRenderer::settle`] or
    /// [`GpuRenderer::finish`] (its backward pass, a loss) is right only if the frame fitted
    /// its buffers; a step that changes state from it is held back on the device when it did
    /// not ([`GpuRenderer::frame_keys`]).
    pub fn submit(
        &mut self,
        scene: &GpuScene<M>,
        camera: &Camera,
    ) -> Result<TileGrid, GpuRenderError> {
        self.submit_from(Projection::Scene(scene), camera)
    }

    /// [`GpuRenderer::submit`] of `project`'s results of `source`.
    fn submit_from(
        &mut self,
        source: Projection<M>,
        camera: &Camera,
    ) -> Result<TileGrid, GpuRenderError> {
        (self.frame, self.pending) = (None, None);
        let gpu = self.gpu;
        let grid = splat_core::frame::check::<M>(camera, &self.opts)?;
        let n = source.len();
        let stamp = match source {
            Projection::Scene(scene) => scene.stamp,
            Projection::Given(_) => GIVEN,
        };
        let tiles = grid.tile_count() as u32;
        let p_max = self
            .opts
            .p_max
            .map_or(u32::MAX, |p| p.min(u32::MAX as usize) as u32);
        let frame = (source, camera);
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        // Project, count, prefix sum.
        if self.front.room() == 0 {
            let counted = self.front.count(gpu, frame, (&grid, p_max), &self.timer)?;
            self.front.reserve(gpu, counted)?;
        } else {
            (self.front).record_count(gpu, &mut enc, frame, (&grid, p_max), &self.timer)?;
        }

        // Emit, sort, ranges, bins, shade.
        self.tiles
            .prepare(gpu, self.front.room() as u32, tiles, p_max)?;
        let pixels = (grid.width * grid.height) as usize;
        self.pixels.ensure(gpu, pixels * self.state.words())?;
        self.timer.start(&mut enc, PACK);
        if let Some(packer) = &mut self.packer {
            packer.record(gpu, &mut enc, &self.front, n)?;
        }
        self.timer.end(&mut enc, PACK);
        self.timer.start(&mut enc, SORT);
        self.front.emit_sorted(gpu, &mut enc)?;
        let key_count = self.front.key_count();
        self.tiles
            .record(gpu, &mut enc, &self.front.keys, key_count)?;
        self.timer.end(&mut enc, SORT);
        self.timer.start(&mut enc, SHADE);
        let (model, opts, state) = (camera.model, self.opts, self.state);
        let packing = self.packer.as_ref().map(ShadePacker::packing);
        let shade = self.shade.get(model, || {
            let (tile, depth, blend) = (opts.tile_size, opts.depth, opts.blend);
            let source = entries::shade::<M>(gpu, model, tile, depth, state, packing)?;
            gpu.kernel_with(&source, "shade_tiles", &entries::blend_constants(blend))
        })?;
        let mut inputs = self.tile_pass_inputs();
        inputs.push(("pixel_out", &self.pixels));
        if M::HAS_PIXEL_INFO {
            inputs.push(("camera_words", &self.front.camera));
        }
        let bind = gpu.bind_named(&shade, &inputs)?;
        dispatch(&mut enc, &shade.pipeline, &bind, tiles);
        self.timer.end(&mut enc, SHADE);
        self.timer.resolve(&mut enc, PROJECT..BLEND);
        gpu.queue.submit([enc.finish()]);
        self.pending = Some(Pending {
            grid,
            primitives: n,
            camera: *camera,
        });
        self.rendered_from = stamp;
        Ok(grid)
    }

    /// Waits for the frame submitted last and says what it was. A frame with more
    /// intersections than the buffers held (its tile lists were cut short) is rendered again
    /// first, with room for them.
    pub fn finish(&mut self, scene: &GpuScene<M>) -> Result<FrameInfo, GpuRenderError> {
        if let Some(info) = self.frame {
            return Ok(info);
        }
        let camera = self.pending.ok_or(GpuRenderError::NoFrame)?.camera;
        let mut redone = false;
        loop {
            if let Some(info) = self.settle(scene)? {
                return Ok(FrameInfo { redone, ..info });
            }
            redone = true;
            self.submit(scene, &camera)?;
        }
    }

    /// Waits for the frame submitted last (at once after a wait that covered it) and says
    /// whether it fitted the buffers: `Some` finishes it, as [`GpuRenderer::finish`] does;
    /// `None`: its tile lists were cut short, the buffers have room for it now, and it and
    /// what was recorded from it must be submitted again.
    pub fn settle(&mut self, scene: &GpuScene<M>) -> Result<Option<FrameInfo>, GpuRenderError> {
        let p = self.pending.ok_or(GpuRenderError::NoFrame)?;
        scene.check_drawn(p.primitives, self.rendered_from)?;
        self.settle_any()
    }

    /// [`GpuRenderer::settle`] of whatever frame was submitted last.
    fn settle_any(&mut self) -> Result<Option<FrameInfo>, GpuRenderError> {
        let p = self.pending.ok_or(GpuRenderError::NoFrame)?;
        let counted = self.front.counted(self.gpu)?;
        if counted.cut {
            self.front.reserve(self.gpu, counted)?;
            self.pending = None;
            return Ok(None);
        }
        let info = FrameInfo {
            grid: p.grid,
            primitives: p.primitives,
            visible: counted.visible,
            intersections: counted.intersections as usize,
            redone: false,
        };
        (self.frame, self.pending) = (Some(info), None);
        Ok(Some(info))
    }

    /// The key count of the frame submitted last, on the device (`[keys sorted, cut]`,
    /// `settle.wgsl`): a kernel that changes state from the frame binds it and does nothing
    /// when word 1 is set (the frame was cut: [`GpuRenderer::settle`]).
    pub fn frame_keys(&self) -> &wgpu::Buffer {
        self.front.key_count()
    }

    /// The grid and primitive count of the frame finished last, or else of the one submitted.
    fn current(&self) -> Result<(TileGrid, usize), GpuRenderError> {
        let frame = self.frame.map(|f| (f.grid, f.primitives));
        let pending = self.pending.map(|p| (p.grid, p.primitives));
        frame.or(pending).ok_or(GpuRenderError::NoFrame)
    }

    /// The last frame's outputs (as `RenderOptions` asked) and stats.
    pub fn download_frame(&self) -> Result<Frame, GpuRenderError> {
        let info = self.frame.ok_or(GpuRenderError::NoFrame)?;
        let (grid, channels) = (info.grid, self.layout.channels);
        let pixels = (grid.width * grid.height) as usize;
        let words = self.gpu.read(&self.pixels, pixels * self.state.words())?;
        let out = self.state.decode(&words);
        let tiles = grid.tile_count();
        let ranges = self.gpu.read(&self.tiles.ranges, 2 * tiles)?;
        let mut color = Vec::with_capacity(pixels * channels);
        let (mut t, mut dacc) = (Vec::with_capacity(pixels), Vec::with_capacity(pixels));
        for px in out.chunks_exact(channels + 2) {
            color.extend(&px[..channels]);
            t.push(px[channels]);
            dacc.push(px[channels + 1]);
        }
        let (alpha, depth) = splat_core::frame::alpha_and_depth(&grid, &self.opts, &t, &dacc);
        let times = self.stage_times()?;
        let stats = Stats {
            primitives: info.primitives,
            visible: info.visible,
            intersections: info.intersections,
            longest_list: ranges
                .chunks_exact(2)
                .map(|r| r[1] - r[0])
                .max()
                .unwrap_or(0) as usize,
            pairs: 0,
            preprocess: times.preprocess,
            rasterize: times.rasterize,
            shade: times.shade,
        };
        Ok(Frame {
            color: Image {
                width: grid.width,
                height: grid.height,
                channels,
                data: color,
            },
            alpha,
            depth,
            stats,
        })
    }

    /// The last frame's tile lists, read back: each tile's primitives front to back, whole
    /// (`P_max` caps what the blends read, not the lists), as the CPU's
    /// [`TileLists`].
    pub fn download_tile_lists(&self) -> Result<TileLists, GpuRenderError> {
        let info = self.frame.ok_or(GpuRenderError::NoFrame)?;
        let tiles = info.grid.tile_count();
        let ranges = self.gpu.read(&self.tiles.ranges, 2 * tiles)?;
        let keyed = self.gpu.read(&self.front.prims, info.intersections)?;
        let mut lists = TileLists {
            prims: Vec::with_capacity(info.intersections),
            ranges: vec![0],
        };
        for r in ranges.chunks_exact(2) {
            lists.prims.extend(&keyed[r[0] as usize..r[1] as usize]);
            lists.ranges.push(lists.prims.len() as u32);
        }
        Ok(lists)
    }

    /// The backward pass of the last frame of `scene` (unchanged since), given the gradient of
    /// each output, with the gradient accumulation `acc`: one submission; the gradients stay
    /// on the device until [`GpuRenderer::download_gradients`].
    pub fn backward(
        &mut self,
        scene: &GpuScene<M>,
        grad: &FrameGrad,
        acc: Accumulation,
    ) -> Result<(), GpuRenderError> {
        let info = self.frame.ok_or(GpuRenderError::NoFrame)?;
        let channels = self.layout.channels;
        let pixels = (info.grid.width * info.grid.height) as usize;
        grad.check(pixels, channels, self.opts.depth)?;
        let want_depth = grad.depth.is_some();
        let mut words = std::mem::take(&mut self.pixel_grad_host);
        interleave(grad, (pixels, channels), &mut words);
        self.gpu.write(self.pixel_gradients()?, &words);
        self.pixel_grad_host = words;
        self.backward_recorded(scene, want_depth, acc)
    }

    /// The backward pass of the last frame of `scene`, with the output gradients already in
    /// [`GpuRenderer::pixel_gradients`] (written there by a loss on the device; depth's
    /// ignored): no host transfer. The frame may be one submitted and not finished yet
    /// ([`GpuRenderer::submit`] says when that is right).
    pub fn backward_on_device(
        &mut self,
        scene: &GpuScene<M>,
        acc: Accumulation,
    ) -> Result<(), GpuRenderError> {
        self.backward_recorded(scene, false, acc)
    }

    /// The buffer of the last frame's output gradients: per pixel the color channels, alpha,
    /// depth.
    pub fn pixel_gradients(&mut self) -> Result<&wgpu::Buffer, GpuRenderError> {
        let (grid, _) = self.current()?;
        let pixels = (grid.width * grid.height) as usize;
        self.pixel_grad
            .ensure(self.gpu, pixels * (self.layout.channels + 2))?;
        Ok(&self.pixel_grad)
    }

    /// The last frame's per-pixel state: the color channels, final T, sum of weight * depth,
    /// stored as [`GpuRenderer::state_layout`] says (f32 words unless the options chose a
    /// narrower precision).
    pub fn pixel_state(&self) -> &wgpu::Buffer {
        &self.pixels
    }

    /// How [`GpuRenderer::pixel_state`] stores each pixel.
    pub fn state_layout(&self) -> PixelState {
        self.state
    }

    /// `project`'s results of the last frame, [`Layout`]'s stride per primitive (the first
    /// word nonzero where the primitive is visible).
    pub fn projected(&self) -> (&wgpu::Buffer, usize) {
        (&self.front.projected, self.layout.stride)
    }

    /// How the shade data is packed for the blends (`None` at f32: they read
    /// [`GpuRenderer::projected`]).
    pub fn shade_packing(&self) -> Option<&ShadePacking> {
        self.packer.as_ref().map(ShadePacker::packing)
    }

    /// The last frame's packed shade data, decoded as the blends decode it: `M::Shade::LEN`
    /// values per primitive (`None` at f32).
    pub fn download_shade_data(&self) -> Result<Option<Vec<f32>>, GpuRenderError> {
        let info = self.frame.ok_or(GpuRenderError::NoFrame)?;
        let Some(packer) = &self.packer else {
            return Ok(None);
        };
        let packing = packer.packing();
        let words = self
            .gpu
            .read(&packer.packed, info.primitives * packing.words())?;
        let ranges = self.gpu.read(&packer.ranges, packing.range_words())?;
        Ok(Some(packing.decode(&words, &ranges)))
    }

    /// The last frame's camera, as its words.
    pub fn camera_buffer(&self) -> &wgpu::Buffer {
        &self.front.camera
    }

    /// Float slots of `M::Params` (the gradient words per primitive).
    pub fn param_floats(&self) -> usize {
        self.adjoint.param_floats
    }

    fn backward_recorded(
        &mut self,
        scene: &GpuScene<M>,
        want_depth: bool,
        acc: Accumulation,
    ) -> Result<(), GpuRenderError> {
        let (grid, n) = self.current()?;
        scene.check_drawn(n, self.rendered_from)?;
        let gpu = self.gpu;
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        self.record_blend(&mut enc, want_depth, acc)?;
        self.timer.start(&mut enc, ADJOINT);
        (self.adjoint).record(gpu, &mut enc, scene, &self.front, &grid)?;
        self.timer.end(&mut enc, ADJOINT);
        self.timer.resolve(&mut enc, BLEND..STAGES);
        gpu.queue.submit([enc.finish()]);
        Ok(())
    }

    /// Records the backward blend of the last frame, after the adjoint's start: each
    /// primitive's shade and depth gradient summed in its `grads` (timed as `BLEND`).
    fn record_blend(
        &mut self,
        enc: &mut wgpu::CommandEncoder,
        want_depth: bool,
        acc: Accumulation,
    ) -> Result<(), GpuRenderError> {
        let gpu = self.gpu;
        let (grid, n) = self.current()?;
        let blend = self.blend(want_depth, acc)?;
        (self.adjoint).record_start::<M>(gpu, enc, (&grid, n), &self.pixel_grad, want_depth)?;
        self.timer.start(enc, BLEND);
        let adjoint = &self.adjoint;
        let mut inputs = self.tile_pass_inputs();
        inputs.extend([
            ("pixel_state", &*self.pixels),
            ("pixel_grad", &self.pixel_grad),
            ("grads", &adjoint.grads),
            ("issued", &adjoint.issued),
        ]);
        if M::HAS_PIXEL_INFO {
            inputs.push(("camera_words", &self.front.camera));
            inputs.push(("pixel_cotangent", &adjoint.pixel_cotangent));
        }
        if let Some(largest) = &adjoint.largest {
            inputs.push(("grad_largest", &largest.bits));
        }
        let tiles = grid.tile_count() as u32;
        let bind = gpu.bind_named(&blend, &inputs)?;
        dispatch(enc, &blend.pipeline, &bind, tiles);
        self.timer.end(enc, BLEND);
        Ok(())
    }

    /// The bindings every tile pass (forward and backward blend) shares (`tile_pass.wgsl`).
    fn tile_pass_inputs(&self) -> Vec<(&'static str, &wgpu::Buffer)> {
        let mut inputs = vec![
            ("projected", &*self.front.projected),
            ("tile_prims", &*self.front.prims),
            ("tile_ranges", &*self.tiles.ranges),
            ("tile_order", &*self.tiles.order),
            ("frame", &self.front.frame_uniform),
        ];
        if let Some(packer) = &self.packer {
            inputs.push(("packed_shade", &packer.packed));
            if packer.packing().has_ranges() {
                inputs.push(("shade_ranges", &packer.ranges));
            }
        }
        inputs
    }

    fn blend(&mut self, want_depth: bool, acc: Accumulation) -> Result<Kernel, GpuRenderError> {
        let gpu = self.gpu;
        if acc.float_atomics && !gpu.float_atomics {
            return Err(GpuError::Shader("this adapter has no f32 atomics".into()).into());
        }
        if acc.reduce == Reduction::Subgroup && !gpu.subgroups {
            return Err(GpuError::Shader("this adapter has no subgroup operations".into()).into());
        }
        let key = (self.front.model, want_depth, acc);
        if let Some(p) = self.blends.get(&key) {
            return Ok(p.clone());
        }
        let packing = self.packer.as_ref().map(ShadePacker::packing);
        let source =
            entries::backward::<M>(gpu, key.0, &self.opts, want_depth, acc, self.state, packing)?;
        let constants = entries::blend_constants(self.opts.blend);
        let k = gpu.kernel_with(&source, "backward_tiles", &constants)?;
        self.blends.insert(key, k.clone());
        Ok(k)
    }

    /// The parameter gradient words on the device (`M::Params`' float slots per primitive),
    /// for an optimizer on the device.
    pub fn param_gradients(&self) -> &wgpu::Buffer {
        &self.adjoint.param_grads
    }

    /// The gradient of each primitive's shade data on the device, [`Layout::grad_words`] f32
    /// words per primitive (`M::Shade`'s float slots, then the depth's), as the last backward
    /// blend left it; `None` where the sums are held in f16.
    pub fn shade_gradients(&self) -> Option<(&wgpu::Buffer, usize)> {
        let adjoint = &self.adjoint;
        (!adjoint.sums.half).then_some((&*adjoint.grads, self.layout.grad_words))
    }

    /// Bytes the last frame's sorts used ([`super::sort_bytes`]).
    pub fn sort_bytes(&self) -> usize {
        self.frame.map_or(0, |f| {
            super::sort_bytes(f.primitives, f.intersections, f.grid.tile_count() as u32)
        })
    }

    /// Bytes the last backward pass's per-primitive gradient sums took.
    pub fn gradient_sum_bytes(&self) -> usize {
        (self.adjoint).sum_bytes(self.frame.map_or(0, |f| f.primitives))
    }

    /// The last frame's stage times, read back alone (a few words; no image or gradient).
    /// Waits for the GPU.
    pub fn stage_times(&self) -> Result<StageTimes, GpuRenderError> {
        let times = self.timer.read(self.gpu)?.unwrap_or_default();
        let time = |s: u32| times.get(s as usize).copied().unwrap_or_default();
        Ok(StageTimes {
            preprocess: time(PROJECT) + time(PACK),
            rasterize: time(COUNT) + time(SORT),
            shade: time(SHADE),
            blend: time(BLEND),
            project: time(ADJOINT),
        })
    }

    /// The last backward pass's gradients, read back.
    pub fn download_gradients(&self) -> Result<GpuGradients<M>, GpuRenderError> {
        let info = self.frame.ok_or(GpuRenderError::NoFrame)?;
        let times = self.stage_times()?;
        let stats = BackwardStats {
            blend: times.blend,
            reduce: Default::default(),
            project: times.project,
        };
        let sizes = (&info.grid, info.primitives);
        Ok((self.adjoint).download::<M>(self.gpu, sizes, stats)?)
    }
}
