//! One compute dispatch with the binding layout of the kernel harness: storage inputs at
//! bindings 0..n (32-bit words), the output at n, and a small uniform block at n + 1.
//! Returns the output words.

use super::device::dispatch;
use super::{Gpu, GpuError};

/// Compiles `source`, binds `inputs`, an output of `out_words` words and `uniform`, dispatches
/// `groups` workgroups of entry point `entry`, and reads the output back.
pub fn run(
    gpu: &Gpu,
    source: &str,
    entry: &str,
    inputs: &[&[u32]],
    uniform: &[u32],
    out_words: usize,
    groups: u32,
) -> Result<Vec<u32>, GpuError> {
    let pipeline = gpu.pipeline(source, entry)?;
    let buffers = inputs
        .iter()
        .map(|w| gpu.buffer_from("kernel input", w))
        .collect::<Result<Vec<_>, _>>()?;
    let output = gpu.buffer("kernel output", out_words)?;
    let uniform = gpu.uniform(uniform);
    let mut all: Vec<&wgpu::Buffer> = buffers.iter().collect();
    all.extend([&output, &uniform]);
    let bind = gpu.bind(&pipeline, &all);
    let mut encoder = gpu.device.create_command_encoder(&Default::default());
    dispatch(&mut encoder, &pipeline, &bind, groups);
    gpu.finish(encoder)?;
    gpu.read(&output, out_words)
}
