//! A forward render on the GPU, as a first step towards the full wgpu pipeline: `project`
//! runs on the GPU (one invocation per primitive), tile lists are built on the CPU by the same
//! rasterizer as the CPU backend, and blending runs on the GPU (one invocation per pixel, the
//! method's generated `evaluate` called per list entry, the same stopping rule). The method's
//! WGSL is the one the macro generated; only the entry points are written here.
//!
//! Not yet on the GPU: the prefix sum / emit / radix sort of the rasterizer, workgroup-shared
//! batches, the backward pass.

use super::kernel::{self, Signature, load};
use super::{Gpu, GpuError};
use crate::flat::Flat;
use crate::method::SplatMethod;
use crate::pipeline::preprocess;
use crate::pipeline::{Frame, Image, RenderError, RenderOptions, Stats};
use crate::types::{Camera, Projected};
use std::fmt::Write;
use std::time::Instant;

#[derive(Debug, thiserror::Error)]
pub enum GpuRenderError {
    #[error(transparent)]
    Render(#[from] RenderError),
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

fn words<T: Flat>(v: &T) -> Vec<u32> {
    let mut w = vec![0.0f32; T::LEN];
    v.write_words(&mut w);
    w.into_iter().map(f32::to_bits).collect()
}

pub fn render<M: SplatMethod>(
    gpu: &Gpu,
    params: &[M::Params],
    camera: &Camera,
    opts: &RenderOptions,
) -> Result<Frame, GpuRenderError> {
    let grid = crate::pipeline::check(camera, opts)?;
    if let Some(i) = params.iter().position(|p| !p.is_finite()) {
        return Err(RenderError::NonFinite(i).into());
    }
    let wgsl = M::SOURCE.wgsl;
    let mut stats = Stats {
        primitives: params.len(),
        ..Stats::default()
    };

    // 1. project on the GPU.
    let t0 = Instant::now();
    let cam = words(camera);
    let rows: Vec<Vec<u32>> = params.iter().map(words).collect();
    let out = kernel::run_shared(gpu, wgsl, "project", &rows, &cam)?;
    let projected: Vec<Projected<M::Cull, M::Shade>> = out.iter().map(|w| unpack::<M>(w)).collect();
    let pre = preprocess::filter::<M>(projected, &grid);
    stats.visible = pre.visible.len();
    stats.preprocess = t0.elapsed();

    // 2. tile lists on the CPU.
    let lists = crate::pipeline::tile_lists(&pre, &grid, &mut stats)?;

    // 3. blend on the GPU.
    let t2 = Instant::now();
    let shade: Vec<u32> = pre.projected.iter().flat_map(|p| words(&p.shade)).collect();
    let depth: Vec<u32> = pre.projected.iter().map(|p| p.depth.to_bits()).collect();
    let channels = M::Color::LEN;
    let source = shade_source::<M>(wgsl)?;
    let p_max = opts
        .p_max
        .map_or(u32::MAX, |p| p.min(u32::MAX as usize) as u32);
    let uniforms = [
        grid.width,
        grid.height,
        grid.size,
        grid.tiles_x,
        p_max,
        0,
        0,
        0,
    ];
    let pixels = (grid.width * grid.height) as usize;
    let mut inputs: Vec<&[u32]> = vec![&shade, &depth, &lists.prims, &lists.ranges];
    if M::HAS_PIXEL_INFO {
        inputs.push(&cam);
    }
    let out = super::dispatch::run_pixels(
        gpu,
        &source,
        &inputs,
        &uniforms,
        pixels * (channels + 2),
        (grid.width, grid.height),
    )?;
    stats.shade = t2.elapsed();
    let f = |w: u32| f32::from_bits(w);
    let mut color = Vec::with_capacity(pixels * channels);
    let (mut t, mut dacc) = (Vec::with_capacity(pixels), Vec::with_capacity(pixels));
    for px in out.chunks_exact(channels + 2) {
        color.extend(px[..channels].iter().map(|w| f(*w)));
        t.push(f(px[channels]));
        dacc.push(f(px[channels + 1]));
    }
    let (alpha, depth) = crate::pipeline::alpha_and_depth(&grid, opts, &t, &dacc);
    let color = Image {
        width: grid.width,
        height: grid.height,
        channels,
        data: color,
    };
    Ok(Frame {
        color,
        alpha,
        depth,
        stats,
    })
}

/// Rebuilds `project`'s output from its result words (slot order = field order).
fn unpack<M: SplatMethod>(w: &[u32]) -> Projected<M::Cull, M::Shade> {
    let f: Vec<f32> = w.iter().map(|x| f32::from_bits(*x)).collect();
    let c = 6 + M::Cull::LEN;
    Projected {
        visible: w[0] != 0,
        depth: f[1],
        bbox_min: glam::Vec2::new(f[2], f[3]),
        bbox_max: glam::Vec2::new(f[4], f[5]),
        cull: M::Cull::read_words(&f[6..c]),
        shade: M::Shade::read_words(&f[c..]),
    }
}

/// The method's WGSL plus the per-pixel blending entry point `splat_shade`.
fn shade_source<M: SplatMethod>(wgsl: &str) -> Result<String, GpuError> {
    let eval: Signature = kernel::signature(wgsl, "evaluate")?;
    let np = M::Pixel::LEN;
    let ns = M::Shade::LEN;
    let channels = M::Color::LEN;
    let mut s = String::from(wgsl);
    // The camera is bound only when pixel_info reads it (an unused binding is dropped from the
    // derived layout).
    let bindings = if M::HAS_PIXEL_INFO {
        "@group(0) @binding(4) var<storage, read> camera_words: array<u32>;
@group(0) @binding(5) var<storage, read_write> pixel_out: array<u32>;
@group(0) @binding(6) var<uniform> frame: array<vec4<u32>, 2>;"
    } else {
        "@group(0) @binding(4) var<storage, read_write> pixel_out: array<u32>;
@group(0) @binding(5) var<uniform> frame: array<vec4<u32>, 2>;"
    };
    s.push_str(
        &"
@group(0) @binding(0) var<storage, read> shade_words: array<u32>;
@group(0) @binding(1) var<storage, read> prim_depth: array<u32>;
@group(0) @binding(2) var<storage, read> tile_prims: array<u32>;
@group(0) @binding(3) var<storage, read> tile_ranges: array<u32>;
BINDINGS

@compute @workgroup_size(8, 8)
fn splat_shade(@builtin(global_invocation_id) gid: vec3<u32>) {
    let width = frame[0].x;
    let height = frame[0].y;
    let tile_size = frame[0].z;
    let tiles_x = frame[0].w;
    let p_max = frame[1].x;
    if (gid.x >= width || gid.y >= height) {
        return;
    }
    let tile = (gid.y / tile_size) * tiles_x + gid.x / tile_size;
    let start = tile_ranges[tile];
    let end = start + min(tile_ranges[tile + 1u] - start, p_max);
    let px = f32(gid.x) + 0.5;
    let py = f32(gid.y) + 0.5;
"
        .replace("BINDINGS", bindings),
    );
    // Pixel data: the pixel centre, or pixel_info's result.
    let pixel_args: Vec<String> = if M::HAS_PIXEL_INFO {
        let info = kernel::signature(wgsl, "pixel_info")?;
        let cam: Vec<String> = (0..Camera::LEN)
            .map(|k| format!("bitcast<f32>(camera_words[{k}u])"))
            .collect();
        let _ = writeln!(
            s,
            "    let pixel = {}(px, py, {});",
            info.name,
            cam.join(", ")
        );
        info.results
            .iter()
            .map(|(m, _)| format!("pixel.{m}"))
            .collect()
    } else {
        vec!["px".into(), "py".into()]
    };
    debug_assert_eq!(pixel_args.len(), np);
    let _ = writeln!(s, "    var t = 1.0;\n    var depth_acc = 0.0;");
    for ch in 0..channels {
        let _ = writeln!(s, "    var c{ch} = 0.0;");
    }
    s.push_str("    for (var k = start; k < end; k++) {\n        let p = tile_prims[k];\n");
    let _ = writeln!(s, "        let base = p * {ns}u;");
    let mut args = pixel_args;
    for (j, kind) in eval.args.iter().enumerate().skip(np) {
        args.push(load(*kind, &format!("shade_words[base + {}u]", j - np)));
    }
    let _ = writeln!(s, "        let r = {}({});", eval.name, args.join(", "));
    let (alpha, valid) = (&eval.results[0].0, &eval.results[channels + 1].0);
    let _ = writeln!(
        s,
        "        if (r.{valid} == 0u) {{\n            continue;\n        }}"
    );
    let _ = writeln!(
        s,
        "        let next = t * (1.0 - r.{alpha});\n        if (next <= 1e-4) {{\n            break;\n        }}"
    );
    let _ = writeln!(s, "        let w = r.{alpha} * t;");
    for ch in 0..channels {
        let _ = writeln!(s, "        c{ch} += w * r.{};", eval.results[1 + ch].0);
    }
    s.push_str("        depth_acc += w * bitcast<f32>(prim_depth[p]);\n        t = next;\n    }\n");
    let _ = writeln!(
        s,
        "    let out = (gid.y * width + gid.x) * {}u;",
        channels + 2
    );
    for ch in 0..channels {
        let _ = writeln!(s, "    pixel_out[out + {ch}u] = bitcast<u32>(c{ch});");
    }
    let _ = writeln!(s, "    pixel_out[out + {}u] = bitcast<u32>(t);", channels);
    let _ = writeln!(
        s,
        "    pixel_out[out + {}u] = bitcast<u32>(depth_acc);\n}}",
        channels + 1
    );
    Ok(s)
}
