//! Generic checks over the flat forms every kernel gets.

use splat_runtime::{F32x8, LANES, U32x8};

/// Flat f64 forward: (floats, ints) -> (floats, ints).
pub type TwinFn<const NF: usize, const NI: usize, const MF: usize, const MI: usize> =
    fn(&[f64; NF], &[u32; NI]) -> ([f64; MF], [u32; MI]);
/// Flat f64 adjoint: (floats, ints, cotangent of the float outputs) -> cotangent of the float inputs.
pub type TwinAdjointFn<const NF: usize, const NI: usize, const MF: usize> =
    fn(&[f64; NF], &[u32; NI], &[f64; MF]) -> [f64; NF];

/// Largest errors seen by [`gradient`].
#[derive(Debug, Default, Clone, Copy)]
pub struct GradientReport {
    /// Max over entries of |fd - ad| / max(|fd|, |ad|, FLOOR).
    pub jacobian: f64,
    /// Max over trials of |<y, J x> - <J^T y, x>| / max(|lhs|, |rhs|, FLOOR).
    pub dot_product: f64,
    pub trials: usize,
}

/// Below this magnitude an entry's error is measured in absolute terms.
pub const FLOOR: f64 = 1e-3;

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / a.abs().max(b.abs()).max(FLOOR)
}

/// Central difference of `f` along `dir` at `x`, with step `h` scaled to `x`.
fn directional<const NF: usize, const NI: usize, const MF: usize, const MI: usize>(
    f: TwinFn<NF, NI, MF, MI>,
    x: &[f64; NF],
    ints: &[u32; NI],
    dir: &[f64; NF],
) -> [f64; MF] {
    let scale = x.iter().fold(1.0f64, |m, v| m.max(v.abs()));
    let h = 1e-6 * scale;
    let shifted = |s: f64| {
        let mut y = *x;
        for i in 0..NF {
            y[i] += s * h * dir[i];
        }
        f(&y, ints).0
    };
    let (p, m) = (shifted(1.0), shifted(-1.0));
    let mut d = [0.0; MF];
    for j in 0..MF {
        d[j] = (p[j] - m[j]) / (2.0 * h);
    }
    d
}

/// Compares the adjoint with central finite differences of the f64 twin, entry by entry of
/// the Jacobian, and checks the dot-product identity, on `trials` inputs from `sample`.
pub fn gradient<const NF: usize, const NI: usize, const MF: usize, const MI: usize>(
    f: TwinFn<NF, NI, MF, MI>,
    adj: TwinAdjointFn<NF, NI, MF>,
    sample: impl Fn(&mut fastrand::Rng) -> ([f64; NF], [u32; NI]),
    seed: u64,
    trials: usize,
) -> GradientReport {
    let mut rng = fastrand::Rng::with_seed(seed);
    let mut report = GradientReport {
        trials,
        ..Default::default()
    };
    for _ in 0..trials {
        let (x, ints) = sample(&mut rng);
        // Full Jacobian: columns by finite differences, rows by the adjoint.
        let mut rows = vec![[0.0; NF]; MF];
        for (j, row) in rows.iter_mut().enumerate() {
            let mut e = [0.0; MF];
            e[j] = 1.0;
            *row = adj(&x, &ints, &e);
        }
        for i in 0..NF {
            let mut e = [0.0; NF];
            e[i] = 1.0;
            let col = directional(f, &x, &ints, &e);
            for j in 0..MF {
                report.jacobian = report.jacobian.max(rel(col[j], rows[j][i]));
            }
        }
        // <y, J x> = <J^T y, x> for random x, y; x of unit length, so the difference steps as
        // far as the Jacobian's columns do however many inputs there are.
        let mut xd: [f64; NF] = std::array::from_fn(|_| rng.f64() * 2.0 - 1.0);
        let norm = xd
            .iter()
            .map(|v| v * v)
            .sum::<f64>()
            .sqrt()
            .max(f64::MIN_POSITIVE);
        xd.iter_mut().for_each(|v| *v /= norm);
        let yb: [f64; MF] = std::array::from_fn(|_| rng.f64() * 2.0 - 1.0);
        let jx = directional(f, &x, &ints, &xd);
        let jty = adj(&x, &ints, &yb);
        let lhs: f64 = yb.iter().zip(&jx).map(|(a, b)| a * b).sum();
        let rhs: f64 = jty.iter().zip(&xd).map(|(a, b)| a * b).sum();
        report.dot_product = report.dot_product.max(rel(lhs, rhs));
    }
    report
}

/// Compares a Jacobian computed inside a kernel (`jac`: the gradient of `f`'s output `i` by
/// its inputs `wrt` at `i * wrt.len()`) with central differences of `f`'s f64 twin, on `trials`
/// inputs from `sample`; returns the largest relative error of an entry.
pub fn jacobian_vs_differences<
    const NF: usize,
    const NI: usize,
    const MF: usize,
    const MI: usize,
    const MJ: usize,
    const MJI: usize,
>(
    f: TwinFn<NF, NI, MF, MI>,
    jac: TwinFn<NF, NI, MJ, MJI>,
    wrt: std::ops::Range<usize>,
    sample: impl Fn(&mut fastrand::Rng) -> ([f64; NF], [u32; NI]),
    seed: u64,
    trials: usize,
) -> f64 {
    assert_eq!(MJ, MF * wrt.len(), "one gradient per output");
    let mut rng = fastrand::Rng::with_seed(seed);
    let mut worst = 0.0f64;
    for _ in 0..trials {
        let (x, ints) = sample(&mut rng);
        let (j, _) = jac(&x, &ints);
        for (k, input) in wrt.clone().enumerate() {
            let mut e = [0.0; NF];
            e[input] = 1.0;
            let col = directional(f, &x, &ints, &e);
            for (i, d) in col.iter().enumerate() {
                worst = worst.max(rel(*d, j[i * wrt.len() + k]));
            }
        }
    }
    worst
}

/// Uniform samples in `[lo, hi)`.
pub fn uniform<const N: usize>(rng: &mut fastrand::Rng, lo: f64, hi: f64) -> [f64; N] {
    std::array::from_fn(|_| lo + (hi - lo) * rng.f64())
}

/// Flat f32 forward / lane forward.
pub type ScalarFn<const NF: usize, const NI: usize, const MF: usize, const MI: usize> =
    fn(&[f32; NF], &[u32; NI]) -> ([f32; MF], [u32; MI]);
pub type LaneFn<const NF: usize, const NI: usize, const MF: usize, const MI: usize> =
    fn(&[F32x8; NF], &[U32x8; NI]) -> ([F32x8; MF], [U32x8; MI]);

fn same_bits(a: f32, b: f32) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

/// Runs the lane form on eight inputs and the scalar form on each; returns how many output
/// values differed in any bit (NaN equals NaN).
pub fn lanes_vs_scalar<const NF: usize, const NI: usize, const MF: usize, const MI: usize>(
    scalar: ScalarFn<NF, NI, MF, MI>,
    lanes: LaneFn<NF, NI, MF, MI>,
    inputs: &[([f32; NF], [u32; NI]); LANES],
) -> usize {
    let lf: [F32x8; NF] = std::array::from_fn(|i| F32x8(std::array::from_fn(|l| inputs[l].0[i])));
    let li: [U32x8; NI] = std::array::from_fn(|i| U32x8(std::array::from_fn(|l| inputs[l].1[i])));
    let (of, oi) = lanes(&lf, &li);
    let mut diffs = 0;
    for (l, (xf, xi)) in inputs.iter().enumerate() {
        let (sf, si) = scalar(xf, xi);
        diffs += (0..MF)
            .filter(|&j| !same_bits(sf[j], of[j].lane(l)))
            .count();
        diffs += (0..MI).filter(|&j| si[j] != oi[j].lane(l)).count();
    }
    diffs
}

/// Flat f32 adjoint / lane adjoint.
pub type ScalarAdjointFn<const NF: usize, const NI: usize, const MF: usize> =
    fn(&[f32; NF], &[u32; NI], &[f32; MF]) -> [f32; NF];
pub type LaneAdjointFn<const NF: usize, const NI: usize, const MF: usize> =
    fn(&[F32x8; NF], &[U32x8; NI], &[F32x8; MF]) -> [F32x8; NF];

/// Same for adjoints: every input cotangent must match bit for bit.
pub fn adjoint_lanes_vs_scalar<const NF: usize, const NI: usize, const MF: usize>(
    scalar: ScalarAdjointFn<NF, NI, MF>,
    lanes: LaneAdjointFn<NF, NI, MF>,
    inputs: &[([f32; NF], [u32; NI], [f32; MF]); LANES],
) -> usize {
    let lf: [F32x8; NF] = std::array::from_fn(|i| F32x8(std::array::from_fn(|l| inputs[l].0[i])));
    let li: [U32x8; NI] = std::array::from_fn(|i| U32x8(std::array::from_fn(|l| inputs[l].1[i])));
    let ld: [F32x8; MF] = std::array::from_fn(|i| F32x8(std::array::from_fn(|l| inputs[l].2[i])));
    let o = lanes(&lf, &li, &ld);
    let mut diffs = 0;
    for (l, (xf, xi, d)) in inputs.iter().enumerate() {
        let s = scalar(xf, xi, d);
        diffs += (0..NF).filter(|&j| !same_bits(s[j], o[j].lane(l))).count();
    }
    diffs
}
