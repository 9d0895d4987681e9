//! What a method module imports: the glam types, the built-in method types, and the intrinsics
//! that have no glam method form. The functions here are ordinary Rust with the same meaning the
//! `#[splat_method]` compiler gives them, so method code also reads (and type-checks in an IDE)
//! as plain Rust.

pub use crate::types::{Camera, Contribution, Projected, Tile};
pub use glam::{Mat2, Mat3, Quat, Vec2, Vec2Swizzles, Vec3, Vec3Swizzles, Vec4, Vec4Swizzles};

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

/// The free forms of methods a kernel may call (`exp(x)` for `x.exp()`, the compiler's
/// `FREE_AS_METHOD`), as ordinary Rust of the same meaning, so that a method's source also
/// compiles as it is written (`codegen-tests/tests/plain.rs` compiles its corpus both ways and
/// compares them).
pub use free::{
    abs, atan2, clamp, cos, cross, determinant, dot, exp, inverse, length, ln, log, log1p, max,
    min, normalize, sin, sqrt, tan, transpose,
};

/// The free forms' definitions, and the traits that say which types each takes.
pub mod free {
    use glam::{Mat2, Mat3, Vec2, Vec3, Vec4};

    macro_rules! of_f32 {
        ($($name:ident => $method:ident),*) => {$(
            #[doc = concat!("`x.", stringify!($method), "()`.")]
            #[inline(always)]
            pub fn $name(x: f32) -> f32 {
                x.$method()
            }
        )*};
    }
    of_f32!(exp => exp, ln => ln, log => ln, log1p => ln_1p, sqrt => sqrt, sin => sin,
        cos => cos, tan => tan);

    /// `y.atan2(x)`: the angle of (x, y).
    #[inline(always)]
    pub fn atan2(y: f32, x: f32) -> f32 {
        y.atan2(x)
    }

    /// Types with element-wise `abs`, `min`, `max` and `clamp`: `f32` and the vectors.
    pub trait Elementwise: Copy {
        fn abs_of(self) -> Self;
        fn min_of(self, other: Self) -> Self;
        fn max_of(self, other: Self) -> Self;
        fn clamp_of(self, lo: Self, hi: Self) -> Self;
    }

    /// Vectors: `dot`, `length`, `normalize`.
    pub trait Vector: Copy {
        fn dot_of(self, other: Self) -> f32;
        fn length_of(self) -> f32;
        fn normalize_of(self) -> Self;
    }

    /// Square matrices: `transpose`, `inverse`, `determinant`.
    pub trait Matrix: Copy {
        fn transpose_of(self) -> Self;
        fn inverse_of(self) -> Self;
        fn determinant_of(self) -> f32;
    }

    macro_rules! elementwise {
        ($($t:ty),*) => {$(
            impl Elementwise for $t {
                fn abs_of(self) -> Self { self.abs() }
                fn min_of(self, other: Self) -> Self { self.min(other) }
                fn max_of(self, other: Self) -> Self { self.max(other) }
                fn clamp_of(self, lo: Self, hi: Self) -> Self { self.clamp(lo, hi) }
            }
        )*};
    }
    elementwise!(f32, Vec2, Vec3, Vec4);

    macro_rules! vector {
        ($($t:ty),*) => {$(
            impl Vector for $t {
                fn dot_of(self, other: Self) -> f32 { self.dot(other) }
                fn length_of(self) -> f32 { self.length() }
                fn normalize_of(self) -> Self { self.normalize() }
            }
        )*};
    }
    vector!(Vec2, Vec3, Vec4);

    macro_rules! matrix {
        ($($t:ty),*) => {$(
            impl Matrix for $t {
                fn transpose_of(self) -> Self { self.transpose() }
                fn inverse_of(self) -> Self { self.inverse() }
                fn determinant_of(self) -> f32 { self.determinant() }
            }
        )*};
    }
    matrix!(Mat2, Mat3);

    /// `x.abs()`.
    #[inline(always)]
    pub fn abs<T: Elementwise>(x: T) -> T {
        x.abs_of()
    }

    /// `a.min(b)`.
    #[inline(always)]
    pub fn min<T: Elementwise>(a: T, b: T) -> T {
        a.min_of(b)
    }

    /// `a.max(b)`.
    #[inline(always)]
    pub fn max<T: Elementwise>(a: T, b: T) -> T {
        a.max_of(b)
    }

    /// `x.clamp(lo, hi)`.
    #[inline(always)]
    pub fn clamp<T: Elementwise>(x: T, lo: T, hi: T) -> T {
        x.clamp_of(lo, hi)
    }

    /// `a.dot(b)`.
    #[inline(always)]
    pub fn dot<T: Vector>(a: T, b: T) -> f32 {
        a.dot_of(b)
    }

    /// `v.length()`.
    #[inline(always)]
    pub fn length<T: Vector>(v: T) -> f32 {
        v.length_of()
    }

    /// `v.normalize()`.
    #[inline(always)]
    pub fn normalize<T: Vector>(v: T) -> T {
        v.normalize_of()
    }

    /// `a.cross(b)`.
    #[inline(always)]
    pub fn cross(a: Vec3, b: Vec3) -> Vec3 {
        a.cross(b)
    }

    /// `m.transpose()`.
    #[inline(always)]
    pub fn transpose<T: Matrix>(m: T) -> T {
        m.transpose_of()
    }

    /// `m.inverse()`.
    #[inline(always)]
    pub fn inverse<T: Matrix>(m: T) -> T {
        m.inverse_of()
    }

    /// `m.determinant()`.
    #[inline(always)]
    pub fn determinant<T: Matrix>(m: T) -> f32 {
        m.determinant_of()
    }
}
