//! One compute dispatch with the binding layout every splat entry point uses: storage inputs
//! at bindings 0..n (read-only, 32-bit words), the output at n (read-write), and a small
//! uniform block at n + 1. Returns the output words.

use super::{Gpu, GpuError};
use wgpu::util::DeviceExt;

fn as_bytes(words: &[u32]) -> &[u8] {
    // SAFETY: u32 has no padding and every byte pattern is a valid u8.
    unsafe { std::slice::from_raw_parts(words.as_ptr() as *const u8, std::mem::size_of_val(words)) }
}

/// Compiles `source`, binds `inputs`, an output of `out_words` words and `uniform`, dispatches
/// `workgroups` of entry point `entry`, and reads the output back.
pub fn run(
    gpu: &Gpu,
    source: &str,
    entry: &str,
    inputs: &[&[u32]],
    uniform: &[u32],
    out_words: usize,
    workgroups: (u32, u32),
) -> Result<Vec<u32>, GpuError> {
    let device = &gpu.device;
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(entry),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(entry),
        layout: None,
        module: &module,
        entry_point: Some(entry),
        compilation_options: Default::default(),
        cache: None,
    });
    if let Some(e) = pollster::block_on(scope.pop()) {
        return Err(GpuError::Shader(e.to_string()));
    }
    // Bindings cannot be empty: every buffer holds at least one word.
    let storage = |words: &[u32]| {
        let padded: Vec<u32> = if words.is_empty() {
            vec![0]
        } else {
            words.to_vec()
        };
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: None,
            contents: as_bytes(&padded),
            usage: wgpu::BufferUsages::STORAGE,
        })
    };
    let buffers: Vec<wgpu::Buffer> = inputs.iter().map(|w| storage(w)).collect();
    let size = (4 * out_words.max(1)) as u64;
    let output = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("output"),
        size,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let readback = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut uniform_words = uniform.to_vec();
    uniform_words.resize(uniform.len().div_ceil(4).max(1) * 4, 0);
    let uniform_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("uniform"),
        contents: as_bytes(&uniform_words),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let n = buffers.len() as u32;
    let mut entries: Vec<wgpu::BindGroupEntry> = buffers
        .iter()
        .enumerate()
        .map(|(i, b)| wgpu::BindGroupEntry {
            binding: i as u32,
            resource: b.as_entire_binding(),
        })
        .collect();
    entries.push(wgpu::BindGroupEntry {
        binding: n,
        resource: output.as_entire_binding(),
    });
    entries.push(wgpu::BindGroupEntry {
        binding: n + 1,
        resource: uniform_buf.as_entire_binding(),
    });
    let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(entry),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &entries,
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.dispatch_workgroups(workgroups.0, workgroups.1, 1);
    }
    encoder.copy_buffer_to_buffer(&output, 0, &readback, 0, size);
    gpu.queue.submit([encoder.finish()]);
    let slice = readback.slice(..);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| GpuError::Readback(e.to_string()))?;
    rx.recv()
        .map_err(|e| GpuError::Readback(e.to_string()))?
        .map_err(|e| GpuError::Readback(e.to_string()))?;
    let words = {
        let bytes = slice
            .get_mapped_range()
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        bytes
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
            .take(out_words)
            .collect()
    };
    readback.unmap();
    Ok(words)
}

/// Dispatches an 8 x 8 workgroup grid over `size` pixels.
pub fn run_pixels(
    gpu: &Gpu,
    source: &str,
    inputs: &[&[u32]],
    uniform: &[u32],
    out_words: usize,
    size: (u32, u32),
) -> Result<Vec<u32>, GpuError> {
    run(
        gpu,
        source,
        "splat_shade",
        inputs,
        uniform,
        out_words,
        (size.0.div_ceil(8), size.1.div_ceil(8)),
    )
}
