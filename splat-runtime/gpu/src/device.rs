//! The device, and the small vocabulary every stage is written in: buffers checked against the
//! device's limits (and buffers that persist across frames, grown to a high-water mark),
//! compute pipelines compiled once per (source, entry point) with their bindings bound by name,
//! dispatches split over two dimensions, and synchronous readback.

use super::GpuError;
use std::collections::HashMap;
use std::hash::{DefaultHasher, Hash, Hasher};
use std::sync::Mutex;
use wgpu::util::DeviceExt;

/// Workgroups per dispatch dimension (WebGPU's limit); shaders rebuild the linear index as
/// `wid.y * MAX_GROUPS + wid.x`.
pub const MAX_GROUPS: u32 = 65535;

/// A wgpu device and its queue.
pub struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    /// Adapter name and backend, for reports.
    pub adapter: String,
    /// `atomicAdd` on `f32` in storage memory (`SHADER_FLOAT32_ATOMIC`).
    pub float_atomics: bool,
    /// Subgroup operations (`subgroupAdd`).
    pub subgroups: bool,
    /// A CPU implementation (lavapipe, WARP, SwiftShader): correct but slow.
    pub software: bool,
    /// Timestamp queries around compute passes (`TIMESTAMP_QUERY`): stage times on the GPU.
    pub timestamps: bool,
    /// Blending into `Rgba32Float` render targets (`FLOAT32_BLENDABLE`).
    pub float32_blending: bool,
    /// Blending into `Rgba16Unorm` render targets (`TEXTURE_FORMAT_16BIT_NORM` and the
    /// adapter's format features).
    pub unorm16_targets: bool,
    /// Whether naga adds its run-time checks to the shaders ([`Gpu::with_shader_checks`]);
    /// part of what the compiled pipelines are, so only set through that.
    shader_checks: bool,
    limits: wgpu::Limits,
    /// Kernels by (source, entry point, override constants).
    pipelines: Mutex<HashMap<u64, Kernel>>,
}

pub(crate) fn as_bytes(words: &[u32]) -> &[u8] {
    // SAFETY: u32 has no padding and every byte pattern is a valid u8.
    unsafe { std::slice::from_raw_parts(words.as_ptr() as *const u8, std::mem::size_of_val(words)) }
}

/// Workgroup counts for `groups` workgroups, spilling past 65,535 into the second dimension.
pub fn grid_of(groups: u32) -> (u32, u32) {
    let groups = groups.max(1);
    (groups.min(MAX_GROUPS), groups.div_ceil(MAX_GROUPS))
}

/// How every storage buffer is used: bound to shaders, copied in and out.
const STORAGE: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE
    .union(wgpu::BufferUsages::COPY_SRC)
    .union(wgpu::BufferUsages::COPY_DST);

/// The instance adapters are found through (Vulkan, Metal, DX12).
fn instance() -> wgpu::Instance {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
    desc.backends = wgpu::Backends::PRIMARY;
    wgpu::Instance::new(desc)
}

/// The adapter wgpu picks first, preferring a fast one (a software one such as lavapipe is
/// fine).
pub(crate) fn first_adapter() -> Result<wgpu::Adapter, GpuError> {
    pollster::block_on(instance().request_adapter(&wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        ..Default::default()
    }))
    .map_err(|e| GpuError::NoAdapter(e.to_string()))
}

impl Gpu {
    /// The first adapter wgpu finds (a software one such as lavapipe is fine), with float
    /// atomics enabled where the adapter has them.
    pub fn new() -> Result<Gpu, GpuError> {
        Gpu::on(first_adapter()?)
    }

    /// The `k`-th of this machine's adapters, counting around (hardware ones, or all where
    /// there are none): the `k`-th process on a machine takes its own GPU.
    pub fn nth(k: usize) -> Result<Gpu, GpuError> {
        let all = pollster::block_on(instance().enumerate_adapters(wgpu::Backends::PRIMARY));
        let hardware = |a: &wgpu::Adapter| a.get_info().device_type != wgpu::DeviceType::Cpu;
        let (hard, soft): (Vec<_>, Vec<_>) = all.into_iter().partition(hardware);
        let pool = if hard.is_empty() { soft } else { hard };
        let count = pool.len().max(1);
        let adapter = (pool.into_iter().nth(k % count))
            .ok_or_else(|| GpuError::NoAdapter("wgpu found none".into()))?;
        Gpu::on(adapter)
    }

    /// A device on `adapter`.
    fn on(adapter: wgpu::Adapter) -> Result<Gpu, GpuError> {
        Gpu::open_with(&adapter, |adapter, desc| {
            pollster::block_on(adapter.request_device(desc))
                .map_err(|e| GpuError::Device(e.to_string()))
        })
    }

    /// A device on `adapter` with the features the runtime uses where it has them, opened by
    /// `open` (wgpu's request, or one through its Vulkan layer with extensions of our own).
    pub(crate) fn open_with(
        adapter: &wgpu::Adapter,
        open: impl FnOnce(
            &wgpu::Adapter,
            &wgpu::DeviceDescriptor,
        ) -> Result<(wgpu::Device, wgpu::Queue), GpuError>,
    ) -> Result<Gpu, GpuError> {
        let info = adapter.get_info();
        let features = adapter.features()
            & (wgpu::Features::SHADER_FLOAT32_ATOMIC
                | wgpu::Features::SUBGROUP
                | wgpu::Features::TIMESTAMP_QUERY
                | wgpu::Features::FLOAT32_BLENDABLE
                | wgpu::Features::TEXTURE_FORMAT_16BIT_NORM
                | wgpu::Features::TEXTURE_ADAPTER_SPECIFIC_FORMAT_FEATURES);
        // Rendering into (and blending) Rgba16Unorm is an adapter-specific format feature.
        let unorm16 = adapter.get_texture_format_features(wgpu::TextureFormat::Rgba16Unorm);
        let unorm16_targets = features.contains(
            wgpu::Features::TEXTURE_FORMAT_16BIT_NORM
                | wgpu::Features::TEXTURE_ADAPTER_SPECIFIC_FORMAT_FEATURES,
        ) && unorm16
            .allowed_usages
            .contains(wgpu::TextureUsages::RENDER_ATTACHMENT)
            && unorm16
                .flags
                .contains(wgpu::TextureFormatFeatureFlags::BLENDABLE);
        let limits = adapter.limits();
        let (device, queue) = open(
            adapter,
            &wgpu::DeviceDescriptor {
                label: Some("splat"),
                required_features: features,
                required_limits: limits.clone(),
                ..Default::default()
            },
        )?;
        Ok(Gpu {
            device,
            queue,
            adapter: format!("{} ({:?})", info.name, info.backend),
            float_atomics: features.contains(wgpu::Features::SHADER_FLOAT32_ATOMIC),
            subgroups: features.contains(wgpu::Features::SUBGROUP),
            software: info.device_type == wgpu::DeviceType::Cpu,
            timestamps: features.contains(wgpu::Features::TIMESTAMP_QUERY),
            float32_blending: features.contains(wgpu::Features::FLOAT32_BLENDABLE),
            unorm16_targets,
            shader_checks: false,
            limits,
            pipelines: Mutex::new(HashMap::new()),
        })
    }

    /// The same device compiling its shaders with naga's run-time checks (`on`) or without
    /// (the default). Off, the shaders run as written: every loop of the runtime's shaders is
    /// bounded by a count but the compare-exchange loops, which end once their exchange
    /// succeeds; a method's code has no loops; array indices stay within their arrays;
    /// divisors are image or record sizes; and storage buffers keep the driver's robust
    /// access. On, each loop carries a 64-bit counter that keeps the driver from
    /// unrolling it (wgpu issue 7698 reports compute passes 100x slower), each array index a
    /// clamp and each integer division a guard: for finding a shader fault, and for
    /// measuring what the checks cost.
    pub fn with_shader_checks(mut self, on: bool) -> Gpu {
        self.shader_checks = on;
        self.pipelines.get_mut().unwrap().clear();
        self
    }

    /// Whether the shaders carry naga's run-time checks ([`Gpu::with_shader_checks`]).
    pub fn shader_checks(&self) -> bool {
        self.shader_checks
    }

    /// A shader module of WGSL `source` (its functions the entry points do not reach pruned),
    /// with or without run-time checks as [`Gpu::shader_checks`] says, and the binding slot of
    /// every resource it declares ([`binding_slots`]), so its buffers are bound by name.
    pub fn shader_module(
        &self,
        label: &str,
        source: &str,
    ) -> Result<(wgpu::ShaderModule, Vec<(String, u32)>), GpuError> {
        let source = super::prune::reachable_only(source);
        let slots = binding_slots(&source)?;
        let desc = wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        };
        let checks = match self.shader_checks {
            true => wgpu::ShaderRuntimeChecks::checked(),
            false => wgpu::ShaderRuntimeChecks::unchecked(),
        };
        // SAFETY: the runtime's shaders stay within their arrays, end every loop and divide
        // by nonzero sizes (`with_shader_checks` says why).
        let module = unsafe { self.device.create_shader_module_trusted(desc, checks) };
        Ok((module, slots))
    }

    /// The device's limits (those of the adapter).
    pub fn limits(&self) -> &wgpu::Limits {
        &self.limits
    }

    /// This device with storage bindings of at most `bytes` (its own if larger): for tests
    /// of what outgrows the limit.
    #[doc(hidden)]
    pub fn set_binding_limit(&mut self, bytes: u64) {
        let own = &mut self.limits.max_storage_buffer_binding_size;
        *own = (*own).min(bytes);
    }

    /// Bytes of workgroup memory a shader may use.
    pub fn workgroup_storage(&self) -> u32 {
        self.limits.max_compute_workgroup_storage_size
    }

    fn check_size(&self, what: &'static str, bytes: u64) -> Result<(), GpuError> {
        let limit = self
            .limits
            .max_storage_buffer_binding_size
            .min(self.limits.max_buffer_size);
        if bytes > limit {
            return Err(GpuError::TooLarge { what, bytes, limit });
        }
        Ok(())
    }

    /// `create` (which allocates `bytes` for `what`), with the device running out of memory
    /// turned into an error naming the buffer.
    fn allocate(
        &self,
        what: &'static str,
        bytes: u64,
        create: impl FnOnce() -> wgpu::Buffer,
    ) -> Result<wgpu::Buffer, GpuError> {
        self.check_size(what, bytes)?;
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let buffer = create();
        match pollster::block_on(scope.pop()) {
            Some(_) => Err(GpuError::OutOfMemory { what, bytes }),
            None => Ok(buffer),
        }
    }

    /// A storage buffer of `words` 32-bit words (at least one), contents undefined until written.
    pub fn buffer(&self, what: &'static str, words: usize) -> Result<wgpu::Buffer, GpuError> {
        let bytes = 4 * words.max(1) as u64;
        self.allocate(what, bytes, || {
            self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(what),
                size: bytes,
                usage: STORAGE,
                mapped_at_creation: false,
            })
        })
    }

    /// A storage buffer holding `words` (one zero word if empty: bindings cannot be empty).
    pub fn buffer_from(&self, what: &'static str, words: &[u32]) -> Result<wgpu::Buffer, GpuError> {
        let contents: &[u32] = if words.is_empty() { &[0] } else { words };
        self.allocate(what, 4 * contents.len() as u64, || {
            self.device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some(what),
                    contents: as_bytes(contents),
                    usage: STORAGE,
                })
        })
    }

    /// A uniform block of `words` 32-bit words (a multiple of four), written per frame with
    /// [`Gpu::write`].
    pub fn uniform_buffer(&self, words: usize) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("uniform"),
            size: 4 * words.div_ceil(4).max(1) as u64 * 4,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// Writes `words` at the start of `buffer`; the write lands before the next submission.
    pub fn write(&self, buffer: &wgpu::Buffer, words: &[u32]) {
        if !words.is_empty() {
            self.queue.write_buffer(buffer, 0, as_bytes(words));
        }
    }

    /// A uniform block of `words`, padded to 16 bytes.
    pub fn uniform(&self, words: &[u32]) -> wgpu::Buffer {
        let mut padded = words.to_vec();
        padded.resize(words.len().div_ceil(4).max(1) * 4, 0);
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("uniform"),
                contents: as_bytes(&padded),
                usage: wgpu::BufferUsages::UNIFORM,
            })
    }

    /// The pipeline of `entry` in `source` (compiled on first use), with the binding slot of
    /// every variable the source declares, so its buffers are bound by name.
    pub fn kernel(&self, source: &str, entry: &str) -> Result<Kernel, GpuError> {
        self.kernel_with(source, entry, &[])
    }

    /// [`Gpu::kernel`] with its `override` constants set to `constants` (name, value):
    /// compiled on first use for each set of values.
    pub fn kernel_with(
        &self,
        source: &str,
        entry: &str,
        constants: &[(&str, f64)],
    ) -> Result<Kernel, GpuError> {
        let mut h = DefaultHasher::new();
        (source, entry).hash(&mut h);
        for (name, value) in constants {
            (name, value.to_bits()).hash(&mut h);
        }
        let key = h.finish();
        if let Some(k) = self.pipelines.lock().unwrap().get(&key) {
            return Ok(k.clone());
        }
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let (module, slots) = self.shader_module(entry, source)?;
        let pipeline = self
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: None,
                module: &module,
                entry_point: Some(entry),
                compilation_options: wgpu::PipelineCompilationOptions {
                    constants,
                    ..Default::default()
                },
                cache: None,
            });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Shader(format!("{entry}: {e}")));
        }
        let kernel = Kernel {
            pipeline,
            slots,
            entry: entry.to_string(),
        };
        self.pipelines.lock().unwrap().insert(key, kernel.clone());
        Ok(kernel)
    }

    /// A bind group for `kernel` with each buffer at the slot its name is declared with (name
    /// exactly the bindings the entry point uses: its derived layout holds no others).
    pub fn bind_named(
        &self,
        kernel: &Kernel,
        buffers: &[(&str, &wgpu::Buffer)],
    ) -> Result<wgpu::BindGroup, GpuError> {
        let layout = kernel.pipeline.get_bind_group_layout(0);
        self.bind_slots(&kernel.entry, &layout, &kernel.slots, buffers)
    }

    /// A bind group of `layout` with each buffer at its slot in `slots` ([`binding_slots`]).
    pub fn bind_slots(
        &self,
        entry: &str,
        layout: &wgpu::BindGroupLayout,
        slots: &[(String, u32)],
        buffers: &[(&str, &wgpu::Buffer)],
    ) -> Result<wgpu::BindGroup, GpuError> {
        let mut entries = Vec::with_capacity(buffers.len());
        for (name, buffer) in buffers {
            let slot = slots
                .iter()
                .find(|(n, _)| n == name)
                .map(|(_, slot)| *slot)
                .ok_or_else(|| {
                    GpuError::Shader(format!("`{entry}` declares no binding `{name}`"))
                })?;
            entries.push(wgpu::BindGroupEntry {
                binding: slot,
                resource: buffer.as_entire_binding(),
            });
        }
        Ok(self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(entry),
            layout,
            entries: &entries,
        }))
    }

    /// Submits `encoder` and waits until the GPU is done.
    pub fn finish(&self, encoder: wgpu::CommandEncoder) -> Result<(), GpuError> {
        self.queue.submit([encoder.finish()]);
        self.wait()
    }

    /// Waits until the GPU has finished everything submitted so far.
    pub fn wait(&self) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        Ok(())
    }

    /// Reads the first `words` words of `buffer` back.
    pub fn read(&self, buffer: &wgpu::Buffer, words: usize) -> Result<Vec<u32>, GpuError> {
        let [out] = self.read_together([(buffer, words)])?;
        Ok(out)
    }

    /// Reads the first words of each buffer back, with one submission and one wait for all
    /// (each read alone is a round trip to the GPU).
    pub fn read_together<const N: usize>(
        &self,
        parts: [(&wgpu::Buffer, usize); N],
    ) -> Result<[Vec<u32>; N], GpuError> {
        let total: usize = parts.iter().map(|p| p.1.max(1)).sum();
        let readback = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: 4 * total.max(1) as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = self.device.create_command_encoder(&Default::default());
        let mut at = 0;
        for (buffer, words) in parts {
            let size = 4 * words.max(1) as u64;
            encoder.copy_buffer_to_buffer(buffer, 0, &readback, at, size);
            at += size;
        }
        self.queue.submit([encoder.finish()]);
        let all = self.read_mappable(&readback, total)?;
        let mut rest = &all[..];
        Ok(parts.map(|(_, words)| {
            let (part, tail) = rest.split_at(words.max(1));
            rest = tail;
            part[..words].to_vec()
        }))
    }

    /// Reads the first `words` words of a `MAP_READ` buffer, once the GPU is done with it.
    pub fn read_mappable(&self, buffer: &wgpu::Buffer, words: usize) -> Result<Vec<u32>, GpuError> {
        let slice = buffer.slice(..4 * words.max(1) as u64);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        rx.recv()
            .map_err(|e| GpuError::Readback(e.to_string()))?
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        let out = {
            let bytes = slice
                .get_mapped_range()
                .map_err(|e| GpuError::Readback(e.to_string()))?;
            bytes
                .chunks_exact(4)
                .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
                .take(words)
                .collect()
        };
        buffer.unmap();
        Ok(out)
    }
}

/// A compute pipeline whose buffers are bound by the names its source declares them with.
#[derive(Clone)]
pub struct Kernel {
    pub pipeline: wgpu::ComputePipeline,
    /// (variable name, binding slot) of every `@group(0) @binding(N) var<...> name` line.
    slots: Vec<(String, u32)>,
    entry: String,
}

/// The binding slot of every resource `source` declares (`@group(0) @binding(N) var ... name`),
/// by name, as naga parses it. `source` is the module as compiled: pruned
/// ([`reachable_only`](super::prune::reachable_only)), since the functions no entry point
/// reaches may call functions the source leaves out.
pub fn binding_slots(source: &str) -> Result<Vec<(String, u32)>, GpuError> {
    let module = naga::front::wgsl::parse_str(source)
        .map_err(|e| GpuError::Shader(e.emit_to_string(source)))?;
    Ok(module
        .global_variables
        .iter()
        .filter_map(|(_, v)| Some((v.name.clone()?, v.binding.as_ref()?.binding)))
        .collect())
}

/// A storage buffer that persists across frames: re-created only when a frame needs more
/// words than it holds (then with a quarter to spare), so steady frames allocate nothing.
pub struct Grown {
    what: &'static str,
    buffer: wgpu::Buffer,
    words: usize,
}

impl Grown {
    pub fn new(gpu: &Gpu, what: &'static str, words: usize) -> Result<Grown, GpuError> {
        Ok(Grown {
            what,
            buffer: gpu.buffer(what, words)?,
            words: words.max(1),
        })
    }

    /// The words it holds.
    pub fn words(&self) -> usize {
        self.words
    }

    /// Makes room for `words` (contents are lost when it grows).
    pub fn ensure(&mut self, gpu: &Gpu, words: usize) -> Result<(), GpuError> {
        if words <= self.words {
            return Ok(());
        }
        let limit = (gpu
            .limits
            .max_storage_buffer_binding_size
            .min(gpu.limits.max_buffer_size)
            / 4) as usize;
        let spare = (words + words / 4).min(limit).max(words);
        self.buffer = gpu.buffer(self.what, spare)?;
        self.words = spare;
        Ok(())
    }
}

impl std::ops::Deref for Grown {
    type Target = wgpu::Buffer;
    fn deref(&self) -> &wgpu::Buffer {
        &self.buffer
    }
}

/// Records one dispatch of `groups` workgroups (split over two dimensions) into `encoder`.
pub fn dispatch(
    encoder: &mut wgpu::CommandEncoder,
    pipeline: &wgpu::ComputePipeline,
    bind: &wgpu::BindGroup,
    groups: u32,
) {
    let (x, y) = grid_of(groups);
    let mut pass = encoder.begin_compute_pass(&Default::default());
    pass.set_pipeline(pipeline);
    pass.set_bind_group(0, bind, &[]);
    pass.dispatch_workgroups(x, y, 1);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buffers_read_together_come_back_whole_and_in_order() {
        let Some(gpu) = super::super::adapter_or_skip() else {
            return;
        };
        let a: Vec<u32> = (0..70).collect();
        let b: Vec<u32> = (100..103).collect();
        let (ba, bb) = (
            gpu.buffer_from("a", &a).unwrap(),
            gpu.buffer_from("b", &b).unwrap(),
        );
        let [got_b, none, got_a] = gpu.read_together([(&bb, 3), (&ba, 0), (&ba, 70)]).unwrap();
        assert_eq!((got_a, got_b, none), (a, b, vec![]));
    }

    #[test]
    fn buffers_past_the_device_limits_are_refused_by_name() {
        let Some(gpu) = super::super::adapter_or_skip() else {
            return;
        };
        let limit = gpu
            .limits
            .max_storage_buffer_binding_size
            .min(gpu.limits.max_buffer_size);
        let err = gpu
            .buffer("intersection keys", (limit / 4 + 1) as usize)
            .unwrap_err();
        assert!(
            matches!(
                err,
                GpuError::TooLarge {
                    what: "intersection keys",
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("lower the resolution"), "{err}");
        assert_eq!(grid_of(65_535), (65_535, 1));
        assert_eq!(grid_of(65_536), (65_535, 2));
        assert_eq!(grid_of(0), (1, 1));
    }

    #[test]
    fn binding_slots_are_read_from_the_declarations() {
        let source = "@group(0) @binding(0) var<storage, read> keys: array<vec2<u32>>;
@group(0) @binding(2) var<uniform> info: vec4<u32>; // n
// @binding is mentioned here without a declaration
@group(0) @binding(8) var<storage, read_write> issued: array<atomic<u32>, 2>;";
        assert_eq!(
            binding_slots(source).unwrap(),
            [
                ("keys".to_string(), 0),
                ("info".into(), 2),
                ("issued".into(), 8)
            ]
        );
    }
}
