//! The method-specific compute entry points, written around the method's generated WGSL.
//!
//! The templates in `shaders/` hold the runtime's logic; what depends on the method (how many
//! words each type has, the calls to `project`, `tile_cull`, `pixel_info`, `evaluate` and the
//! adjoints with one argument per slot) is filled in here from the signatures the compiler
//! emitted beside the WGSL (`SplatMethod::SOURCE.functions`). The method's source never
//! changes between backends.

use super::kernel::{self, load};
use super::packing::ShadePacking;
use super::raster::Blending;
use super::scatter;
use super::state::PixelState;
use super::sums::Sums;
use super::{Gpu, GpuError};
use splat_core::blend::Blend;
use splat_core::flat::Flat;
use splat_core::frame::RenderOptions;
use splat_core::method::{GradientSet, SplatMethod, WgslFunction};
use splat_core::types::{Camera, CameraModel};

/// How `backward` adds its gradients: an option of its entry point.
pub use super::scatter::{Accumulation, FragmentReduction, Reduction};

use crate::frame_uniform::WGSL as FRAME_UNIFORM;

const TILES: &str = include_str!("shaders/tiles.wgsl");
/// `fn finite`, for the shaders that test their inputs.
pub const FINITE: &str = include_str!("shaders/finite.wgsl");
/// `fn pixel_span`: the pixels a projected primitive covers, as the CPU's `pipeline::filter`
/// and `TileGrid::rect` (needs [`FINITE`]).
pub const PIXEL_SPAN: &str = include_str!("shaders/pixel_span.wgsl");
const DEPTH: &str = include_str!("shaders/depth.wgsl");
const COUNT: &str = include_str!("shaders/count.wgsl");
const EMIT: &str = include_str!("shaders/emit.wgsl");
const TILE_PASS: &str = include_str!("shaders/tile_pass.wgsl");
const SHADE: &str = include_str!("shaders/shade.wgsl");
const BACKWARD: &str = include_str!("shaders/backward.wgsl");
const PROJECT_BACKWARD: &str = include_str!("shaders/project_backward.wgsl");
const PIXEL_BACKWARD: &str = include_str!("shaders/pixel_backward.wgsl");
const QUADS: &str = include_str!("shaders/quads.wgsl");
const RASTER: &str = include_str!("shaders/raster.wgsl");
const RASTER_BACKWARD: &str = include_str!("shaders/raster_backward.wgsl");
const SHADE_PACK: &str = include_str!("shaders/shade_pack.wgsl");
/// `fn to_half`, `fn from_half`: f16 conversions on the bits.
pub const HALF: &str = include_str!("shaders/half.wgsl");

/// Bytes of workgroup memory kept free of the batch (counters, flags).
const RESERVED_BYTES: u32 = 256;

/// Replaces every `{{KEY}}` of `template`.
fn fill(template: &str, pairs: &[(&str, String)]) -> String {
    let mut s = template.to_string();
    for (k, v) in pairs {
        s = s.replace(&format!("{{{{{k}}}}}"), v);
    }
    debug_assert!(!s.contains("{{"), "unfilled placeholder in\n{s}");
    s
}

/// Word counts of a method's types, as laid out in the GPU buffers.
#[derive(Clone, Copy, Debug)]
pub struct Layout {
    /// Words of `project`'s result per primitive: visible, depth, bbox (4), cull, shade.
    pub stride: usize,
    pub shade_at: usize,
    pub shade_words: usize,
    /// Float slots of the shade type (its gradient words).
    pub shade_floats: usize,
    pub channels: usize,
    /// Gradient words per primitive: shade float slots, then depth.
    pub grad_words: usize,
}

impl Layout {
    pub fn of<M: SplatMethod>() -> Layout {
        let shade_floats = M::ShadeLanes::default().as_ref().len();
        Layout {
            stride: 6 + M::Cull::LEN + M::Shade::LEN,
            shade_at: 6 + M::Cull::LEN,
            shade_words: M::Shade::LEN,
            shade_floats,
            channels: M::Color::LEN,
            grad_words: shade_floats + 1,
        }
    }
}

/// The generated WGSL function of `M`'s kernel `name`.
fn sig<M: SplatMethod>(name: &str) -> Result<&'static WgslFunction, GpuError> {
    kernel::function(M::SOURCE.functions, name)
}

/// `M`'s kernel `name` compiled for the camera `model` only, where the kernel reads the model
/// (the compiler names that variant `{name}_{model}`); otherwise the kernel itself.
fn sig_for<M: SplatMethod>(
    name: &str,
    model: CameraModel,
) -> Result<&'static WgslFunction, GpuError> {
    kernel::function(M::SOURCE.functions, &format!("{name}_{model}")).or_else(|_| sig::<M>(name))
}

/// `project` for the camera `model` over one primitive per invocation (the kernel harness:
/// parameters per row, the camera shared).
pub fn project<M: SplatMethod>(model: CameraModel) -> Result<String, GpuError> {
    let wgsl = M::SOURCE.wgsl;
    Ok(kernel::harness_source(
        wgsl,
        sig_for::<M>("project", model)?,
        M::Params::LEN,
    ))
}

/// The entry points over each primitive's tiles (`shaders/tiles.wgsl`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TilesEntry {
    /// `depth_keys`: the keys of the depth sort.
    DepthKeys,
    /// `count_tiles`: each primitive's kept tiles, front to back.
    Count,
    /// `emit_tiles`: one (tile, primitive) key per kept tile, front to back.
    Emit,
}

/// The module of `entry`; `use_cull` false keeps every box tile.
pub fn tiles<M: SplatMethod>(entry: TilesEntry, use_cull: bool) -> Result<String, GpuError> {
    let wgsl = M::SOURCE.wgsl;
    let layout = Layout::of::<M>();
    let keep = if M::HAS_TILE_CULL && use_cull {
        let cull = sig::<M>("tile_cull")?;
        let mut args: Vec<String> = ["lo.x", "lo.y", "hi.x", "hi.y"].map(String::from).into();
        for (k, kind) in cull.args.iter().enumerate().skip(4) {
            args.push(load(
                *kind,
                &format!("projected[i * STRIDE + CULL_AT + {}u]", k - 4),
            ));
        }
        format!(
            "{}({}).{} != 0u",
            cull.name,
            args.join(", "),
            cull.results[0].0
        )
    } else {
        "true".into()
    };
    let (entry, emit_code) = match entry {
        TilesEntry::DepthKeys => (DEPTH, ""),
        TilesEntry::Count => (COUNT, ""),
        TilesEntry::Emit => (
            EMIT,
            // Past the buffers' room (frame.room) the frame is cut and rendered again.
            "if (first + n < frame.room) {
                    keys[first + n] = ty * frame.tiles_x + tx;
                    vals[first + n] = i;
                }",
        ),
    };
    let body = fill(
        TILES,
        &[
            ("STRIDE", layout.stride.to_string()),
            ("KEEP", keep),
            ("EMIT", emit_code.into()),
            ("ENTRY", entry.into()),
        ],
    );
    Ok(format!(
        "{wgsl}\n{FRAME_UNIFORM}\n{FINITE}\n{PIXEL_SPAN}\n{body}"
    ))
}

/// Workgroup sizes and batch sizes of a blend pass.
struct BlendSizes {
    wg: u32,
    batch: u32,
    /// Gradient words reduced per round (backward with reduction only).
    rc: u32,
}

fn blend_sizes(
    gpu: &Gpu,
    tile: u32,
    layout: &Layout,
    workgroup_reduce: bool,
) -> Result<BlendSizes, GpuError> {
    let wg = tile * tile;
    let mut budget = gpu.workgroup_storage().saturating_sub(RESERVED_BYTES);
    let rc = if workgroup_reduce {
        let rc = ((budget / 2) / (4 * wg))
            .min(layout.grad_words as u32)
            .max(1);
        budget = budget.saturating_sub(4 * wg * rc);
        rc
    } else {
        1
    };
    // Per staged entry: shade words, depth, primitive index.
    let batch = (budget / (4 * (layout.shade_words as u32 + 2))).min(wg);
    if batch == 0 {
        return Err(GpuError::Shader(format!(
            "a primitive's {} shade words do not fit in {} bytes of workgroup memory",
            layout.shade_words,
            gpu.workgroup_storage()
        )));
    }
    Ok(BlendSizes { wg, batch, rc })
}

/// The pixel data under the camera `model`: its binding (camera words, only with
/// `pixel_info`), the code computing it from `px, py`, and its slot expressions.
fn pixel<M: SplatMethod>(
    camera_binding: u32,
    model: CameraModel,
) -> Result<(String, String, Vec<String>), GpuError> {
    if !M::HAS_PIXEL_INFO {
        return Ok((String::new(), String::new(), vec!["px".into(), "py".into()]));
    }
    let info = sig_for::<M>("pixel_info", model)?;
    let cam: Vec<String> = info.args[2..]
        .iter()
        .enumerate()
        .map(|(k, kind)| load(*kind, &format!("camera_words[{k}u]")))
        .collect();
    let binding = format!(
        "@group(0) @binding({camera_binding}) var<storage, read> camera_words: array<u32>;"
    );
    let code = format!("let pixel = {}(px, py, {});", info.name, cam.join(", "));
    let args = info
        .results
        .iter()
        .map(|(m, _)| format!("pixel.{m}"))
        .collect();
    Ok((binding, code, args))
}

/// `evaluate(pixel, shade words)`, the shade words read from `words[s + k]`, and its
/// signature.
fn evaluate_call<M: SplatMethod>(
    pixel_args: &[String],
    words: &str,
) -> Result<(String, &'static WgslFunction), GpuError> {
    let eval = sig::<M>("evaluate")?;
    let np = pixel_args.len();
    let mut args = pixel_args.to_vec();
    for (j, kind) in eval.args.iter().enumerate().skip(np) {
        args.push(load(*kind, &format!("{words}[s + {}u]", j - np)));
    }
    Ok((format!("{}({})", eval.name, args.join(", ")), eval))
}

/// `evaluate`'s adjoint, as both backward blends call it: its signature, the call (as
/// `adjoint`) on the pixel data `pixel_args`, the shade words read from `words[s + k]`, the
/// cotangent `d_alpha`, `w` times each color channel's cotangent `d_color(c)`, and the gradient
/// groups of `opts`; and the statements setting each shade gradient word from the call's
/// result, named `result`, indented by `indent`.
fn evaluate_adjoint_call<M: SplatMethod>(
    pixel_args: &[String],
    words: &str,
    d_color: impl Fn(usize) -> String,
    opts: &RenderOptions,
    (result, indent): (&str, &str),
) -> Result<(&'static WgslFunction, String, String), GpuError> {
    let adj = sig::<M>("evaluate_adjoint")?;
    let layout = Layout::of::<M>();
    let (np, ns, nc) = (pixel_args.len(), layout.shade_words, layout.channels);
    // The pixel data, the shade data, the cotangents of alpha and color, the groups' mask.
    if adj.args.len() != np + ns + 1 + nc + 1 {
        return Err(GpuError::Shader(format!(
            "evaluate_adjoint takes {} arguments, expected {}",
            adj.args.len(),
            np + ns + 1 + nc + 1
        )));
    }
    let mut args: Vec<String> = pixel_args.to_vec();
    for (j, kind) in adj.args.iter().enumerate().skip(np).take(ns) {
        args.push(load(*kind, &format!("{words}[s + {}u]", j - np)));
    }
    args.push("d_alpha".into());
    args.extend((0..nc).map(|c| format!("w * {}", d_color(c))));
    args.push(format!("{}u", opts.gradients.shade_groups::<M>()));
    let nsf = layout.shade_floats;
    let first = adj.results.len() - nsf;
    let shade_grads = (0..nsf)
        .map(|k| {
            let m = &adj.results[first + k].0;
            format!("{indent}{} = {result}.{m};\n", scatter::word(k))
        })
        .collect();
    Ok((
        adj,
        format!("{}({})", adj.name, args.join(", ")),
        shade_grads,
    ))
}

/// The shade packing's module for `M` (`shade_range`, `shade_pack`), its own placeholders
/// filled with `pairs`.
pub(crate) fn shade_pack<M: SplatMethod>(pairs: &[(&str, String)]) -> Result<String, GpuError> {
    let layout = Layout::of::<M>();
    let mut pairs = pairs.to_vec();
    pairs.push(("SHADE_AT", layout.shade_at.to_string()));
    let entry = fill(SHADE_PACK, &pairs);
    let body = fill(
        TILES,
        &[
            ("STRIDE", layout.stride.to_string()),
            ("KEEP", "true".into()),
            ("EMIT", String::new()),
            ("ENTRY", entry),
        ],
    );
    Ok(format!(
        "{FRAME_UNIFORM}\n{FINITE}\n{PIXEL_SPAN}\n{HALF}\n{body}"
    ))
}

fn tile_pass(layout: &Layout, tile: u32, b: &BlendSizes, packing: Option<&ShadePacking>) -> String {
    let (bindings, stage) = match packing {
        None => (
            String::new(),
            "        for (var w = 0u; w < NS; w++) {
            batch_words[lid * NS + w] = projected[p * STRIDE + SHADE_AT + w];
        }"
            .to_string(),
        ),
        Some(packing) => {
            let mut bindings = format!(
                "// The shade data packed at {} (`gpu::shade_pack`).
@group(0) @binding(11) var<storage, read> packed_shade: array<u32>;
",
                packing.precision.name()
            );
            if packing.has_ranges() {
                bindings += "@group(0) @binding(12) var<storage, read> shade_ranges: array<u32>;\n";
            }
            (bindings, packing.wgsl_stage())
        }
    };
    // f16 conversions for packed shade data and f16 gradient sums (unused ones are pruned).
    let pass = fill(
        TILE_PASS,
        &[
            ("SHADE_BINDINGS", bindings),
            ("STAGE_SHADE", stage),
            ("TILE", tile.to_string()),
            ("WG", b.wg.to_string()),
            ("BATCH", b.batch.to_string()),
            ("NS", layout.shade_words.to_string()),
            ("STRIDE", layout.stride.to_string()),
            ("SHADE_AT", layout.shade_at.to_string()),
            ("CHANNELS", layout.channels.to_string()),
            (
                "BATCH_WORDS",
                (b.batch as usize * layout.shade_words.max(1)).to_string(),
            ),
        ],
    );
    format!("{FRAME_UNIFORM}\n{FINITE}\n{HALF}\n{pass}")
}

/// `shade_tiles`: the forward blend under the camera `model`, one workgroup per tile of
/// `tile` x `tile` pixels, reading the shade data packed as `packing` says (or `project`'s
/// own), storing each pixel as `state` says.
pub fn shade<M: SplatMethod>(
    gpu: &Gpu,
    model: CameraModel,
    tile: u32,
    want_depth: bool,
    state: PixelState,
    packing: Option<&ShadePacking>,
) -> Result<String, GpuError> {
    let wgsl = M::SOURCE.wgsl;
    let layout = Layout::of::<M>();
    let b = blend_sizes(gpu, tile, &layout, false)?;
    let (camera, pixel_code, pixel_args) = pixel::<M>(6, model)?;
    let (call, eval) = evaluate_call::<M>(&pixel_args, "batch_words")?;
    let nc = layout.channels;
    let accumulate: String = (0..nc)
        .map(|c| {
            format!(
                "            color[{c}] += w * r.{};\n",
                eval.results[1 + c].0
            )
        })
        .collect();
    let depth = if want_depth {
        "depth_acc += w * batch_depth[j];"
    } else {
        ""
    };
    let body = fill(
        SHADE,
        &[
            ("CAMERA_BINDING", camera),
            ("WG", b.wg.to_string()),
            ("PIXEL", pixel_code),
            ("EVALUATE", call),
            ("VALID", eval.results[nc + 1].0.to_string()),
            ("ALPHA", eval.results[0].0.to_string()),
            ("ACCUMULATE", accumulate),
            ("DEPTH", depth.into()),
            ("STORE", state.wgsl_store("pixel_out", "walked")),
        ],
    );
    Ok(format!(
        "{wgsl}\n{}\n{body}",
        tile_pass(&layout, tile, &b, packing)
    ))
}

/// `backward_tiles`: the backward blend under the camera `model` with the gradient
/// accumulation `acc`, replaying against the pixels stored as `state` says (the shade data
/// packed as `packing` says, as in the forward pass), for the tile size and gradient groups of
/// `opts` (the groups a constant of the pipeline: `evaluate`'s adjoint branches on them fold;
/// the blend's thresholds its override constants, [`blend_constants`]).
pub fn backward<M: SplatMethod>(
    gpu: &Gpu,
    model: CameraModel,
    opts: &RenderOptions,
    want_depth: bool,
    acc: Accumulation,
    state: PixelState,
    packing: Option<&ShadePacking>,
) -> Result<String, GpuError> {
    let tile = opts.tile_size;
    let wgsl = M::SOURCE.wgsl;
    let layout = Layout::of::<M>();
    let b = blend_sizes(gpu, tile, &layout, acc.reduce == Reduction::Workgroup)?;
    let (camera, pixel_code, pixel_args) = pixel::<M>(9, model)?;
    let (call, eval) = evaluate_call::<M>(&pixel_args, "batch_words")?;
    let d_color = |c: usize| format!("d_color[{c}]");
    let indent = " ".repeat(20);
    let (adj, adjoint, shade_grads) =
        evaluate_adjoint_call::<M>(&pixel_args, "batch_words", d_color, opts, ("a", &indent))?;
    let (np, nc) = (pixel_args.len(), layout.channels);
    let color_terms: String = (0..nc)
        .map(|c| {
            format!(
                "                        let cc{c} = r.{m};
                        if (first) {{
                            reference[{c}] = cc{c};
                        }}
                        let b{c} = blend_term(cc{c}, reference[{c}], behind[{c}], t, w, one_minus, t_final);
                        d_alpha += b{c}.x * d_color[{c}];
                        behind[{c}] = b{c}.y;
",
                m = eval.results[1 + c].0
            )
        })
        .collect();
    let scatter = scatter::scatter(acc.reduce, layout.grad_words, b.rc as usize);
    let sums = Sums::at(opts.gradient_precision);
    let (grad_atomic, add_grad) = sums.wgsl_add(acc.float_atomics);
    let note = match acc.reduce {
        Reduction::Workgroup => {
            "each entry's gradient is first summed over the workgroup in workgroup memory (one atomic per tile, entry and word)."
        }
        Reduction::Subgroup => {
            "each entry's gradient is first summed over the subgroup (one atomic per subgroup, entry and word)."
        }
        Reduction::None => {
            "one atomic per pixel, entry and word (the baseline the reductions are measured against)."
        }
    };
    // naga takes subgroup builtins without `enable subgroups;` (which it rejects as not yet
    // implemented) once the device has the SUBGROUP feature.
    let lane = if acc.reduce == Reduction::Subgroup {
        ", @builtin(subgroup_invocation_id) lane: u32"
    } else {
        ""
    };
    // With `pixel_info`, each pixel sums its data's cotangent and stores it for
    // `pixel_backward` (the camera's gradient through the rays).
    let (pixel_binding, pixel_decl, pixel_grads, pixel_store) = if M::HAS_PIXEL_INFO {
        (
            "@group(0) @binding(10) var<storage, read_write> pixel_cotangent: array<u32>;".into(),
            format!("    var d_pixel: array<f32, {np}>;"),
            (0..np)
                .map(|k| {
                    format!(
                        "                    d_pixel[{k}] += a.{};
",
                        adj.results[k].0
                    )
                })
                .collect(),
            format!(
                "    if (at.inside) {{
        for (var k = 0u; k < {np}u; k++) {{
            pixel_cotangent[(at.y * frame.width + at.x) * {np}u + k] = bitcast<u32>(d_pixel[k]);
        }}
    }}"
            ),
        )
    } else {
        (String::new(), String::new(), String::new(), String::new())
    };
    let body = fill(
        BACKWARD,
        &[
            ("PIXEL_GRAD_BINDING", pixel_binding),
            ("PIXEL_GRAD_DECL", pixel_decl),
            ("PIXEL_GRADS", pixel_grads),
            ("PIXEL_GRAD_STORE", pixel_store),
            ("REDUCTION_NOTE", note.into()),
            ("NG", layout.grad_words.to_string()),
            ("GRAD_ATOMIC", grad_atomic.into()),
            ("CAMERA_BINDING", camera),
            (
                "RED_WORDS",
                if acc.reduce == Reduction::Workgroup {
                    b.rc * b.wg
                } else {
                    1
                }
                .to_string(),
            ),
            ("LANE", lane.into()),
            ("SUM_BINDING", sum_binding(sums, 13)),
            ("ADD_GRAD", add_grad),
            ("WG", b.wg.to_string()),
            ("PIXEL", pixel_code),
            ("EVALUATE", call),
            ("VALID", eval.results[nc + 1].0.to_string()),
            ("ALPHA", eval.results[0].0.to_string()),
            ("WANT_DEPTH", want_depth.to_string()),
            (
                "ALPHA_COTANGENT",
                opts.gradients.alpha_cotangent::<M>().to_string(),
            ),
            ("COLOR_TERMS", color_terms),
            ("EVALUATE_ADJOINT", adjoint),
            ("SHADE_GRADS", shade_grads),
            ("SCATTER", scatter),
            ("GRAD_DECL", scatter::declare(layout.grad_words)),
            ("DEPTH_GRAD", scatter::word(layout.grad_words - 1)),
            ("STATE", state.wgsl_load("pixel_state")),
            (
                "D_FINAL",
                match state.depth {
                    true => "state_value(pix, CHANNELS + 1u)",
                    false => "0.0",
                }
                .into(),
            ),
        ],
    );
    Ok(format!(
        "{wgsl}\n{}\n{body}",
        tile_pass(&layout, tile, &b, packing)
    ))
}

/// Where the hardware forward's programmable blending binds its first state texture.
const RASTER_STATE_BINDING: u32 = 16;

/// Values per render target of the hardware-rasterized forward pass: three, then the alpha
/// each target blends by.
pub const RASTER_VALUES: usize = 3;

/// The render targets holding `M`'s color channels, [`RASTER_VALUES`] per target.
pub fn raster_color_targets<M: SplatMethod>() -> usize {
    M::Color::LEN.div_ceil(RASTER_VALUES)
}

/// The blend's thresholds as the `override` constants of the tile passes (`shade`, `backward`:
/// `T_MIN`, `ALPHA_MIN`), set when their pipelines are compiled.
pub fn blend_constants(rule: Blend) -> [(&'static str, f64); 2] {
    [
        ("T_MIN", f64::from(rule.stop_at())),
        ("ALPHA_MIN", f64::from(rule.alpha_min)),
    ]
}

/// The hardware-rasterized forward pass under the camera `model` (`quad_vertex`,
/// `splat_fragment`): the color channels in `color_targets` targets, then (with `depth`) the
/// depth in one more target ([`raster_color_targets`] of them for the colors). With
/// `Blending::Programmable` the fragment blends itself: it reads each target's state (a
/// texture, bound from 16 on, that `programmable_blend` makes an input attachment) and writes
/// what fixed-function blending would, and stops its pixel as the tile path does (before the
/// primitive that would bring T to `T_STOP` or below), marking it in one more target.
pub fn raster<M: SplatMethod>(
    model: CameraModel,
    depth: bool,
    blending: Blending,
) -> Result<String, GpuError> {
    let layout = Layout::of::<M>();
    let (camera, pixel_code, pixel_args) = pixel::<M>(3, model)?;
    let (call, eval) = evaluate_call::<M>(&pixel_args, "projected")?;
    let targets = RasterTargets::of::<M>(eval, depth, blending);
    let body = fill(
        RASTER,
        &[
            ("TARGETS", targets.decls.clone()),
            ("PIXEL", pixel_code),
            ("EVALUATE", call),
            ("VALID", eval.results[layout.channels + 1].0.to_string()),
            ("ALPHA", eval.results[0].0.to_string()),
            ("WRITE", targets.forward(blending)),
        ],
    );
    Ok(format!(
        "{}\n{body}\n{}",
        quads::<M>(camera),
        targets.states
    ))
}

/// The method's WGSL and the quads' vertex stage (`shaders/quads.wgsl`), with the camera's
/// binding `camera`.
fn quads<M: SplatMethod>(camera: String) -> String {
    let layout = Layout::of::<M>();
    let quads = fill(
        QUADS,
        &[
            ("STRIDE", layout.stride.to_string()),
            ("SHADE_AT", layout.shade_at.to_string()),
            ("CAMERA_BINDING", camera),
        ],
    );
    format!("{}\n{FRAME_UNIFORM}\n{quads}", M::SOURCE.wgsl)
}

/// What the quads' fragment shaders write, for `evaluate`'s result `r` of alpha `a` and the
/// primitive's `depth`: the color channels [`RASTER_VALUES`] to a target `t0`, `t1`, ..., then
/// (with `depth`) the depth in one more.
struct RasterTargets {
    /// The fields of the `Targets` struct.
    decls: String,
    /// The state textures and what they need (programmable blending).
    states: String,
    /// Programmable blending: reads each target's state `s0`, `s1`, ...
    read: String,
    /// Sets `out` to what the fragment blends: the premultiplied values (fixed-function
    /// blending), or (programmable) the state blended under.
    blend: String,
    /// Programmable blending: sets `out` to the state as it was.
    keep: String,
    /// Per target, the expressions it blends ("0.0" past the values).
    values: Vec<Vec<String>>,
}

impl RasterTargets {
    fn of<M: SplatMethod>(eval: &WgslFunction, depth: bool, blending: Blending) -> RasterTargets {
        let color: Vec<String> = (0..M::Color::LEN)
            .map(|c| format!("r.{}", eval.results[1 + c].0))
            .collect();
        let mut values: Vec<Vec<String>> = color
            .chunks(RASTER_VALUES)
            .map(<[String]>::to_vec)
            .collect();
        if depth {
            values.push(vec!["depth".into()]);
        }
        let mut t = RasterTargets {
            decls: String::new(),
            states: String::new(),
            read: String::new(),
            blend: String::new(),
            keep: String::new(),
            values: vec![],
        };
        for (k, values) in values.iter_mut().enumerate() {
            values.resize(RASTER_VALUES, "0.0".into());
            t.decls += &format!("    @location({k}) t{k}: vec4<f32>,\n");
            let [v0, v1, v2] = [&values[0], &values[1], &values[2]];
            let src = format!("vec4<f32>(a * {v0}, a * {v1}, a * {v2}, a)");
            match blending {
                Blending::FixedFunction => t.blend += &format!("    out.t{k} = {src};\n"),
                // "Under", as the fixed-function blend state of `raster.rs`: dst + (1 - dst.a) src.
                Blending::Programmable => {
                    let binding = RASTER_STATE_BINDING + k as u32;
                    t.states +=
                        &format!("@group(0) @binding({binding}) var state{k}: texture_2d<f32>;\n");
                    t.read +=
                        &format!("    let s{k} = textureLoad(state{k}, vec2<i32>(0, 0), 0);\n");
                    t.blend += &format!("        out.t{k} = s{k} + (1.0 - s{k}.a) * {src};\n");
                    t.keep += &format!("        out.t{k} = s{k};\n");
                }
            }
        }
        if blending == Blending::Programmable {
            // The pixel's stop mark: a target after the values', read like them.
            let n = values.len();
            let binding = RASTER_STATE_BINDING + n as u32;
            t.decls += &format!("    @location({n}) stopped: vec4<u32>,\n");
            t.states += &format!(
                "@group(0) @binding({binding}) var stop_mark: texture_2d<u32>;
// Transmittance at or below which a pixel stops (`Blend::stop_at`).
override T_STOP: f32;
"
            );
        }
        t.values = values;
        t
    }

    /// The forward fragment's writes into `out` under `blending`: the values for the blend
    /// unit, or the state read and blended under, a pixel stopped (then `out` is returned at
    /// once, the state kept and the stop marked), or a pixel already stopped left alone.
    fn forward(&self, blending: Blending) -> String {
        match blending {
            Blending::FixedFunction => self.blend.clone(),
            Blending::Programmable => format!(
                "    if (textureLoad(stop_mark, vec2<i32>(0, 0), 0).x != 0u) {{
        discard;
    }}
{read}    if ((1.0 - s0.a) * (1.0 - a) <= T_STOP) {{
        out.stopped = vec4<u32>(1u, 0u, 0u, 0u);
{keep}        return out;
    }}
    out.stopped = vec4<u32>(0u);
{blend}",
                read = self.read,
                keep = self.keep,
                blend = self.blend
            ),
        }
    }
}

/// The hardware path's backward blend under the camera `model` (`quad_vertex`,
/// `splat_backward`, `shaders/raster_backward.wgsl`): the programmable forward's draw replayed
/// into the same targets (with `depth`, its depth target), each fragment adding its
/// primitive's shade and depth gradients (the depth's with `want_depth`), summed as `reduce`
/// says, into `grads` held as `sums` say, by f32 atomics where `float_atomics` (else
/// compare-exchange), for the gradient groups of `opts`; ray methods add their pixel
/// cotangents too, when the camera's gradient is asked for. Its `front_facing` means a helper
/// invocation (`programmable_blend::spirv::front_facing_as_helper`).
pub fn raster_backward<M: SplatMethod>(
    model: CameraModel,
    opts: &RenderOptions,
    want_depth: bool,
    sums: Sums,
    (reduce, float_atomics): (FragmentReduction, bool),
) -> Result<String, GpuError> {
    let layout = Layout::of::<M>();
    let (camera, pixel_code, pixel_args) = pixel::<M>(3, model)?;
    let (call, eval) = evaluate_call::<M>(&pixel_args, "projected")?;
    let d_color = |c: usize| format!("pixel_grad[at + {c}u]");
    let (adj, adjoint, shade_grads) =
        evaluate_adjoint_call::<M>(&pixel_args, "projected", d_color, opts, ("ga", "        "))?;
    let (np, nc) = (pixel_args.len(), layout.channels);
    let targets = RasterTargets::of::<M>(eval, opts.depth, Blending::Programmable);
    // Each channel's value after this fragment: the component of its target.
    let after = |c: usize| {
        format!(
            "out.t{}.{}",
            c / RASTER_VALUES,
            ["x", "y", "z"][c % RASTER_VALUES]
        )
    };
    let color_terms: String = (0..nc)
        .map(|c| {
            format!(
                "        d_alpha += pixel_grad[at + {c}u] * (t * {v} - (pixel_final[at + {c}u] - {after}) / one_minus);\n",
                v = targets.values[c / RASTER_VALUES][c % RASTER_VALUES],
                after = after(c),
            )
        })
        .collect();
    let depth_after = match opts.depth {
        true => format!("out.t{}.x", targets.values.len() - 1),
        false => "0.0".into(),
    };
    let (grad_atomic, add_grad) = sums.wgsl_add(float_atomics);
    // Ray methods: each fragment adds its pixel data's cotangent to its pixel's, for
    // `pixel_backward` (the camera's gradient through the rays).
    let (pixel_binding, add_pixel, pixel_grads) = if M::HAS_PIXEL_INFO && opts.gradients.camera() {
        let (atomic, add) =
            super::sums::wgsl_add_f32("add_pixel", "pixel_cotangent", float_atomics);
        (
            format!(
                "@group(0) @binding(9) var<storage, read_write> pixel_cotangent: array<{atomic}>;"
            ),
            add,
            (0..np)
                .map(|k| {
                    format!(
                        "    add_pixel(pix * {np}u + {k}u, ga.{});\n",
                        adj.results[k].0
                    )
                })
                .collect(),
        )
    } else {
        (String::new(), String::new(), String::new())
    };
    let body = fill(
        RASTER_BACKWARD,
        &[
            ("REDUCTION_NOTE", reduce.shader_note()),
            ("NG", layout.grad_words.to_string()),
            ("CHANNELS", nc.to_string()),
            (
                "ALPHA_COTANGENT",
                opts.gradients.alpha_cotangent::<M>().to_string(),
            ),
            ("WANT_DEPTH", want_depth.to_string()),
            ("GRAD_ATOMIC", grad_atomic.into()),
            ("SUM_BINDING", sum_binding(sums, 8)),
            ("PIXEL_GRAD_BINDING", pixel_binding),
            ("ADD_GRAD", format!("{add_grad}\n{add_pixel}")),
            ("TARGETS", targets.decls),
            ("PIXEL", pixel_code),
            ("EVALUATE", call),
            ("VALID", eval.results[nc + 1].0.to_string()),
            ("ALPHA", eval.results[0].0.to_string()),
            ("READ", targets.read),
            ("KEEP", targets.keep),
            ("BLEND", targets.blend),
            ("COLOR_TERMS", color_terms),
            ("DEPTH_AFTER", depth_after),
            ("EVALUATE_ADJOINT", adjoint),
            ("GRAD_DECL", scatter::declare(layout.grad_words)),
            ("SHADE_GRADS", shade_grads),
            ("DEPTH_GRAD", scatter::word(layout.grad_words - 1)),
            (
                "SCATTER",
                scatter::scatter_fragments(reduce, layout.grad_words),
            ),
            ("PIXEL_GRADS", pixel_grads),
        ],
    );
    let half = match sums.half {
        true => format!("{FINITE}\n{HALF}"),
        false => String::new(),
    };
    Ok(format!(
        "{}\n{body}\n{}\n{half}",
        quads::<M>(camera),
        targets.states
    ))
}

/// The float slots of `M::Params` (gradient words per primitive): `project_adjoint`'s
/// results are the parameters' float slots, then the camera's (its leading words).
pub fn param_floats<M: SplatMethod>() -> Result<usize, GpuError> {
    let adj = sig::<M>("project_adjoint")?;
    adj.results
        .len()
        .checked_sub(Camera::FLOAT_SLOTS)
        .ok_or_else(|| GpuError::Shader("project_adjoint has too few results".into()))
}

/// `project_backward`: `project`'s adjoint under the camera `model` per primitive, camera
/// gradients per workgroup. The gradient groups `wanted` are a constant of the pipeline: the
/// adjoint's branches on them fold, and without the camera no workgroup sums it.
pub fn project_backward<M: SplatMethod>(
    model: CameraModel,
    wanted: GradientSet,
    sums: Sums,
) -> Result<String, GpuError> {
    let wgsl = M::SOURCE.wgsl;
    let layout = Layout::of::<M>();
    let adj = sig_for::<M>("project_adjoint", model)?;
    let (np, ncam) = (M::Params::LEN, Camera::LEN);
    let npf = param_floats::<M>()?;
    // Arguments: parameters, camera, then the cotangent's float slots: depth, bbox (4), cull
    // (zero: no gradient flows through culling), shade; then the gradient groups' mask.
    let cull_floats = adj
        .args
        .len()
        .checked_sub(np + ncam + 5 + layout.shade_floats + 1)
        .ok_or_else(|| GpuError::Shader("project_adjoint has too few arguments".into()))?;
    let mut args: Vec<String> = adj.args[..np]
        .iter()
        .enumerate()
        .map(|(k, kind)| load(*kind, &format!("params[i * NP + {k}u]")))
        .collect();
    args.extend(
        adj.args[np..np + ncam]
            .iter()
            .enumerate()
            .map(|(k, kind)| load(*kind, &format!("camera_words[{k}u]"))),
    );
    args.push("grad(i * NG + NG - 1u)".into());
    args.extend(std::iter::repeat_n("0.0".to_string(), 4 + cull_floats));
    args.extend((0..layout.shade_floats).map(|k| format!("grad(i * NG + {k}u)")));
    args.push(format!("{}u", wanted.bits()));
    let mut write = String::new();
    for (k, (m, _)) in adj.results.iter().enumerate() {
        if k < npf {
            write += &format!("            param_grads[i * NPF + {k}u] = bitcast<u32>(a.{m});\n");
        } else if wanted.camera() {
            write += &format!("            cam[{}] = a.{m};\n", k - npf);
        }
    }
    let body = fill(
        PROJECT_BACKWARD,
        &[
            ("NP", np.to_string()),
            ("NPF", npf.to_string()),
            ("NCAM", Camera::FLOAT_SLOTS.to_string()),
            ("NG", layout.grad_words.to_string()),
            ("STRIDE", layout.stride.to_string()),
            ("RED_WORDS", (64 * Camera::FLOAT_SLOTS).to_string()),
            ("SUM_CAMERA", wanted.camera().to_string()),
            (
                "PROJECT_ADJOINT",
                format!("{}({})", adj.name, args.join(", ")),
            ),
            ("WRITE", write),
            ("SUM_BINDING", sum_binding(sums, 7)),
            ("GRAD_READ", sums.wgsl_read().into()),
        ],
    );
    Ok(format!("{wgsl}\n{FINITE}\n{HALF}\n{body}"))
}

/// The binding of the largest output gradient's bits at `slot`, for f16 sums.
fn sum_binding(sums: Sums, slot: u32) -> String {
    match sums.half {
        true => format!("@group(0) @binding({slot}) var<storage, read> grad_largest: array<u32>;"),
        false => String::new(),
    }
}

/// `pixel_backward`: `pixel_info`'s adjoint under the camera `model` per pixel, camera
/// gradients per workgroup (only for methods with `pixel_info`).
pub fn pixel_backward<M: SplatMethod>(model: CameraModel) -> Result<String, GpuError> {
    let wgsl = M::SOURCE.wgsl;
    let adj = sig_for::<M>("pixel_info_adjoint", model)?;
    let ncam = Camera::LEN;
    // Arguments: the pixel centre, the camera, the pixel data's cotangent. Results: the
    // centre's cotangent (2), then the camera's float slots.
    let npx = adj.args.len() - 2 - ncam;
    let mut args: Vec<String> = vec!["px".into(), "py".into()];
    args.extend(
        adj.args[2..2 + ncam]
            .iter()
            .enumerate()
            .map(|(k, kind)| load(*kind, &format!("camera_words[{k}u]"))),
    );
    args.extend((0..npx).map(|k| format!("bitcast<f32>(pixel_cotangent[i * NPX + {k}u])")));
    let write: String = adj.results[2..]
        .iter()
        .enumerate()
        .map(|(k, (m, _))| format!("        cam[{k}] = a.{m};\n"))
        .collect();
    let body = fill(
        PIXEL_BACKWARD,
        &[
            ("NCAM", Camera::FLOAT_SLOTS.to_string()),
            ("NPX", npx.to_string()),
            ("RED_WORDS", (64 * Camera::FLOAT_SLOTS).to_string()),
            (
                "PIXEL_INFO_ADJOINT",
                format!("{}({})", adj.name, args.join(", ")),
            ),
            ("WRITE", write),
        ],
    );
    Ok(format!("{wgsl}\n{body}"))
}
