//! The hardware-rasterized forward pass (Yuan and He's differentiable hardware rasterization,
//! forward half): no tile lists. The primitives are sorted once by depth (O(N) sort memory
//! where the tile path also sorts one key per (primitive, tile) pair), drawn as quads over
//! their boxes by a render pipeline whose fragment shader calls the method's generated
//! `evaluate`, and blended front to back by fixed-function blending into render targets of the
//! precision `RenderOptions::precision` asks for: `Rgba32Float`, `Rgba16Float`, `Rgba16Unorm`
//! or `Rgba8Unorm`. Every blend rounds to the target's format, as on the hardware the paper
//! measures; unorm targets saturate.
//!
//! It differs from the tile path in what fixed-function blending cannot do: a pixel is never
//! stopped at `t_min` (its later primitives still blend; they add at most `t_min` of color),
//! and there is no P_max.
//!
//! With [`Blending::Programmable`] (a device from [`super::programmable_blend::open`]) the
//! fragments blend themselves, reading and writing the targets in rasterization order: the
//! same images, and a stop mark per pixel, so a pixel stops at `t_min` as on the tile path.
//! Such a frame has a backward pass of its own ([`backward`]), which replays the draw.

use super::adjoint::Adjoint;
use super::device::Grown;
use super::front::{COUNT, Front, PROJECT, Projection, SORT};
use super::per_model::PerModel;
use super::programmable_blend::{Order, RasterPass, RasterPassDesc};
use super::resident::FrameInfo;
use super::timing::StageTimer;
use super::{Gpu, GpuError, entries};
use super::{GpuRenderError, GpuScene};
use half::f16;
use splat_core::frame::{Frame, Image, RenderOptions, Stats};
use splat_core::grid::TileGrid;
use splat_core::method::SplatMethod;
use splat_core::precision::Precision;
use splat_core::types::{Camera, CameraModel};
use std::marker::PhantomData;

mod backward;

// The renderer's timed stages after the front's (two timestamps each).
const DRAW: u32 = 3;
/// `project`'s adjoint (and `pixel_info`'s) after the backward replay.
const ADJOINT: u32 = 4;
const STAGES: u32 = 5;

/// The render-target format that stores values at `precision`.
pub fn target_format(precision: Precision) -> wgpu::TextureFormat {
    match precision {
        Precision::F32 => wgpu::TextureFormat::Rgba32Float,
        Precision::F16 => wgpu::TextureFormat::Rgba16Float,
        Precision::Unorm16 => wgpu::TextureFormat::Rgba16Unorm,
        Precision::Unorm8 => wgpu::TextureFormat::Rgba8Unorm,
    }
}

/// Whether `gpu` can blend into targets of `precision` (f32 and unorm16 need features).
pub fn supports(gpu: &Gpu, precision: Precision) -> bool {
    match precision {
        Precision::F32 => gpu.float32_blending,
        Precision::Unorm16 => gpu.unorm16_targets,
        Precision::F16 | Precision::Unorm8 => true,
    }
}

/// The format of programmable blending's stop mark per pixel.
const STOP_MARK: wgpu::TextureFormat = wgpu::TextureFormat::R8Uint;

/// How the fragments' values reach the targets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Blending {
    /// The blend unit's "under" (a wgpu render pipeline).
    FixedFunction,
    /// The fragment shader reads its pixel's targets and writes the blend itself, in
    /// rasterization order (a raw Vulkan pass, [`super::programmable_blend`]).
    Programmable,
}

/// A hardware-rasterized renderer for one method and one set of options: pipeline built
/// once, buffers and targets kept across frames.
pub struct HardwareRenderer<'g, M: SplatMethod> {
    gpu: &'g Gpu,
    opts: RenderOptions,
    channels: usize,
    front: Front,
    /// The render pipeline and its binding slots, per camera model used.
    pipelines: PerModel<(wgpu::RenderPipeline, Vec<(String, u32)>)>,
    /// Per target: its format (the color targets, then depth's).
    formats: Vec<wgpu::TextureFormat>,
    color_targets: usize,
    /// The render targets, made for the last frame's size.
    targets: Vec<wgpu::Texture>,
    blending: Blending,
    /// With programmable blending: the pass of the last frame's camera model, which also
    /// holds its targets.
    programmable: Option<(CameraModel, RasterPass)>,
    /// The last programmable draw's time, measured on the host.
    draw_time: std::time::Duration,
    /// The last programmable draw's state images decoded to f32 (four values per pixel), once
    /// asked for: the frame's download and the backward pass both read them.
    state: std::sync::OnceLock<Vec<Vec<f32>>>,
    /// The backward replay of the last camera model, depth gradient and reduction used.
    backward_pass: Option<backward::BackwardPass>,
    /// The gradient sums and the adjoints after the backward replay.
    adjoint: Adjoint,
    /// Per pixel, for the backward replay: the forward's final state (color, T, depth sum) and
    /// the output gradients, f32 words.
    pixel_final: Grown,
    pixel_grad: Grown,
    pixel_grad_host: Vec<u32>,
    /// The last backward replay's time, measured on the host.
    backward_time: std::time::Duration,
    timer: StageTimer,
    frame: Option<FrameInfo>,
    /// The stamp of the scene's upload the last frame was rendered from.
    rendered_from: u64,
    method: PhantomData<M>,
}

impl<'g, M: SplatMethod> HardwareRenderer<'g, M> {
    /// A renderer producing the outputs `opts` asks for, stored at `opts.precision`
    /// (`tile_size` and `tile_cull` do not apply; `p_max` must be `None`).
    pub fn new(gpu: &'g Gpu, opts: &RenderOptions) -> Result<Self, GpuRenderError> {
        Self::with_blending(gpu, opts, Blending::FixedFunction)
    }

    /// [`HardwareRenderer::new`] with the targets blended as `blending` says.
    pub fn with_blending(
        gpu: &'g Gpu,
        opts: &RenderOptions,
        blending: Blending,
    ) -> Result<Self, GpuRenderError> {
        let refuse = |why: String| GpuError::Hardware(why);
        if opts.shade_precision != Precision::F32 {
            return Err(refuse(format!(
                "its fragments read `project`'s shade data at f32, not {} (use the tile path)",
                opts.shade_precision.name()
            ))
            .into());
        }
        if opts.p_max.is_some() {
            return Err(
                refuse("there are no tile lists to cap: P_max must be unset".into()).into(),
            );
        }
        if blending == Blending::FixedFunction && !supports(gpu, opts.precision) {
            return Err(refuse(format!(
                "this adapter cannot blend into {:?} targets (precision {})",
                target_format(opts.precision),
                opts.precision.name()
            ))
            .into());
        }
        let color_targets = entries::raster_color_targets::<M>();
        let mut formats = vec![target_format(opts.precision); color_targets];
        if opts.depth {
            // Depth sums are not bounded: f16 where the colors are unorm, as on the CPU.
            formats.push(target_format(match opts.precision {
                Precision::F32 => Precision::F32,
                _ => Precision::F16,
            }));
        }
        let limits = gpu.limits();
        // Programmable blending draws into one more image: each pixel's stop mark.
        let mark = (blending == Blending::Programmable).then_some(STOP_MARK);
        let attached = || formats.iter().chain(&mark);
        let bytes: u32 = attached()
            .map(|f| f.block_copy_size(None).unwrap_or(16))
            .sum();
        if attached().count() as u32 > limits.max_color_attachments
            || bytes > limits.max_color_attachment_bytes_per_sample
        {
            return Err(refuse(format!(
                "{} targets of {bytes} bytes per pixel exceed this adapter's {} targets of {} bytes: use a narrower precision or fewer channels",
                attached().count(),
                limits.max_color_attachments,
                limits.max_color_attachment_bytes_per_sample
            ))
            .into());
        }
        Ok(HardwareRenderer {
            gpu,
            opts: *opts,
            channels: entries::Layout::of::<M>().channels,
            front: Front::new::<M>(gpu, false)?,
            pipelines: PerModel::new(),
            formats,
            color_targets,
            targets: vec![],
            blending,
            programmable: None,
            draw_time: Default::default(),
            state: Default::default(),
            backward_pass: None,
            adjoint: Adjoint::new::<M>(gpu, opts)?,
            pixel_final: Grown::new(gpu, "final pixel state", 1)?,
            pixel_grad: Grown::new(gpu, "pixel gradients", 1)?,
            pixel_grad_host: Vec::new(),
            backward_time: Default::default(),
            timer: StageTimer::new(gpu, STAGES),
            frame: None,
            rendered_from: 0,
            method: PhantomData,
        })
    }

    /// Renders `scene` through `camera` into the targets (download with
    /// [`HardwareRenderer::download_frame`]). Waits once, for the visible count.
    pub fn forward(
        &mut self,
        scene: &GpuScene<M>,
        camera: &Camera,
    ) -> Result<FrameInfo, GpuRenderError> {
        self.frame = None;
        let gpu = self.gpu;
        let grid = splat_core::frame::check::<M>(camera, &self.opts)?;
        let side = gpu.limits().max_texture_dimension_2d;
        if grid.width > side || grid.height > side {
            let why = format!(
                "a {}x{} frame exceeds this adapter's {side}-pixel render targets: use the tile path",
                grid.width, grid.height
            );
            return Err(GpuError::Hardware(why).into());
        }
        // One tile over the whole image: one key per visible primitive, front to back (the
        // depth sort's order; no tile pass).
        let whole = TileGrid::new(grid.width, grid.height, grid.width.max(grid.height));
        let counted = (self.front).count(
            gpu,
            (Projection::Scene(scene), camera),
            (&whole, u32::MAX),
            &self.timer,
        )?;
        self.front.reserve(gpu, counted)?;
        let info = FrameInfo {
            grid,
            primitives: scene.len(),
            visible: counted.visible,
            intersections: counted.intersections as usize,
            redone: false,
        };
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        self.timer.start(&mut enc, SORT);
        self.front.emit_sorted(gpu, &mut enc)?;
        self.timer.end(&mut enc, SORT);
        // A programmable draw is timed on the host (`download_frame`): the raw pass holds no
        // queries, and its DRAW stage here is empty.
        self.timer.start(&mut enc, DRAW);
        if self.blending == Blending::FixedFunction {
            self.record_quads(&mut enc, camera.model, info)?;
        }
        self.timer.end(&mut enc, DRAW);
        self.timer.resolve(&mut enc, PROJECT..ADJOINT);
        gpu.queue.submit([enc.finish()]);
        if self.blending == Blending::Programmable {
            self.draw_programmable(camera.model, info)?;
        }
        self.frame = Some(info);
        self.rendered_from = scene.stamp;
        Ok(info)
    }

    /// Records the frame's quads under the camera `model`, blended by the blend unit into the
    /// targets (made for the frame's size).
    fn record_quads(
        &mut self,
        enc: &mut wgpu::CommandEncoder,
        model: CameraModel,
        info: FrameInfo,
    ) -> Result<(), GpuError> {
        let gpu = self.gpu;
        let size = (info.grid.width, info.grid.height);
        let made_for = |t: &wgpu::Texture| (t.width(), t.height());
        if self.targets.first().map(made_for) != Some(size) {
            self.targets = self.make_targets(size);
        }
        let inputs = quad_inputs::<M>(&self.front);
        let (opts, formats) = (self.opts, &self.formats);
        let (pipeline, slots) = self.pipelines.get(model, || {
            let source = entries::raster::<M>(model, opts.depth, Blending::FixedFunction)?;
            build_pipeline(gpu, &source, formats, opts.blend.alpha_min)
        })?;
        let layout = pipeline.get_bind_group_layout(0);
        let bind = gpu.bind_slots("splat_fragment", &layout, &slots, &inputs)?;
        let views: Vec<wgpu::TextureView> = self
            .targets
            .iter()
            .map(|t| t.create_view(&Default::default()))
            .collect();
        let attachments: Vec<Option<wgpu::RenderPassColorAttachment>> = views
            .iter()
            .map(|view| {
                Some(wgpu::RenderPassColorAttachment {
                    view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                        store: wgpu::StoreOp::Store,
                    },
                })
            })
            .collect();
        let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("splat quads"),
            color_attachments: &attachments,
            ..Default::default()
        });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.draw(0..4, 0..info.intersections as u32);
        Ok(())
    }

    /// The frame's quads drawn by the programmable pass of `model` (built on first use), after
    /// the sort submitted before it. Waits for the draw.
    fn draw_programmable(&mut self, model: CameraModel, info: FrameInfo) -> Result<(), GpuError> {
        let gpu = self.gpu;
        if self.programmable.as_ref().map(|(m, _)| *m) != Some(model) {
            let source = entries::raster::<M>(model, self.opts.depth, Blending::Programmable)?;
            // The targets, then each pixel's stop mark.
            let mut states = self.formats.clone();
            states.push(STOP_MARK);
            let desc = RasterPassDesc {
                source: &source,
                vertex: "quad_vertex",
                fragment: "splat_fragment",
                states: &states,
                constants: &self.programmable_constants(),
                strips: true,
                order: Order::Rasterization,
                helper_flag: false,
                readback: true,
            };
            self.programmable = Some((model, RasterPass::new(gpu, &desc)?));
        }
        let (_, pass) = self.programmable.as_mut().expect("built above");
        let inputs = quad_inputs::<M>(&self.front);
        let size = (info.grid.width, info.grid.height);
        self.state = Default::default();
        self.draw_time = pass.draw(gpu, size, 4, info.intersections as u32, &inputs)?;
        Ok(())
    }

    /// The programmable passes' `override` constants: the blend's thresholds.
    fn programmable_constants(&self) -> [(&'static str, f64); 2] {
        [
            ("ALPHA_MIN", f64::from(self.opts.blend.alpha_min)),
            ("T_STOP", f64::from(self.opts.blend.stop_at())),
        ]
    }

    /// Bytes the last frame's sorts used ([`super::sort_bytes`]).
    pub fn sort_bytes(&self) -> usize {
        self.frame
            .map_or(0, |f| super::sort_bytes(f.primitives, f.intersections, 1))
    }

    /// The last frame's outputs (as `RenderOptions` asked), read back from the targets.
    pub fn download_frame(&self) -> Result<Frame, GpuRenderError> {
        let info = self.frame.ok_or(GpuRenderError::NoFrame)?;
        let grid = info.grid;
        let pixels = (grid.width * grid.height) as usize;
        let read;
        let values = match &self.programmable {
            Some(_) => self.state_values()?,
            None => {
                read = read_targets(self.gpu, &self.targets, (grid.width, grid.height))?;
                &read[..]
            }
        };
        let mut color = Vec::with_capacity(pixels * self.channels);
        let (mut t, mut dacc) = (Vec::with_capacity(pixels), vec![0.0; pixels]);
        for p in 0..pixels {
            for c in 0..self.channels {
                let per = entries::RASTER_VALUES;
                color.push(values[c / per][4 * p + c % per]);
            }
            t.push(1.0 - values[0][4 * p + 3]);
        }
        if self.opts.depth {
            for (p, d) in dacc.iter_mut().enumerate() {
                *d = values[self.color_targets][4 * p];
            }
        }
        let (alpha, depth) = splat_core::frame::alpha_and_depth(&grid, &self.opts, &t, &dacc);
        let times = self.timer.read(self.gpu)?.unwrap_or_default();
        let time = |s: u32| times.get(s as usize).copied().unwrap_or_default();
        Ok(Frame {
            color: Image {
                width: grid.width,
                height: grid.height,
                channels: self.channels,
                data: color,
            },
            alpha,
            depth,
            stats: Stats {
                primitives: info.primitives,
                visible: info.visible,
                intersections: info.intersections,
                longest_list: info.intersections,
                pairs: 0,
                preprocess: time(PROJECT),
                rasterize: time(COUNT) + time(SORT),
                shade: match self.blending {
                    Blending::FixedFunction => time(DRAW),
                    Blending::Programmable => self.draw_time,
                },
            },
        })
    }

    fn make_targets(&self, (width, height): (u32, u32)) -> Vec<wgpu::Texture> {
        self.formats
            .iter()
            .map(|format| {
                self.gpu.device.create_texture(&wgpu::TextureDescriptor {
                    label: Some("splat render target"),
                    size: wgpu::Extent3d {
                        width,
                        height,
                        depth_or_array_layers: 1,
                    },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: *format,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
                    view_formats: &[],
                })
            })
            .collect()
    }
}

/// What the quads' shaders bind (`shaders/raster.wgsl`), by name: the front's projected
/// primitives, their depth order, the frame and (ray methods) the camera.
fn quad_inputs<M: SplatMethod>(front: &Front) -> Vec<(&'static str, &wgpu::Buffer)> {
    let mut inputs: Vec<(&str, &wgpu::Buffer)> = vec![
        ("projected", &front.projected),
        ("order", &front.prims),
        ("frame", &front.frame_uniform),
    ];
    if M::HAS_PIXEL_INFO {
        inputs.push(("camera_words", &front.camera));
    }
    inputs
}

/// The quad pipeline: triangle strips, front-to-back ("under") blending into every target;
/// with the binding slots of its module.
fn build_pipeline(
    gpu: &Gpu,
    source: &str,
    formats: &[wgpu::TextureFormat],
    alpha_min: f32,
) -> Result<(wgpu::RenderPipeline, Vec<(String, u32)>), GpuError> {
    // The fragment's `override ALPHA_MIN`: pairs below it are skipped.
    let constants = [("ALPHA_MIN", f64::from(alpha_min))];
    let scope = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
    let (module, slots) = gpu.shader_module("splat quads", source)?;
    let under = wgpu::BlendComponent {
        src_factor: wgpu::BlendFactor::OneMinusDstAlpha,
        dst_factor: wgpu::BlendFactor::One,
        operation: wgpu::BlendOperation::Add,
    };
    let targets: Vec<Option<wgpu::ColorTargetState>> = formats
        .iter()
        .map(|format| {
            Some(wgpu::ColorTargetState {
                format: *format,
                blend: Some(wgpu::BlendState {
                    color: under,
                    alpha: under,
                }),
                write_mask: wgpu::ColorWrites::ALL,
            })
        })
        .collect();
    let pipeline = gpu
        .device
        .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("splat quads"),
            layout: None,
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("quad_vertex"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::TriangleStrip,
                ..Default::default()
            },
            depth_stencil: None,
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("splat_fragment"),
                compilation_options: wgpu::PipelineCompilationOptions {
                    constants: &constants,
                    ..Default::default()
                },
                targets: &targets,
            }),
            multiview_mask: None,
            cache: None,
        });
    if let Some(e) = pollster::block_on(scope.pop()) {
        return Err(GpuError::Shader(format!("splat quads: {e}")));
    }
    Ok((pipeline, slots))
}

/// Every target's texels as f32, four per pixel, row after row.
fn read_targets(
    gpu: &Gpu,
    targets: &[wgpu::Texture],
    (width, height): (u32, u32),
) -> Result<Vec<Vec<f32>>, GpuError> {
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    let mut copies = vec![];
    for texture in targets {
        let texel = texture.format().block_copy_size(None).unwrap_or(16);
        let row = (texel * width).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let buffer = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("render target readback"),
            size: (row * height).max(4) as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        enc.copy_texture_to_buffer(
            texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row),
                    rows_per_image: Some(height),
                },
            },
            texture.size(),
        );
        copies.push((buffer, texture.format(), texel, row));
    }
    gpu.queue.submit([enc.finish()]);
    let mut out = vec![];
    for (buffer, format, texel, row) in copies {
        let words = gpu.read_mappable(&buffer, (row * height / 4) as usize)?;
        let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        let mut values = Vec::with_capacity(4 * (width * height) as usize);
        for y in 0..height {
            let line = &bytes[(y * row) as usize..][..(texel * width) as usize];
            values.extend(decode(format, line));
        }
        out.push(values);
    }
    Ok(out)
}

/// Texel bytes of `format` as f32 values.
fn decode(format: wgpu::TextureFormat, bytes: &[u8]) -> Vec<f32> {
    let u16s = || {
        bytes
            .chunks_exact(2)
            .map(|c| u16::from_le_bytes([c[0], c[1]]))
    };
    match format {
        wgpu::TextureFormat::Rgba32Float => bytes
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect(),
        wgpu::TextureFormat::Rgba16Float => u16s().map(|h| f16::from_bits(h).to_f32()).collect(),
        wgpu::TextureFormat::Rgba16Unorm => u16s().map(|v| v as f32 / 65535.0).collect(),
        _ => bytes.iter().map(|v| *v as f32 / 255.0).collect(),
    }
}
