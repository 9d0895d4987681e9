//! The generated WGSL runs on the GPU and computes what the Rust forms compute: every corpus
//! kernel and its adjoint, on the corpus checks' random inputs (`codegen_tests::samples`). The
//! GPU result and the CPU f32 result are each held to the f64 twin, output by output, with the
//! checks' one rule (`Bound`: `tol` of each value plus `tol` of that output's largest over
//! the inputs), the GPU's bound independent of the CPU's error. Kernels using inverse
//! trigonometry get `TOL_INVERSE_TRIG` on the GPU: Vulkan only requires 4096 ulp for atan /
//! asin / acos (and tan inherits sin/cos's absolute bound).
//!
//! Needs a wgpu adapter (Mesa's lavapipe is enough). With `SPLAT_REQUIRE_GPU=1` (set by
//! `.ci/run`) a missing adapter fails the test; otherwise the test reports and skips.

use codegen_tests::corpus::*;
use codegen_tests::samples;
use fastrand::Rng;
use splat_runtime::checks::bound::Bound;
use splat_runtime::gpu::{Gpu, kernel};
use splat_runtime::{WgslFunction, WgslScalar};

/// About ten f32 ulps of each value plus ten of its output's largest. Measured (lavapipe,
/// 2026-12-06): worst 3.2e-7 (`arith`'s GPU forward; `rotate`'s adjoint 3.0e-7 on both).
const TOL: f64 = 6e-7;
/// The GPU's inverse trigonometry, which Vulkan lets be 4096 ulp off: measured 4.0e-5
/// (`trig`'s forward).
const TOL_INVERSE_TRIG: f64 = 1e-4;

type ScalarFn<const NF: usize, const NI: usize, const MF: usize, const MI: usize> =
    fn(&[f32; NF], &[u32; NI]) -> ([f32; MF], [u32; MI]);
type AdjointFn<const NF: usize, const NI: usize, const MF: usize> =
    fn(&[f32; NF], &[u32; NI], &[f32; MF]) -> [f32; NF];
type TwinFn<const NF: usize, const NI: usize, const MF: usize, const MI: usize> =
    fn(&[f64; NF], &[u32; NI]) -> ([f64; MF], [u32; MI]);
type TwinAdjointFn<const NF: usize, const NI: usize, const MF: usize> =
    fn(&[f64; NF], &[u32; NI], &[f64; MF]) -> [f64; NF];

/// Worst fractions of the bound against the f64 twin: (GPU forward, CPU forward, GPU adjoint,
/// CPU adjoint).
#[derive(Debug, Default, Clone, Copy)]
struct Errors {
    gpu: f64,
    cpu: f64,
    gpu_adj: f64,
    cpu_adj: f64,
}

/// Per output slot (columns of `rows`), the values of every row.
fn columns(rows: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let n = rows.first().map_or(0, Vec::len);
    (0..n)
        .map(|j| rows.iter().map(|r| r[j]).collect())
        .collect()
}

/// The worst fraction of `bound` over the slots of `got` against `twin` (a NaN where the twin
/// has one is a match: the kinks corpus returns NaN on purpose).
fn worst(bound: Bound, got: &[Vec<f64>], twin: &[Vec<f64>]) -> f64 {
    let (got, twin) = (columns(got), columns(twin));
    got.iter()
        .zip(&twin)
        .map(|(g, t)| {
            let keep = |i: &usize| !(g[*i].is_nan() && t[*i].is_nan());
            let pick =
                |v: &[f64]| -> Vec<f64> { (0..v.len()).filter(keep).map(|i| v[i]).collect() };
            bound.fit(&pick(g), &pick(t), None).of_bound
        })
        .fold(0.0, f64::max)
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
    sample: impl Fn(&mut Rng) -> ([f64; NF], [u32; NI]),
    (cpu_bound, gpu_bound): (Bound, Bound),
) -> Errors {
    let mut rng = Rng::with_seed(17);
    let rows: Vec<Row<NF, NI>> = (0..256)
        .map(|_| {
            let (floats, ints) = sample(&mut rng);
            Row {
                floats: floats.map(|x| x as f32),
                ints,
            }
        })
        .collect();
    let fwd_sig = kernel::function(functions, k.name).unwrap();
    let inputs: Vec<Vec<u32>> = rows
        .iter()
        .map(|r| words(fwd_sig.args, &r.floats, &r.ints))
        .collect();
    let out = kernel::run(gpu, wgsl, fwd_sig, &inputs).unwrap();
    let (mut on_gpu, mut on_cpu, mut twin) = (vec![], vec![], vec![]);
    for (r, o) in rows.iter().zip(&out) {
        let (cf, ci) = (k.f)(&r.floats, &r.ints);
        let (tf, _) = (k.twin)(&widen(&r.floats), &r.ints);
        let mut ii = ci.iter();
        let mut g = vec![];
        for ((_, kind), w) in fwd_sig.results.iter().zip(o) {
            if *kind == WgslScalar::F32 {
                g.push(f32::from_bits(*w) as f64);
            } else {
                assert_eq!(*w, *ii.next().unwrap(), "{}: integer result", k.name);
            }
        }
        on_gpu.push(g);
        on_cpu.push(cf.iter().map(|x| *x as f64).collect());
        twin.push(tf.to_vec());
    }
    let mut e = Errors {
        gpu: worst(gpu_bound, &on_gpu, &twin),
        cpu: worst(cpu_bound, &on_cpu, &twin),
        ..Default::default()
    };
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
    let (mut on_gpu, mut on_cpu, mut twin) = (vec![], vec![], vec![]);
    for ((r, d), o) in rows.iter().zip(&bars).zip(&out) {
        let c = (k.adj)(&r.floats, &r.ints, d);
        on_gpu.push(o.iter().map(|w| f32::from_bits(*w) as f64).collect());
        on_cpu.push(c.iter().map(|x| *x as f64).collect());
        twin.push((k.twin_adj)(&widen(&r.floats), &r.ints, &widen(d)).to_vec());
    }
    e.gpu_adj = worst(gpu_bound, &on_gpu, &twin);
    e.cpu_adj = worst(cpu_bound, &on_cpu, &twin);
    e
}

/// The GPU form's tolerance for a corpus entry's mark.
macro_rules! gpu_tolerance {
    () => {
        TOL
    };
    (inverse_trig) => {
        TOL_INVERSE_TRIG
    };
}

/// Each kernel with its inputs, marked `inverse_trig` where its GPU form gets
/// `TOL_INVERSE_TRIG`; pushes the name of each past its bounds to `$failures`.
macro_rules! gpu_corpus {
    ($gpu:expr, $failures:expr, $($m:ident :: $f:ident / $adj:ident => $sample:expr $(, $inverse_trig:ident)?;)*) => {$(
        {
            let gpu = gpu_tolerance!($($inverse_trig)?);
            let k = Kernel { name: stringify!($f), f: $m::scalar::$f, adj: $m::scalar::$adj, twin: $m::twin::$f, twin_adj: $m::twin::$adj };
            let bounds = (Bound::new(TOL, TOL), Bound::new(gpu, gpu));
            let e = check($gpu, ($m::GENERATED_WGSL, $m::GENERATED_FUNCTIONS), k, $sample, bounds);
            println!(
                "{:<28} of the bounds: forward gpu {:.3} cpu {:.3} | adjoint gpu {:.3} cpu {:.3}",
                concat!(stringify!($m), "::", stringify!($f)), e.gpu, e.cpu, e.gpu_adj, e.cpu_adj
            );
            if e.gpu.max(e.cpu).max(e.gpu_adj).max(e.cpu_adj) > 1.0 {
                $failures.push(format!("{}: {e:?}", stringify!($f)));
            }
        }
    )*};
}

#[test]
fn corpus_kernels_match_the_rust_forms_on_the_gpu() {
    let Some(gpu) = splat_runtime::gpu::adapter_or_skip() else {
        return;
    };
    println!("adapter: {}", gpu.adapter);
    let mut failures: Vec<String> = vec![];
    codegen_tests::with_corpus!(gpu_corpus!(&gpu, failures,));
    // The kinks corpus (its gradients are checked by rule in `tests/kinks.rs`) runs here too.
    gpu_corpus!(&gpu, failures,
        kinks::nan_branch / nan_branch_adjoint => samples::plain::<1>(-1.0, 1.0);
        kinks::lazy_div / lazy_div_adjoint => samples::plain::<2>(-1.0, 1.0);
    );
    assert!(
        failures.is_empty(),
        "GPU results beyond the bounds: {failures:#?}"
    );
}
