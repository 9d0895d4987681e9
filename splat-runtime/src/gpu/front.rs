//! The front of a GPU frame, shared by the tile-based forward pass ([`super::resident`]) and
//! the hardware-rasterized one ([`super::raster`]): `project` per primitive, each primitive's
//! count of (kept) tiles and their prefix sum; then the (depth, tile) keys emitted and sorted.
//! How many keys there are is settled on the device (`settle.wgsl`): all of them, or as many
//! as the buffers hold, so a frame can be recorded whole with the room of the frames before it
//! and learn afterwards whether it fitted ([`Counted::cut`]). A frame that must know first
//! reads its count back in between ([`Front::count`], then [`Front::reserve`]). The hardware
//! path runs it with one tile covering the image: one key per visible primitive, sorted by
//! depth.

use super::device::{Grown, Kernel, as_bytes, dispatch};
use super::entries::{self, Layout};
use super::per_model::PerModel;
use super::resident::{GpuRenderError, GpuScene, words_of};
use super::sort::{RadixSort, Scan};
use super::timing::StageTimer;
use super::{Gpu, GpuError};
use crate::flat::Flat;
use crate::method::SplatMethod;
use crate::pipeline::RenderError;
use crate::pipeline::grid::TileGrid;
use crate::pipeline::rasterize::MAX_INTERSECTIONS;
use crate::types::{Camera, CameraModel};

// The front's timed stages, the first of every renderer's timer (two timestamps each).
pub(crate) const PROJECT: u32 = 0;
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

pub(crate) struct Front {
    project: PerModel<Kernel>,
    count: Kernel,
    settle: Kernel,
    emit: Kernel,
    pub camera: wgpu::Buffer,
    /// (primitives, width, height, tile size), (tiles_x, P_max, tiles, keys the buffers hold).
    pub frame_info: wgpu::Buffer,
    /// (primitives, 0, 0, 0).
    pub count_info: wgpu::Buffer,
    pub projected: Grown,
    counts: Grown,
    /// Intersections (low, high word), primitives with a tile rectangle.
    totals: wgpu::Buffer,
    /// Keys emitted and sorted, 1 if the lists were cut (`settle.wgsl`).
    key_count: wgpu::Buffer,
    /// `totals` then `key_count`, for the host.
    totals_staging: wgpu::Buffer,
    scan: Scan,
    pub keys: Grown,
    /// The primitive of each sorted key.
    pub prims: Grown,
    sort: RadixSort,
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
            count: gpu.kernel(&entries::tiles::<M>(false, use_cull)?, "count_tiles")?,
            settle: gpu.kernel(SETTLE, "settle_count")?,
            emit: gpu.kernel(&entries::tiles::<M>(true, use_cull)?, "emit_tiles")?,
            camera: gpu.buffer("camera", Camera::LEN)?,
            frame_info: gpu.uniform_buffer(8),
            count_info: gpu.uniform_buffer(4),
            projected: grown("projected primitives", 1)?,
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
            keys: grown("intersection keys", 2)?,
            prims: grown("intersection primitives", 1)?,
            sort: RadixSort::new(gpu)?,
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

    /// Records `project` of `scene` through `camera`, each primitive's count of tiles of
    /// `grid` and their prefix sum (timed as `PROJECT` and `COUNT`). Lists are read capped at
    /// `p_max` entries.
    pub fn record_count<M: SplatMethod>(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        (scene, camera): (&GpuScene<M>, &Camera),
        (grid, p_max): (&TileGrid, u32),
        timer: &StageTimer,
    ) -> Result<(), GpuRenderError> {
        let n = scene.len();
        let n32 = n as u32;
        let model = camera.model;
        let project = self.project.get(model, || {
            gpu.kernel(&entries::project::<M>(model)?, "splat_harness")
        })?;
        self.n = n32;
        self.model = model;
        self.tiles = grid.tile_count() as u32;
        self.projected.ensure(gpu, n * Layout::of::<M>().stride)?;
        self.counts.ensure(gpu, n)?;
        self.scan.prepare(gpu, n32)?;
        gpu.write(&self.camera, &words_of(std::slice::from_ref(camera)));
        // All but the last word, the room, which only `reserve` writes.
        gpu.write(
            &self.frame_info,
            &[
                n32,
                grid.width,
                grid.height,
                grid.size,
                grid.tiles_x,
                p_max,
                self.tiles,
            ],
        );
        gpu.write(&self.count_info, &[n32, 0, 0, 0]);

        enc.clear_buffer(&self.totals, 0, None);
        timer.start(enc, PROJECT);
        let bind = gpu.bind_named(
            &project,
            &[
                ("harness_rows", scene.buffer()),
                ("harness_shared", &self.camera),
                ("harness_out", &self.projected),
                ("harness_count", &self.count_info),
            ],
        )?;
        dispatch(enc, &project.pipeline, &bind, n32.div_ceil(64));
        timer.end(enc, PROJECT);
        timer.start(enc, COUNT);
        let bind = gpu.bind_named(
            &self.count,
            &[
                ("projected", &self.projected),
                ("counts", &self.counts),
                ("frame", &self.frame_info),
                ("totals", &self.totals),
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
        frame: (&GpuScene<M>, &Camera),
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
        self.keys.ensure(gpu, 2 * keys)?;
        self.prims.ensure(gpu, keys)?;
        self.room = (self.keys.words() / 2).min(self.prims.words());
        // The frame's uniform says how many keys fit (recorded frames read it when they run).
        let room = [self.room as u32];
        gpu.queue
            .write_buffer(&self.frame_info, 28, as_bytes(&room));
        Ok(())
    }

    /// Records the keys' count for this frame (all, or the buffers' room: `settle.wgsl`), their
    /// emission and sort by (tile, depth), and the copy of the totals that
    /// [`Front::counted`] reads.
    pub fn emit_sorted(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
    ) -> Result<(), GpuError> {
        let room = self.room as u32;
        self.sort.prepare(gpu, room, self.tiles)?;
        let bind = gpu.bind_named(
            &self.settle,
            &[
                ("totals", &self.totals),
                ("frame", &self.frame_info),
                ("key_count", &self.key_count),
            ],
        )?;
        dispatch(enc, &self.settle.pipeline, &bind, 1);
        let bind = gpu.bind_named(
            &self.emit,
            &[
                ("projected", &self.projected),
                ("counts", &self.counts),
                ("frame", &self.frame_info),
                ("keys", &self.keys),
                ("vals", &self.prims),
            ],
        )?;
        dispatch(enc, &self.emit.pipeline, &bind, self.n.div_ceil(256));
        self.sort
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
