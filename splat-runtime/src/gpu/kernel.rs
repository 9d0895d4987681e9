//! Runs one function of a generated WGSL module over a batch of inputs on the GPU.
//!
//! The harness reads the function's signature from the module (naga's WGSL front end), wraps
//! it in a compute entry point that loads each argument from a storage buffer of 32-bit words
//! (floats and integers by bit pattern, `bool` as 0/1), calls it, and stores every member of
//! its result struct back as words. One invocation per batch element.

use super::{Gpu, GpuError};
use std::fmt::Write;

/// A 32-bit word per argument or result member.
pub type Word = u32;

/// The scalar kind of each argument and result member of a WGSL function.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Signature {
    pub name: String,
    pub args: Vec<naga::ScalarKind>,
    pub results: Vec<(String, naga::ScalarKind)>,
}

fn kind_of(
    module: &naga::Module,
    ty: naga::Handle<naga::Type>,
) -> Result<naga::ScalarKind, GpuError> {
    match module.types[ty].inner {
        naga::TypeInner::Scalar(s) => Ok(s.kind),
        ref other => Err(GpuError::Shader(format!(
            "unsupported argument type {other:?}"
        ))),
    }
}

/// The signature of function `name` (or `name_`, as naga renames built-in names) in `wgsl`.
pub fn signature(wgsl: &str, name: &str) -> Result<Signature, GpuError> {
    let module =
        naga::front::wgsl::parse_str(wgsl).map_err(|e| GpuError::Shader(e.emit_to_string(wgsl)))?;
    let renamed = format!("{name}_");
    let (_, f) = module
        .functions
        .iter()
        .find(|(_, f)| {
            f.name.as_deref() == Some(name) || f.name.as_deref() == Some(renamed.as_str())
        })
        .ok_or_else(|| GpuError::Shader(format!("no function `{name}` in the module")))?;
    let args = f
        .arguments
        .iter()
        .map(|a| kind_of(&module, a.ty))
        .collect::<Result<_, _>>()?;
    let result = f
        .result
        .as_ref()
        .ok_or_else(|| GpuError::Shader(format!("`{name}` returns nothing")))?;
    let naga::TypeInner::Struct { members, .. } = &module.types[result.ty].inner else {
        return Err(GpuError::Shader(format!(
            "`{name}` does not return a struct"
        )));
    };
    let results = members
        .iter()
        .map(|m| Ok((m.name.clone().unwrap_or_default(), kind_of(&module, m.ty)?)))
        .collect::<Result<_, GpuError>>()?;
    Ok(Signature {
        name: f.name.clone().unwrap_or_default(),
        args,
        results,
    })
}

fn load(kind: naga::ScalarKind, word: &str) -> String {
    match kind {
        naga::ScalarKind::Float => format!("bitcast<f32>({word})"),
        naga::ScalarKind::Sint => format!("bitcast<i32>({word})"),
        naga::ScalarKind::Bool => format!("({word} != 0u)"),
        _ => word.to_string(),
    }
}

fn store(kind: naga::ScalarKind, value: &str) -> String {
    match kind {
        naga::ScalarKind::Float | naga::ScalarKind::Sint => format!("bitcast<u32>({value})"),
        naga::ScalarKind::Bool => format!("select(0u, 1u, {value})"),
        _ => value.to_string(),
    }
}

/// The module's WGSL with a compute entry point `splat_harness` calling `sig`.
pub fn harness_source(wgsl: &str, sig: &Signature) -> String {
    let (na, nr) = (sig.args.len(), sig.results.len());
    let mut s = String::from(wgsl);
    s.push_str("\n@group(0) @binding(0) var<storage, read> harness_in: array<u32>;\n");
    s.push_str("@group(0) @binding(1) var<storage, read_write> harness_out: array<u32>;\n");
    s.push_str("@group(0) @binding(2) var<uniform> harness_count: vec4<u32>;\n\n");
    s.push_str("@compute @workgroup_size(64)\nfn splat_harness(@builtin(global_invocation_id) gid: vec3<u32>) {\n");
    s.push_str("    let i = gid.x;\n    if (i >= harness_count.x) {\n        return;\n    }\n");
    let _ = writeln!(s, "    let base = i * {}u;", na.max(1));
    let args: Vec<String> = sig
        .args
        .iter()
        .enumerate()
        .map(|(k, kind)| load(*kind, &format!("harness_in[base + {k}u]")))
        .collect();
    let _ = writeln!(s, "    let r = {}({});", sig.name, args.join(", "));
    let _ = writeln!(s, "    let out = i * {}u;", nr.max(1));
    for (k, (member, kind)) in sig.results.iter().enumerate() {
        let _ = writeln!(
            s,
            "    harness_out[out + {k}u] = {};",
            store(*kind, &format!("r.{member}"))
        );
    }
    s.push_str("}\n");
    s
}

/// Runs `function` of `wgsl` on every input row (`args.len()` words per row); returns the
/// result rows (`results.len()` words each).
pub fn run(
    gpu: &Gpu,
    wgsl: &str,
    function: &str,
    inputs: &[Vec<Word>],
) -> Result<Vec<Vec<Word>>, GpuError> {
    use wgpu::util::DeviceExt;
    let sig = signature(wgsl, function)?;
    let (na, nr) = (sig.args.len(), sig.results.len());
    let n = inputs.len();
    if let Some(bad) = inputs.iter().find(|r| r.len() != na) {
        return Err(GpuError::Shader(format!(
            "`{function}` takes {na} words per row, got {}",
            bad.len()
        )));
    }
    let source = harness_source(wgsl, &sig);
    let device = &gpu.device;
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("splat harness"),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("splat harness"),
        layout: None,
        module: &module,
        entry_point: Some("splat_harness"),
        compilation_options: Default::default(),
        cache: None,
    });
    if let Some(e) = pollster::block_on(scope.pop()) {
        return Err(GpuError::Shader(e.to_string()));
    }
    let mut flat: Vec<Word> = inputs.iter().flatten().copied().collect();
    flat.resize(flat.len().max(1), 0);
    let input = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("harness in"),
        contents: as_bytes(&flat),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let out_size = (4 * n * nr.max(1)).max(4) as u64;
    let output = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("harness out"),
        size: out_size,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let readback = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("harness readback"),
        size: out_size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let count = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("harness count"),
        contents: as_bytes(&[n as u32, 0, 0, 0]),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("harness"),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: input.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: output.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: count.as_entire_binding(),
            },
        ],
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.dispatch_workgroups((n as u32).div_ceil(64), 1, 1);
    }
    encoder.copy_buffer_to_buffer(&output, 0, &readback, 0, out_size);
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
    let words: Vec<Word> = {
        let bytes = slice
            .get_mapped_range()
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        bytes
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
            .collect()
    };
    readback.unmap();
    Ok((0..n)
        .map(|i| words[i * nr..(i + 1) * nr].to_vec())
        .collect())
}

fn as_bytes(words: &[u32]) -> &[u8] {
    // SAFETY: u32 has no padding and any byte pattern is a valid u8.
    unsafe { std::slice::from_raw_parts(words.as_ptr() as *const u8, std::mem::size_of_val(words)) }
}
