//! Random inputs for each corpus function, away from its kinks and singular points: shared by
//! the CPU checks (`tests/corpus.rs`) and the GPU's (`tests/gpu.rs`), so both run every kernel
//! on the same kind of input.

use crate::check::uniform;
use fastrand::Rng;

/// Each input uniform in [lo, hi].
pub fn plain<const N: usize>(lo: f64, hi: f64) -> impl Fn(&mut Rng) -> ([f64; N], [u32; 0]) {
    move |r| (uniform(r, lo, hi), [])
}

/// Values of magnitude in [lo, hi] with a random sign.
pub fn signed<const N: usize>(lo: f64, hi: f64) -> impl Fn(&mut Rng) -> ([f64; N], [u32; 0]) {
    move |r| {
        let signed = |r: &mut Rng| (lo + (hi - lo) * r.f64()) * if r.bool() { 1.0 } else { -1.0 };
        (std::array::from_fn(|_| signed(r)), [])
    }
}

/// `mat2`: a well-conditioned matrix (near 1.5 I) and a positive scale.
pub fn mat2(r: &mut Rng) -> ([f64; 5], [u32; 0]) {
    let mut x: [f64; 5] = uniform(r, -0.5, 0.5);
    x[0] += 1.5;
    x[3] += 1.5;
    x[4] = 0.5 + 0.5 * r.f64();
    (x, [])
}

/// `covariance`: a quaternion with a dominant w, log scales, a point in front of the camera.
pub fn covariance(r: &mut Rng) -> ([f64; 10], [u32; 0]) {
    let mut x: [f64; 10] = uniform(r, -1.0, 1.0);
    x[0] = 0.5 + 0.5 * r.f64();
    for s in &mut x[4..7] {
        *s = -1.0 + 1.5 * r.f64();
    }
    x[9] = 2.0 + 2.0 * r.f64();
    (x, [])
}

/// `flags`: a positive float, a bool and a small count.
pub fn flags(r: &mut Rng) -> ([f64; 1], [u32; 2]) {
    ([0.5 + 1.5 * r.f64()], [r.bool() as u32, r.u32(0..10)])
}

/// `splat_of`: a Gaussian in front of the eye, positive scales.
pub fn splat(r: &mut Rng) -> ([f64; 58], [u32; 0]) {
    let mut x: [f64; 58] = uniform(r, -1.0, 1.0);
    x[2] = 2.0 + r.f64(); // mean.z in front of the eye
    for s in &mut x[3..6] {
        *s = 0.1 + 0.9 * r.f64();
    }
    x[57] = -r.f64(); // eye.z
    (x, [])
}

/// `vector_loop`: a positive scale.
pub fn vector_loop(r: &mut Rng) -> ([f64; 4], [u32; 0]) {
    let mut x: [f64; 4] = uniform(r, -1.0, 1.0);
    x[3] = 0.5 + r.f64();
    (x, [])
}

/// `guarded`: both sides of each guard, y away from zero.
pub fn guarded(r: &mut Rng) -> ([f64; 2], [u32; 0]) {
    let y = (0.3 + 0.7 * r.f64()) * if r.bool() { 1.0 } else { -1.0 };
    ([-2.0 + 5.0 * r.f64(), y], [])
}

/// `branch_jacobian`: away from the branches' edges at 0.5.
pub fn branch_sides(r: &mut Rng) -> ([f64; 2], [u32; 0]) {
    let side = |r: &mut Rng| match r.bool() {
        true => 0.1 + 0.3 * r.f64(),
        false => 0.6 + 0.3 * r.f64(),
    };
    ([side(r), side(r)], [])
}
