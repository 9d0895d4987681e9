//! A frame split between the ranks of a sharded run (`splat_train::sharded`): a slice of the
//! scene projected alone and read back; a frame rendered from the records `project` made of
//! every slice, its backward blend read back per record; `project`'s adjoint of a slice from
//! the gradients its records came back with. The records are the CPU's ([`Projected`]), so
//! the wire between ranks is one format for both backends.

use super::{ADJOINT, BLEND, FrameInfo, GIVEN, GpuRenderer, PROJECT, Projection, STAGES};
use crate::device::{Grown, Kernel, dispatch};
use crate::entries::{Accumulation, FINITE, PIXEL_SPAN};
use crate::scene::GpuScene;
use crate::sort::Scan;
use crate::{Gpu, GpuError, GpuRenderError};
use glam::Vec2;
use splat_core::flat::Flat;
use splat_core::grid::TileGrid;
use splat_core::method::SplatMethod;
use splat_core::types::{Camera, Projected};

/// What `project` makes of one primitive.
pub type Record<M> = Projected<<M as SplatMethod>::Cull, <M as SplatMethod>::Shade>;

impl<M: SplatMethod> GpuRenderer<'_, M> {
    /// The primitives of `scene` that reach the rasterizer through `camera` (`project` saw
    /// them and their box holds a pixel centre, as the CPU's filter keeps them): their
    /// places in the scene and their records, compacted on the device and read back (waits
    /// for it).
    pub fn project_visible(
        &mut self,
        scene: &GpuScene<M>,
        camera: &Camera,
    ) -> Result<(Vec<u32>, Vec<Record<M>>), GpuRenderError> {
        let grid = splat_core::frame::check::<M>(camera, &self.opts)?;
        (self.frame, self.pending) = (None, None);
        let (gpu, n, stride) = (self.gpu, scene.len(), self.layout.stride);
        if n == 0 {
            return Ok((vec![], vec![]));
        }
        let x = self.exchange()?;
        x.places.ensure(gpu, n)?;
        x.records.ensure(gpu, n * stride)?;
        x.index.ensure(gpu, n)?;
        x.scan.prepare(gpu, n as u32)?;
        gpu.write(&x.info, &[n as u32, stride as u32, grid.width, grid.height]);
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        enc.clear_buffer(&x.kept, 0, None);
        self.timer.start(&mut enc, PROJECT);
        self.front.record_project(gpu, &mut enc, (scene, camera))?;
        let x = self.exchange.as_ref().expect("made above");
        let projected = &*self.front.projected;
        let groups = (n as u32).div_ceil(256);
        let bind = gpu.bind_named(
            &x.mark,
            &[
                ("info", &x.info),
                ("projected", projected),
                ("places", &x.places),
                ("kept", &x.kept),
            ],
        )?;
        dispatch(&mut enc, &x.mark.pipeline, &bind, groups);
        x.scan.record(gpu, &mut enc, &x.places)?;
        let bind = gpu.bind_named(
            &x.gather,
            &[
                ("info", &x.info),
                ("projected", projected),
                ("places", &x.places),
                ("records", &x.records),
                ("index", &x.index),
            ],
        )?;
        dispatch(&mut enc, &x.gather.pipeline, &bind, groups);
        self.timer.end(&mut enc, PROJECT);
        gpu.queue.submit([enc.finish()]);
        let [kept] = gpu.read_together([(&x.kept, 1)])?;
        let kept = kept[0] as usize;
        if kept == 0 {
            return Ok((vec![], vec![]));
        }
        let [words, index] = gpu.read_together([(&x.records, kept * stride), (&x.index, kept)])?;
        Ok((index, words.chunks_exact(stride).map(decode::<M>).collect()))
    }

    /// Records and submits the frame of `records` through `camera`, as
    /// [`GpuRenderer::submit`] does a scene's; [`GpuRenderer::finish_records`] or
    /// [`GpuRenderer::settle_records`] waits for it.
    pub fn submit_records(
        &mut self,
        records: &[Record<M>],
        camera: &Camera,
    ) -> Result<TileGrid, GpuRenderError> {
        let words = encode::<M>(records, self.layout.stride);
        self.submit_from(Projection::Given(&words), camera)
    }

    /// [`GpuRenderer::settle`] of a frame of records.
    pub fn settle_records(&mut self) -> Result<Option<FrameInfo>, GpuRenderError> {
        self.settle_any()
    }

    /// [`GpuRenderer::finish`] of the frame of `records` through `camera` submitted last.
    pub fn finish_records(
        &mut self,
        records: &[Record<M>],
        camera: &Camera,
    ) -> Result<FrameInfo, GpuRenderError> {
        if self.rendered_from != GIVEN {
            return Err(GpuRenderError::OtherScene);
        }
        let mut redone = false;
        loop {
            if let Some(info) = self.settle_any()? {
                return Ok(FrameInfo { redone, ..info });
            }
            redone = true;
            self.submit_records(records, camera)?;
        }
    }

    /// The backward blend of the frame of records submitted last, from the output gradients
    /// in [`GpuRenderer::pixel_gradients`] (a loss on the device wrote them; depth's
    /// ignored): each record's gradient, read with [`GpuRenderer::download_record_gradients`]
    /// once the frame settled. No adjoint: the records' primitives live on other ranks.
    pub fn blend_records(&mut self, acc: Accumulation) -> Result<(), GpuRenderError> {
        self.refuse_half_sums()?;
        if self.rendered_from != GIVEN {
            return Err(GpuRenderError::OtherScene);
        }
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        self.record_blend(&mut enc, false, acc)?;
        self.timer.start(&mut enc, ADJOINT);
        self.timer.end(&mut enc, ADJOINT);
        self.timer.resolve(&mut enc, BLEND..STAGES);
        self.gpu.queue.submit([enc.finish()]);
        Ok(())
    }

    /// The last backward blend's gradient of each record of its frame: [`Layout`]'s
    /// `grad_words` per record (`M::Shade`'s float slots, then the depth's), read back.
    ///
    /// [`Layout`]: crate::entries::Layout
    pub fn download_record_gradients(&self) -> Result<Vec<f32>, GpuRenderError> {
        self.refuse_half_sums()?;
        let (_, n) = self.current()?;
        let words = n * self.layout.grad_words;
        if words == 0 {
            return Ok(vec![]);
        }
        let bits = self.gpu.read(&self.adjoint.grads, words)?;
        Ok(bits.into_iter().map(f32::from_bits).collect())
    }

    /// `project`'s adjoint for the primitives of `scene` through `camera`, given the shade
    /// and depth gradients of those at `index` (`grad_words` each, as
    /// [`GpuRenderer::download_record_gradients`] reads them; the others' are zero): the
    /// parameter gradients in [`GpuRenderer::param_gradients`], and beside them what density
    /// control's statistics read ([`GpuRenderer::projected`],
    /// [`GpuRenderer::shade_gradients`], [`GpuRenderer::frame_keys`] saying no frame was cut).
    /// The camera's gradient through `pixel_info` is not taken: the pixels are elsewhere.
    pub fn adjoint_from(
        &mut self,
        scene: &GpuScene<M>,
        camera: &Camera,
        (index, record_grads): (&[u32], &[f32]),
    ) -> Result<(), GpuRenderError> {
        self.refuse_half_sums()?;
        let (gpu, n, words) = (self.gpu, scene.len(), self.layout.grad_words);
        let bad = |what: String| Err(GpuError::Shader(what).into());
        if record_grads.len() != index.len() * words {
            return bad(format!(
                "{} gradient words for {} records of {words}",
                record_grads.len(),
                index.len()
            ));
        }
        if let Some(&i) = index.iter().find(|&&i| i as usize >= n) {
            return bad(format!("a record of primitive {i} of a slice of {n}"));
        }
        splat_core::frame::check::<M>(camera, &self.opts)?;
        (self.frame, self.pending) = (None, None);
        self.adjoint.grads.ensure(gpu, n * words)?;
        gpu.write(self.front.key_count(), &[0, 0]);
        let x = self.exchange()?;
        let records = index.len();
        x.index.ensure(gpu, records)?;
        x.record_grads.ensure(gpu, records * words)?;
        gpu.write(&x.index, index);
        let bits: Vec<u32> = record_grads.iter().map(|g| g.to_bits()).collect();
        gpu.write(&x.record_grads, &bits);
        gpu.write(&x.info, &[records as u32, words as u32, 0, 0]);
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        enc.clear_buffer(&self.adjoint.grads, 0, Some(4 * (n * words).max(1) as u64));
        let x = self.exchange.as_ref().expect("made above");
        if records > 0 {
            let bind = gpu.bind_named(
                &x.scatter,
                &[
                    ("info", &x.info),
                    ("index", &x.index),
                    ("record_grads", &x.record_grads),
                    ("grads", &self.adjoint.grads),
                ],
            )?;
            let groups = ((records * words) as u32).div_ceil(256);
            dispatch(&mut enc, &x.scatter.pipeline, &bind, groups);
        }
        self.front.record_project(gpu, &mut enc, (scene, camera))?;
        self.timer.start(&mut enc, BLEND);
        self.timer.end(&mut enc, BLEND);
        self.timer.start(&mut enc, ADJOINT);
        (self.adjoint).record_project(gpu, &mut enc, scene, &self.front)?;
        self.timer.end(&mut enc, ADJOINT);
        self.timer.resolve(&mut enc, BLEND..STAGES);
        gpu.queue.submit([enc.finish()]);
        Ok(())
    }

    /// The exchange's kernels and buffers, made on first use.
    fn exchange(&mut self) -> Result<&mut Exchange, GpuError> {
        if self.exchange.is_none() {
            self.exchange = Some(Exchange::new(self.gpu)?);
        }
        Ok(self.exchange.as_mut().expect("made above"))
    }

    /// Records' gradients cross between ranks as f32 words: sums held in f16 are refused.
    fn refuse_half_sums(&self) -> Result<(), GpuRenderError> {
        match self.adjoint.sums.half {
            true => Err(GpuError::Shader(
                "a sharded frame's gradients are read per record as f32 sums, not f16".into(),
            )
            .into()),
            false => Ok(()),
        }
    }
}

/// The kernels and buffers that compact a slice's records and scatter their gradients
/// (`shaders/records.wgsl`).
pub(super) struct Exchange {
    mark: Kernel,
    gather: Kernel,
    scatter: Kernel,
    info: wgpu::Buffer,
    /// Per primitive whether it is kept, then its place among the kept.
    places: Grown,
    scan: Scan,
    /// `[kept]`.
    kept: wgpu::Buffer,
    records: Grown,
    /// The kept primitives' places in the scene, or the places of the records whose
    /// gradients came back.
    index: Grown,
    record_grads: Grown,
}

impl Exchange {
    fn new(gpu: &Gpu) -> Result<Exchange, GpuError> {
        let source = format!("{FINITE}\n{PIXEL_SPAN}\n{RECORDS}");
        let grown = |what, words| Grown::new(gpu, what, words);
        Ok(Exchange {
            mark: gpu.kernel(&source, "mark_kept")?,
            gather: gpu.kernel(&source, "gather_kept")?,
            scatter: gpu.kernel(&source, "scatter_gradients")?,
            info: gpu.uniform_buffer(4),
            places: grown("places among the kept", 1)?,
            scan: Scan::new(gpu)?,
            kept: gpu.buffer("primitives kept", 1)?,
            records: grown("kept records", 1)?,
            index: grown("records' places", 1)?,
            record_grads: grown("records' gradients", 1)?,
        })
    }
}

const RECORDS: &str = include_str!("../shaders/records.wgsl");

/// A record from its `stride` words on the device: visible, depth, box, `cull`, `shade`.
fn decode<M: SplatMethod>(w: &[u32]) -> Record<M> {
    let f: Vec<f32> = w.iter().map(|&x| f32::from_bits(x)).collect();
    let shade_at = 6 + M::Cull::LEN;
    Projected {
        visible: w[0] != 0,
        depth: f[1],
        bbox_min: Vec2::new(f[2], f[3]),
        bbox_max: Vec2::new(f[4], f[5]),
        cull: M::Cull::read_words(&f[6..shade_at]),
        shade: M::Shade::read_words(&f[shade_at..]),
    }
}

/// `records` as the device holds `project`'s results, `stride` words each ([`decode`]'s).
fn encode<M: SplatMethod>(records: &[Record<M>], stride: usize) -> Vec<u32> {
    let shade_at = 6 + M::Cull::LEN;
    let mut f = vec![0.0f32; records.len() * stride];
    for (w, r) in f.chunks_exact_mut(stride).zip(records) {
        w[1] = r.depth;
        w[2..4].copy_from_slice(&r.bbox_min.to_array());
        w[4..6].copy_from_slice(&r.bbox_max.to_array());
        r.cull.write_words(&mut w[6..shade_at]);
        r.shade.write_words(&mut w[shade_at..]);
    }
    let mut words: Vec<u32> = f.into_iter().map(f32::to_bits).collect();
    for (w, r) in words.chunks_exact_mut(stride).zip(records) {
        w[0] = r.visible as u32;
    }
    words
}
