//! The front of a GPU frame, shared by the tile-based forward pass ([`super::resident`]) and
//! the hardware-rasterized one ([`super::raster`]): `project` per primitive, each primitive's
//! count of (kept) tiles, their prefix sum and the total read back (the frame's one wait,
//! which sizes the sort); then the (depth, tile) keys emitted and sorted. The hardware path
//! runs it with one tile covering the image: one key per visible primitive, sorted by depth.

use super::device::{Grown, Kernel, dispatch};
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
}

pub(crate) struct Front {
    project: PerModel<Kernel>,
    count: Kernel,
    emit: Kernel,
    pub camera: wgpu::Buffer,
    /// (primitives, width, height, tile size), (tiles_x, P_max, tiles, 0).
    pub frame_info: wgpu::Buffer,
    /// (primitives, 0, 0, 0).
    pub count_info: wgpu::Buffer,
    pub projected: Grown,
    counts: Grown,
    /// Intersections (low, high word), primitives with a tile rectangle.
    totals: wgpu::Buffer,
    totals_staging: wgpu::Buffer,
    scan: Scan,
    pub keys: Grown,
    /// The primitive of each sorted key.
    pub prims: Grown,
    sort: RadixSort,
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
            emit: gpu.kernel(&entries::tiles::<M>(true, use_cull)?, "emit_tiles")?,
            camera: gpu.buffer("camera", Camera::LEN)?,
            frame_info: gpu.uniform_buffer(8),
            count_info: gpu.uniform_buffer(4),
            projected: grown("projected primitives", 1)?,
            counts: grown("tiles per primitive", 1)?,
            totals: gpu.buffer("intersection totals", 3)?,
            totals_staging: gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("intersection totals readback"),
                size: 12,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            scan: Scan::new(gpu)?,
            keys: grown("intersection keys", 2)?,
            prims: grown("intersection primitives", 1)?,
            sort: RadixSort::new(gpu)?,
            n: 0,
            tiles: 0,
            model: CameraModel::Pinhole,
        })
    }

    /// Submission 1: project `scene` through `camera`, count each primitive's tiles of `grid`,
    /// prefix sum (timed as `PROJECT` and `COUNT`); waits for the total. Lists are read
    /// capped at `p_max` entries.
    pub fn count<M: SplatMethod>(
        &mut self,
        gpu: &Gpu,
        scene: &GpuScene<M>,
        camera: &Camera,
        (grid, p_max): (&TileGrid, u32),
        timer: &StageTimer,
    ) -> Result<Counted, GpuRenderError> {
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
                0,
            ],
        );
        gpu.write(&self.count_info, &[n32, 0, 0, 0]);

        let mut enc = gpu.device.create_command_encoder(&Default::default());
        enc.clear_buffer(&self.totals, 0, None);
        timer.start(&mut enc, PROJECT);
        let bind = gpu.bind_named(
            &project,
            &[
                ("harness_rows", scene.buffer()),
                ("harness_shared", &self.camera),
                ("harness_out", &self.projected),
                ("harness_count", &self.count_info),
            ],
        )?;
        dispatch(&mut enc, &project.pipeline, &bind, n32.div_ceil(64));
        timer.end(&mut enc, PROJECT);
        timer.start(&mut enc, COUNT);
        let bind = gpu.bind_named(
            &self.count,
            &[
                ("projected", &self.projected),
                ("counts", &self.counts),
                ("frame", &self.frame_info),
                ("totals", &self.totals),
            ],
        )?;
        dispatch(&mut enc, &self.count.pipeline, &bind, n32.div_ceil(256));
        self.scan.record(gpu, &mut enc, &self.counts)?;
        timer.end(&mut enc, COUNT);
        enc.copy_buffer_to_buffer(&self.totals, 0, &self.totals_staging, 0, 12);
        gpu.queue.submit([enc.finish()]);
        let t = gpu.read_mappable(&self.totals_staging, 3)?;
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
        })
    }

    /// Records the emission of the `counted` keys and their sort by (tile, depth).
    pub fn emit_sorted(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        counted: Counted,
    ) -> Result<(), GpuError> {
        let total = counted.intersections as usize;
        self.keys.ensure(gpu, 2 * total)?;
        self.prims.ensure(gpu, total)?;
        self.sort.prepare(gpu, total as u32, self.tiles)?;
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
        self.sort.record(gpu, enc, &self.keys, &self.prims)
    }
}
