//! The front of a GPU frame, shared by the tile-based forward pass ([`super::resident`]) and
//! the hardware-rasterized one ([`super::raster`]): `project` per primitive, the primitives
//! sorted by depth, each one's count of (kept) tiles front to back and their prefix sum; then
//! one tile key per (primitive, tile) emitted front to back and sorted, stably, by tile: each
//! tile's list comes out front to back (ties by index, as the CPU's) after a sort of the
//! primitives on 32 bits and of the keys on the tile bits only, where one sort of all keys on
//! (tile, depth) would take 32 more bits of passes over every key.
//! How many keys there are is settled on the device (`settle.wgsl`): all of them, or as many
//! as the buffers hold, so a frame can be recorded whole with the room of the frames before it
//! and learn afterwards whether it fitted ([`Counted::cut`]). A frame that must know first
//! reads its count back in between ([`Front::count`], then [`Front::reserve`]). The hardware
//! path runs it with one tile covering the image: one key per visible primitive, front to
//! back (no tile pass).

use super::device::{Grown, Kernel, as_bytes, dispatch};
use super::entries::{self, Layout, TilesEntry};
use super::frame_uniform::{self, FrameUniform};
use super::per_model::PerModel;
use super::scene::{GpuScene, words_of};
use super::sort::{RadixSort, Scan, tile_bits};
use super::timing::StageTimer;
use super::{Gpu, GpuError, GpuRenderError};
use splat_core::flat::Flat;
use splat_core::frame::RenderError;
use splat_core::grid::MAX_INTERSECTIONS;
use splat_core::grid::TileGrid;
use splat_core::method::SplatMethod;
use splat_core::types::{Camera, CameraModel};

// The front's timed stages, the first of every renderer's timer (two timestamps each).
pub(crate) const PROJECT: u32 = 0;
/// The depth sort, the count and its prefix sum.
pub(crate) const COUNT: u32 = 1;
/// Emit and sort (and whatever the renderer adds before its next stage).
pub(crate) const SORT: u32 = 2;

/// What the count found.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Counted {
    /// (primitive, tile) pairs to sort.
    pub intersections: u64,
    /// Primitives whose box holds a pixel centre.
    pub visible: usize,
    /// Whether the buffers held fewer keys than that (the frame's lists were cut).
    pub cut: bool,
}

const SETTLE: &str = include_str!("shaders/settle.wgsl");

/// Where a frame's `project` results come from.
pub(crate) enum Projection<'a, M: SplatMethod> {
    /// `project` of a scene's primitives, run on the device.
    Scene(&'a GpuScene<M>),
    /// Results `project` made elsewhere (a sharded run's records of every slice), as the
    /// device holds them: [`Layout`]'s stride of words each.
    Given(&'a [u32]),
}

impl<M: SplatMethod> Projection<'_, M> {
    /// The frame's primitives.
    pub fn len(&self) -> usize {
        match self {
            Projection::Scene(scene) => scene.len(),
            Projection::Given(words) => words.len() / Layout::of::<M>().stride,
        }
    }
}

/// Bits of the depth keys (`depth.wgsl`): a float's.
const DEPTH_BITS: u32 = 32;

pub(crate) struct Front {
    project: PerModel<Kernel>,
    depth: Kernel,
    count: Kernel,
    settle: Kernel,
    emit: Kernel,
    pub camera: wgpu::Buffer,
    /// (primitives, width, height, tile size), (tiles_x, P_max, tiles, keys the buffers hold).
    pub frame_uniform: wgpu::Buffer,
    /// (primitives, 0, 0, 0).
    pub count_info: wgpu::Buffer,
    pub projected: Grown,
    /// The depth sort's keys and values: the primitives front to back once sorted.
    depth_keys: Grown,
    order: Grown,
    /// `[primitives]`: the depth sort's count.
    primitives: wgpu::Buffer,
    depth_sort: RadixSort,
    counts: Grown,
    /// Intersections (low, high word), primitives with a tile rectangle.
    totals: wgpu::Buffer,
    /// Keys emitted and sorted, 1 if the lists were cut (`settle.wgsl`).
    key_count: wgpu::Buffer,
    /// `totals` then `key_count`, for the host.
    totals_staging: wgpu::Buffer,
    scan: Scan,
    /// Each intersection's tile.
    pub keys: Grown,
    /// The primitive of each sorted key.
    pub prims: Grown,
    tile_sort: RadixSort,
    /// Keys the buffers hold (zero before the first `reserve`).
    room: usize,
    /// Primitives, tiles and camera model of the frame counted last.
    n: u32,
    tiles: u32,
    pub model: CameraModel,
}

impl Front {
    /// `use_cull` false keeps every tile of each box (no `tile_cull`).
    pub fn new<M: SplatMethod>(gpu: &Gpu, use_cull: bool) -> Result<Front, GpuError> {
        let grown = |what, words| Grown::new(gpu, what, words);
        Ok(Front {
            project: PerModel::new(),
            depth: gpu.kernel(
                &entries::tiles::<M>(TilesEntry::DepthKeys, use_cull)?,
                "depth_keys",
            )?,
            count: gpu.kernel(
                &entries::tiles::<M>(TilesEntry::Count, use_cull)?,
                "count_tiles",
            )?,
            settle: gpu.kernel(
                &format!("{}\n{SETTLE}", frame_uniform::WGSL),
                "settle_count",
            )?,
            emit: gpu.kernel(
                &entries::tiles::<M>(TilesEntry::Emit, use_cull)?,
                "emit_tiles",
            )?,
            camera: gpu.buffer("camera", Camera::LEN)?,
            frame_uniform: gpu.uniform_buffer(FrameUniform::WORDS),
            count_info: gpu.uniform_buffer(4),
            projected: grown("projected primitives", 1)?,
            depth_keys: grown("depth keys", 1)?,
            order: grown("primitives front to back", 1)?,
            primitives: gpu.buffer("primitives to sort", 1)?,
            depth_sort: RadixSort::new(gpu)?,
            counts: grown("tiles per primitive", 1)?,
            totals: gpu.buffer("intersection totals", 3)?,
            key_count: gpu.buffer("keys sorted", 2)?,
            totals_staging: gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("intersection totals readback"),
                size: 20,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            scan: Scan::new(gpu)?,
            keys: grown("intersection keys", 1)?,
            prims: grown("intersection primitives", 1)?,
            tile_sort: RadixSort::new(gpu)?,
            room: 0,
            n: 0,
            tiles: 0,
            model: CameraModel::Pinhole,
        })
    }

    /// Keys the buffers hold: a frame with more intersections is cut ([`Counted::cut`]).
    /// Zero before the first [`Front::reserve`].
    pub fn room(&self) -> usize {
        self.room
    }

    /// The primitive count and camera of the frame whose `project` results `projected` holds.
    fn frame_of(&mut self, gpu: &Gpu, n: usize, camera: &Camera) {
        (self.n, self.model) = (n as u32, camera.model);
        gpu.write(&self.camera, &words_of(std::slice::from_ref(camera)));
        gpu.write(&self.count_info, &[n as u32, 0, 0, 0]);
    }

    /// Records `project` of `scene` through `camera` alone (its results in `projected`).
    pub fn record_project<M: SplatMethod>(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        (scene, camera): (&GpuScene<M>, &Camera),
    ) -> Result<(), GpuRenderError> {
        let n = scene.len();
        let model = camera.model;
        let project = self.project.get(model, || {
            gpu.kernel(&entries::project::<M>(model)?, "splat_harness")
        })?;
        self.projected.ensure(gpu, n * Layout::of::<M>().stride)?;
        self.frame_of(gpu, n, camera);
        let bind = gpu.bind_named(
            &project,
            &[
                ("harness_rows", scene.buffer()),
                ("harness_shared", &self.camera),
                ("harness_out", &self.projected),
                ("harness_count", &self.count_info),
            ],
        )?;
        dispatch(enc, &project.pipeline, &bind, (n as u32).div_ceil(64));
        Ok(())
    }

    /// Records `project`'s results of `source` through `camera`, the depth sort, each
    /// primitive's count of tiles of `grid` front to back and their prefix sum (timed as
    /// `PROJECT` and `COUNT`). Lists are read capped at `p_max` entries.
    pub fn record_count<M: SplatMethod>(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        (source, camera): (Projection<M>, &Camera),
        (grid, p_max): (&TileGrid, u32),
        timer: &StageTimer,
    ) -> Result<(), GpuRenderError> {
        let n = source.len();
        let n32 = n as u32;
        self.tiles = grid.tile_count() as u32;
        self.depth_keys.ensure(gpu, n)?;
        self.order.ensure(gpu, n)?;
        self.depth_sort.prepare(gpu, n32, DEPTH_BITS)?;
        self.counts.ensure(gpu, n)?;
        self.scan.prepare(gpu, n32)?;
        gpu.write(&self.primitives, &[n32]);
        let info = FrameUniform {
            primitives: n32,
            width: grid.width,
            height: grid.height,
            tile_size: grid.size,
            tiles_x: grid.tiles_x,
            p_max,
            tiles: self.tiles,
            room: self.room as u32,
        };
        gpu.write(&self.frame_uniform, &info.words());

        enc.clear_buffer(&self.totals, 0, None);
        timer.start(enc, PROJECT);
        match source {
            Projection::Scene(scene) => self.record_project(gpu, enc, (scene, camera))?,
            Projection::Given(words) => {
                self.projected.ensure(gpu, words.len())?;
                gpu.write(&self.projected, words);
                self.frame_of(gpu, n, camera);
            }
        }
        timer.end(enc, PROJECT);
        timer.start(enc, COUNT);
        let bind = gpu.bind_named(
            &self.depth,
            &[
                ("projected", &self.projected),
                ("frame", &self.frame_uniform),
                ("keys", &self.depth_keys),
                ("order", &self.order),
            ],
        )?;
        dispatch(enc, &self.depth.pipeline, &bind, n32.div_ceil(256));
        self.depth_sort
            .record(gpu, enc, &self.depth_keys, &self.order, &self.primitives)?;
        let bind = gpu.bind_named(
            &self.count,
            &[
                ("projected", &self.projected),
                ("counts", &self.counts),
                ("frame", &self.frame_uniform),
                ("totals", &self.totals),
                ("order", &self.order),
            ],
        )?;
        dispatch(enc, &self.count.pipeline, &bind, n32.div_ceil(256));
        self.scan.record(gpu, enc, &self.counts)?;
        timer.end(enc, COUNT);
        Ok(())
    }

    /// Submission 1 of a frame that waits for its count: [`Front::record_count`], then the
    /// totals read back.
    pub fn count<M: SplatMethod>(
        &mut self,
        gpu: &Gpu,
        frame: (Projection<M>, &Camera),
        grid: (&TileGrid, u32),
        timer: &StageTimer,
    ) -> Result<Counted, GpuRenderError> {
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        self.record_count(gpu, &mut enc, frame, grid, timer)?;
        enc.copy_buffer_to_buffer(&self.totals, 0, &self.totals_staging, 0, 12);
        gpu.queue.submit([enc.finish()]);
        let t = gpu.read_mappable(&self.totals_staging, 3)?;
        counted(&t, false)
    }

    /// Makes room for the keys `counted` found, with a quarter to spare when the buffers
    /// grow (a `Counted` holds at most `MAX_INTERSECTIONS`: reading the totals refuses more).
    pub fn reserve(&mut self, gpu: &Gpu, counted: Counted) -> Result<(), GpuError> {
        let keys = counted.intersections as usize;
        self.keys.ensure(gpu, keys)?;
        self.prims.ensure(gpu, keys)?;
        self.room = self.keys.words().min(self.prims.words());
        // The frame's uniform says how many keys fit (recorded frames read it when they run).
        let room = [self.room as u32];
        gpu.queue
            .write_buffer(&self.frame_uniform, FrameUniform::ROOM, as_bytes(&room));
        Ok(())
    }

    /// Records the keys' count for this frame (all, or the buffers' room: `settle.wgsl`), their
    /// emission front to back and sort by tile, and the copy of the totals that
    /// [`Front::counted`] reads.
    pub fn emit_sorted(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
    ) -> Result<(), GpuError> {
        let room = self.room as u32;
        self.tile_sort.prepare(gpu, room, tile_bits(self.tiles))?;
        let bind = gpu.bind_named(
            &self.settle,
            &[
                ("totals", &self.totals),
                ("frame", &self.frame_uniform),
                ("key_count", &self.key_count),
            ],
        )?;
        dispatch(enc, &self.settle.pipeline, &bind, 1);
        let bind = gpu.bind_named(
            &self.emit,
            &[
                ("projected", &self.projected),
                ("counts", &self.counts),
                ("frame", &self.frame_uniform),
                ("keys", &self.keys),
                ("vals", &self.prims),
                ("order", &self.order),
            ],
        )?;
        dispatch(enc, &self.emit.pipeline, &bind, self.n.div_ceil(256));
        self.tile_sort
            .record(gpu, enc, &self.keys, &self.prims, &self.key_count)?;
        enc.copy_buffer_to_buffer(&self.totals, 0, &self.totals_staging, 0, 12);
        enc.copy_buffer_to_buffer(&self.key_count, 0, &self.totals_staging, 12, 8);
        Ok(())
    }

    /// How many keys the frame sorts, on the device (`[keys, cut]`): the count the tile
    /// ranges read.
    pub fn key_count(&self) -> &wgpu::Buffer {
        &self.key_count
    }

    /// The last frame's totals, once it has run (waits for it).
    pub fn counted(&self, gpu: &Gpu) -> Result<Counted, GpuRenderError> {
        let t = gpu.read_mappable(&self.totals_staging, 5)?;
        counted(&t, t[4] != 0)
    }
}

/// Bytes the sorts of a frame of `primitives` with `intersections` over `tiles` tiles hold:
/// the depth sort's and the tile sort's keys, values and scratch copies.
pub fn sort_bytes(primitives: usize, intersections: usize, tiles: u32) -> usize {
    RadixSort::bytes_for(primitives, DEPTH_BITS)
        + RadixSort::bytes_for(intersections, tile_bits(tiles))
}

/// The totals' words (intersections low and high, visible) as a count; refuses more
/// intersections than a frame may have.
fn counted(t: &[u32], cut: bool) -> Result<Counted, GpuRenderError> {
    let total = t[0] as u64 | (t[1] as u64) << 32;
    if total > MAX_INTERSECTIONS {
        return Err(RenderError::TooManyIntersections {
            count: total,
            limit: MAX_INTERSECTIONS,
        }
        .into());
    }
    Ok(Counted {
        intersections: total,
        visible: t[2] as usize,
        cut,
    })
}
