//! The wgpu side of the runtime: the device context, one-dispatch plumbing ([`dispatch`]), a
//! harness that runs any generated WGSL function over a batch ([`kernel`]), and a forward
//! render ([`render`]: `project` and blending on the GPU, tile lists still on the CPU).

pub mod dispatch;
pub mod kernel;
pub mod render;

/// A wgpu device and its queue.
pub struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    /// Adapter name and backend, for reports.
    pub adapter: String,
}

#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter found ({0}); on Linux without a GPU, install Mesa's lavapipe (Debian: mesa-vulkan-drivers)"
    )]
    NoAdapter(String),
    #[error("the GPU device could not be created: {0}")]
    Device(String),
    #[error("shader: {0}")]
    Shader(String),
    #[error("reading results back failed: {0}")]
    Readback(String),
}

impl Gpu {
    /// The first adapter wgpu finds (a software one such as lavapipe is fine).
    pub fn new() -> Result<Gpu, GpuError> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = wgpu::Backends::PRIMARY;
        let instance = wgpu::Instance::new(desc);
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let info = adapter.get_info();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("splat"),
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device(e.to_string()))?;
        Ok(Gpu {
            device,
            queue,
            adapter: format!("{} ({:?})", info.name, info.backend),
        })
    }
}
