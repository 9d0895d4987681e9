//! The generated WGSL runs on the GPU and computes what the Rust forms compute: every corpus
//! kernel and its adjoint, on random inputs. Both the GPU result and the CPU f32 result are
//! measured against the f64 twin; the GPU must be within `TOL` of it, or no worse than four
//! times the CPU's own f32 error where the kernel's conditioning makes f32 itself lose more
//! (the EWA adjoint). Kernels using inverse trigonometry get `TOL_INVERSE_TRIG`: Vulkan only
//! requires 4096 ulp for atan / asin / acos (and tan inherits sin/cos's absolute bound).
//!
//! Needs a wgpu adapter (Mesa's lavapipe is enough). With `SPLAT_REQUIRE_GPU=1` (set by
//! `.ci/run`) a missing adapter fails the test; otherwise the test reports and skips.

use codegen_tests::corpus::*;
use splat_runtime::gpu::{Gpu, kernel};
use splat_runtime::{WgslFunction, WgslScalar};

/// |x - f64 twin| <= TOL * max(|twin|, 1): relative, absolute below 1.
const TOL: f64 = 1e-5;
const TOL_INVERSE_TRIG: f64 = 5e-4;

type ScalarFn<const NF: usize, const NI: usize, const MF: usize, const MI: usize> =
    fn(&[f32; NF], &[u32; NI]) -> ([f32; MF], [u32; MI]);
type AdjointFn<const NF: usize, const NI: usize, const MF: usize> =
    fn(&[f32; NF], &[u32; NI], &[f32; MF]) -> [f32; NF];
type TwinFn<const NF: usize, const NI: usize, const MF: usize, const MI: usize> =
    fn(&[f64; NF], &[u32; NI]) -> ([f64; MF], [u32; MI]);
type TwinAdjointFn<const NF: usize, const NI: usize, const MF: usize> =
    fn(&[f64; NF], &[u32; NI], &[f64; MF]) -> [f64; NF];

/// Errors against the f64 twin: (GPU forward, CPU forward, GPU adjoint, CPU adjoint).
#[derive(Debug, Default, Clone, Copy)]
struct Errors {
    gpu: f64,
    cpu: f64,
    gpu_adj: f64,
    cpu_adj: f64,
}

struct Row<const NF: usize, const NI: usize> {
    floats: [f32; NF],
    ints: [u32; NI],
}

/// Interleaves floats and ints back into WGSL argument order.
fn words(kinds: &[WgslScalar], floats: &[f32], ints: &[u32]) -> Vec<u32> {
    let (mut f, mut i) = (floats.iter(), ints.iter());
    kinds
        .iter()
        .map(|k| {
            if *k == WgslScalar::F32 {
                f.next().unwrap().to_bits()
            } else {
                *i.next().unwrap()
            }
        })
        .collect()
}

fn err(x: f32, twin: f64) -> f64 {
    let x = x as f64;
    if x.is_nan() && twin.is_nan() {
        return 0.0;
    }
    (x - twin).abs() / twin.abs().max(1.0)
}

fn widen<const N: usize>(x: &[f32; N]) -> [f64; N] {
    x.map(f64::from)
}

/// Largest errors of the GPU and the CPU f32 forms of one kernel and its adjoint.
struct Kernel<const NF: usize, const NI: usize, const MF: usize, const MI: usize> {
    name: &'static str,
    f: ScalarFn<NF, NI, MF, MI>,
    adj: AdjointFn<NF, NI, MF>,
    twin: TwinFn<NF, NI, MF, MI>,
    twin_adj: TwinAdjointFn<NF, NI, MF>,
}

fn check<const NF: usize, const NI: usize, const MF: usize, const MI: usize>(
    gpu: &Gpu,
    (wgsl, functions): (&str, &[WgslFunction]),
    k: Kernel<NF, NI, MF, MI>,
    (lo, hi, int_max): (f32, f32, u32),
) -> Errors {
    let mut rng = fastrand::Rng::with_seed(17);
    let rows: Vec<Row<NF, NI>> = (0..256)
        .map(|_| Row {
            floats: std::array::from_fn(|_| lo + (hi - lo) * rng.f32()),
            ints: std::array::from_fn(|_| rng.u32(0..=int_max)),
        })
        .collect();
    let fwd_sig = kernel::function(functions, k.name).unwrap();
    let inputs: Vec<Vec<u32>> = rows
        .iter()
        .map(|r| words(fwd_sig.args, &r.floats, &r.ints))
        .collect();
    let out = kernel::run(gpu, wgsl, fwd_sig, &inputs).unwrap();
    let mut e = Errors::default();
    for (r, o) in rows.iter().zip(&out) {
        let (cf, ci) = (k.f)(&r.floats, &r.ints);
        let (tf, _) = (k.twin)(&widen(&r.floats), &r.ints);
        let (mut fi, mut ii) = (0, ci.iter());
        for ((_, kind), w) in fwd_sig.results.iter().zip(o) {
            if *kind == WgslScalar::F32 {
                e.gpu = e.gpu.max(err(f32::from_bits(*w), tf[fi]));
                e.cpu = e.cpu.max(err(cf[fi], tf[fi]));
                fi += 1;
            } else {
                assert_eq!(*w, *ii.next().unwrap(), "{}: integer result", k.name);
            }
        }
    }
    let adj_name = format!("{}_adjoint", k.name);
    let adj_sig = kernel::function(functions, &adj_name).unwrap();
    assert_eq!(adj_sig.args.len(), fwd_sig.args.len() + MF);
    let bars: Vec<[f32; MF]> = rows
        .iter()
        .map(|_| std::array::from_fn(|_| rng.f32() * 2.0 - 1.0))
        .collect();
    let inputs: Vec<Vec<u32>> = rows
        .iter()
        .zip(&bars)
        .map(|(r, d)| {
            let mut w = words(fwd_sig.args, &r.floats, &r.ints);
            w.extend(d.iter().map(|x| x.to_bits()));
            w
        })
        .collect();
    let out = kernel::run(gpu, wgsl, adj_sig, &inputs).unwrap();
    for ((r, d), o) in rows.iter().zip(&bars).zip(&out) {
        let c = (k.adj)(&r.floats, &r.ints, d);
        let t = (k.twin_adj)(&widen(&r.floats), &r.ints, &widen(d));
        for ((w, v), tv) in o.iter().zip(c).zip(t) {
            e.gpu_adj = e.gpu_adj.max(err(f32::from_bits(*w), tv));
            e.cpu_adj = e.cpu_adj.max(err(v, tv));
        }
    }
    e
}

macro_rules! gpu_corpus {
    ($gpu:expr, $($m:ident :: $f:ident / $adj:ident in $lo:literal .. $hi:literal, ints <= $imax:literal $(, $tol:ident)?;)*) => {{
        let mut failures = vec![];
        $(
            let k = Kernel { name: stringify!($f), f: $m::scalar::$f, adj: $m::scalar::$adj, twin: $m::twin::$f, twin_adj: $m::twin::$adj };
            let e = check($gpu, ($m::GENERATED_WGSL, $m::GENERATED_FUNCTIONS), k, ($lo, $hi, $imax));
            #[allow(unused_variables)]
            let tol = TOL;
            $(let tol = $tol;)?
            println!(
                "{:<28} forward gpu {:.1e} cpu {:.1e} | adjoint gpu {:.1e} cpu {:.1e}",
                concat!(stringify!($m), "::", stringify!($f)), e.gpu, e.cpu, e.gpu_adj, e.cpu_adj
            );
            if e.gpu > tol.max(4.0 * e.cpu) || e.gpu_adj > tol.max(4.0 * e.cpu_adj) {
                failures.push(format!("{}: {e:?}", stringify!($f)));
            }
        )*
        failures
    }};
}

#[test]
fn corpus_kernels_match_the_rust_forms_on_the_gpu() {
    let Some(gpu) = splat_runtime::gpu::adapter_or_skip() else {
        return;
    };
    println!("adapter: {}", gpu.adapter);
    let failures = gpu_corpus!(&gpu,
        scalars::arith / arith_adjoint in 0.2 .. 1.5, ints <= 0;
        scalars::transcendental / transcendental_adjoint in 0.2 .. 2.0, ints <= 0;
        scalars::trig / trig_adjoint in -0.9 .. 0.9, ints <= 0, TOL_INVERSE_TRIG;
        scalars::powers / powers_adjoint in 0.3 .. 2.0, ints <= 0;
        scalars::minmax / minmax_adjoint in -1.0 .. 1.0, ints <= 0;
        scalars::rounding / rounding_adjoint in -3.0 .. 3.0, ints <= 0;
        scalars::misc / misc_adjoint in 0.2 .. 3.0, ints <= 0;
        scalars::sincos / sincos_adjoint in -3.0 .. 3.0, ints <= 0;
        vectors::geometry / geometry_adjoint in -1.0 .. 1.0, ints <= 0;
        vectors::elementwise / elementwise_adjoint in 0.2 .. 1.0, ints <= 0;
        vectors::shape / shape_adjoint in -1.0 .. 1.0, ints <= 0;
        vectors::rotate / rotate_adjoint in 0.2 .. 1.0, ints <= 0;
        vectors::components / components_adjoint in -1.0 .. 1.0, ints <= 0;
        matrices::mat3 / mat3_adjoint in -1.0 .. 1.0, ints <= 0;
        matrices::covariance / covariance_adjoint in 0.5 .. 1.0, ints <= 0;
        control::nested / nested_adjoint in -2.0 .. 2.0, ints <= 0;
        control::statements / statements_adjoint in -1.0 .. 1.5, ints <= 0;
        control::vector_loop / vector_loop_adjoint in 0.5 .. 1.0, ints <= 0;
        control::array_loop / array_loop_adjoint in -1.0 .. 1.0, ints <= 0;
        control::flags / flags_adjoint in 0.5 .. 2.0, ints <= 9;
        structured::sh_color / sh_color_adjoint in 0.05 .. 1.0, ints <= 0;
        structured::uses_custom / uses_custom_adjoint in -1.0 .. 1.0, ints <= 0;
        kinks::nan_branch / nan_branch_adjoint in -1.0 .. 1.0, ints <= 0;
        kinks::lazy_div / lazy_div_adjoint in -1.0 .. 1.0, ints <= 0;
        jacobians::every_op_jacobian / every_op_jacobian_adjoint in 0.15 .. 0.85, ints <= 0, TOL_INVERSE_TRIG;
        jacobians::scalar_jacobian / scalar_jacobian_adjoint in -1.5 .. 1.5, ints <= 0;
        jacobians::branch_jacobian / branch_jacobian_adjoint in 0.1 .. 0.4, ints <= 0;
    );
    assert!(
        failures.is_empty(),
        "GPU results beyond the bounds: {failures:#?}"
    );
}
