//! What a method module imports: the glam types, the built-in method types, and the intrinsics
//! that have no glam method form. The functions here are ordinary Rust with the same meaning the
//! `#[splat_method]` compiler gives them, so method code also reads (and type-checks in an IDE)
//! as plain Rust.

pub use crate::types::{Camera, Contribution, Projected, Tile};
pub use glam::{Mat2, Mat3, Quat, Vec2, Vec3, Vec4};

/// `if c { a } else { b }`. Both operands are computed; in the adjoint only the selected one
/// receives a gradient, and a NaN in the other does not leak.
#[inline(always)]
pub fn select<T>(c: bool, a: T, b: T) -> T {
    if c { a } else { b }
}

/// Marks a value as a constant for differentiation: its gradient is not propagated.
#[inline(always)]
pub fn no_diff<T>(v: T) -> T {
    v
}

/// 1 / sqrt(x).
#[inline(always)]
pub fn rsqrt(x: f32) -> f32 {
    1.0 / x.sqrt()
}

/// The error function, 2 / sqrt(pi) times the integral of e^(-t^2) from 0 to x (std has no
/// stable `erf`).
#[inline(always)]
pub fn erf(x: f32) -> f32 {
    crate::math::erf(x)
}

/// 1 / (1 + e^-x).
#[inline(always)]
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// Real spherical harmonics up to degree 3 in direction `dir` (normalized here) summed with the
/// coefficients `sh`, one `Vec3` per basis function (`N` = 1, 4, 9 or 16), in the basis and
/// signs of 3DGS. Kernels get the compiler's builtin of the same meaning.
pub fn spherical_harmonics<const N: usize>(sh: [Vec3; N], dir: Vec3) -> Vec3 {
    let d = dir.normalize();
    let (x, y, z) = (d.x, d.y, d.z);
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let basis = [
        0.282_094_8,
        -0.488_602_5 * y,
        0.488_602_5 * z,
        -0.488_602_5 * x,
        1.092_548_5 * x * y,
        -1.092_548_5 * y * z,
        0.315_391_57 * (2.0 * zz - xx - yy),
        -1.092_548_5 * x * z,
        0.546_274_2 * (xx - yy),
        -0.590_043_6 * y * (3.0 * xx - yy),
        2.890_611_4 * x * y * z,
        -0.457_045_8 * y * (4.0 * zz - xx - yy),
        0.373_176_33 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy),
        -0.457_045_8 * x * (4.0 * zz - xx - yy),
        1.445_305_7 * z * (xx - yy),
        -0.590_043_6 * x * (xx - 3.0 * yy),
    ];
    sh.iter().zip(basis).map(|(c, b)| *c * b).sum()
}
