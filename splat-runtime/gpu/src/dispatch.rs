//! One compute dispatch: storage inputs of 32-bit words, an output and a small uniform block,
//! each bound by the name the source declares it with. Returns the output words.

use super::device::dispatch;
use super::{Gpu, GpuError};

/// Compiles `source`, binds `inputs` (name, words), an output `(name, words)` and a uniform
/// `(name, words)`, dispatches `groups` workgroups of entry point `entry`, and reads the
/// output back.
pub fn run(
    gpu: &Gpu,
    source: &str,
    entry: &str,
    inputs: &[(&str, &[u32])],
    (output_name, out_words): (&str, usize),
    (uniform_name, uniform): (&str, &[u32]),
    groups: u32,
) -> Result<Vec<u32>, GpuError> {
    let kernel = gpu.kernel(source, entry)?;
    let buffers = inputs
        .iter()
        .map(|(_, w)| gpu.buffer_from("kernel input", w))
        .collect::<Result<Vec<_>, _>>()?;
    let output = gpu.buffer("kernel output", out_words)?;
    let uniform = gpu.uniform(uniform);
    let mut named: Vec<(&str, &wgpu::Buffer)> =
        inputs.iter().map(|(name, _)| *name).zip(&buffers).collect();
    named.extend([(output_name, &output), (uniform_name, &uniform)]);
    let bind = gpu.bind_named(&kernel, &named)?;
    let mut encoder = gpu.device.create_command_encoder(&Default::default());
    dispatch(&mut encoder, &kernel.pipeline, &bind, groups);
    gpu.finish(encoder)?;
    gpu.read(&output, out_words)
}
