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

/// 1 / (1 + e^-x).
#[inline(always)]
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}
