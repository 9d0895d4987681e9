//! Runs one function of a generated WGSL module over a batch of inputs on the GPU.
//!
//! The harness takes the function's signature from the compiler's table (a module's
//! `GENERATED_FUNCTIONS`; the WGSL is never parsed here), wraps it in a compute entry point that loads each argument from a storage buffer of 32-bit words
//! (floats and integers by bit pattern, `bool` as 0/1), calls it, and stores every member of
//! its result struct back as words. One invocation per batch element.

use super::{Gpu, GpuError};
use splat_core::method::{WgslFunction, WgslScalar};
use std::fmt::Write;

/// A 32-bit word per argument or result member.
pub type Word = u32;

/// The generated function of kernel `name` in `functions` (a module's
/// `GENERATED_FUNCTIONS`).
pub fn function<'f>(
    functions: &'f [WgslFunction],
    name: &str,
) -> Result<&'f WgslFunction, GpuError> {
    functions
        .iter()
        .find(|f| f.kernel == name)
        .ok_or_else(|| GpuError::Shader(format!("no generated function `{name}`")))
}

/// WGSL reading an argument of `kind` from the 32-bit word expression `word`.
pub(crate) fn load(kind: WgslScalar, word: &str) -> String {
    match kind {
        WgslScalar::F32 => format!("bitcast<f32>({word})"),
        WgslScalar::I32 => format!("bitcast<i32>({word})"),
        WgslScalar::Bool => format!("({word} != 0u)"),
        WgslScalar::U32 => word.to_string(),
    }
}

fn store(kind: WgslScalar, value: &str) -> String {
    match kind {
        WgslScalar::F32 | WgslScalar::I32 => format!("bitcast<u32>({value})"),
        WgslScalar::Bool => format!("select(0u, 1u, {value})"),
        _ => value.to_string(),
    }
}

/// The module's WGSL with a compute entry point `splat_harness` calling `sig`: the first
/// `per_row` arguments come from the row, the rest from the shared words (e.g. the camera).
pub fn harness_source(wgsl: &str, sig: &WgslFunction, per_row: usize) -> String {
    let nr = sig.results.len();
    let shared = sig.args.len() > per_row;
    let mut s = String::from(wgsl);
    // Only bindings the entry point uses appear in the derived layout, so the shared words are
    // bound only when there are some.
    s.push_str("\n@group(0) @binding(0) var<storage, read> harness_rows: array<u32>;\n");
    let mut next = 1;
    if shared {
        s.push_str("@group(0) @binding(1) var<storage, read> harness_shared: array<u32>;\n");
        next = 2;
    }
    let _ = writeln!(
        s,
        "@group(0) @binding({next}) var<storage, read_write> harness_out: array<u32>;"
    );
    let _ = writeln!(
        s,
        "@group(0) @binding({}) var<uniform> harness_count: vec4<u32>;\n",
        next + 1
    );
    s.push_str("@compute @workgroup_size(64)\nfn splat_harness(@builtin(global_invocation_id) gid: vec3<u32>) {\n");
    s.push_str("    let i = gid.y * 65535u * 64u + gid.x; // past 65,535 groups, dispatches are 2D\n    if (i >= harness_count.x) {\n        return;\n    }\n");
    let _ = writeln!(s, "    let base = i * {}u;", per_row.max(1));
    let args: Vec<String> = sig
        .args
        .iter()
        .enumerate()
        .map(|(k, kind)| {
            let word = if k < per_row {
                format!("harness_rows[base + {k}u]")
            } else {
                format!("harness_shared[{}u]", k - per_row)
            };
            load(*kind, &word)
        })
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

/// Runs `function` of `wgsl` on every input row (one word per argument); returns the result
/// rows (one word per result member).
pub fn run(
    gpu: &Gpu,
    wgsl: &str,
    function: &WgslFunction,
    inputs: &[Vec<Word>],
) -> Result<Vec<Vec<Word>>, GpuError> {
    run_shared(gpu, wgsl, function, inputs, &[])
}

/// Like [`run`], with the last `shared.len()` arguments the same for every row.
pub fn run_shared(
    gpu: &Gpu,
    wgsl: &str,
    sig: &WgslFunction,
    rows: &[Vec<Word>],
    shared: &[Word],
) -> Result<Vec<Vec<Word>>, GpuError> {
    let function = sig.kernel;
    let per_row = sig.args.len().checked_sub(shared.len()).ok_or_else(|| {
        GpuError::Shader(format!(
            "`{function}` takes {} arguments, {} shared given",
            sig.args.len(),
            shared.len()
        ))
    })?;
    if let Some(bad) = rows.iter().find(|r| r.len() != per_row) {
        return Err(GpuError::Shader(format!(
            "`{function}` takes {per_row} words per row, got {}",
            bad.len()
        )));
    }
    let n = rows.len();
    let nr = sig.results.len();
    let flat: Vec<Word> = rows.iter().flatten().copied().collect();
    let source = harness_source(wgsl, sig, per_row);
    let mut inputs: Vec<(&str, &[Word])> = vec![("harness_rows", &flat)];
    if !shared.is_empty() {
        inputs.push(("harness_shared", shared));
    }
    let out = super::dispatch::run(
        gpu,
        &source,
        "splat_harness",
        &inputs,
        ("harness_out", n * nr),
        ("harness_count", &[n as u32]),
        (n as u32).div_ceil(64),
    )?;
    Ok((0..n).map(|i| out[i * nr..(i + 1) * nr].to_vec()).collect())
}
