//! Eight-lane value types for the CPU hot loop.
//!
//! Every operation is a plain loop over `[T; 8]` marked `#[inline(always)]`, which LLVM turns
//! into vector instructions on stable Rust (two SSE2 registers on baseline x86-64, one AVX
//! register where the caller enables it with `#[target_feature]`). Masks hold `0` or `!0` per
//! lane so that a select is a bit blend. Lane `i` of every result is computed by exactly the
//! same scalar operation as the scalar code path, which is what makes the lane form of a
//! generated function bit-identical to its scalar form.

use crate::math;
use std::ops::{Add, BitAnd, BitOr, BitXor, Div, Mul, Neg, Not, Rem, Shl, Shr, Sub};

/// Number of lanes of every lane type.
pub const LANES: usize = 8;

/// `[F32x8; N]`: the lane form of a struct of floats (pixel data, colors).
pub trait LaneArray: Copy + Default + Send + Sync + AsRef<[F32x8]> + AsMut<[F32x8]> {}
impl<const N: usize> LaneArray for [F32x8; N] where [F32x8; N]: Default {}

/// Eight `f32` lanes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C, align(32))]
pub struct F32x8(pub [f32; LANES]);

/// Eight boolean lanes, each `0` (false) or `u32::MAX` (true).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(C, align(32))]
pub struct M32x8(pub [u32; LANES]);

/// Eight `u32` lanes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(C, align(32))]
pub struct U32x8(pub [u32; LANES]);

/// Eight `i32` lanes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(C, align(32))]
pub struct I32x8(pub [i32; LANES]);

#[inline(always)]
fn map<T: Copy, U: Copy + Default>(a: [T; LANES], f: impl Fn(T) -> U) -> [U; LANES] {
    let mut out = [U::default(); LANES];
    for i in 0..LANES {
        out[i] = f(a[i]);
    }
    out
}

#[inline(always)]
fn zip<T: Copy, U: Copy, V: Copy + Default>(
    a: [T; LANES],
    b: [U; LANES],
    f: impl Fn(T, U) -> V,
) -> [V; LANES] {
    let mut out = [V::default(); LANES];
    for i in 0..LANES {
        out[i] = f(a[i], b[i]);
    }
    out
}

/// True where the CPU has AVX2 and FMA: hot loops are then run in functions compiled for
/// them (the results are the same bits: no operation is fused without being asked to).
#[inline]
pub fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

#[inline(always)]
fn mask(b: bool) -> u32 {
    (b as u32).wrapping_neg()
}

/// Arithmetic operators between a lane type and itself or its scalar, in both orders.
macro_rules! lane_arith {
    ($lanes:ident, $scalar:ty, $($trait:ident $method:ident $op:tt),*) => {$(
        impl $trait for $lanes {
            type Output = $lanes;
            #[inline(always)]
            fn $method(self, rhs: $lanes) -> $lanes { $lanes(zip(self.0, rhs.0, |a, b| a $op b)) }
        }
        impl $trait<$scalar> for $lanes {
            type Output = $lanes;
            #[inline(always)]
            fn $method(self, rhs: $scalar) -> $lanes { $lanes(map(self.0, |a| a $op rhs)) }
        }
        impl $trait<$lanes> for $scalar {
            type Output = $lanes;
            #[inline(always)]
            fn $method(self, rhs: $lanes) -> $lanes { $lanes(map(rhs.0, |b| self $op b)) }
        }
    )*};
}

/// Comparisons producing a mask, shared by the numeric lane types.
macro_rules! lane_compare {
    ($lanes:ident) => {
        impl $lanes {
            #[inline(always)]
            pub fn lt(self, rhs: Self) -> M32x8 {
                M32x8(zip(self.0, rhs.0, |a, b| mask(a < b)))
            }
            #[inline(always)]
            pub fn le(self, rhs: Self) -> M32x8 {
                M32x8(zip(self.0, rhs.0, |a, b| mask(a <= b)))
            }
            #[inline(always)]
            pub fn gt(self, rhs: Self) -> M32x8 {
                M32x8(zip(self.0, rhs.0, |a, b| mask(a > b)))
            }
            #[inline(always)]
            pub fn ge(self, rhs: Self) -> M32x8 {
                M32x8(zip(self.0, rhs.0, |a, b| mask(a >= b)))
            }
            #[inline(always)]
            pub fn eq(self, rhs: Self) -> M32x8 {
                M32x8(zip(self.0, rhs.0, |a, b| mask(a == b)))
            }
            #[inline(always)]
            pub fn ne(self, rhs: Self) -> M32x8 {
                M32x8(zip(self.0, rhs.0, |a, b| mask(a != b)))
            }
        }
    };
}

lane_arith!(F32x8, f32, Add add +, Sub sub -, Mul mul *, Div div /, Rem rem %);
lane_compare!(F32x8);
lane_arith!(U32x8, u32, BitAnd bitand &, BitOr bitor |, BitXor bitxor ^);
lane_arith!(I32x8, i32, BitAnd bitand &, BitOr bitor |, BitXor bitxor ^);
lane_compare!(U32x8);
lane_compare!(I32x8);

/// Wrapping integer arithmetic, matching the generated scalar code's `wrapping_*` calls.
macro_rules! lane_wrapping {
    ($lanes:ident, $scalar:ty) => {
        impl Add for $lanes {
            type Output = $lanes;
            #[inline(always)]
            fn add(self, rhs: $lanes) -> $lanes {
                $lanes(zip(self.0, rhs.0, <$scalar>::wrapping_add))
            }
        }
        impl Sub for $lanes {
            type Output = $lanes;
            #[inline(always)]
            fn sub(self, rhs: $lanes) -> $lanes {
                $lanes(zip(self.0, rhs.0, <$scalar>::wrapping_sub))
            }
        }
        impl Mul for $lanes {
            type Output = $lanes;
            #[inline(always)]
            fn mul(self, rhs: $lanes) -> $lanes {
                $lanes(zip(self.0, rhs.0, <$scalar>::wrapping_mul))
            }
        }
        /// Division by zero gives 0, like the generated scalar code.
        impl Div for $lanes {
            type Output = $lanes;
            #[inline(always)]
            fn div(self, rhs: $lanes) -> $lanes {
                $lanes(zip(self.0, rhs.0, |a, b| a.checked_div(b).unwrap_or(0)))
            }
        }
        impl Rem for $lanes {
            type Output = $lanes;
            #[inline(always)]
            fn rem(self, rhs: $lanes) -> $lanes {
                $lanes(zip(self.0, rhs.0, |a, b| a.checked_rem(b).unwrap_or(0)))
            }
        }
        impl Shl for $lanes {
            type Output = $lanes;
            #[inline(always)]
            fn shl(self, rhs: $lanes) -> $lanes {
                $lanes(zip(self.0, rhs.0, |a, b| a.wrapping_shl(b as u32)))
            }
        }
        impl Shr for $lanes {
            type Output = $lanes;
            #[inline(always)]
            fn shr(self, rhs: $lanes) -> $lanes {
                $lanes(zip(self.0, rhs.0, |a, b| a.wrapping_shr(b as u32)))
            }
        }
        impl $lanes {
            #[inline(always)]
            pub fn splat(v: $scalar) -> Self {
                Self([v; LANES])
            }
            #[inline(always)]
            pub fn to_f32(self) -> F32x8 {
                F32x8(map(self.0, |a| a as f32))
            }
            #[inline(always)]
            pub fn min(self, rhs: Self) -> Self {
                Self(zip(self.0, rhs.0, |a, b| a.min(b)))
            }
            #[inline(always)]
            pub fn max(self, rhs: Self) -> Self {
                Self(zip(self.0, rhs.0, |a, b| a.max(b)))
            }
            /// Lane `i` of the result is lane `i` of `self`.
            #[inline(always)]
            pub fn lane(self, i: usize) -> $scalar {
                self.0[i]
            }
        }
    };
}
lane_wrapping!(U32x8, u32);
lane_wrapping!(I32x8, i32);

impl Neg for I32x8 {
    type Output = I32x8;
    #[inline(always)]
    fn neg(self) -> I32x8 {
        I32x8(map(self.0, i32::wrapping_neg))
    }
}

impl U32x8 {
    #[inline(always)]
    pub fn to_i32(self) -> I32x8 {
        I32x8(map(self.0, |a| a as i32))
    }
    /// Nonzero lanes become true.
    #[inline(always)]
    pub fn to_mask(self) -> M32x8 {
        M32x8(map(self.0, |a| mask(a != 0)))
    }
}

impl I32x8 {
    #[inline(always)]
    pub fn to_u32(self) -> U32x8 {
        U32x8(map(self.0, |a| a as u32))
    }
    #[inline(always)]
    pub fn abs(self) -> I32x8 {
        I32x8(map(self.0, i32::wrapping_abs))
    }
}

impl Neg for F32x8 {
    type Output = F32x8;
    #[inline(always)]
    fn neg(self) -> F32x8 {
        F32x8(map(self.0, |a| -a))
    }
}

/// Unary `f32` methods applied lane by lane with the same scalar function the scalar path uses.
macro_rules! lane_unary {
    ($($name:ident => $f:expr),* $(,)?) => {
        impl F32x8 {$(
            #[inline(always)]
            pub fn $name(self) -> F32x8 { F32x8(map(self.0, $f)) }
        )*}
    };
}

lane_unary!(
    sqrt => f32::sqrt,
    abs => f32::abs,
    floor => f32::floor,
    ceil => f32::ceil,
    round => f32::round,
    trunc => f32::trunc,
    fract => f32::fract,
    signum => f32::signum,
    exp => math::exp,
    ln => math::ln,
    ln_1p => math::ln_1p,
    erf => math::erf,
    sin => f32::sin,
    cos => f32::cos,
    tan => f32::tan,
    asin => f32::asin,
    acos => f32::acos,
    atan => f32::atan,
    tanh => f32::tanh,
);

impl F32x8 {
    #[inline(always)]
    pub fn splat(v: f32) -> Self {
        Self([v; LANES])
    }
    #[inline(always)]
    pub fn min(self, rhs: Self) -> Self {
        Self(zip(self.0, rhs.0, f32::min))
    }
    #[inline(always)]
    pub fn max(self, rhs: Self) -> Self {
        Self(zip(self.0, rhs.0, f32::max))
    }
    #[inline(always)]
    pub fn atan2(self, rhs: Self) -> Self {
        Self(zip(self.0, rhs.0, f32::atan2))
    }
    #[inline(always)]
    pub fn powf(self, rhs: Self) -> Self {
        Self(zip(self.0, rhs.0, f32::powf))
    }
    #[inline(always)]
    pub fn to_i32(self) -> I32x8 {
        I32x8(map(self.0, |a| a as i32))
    }
    #[inline(always)]
    pub fn to_u32(self) -> U32x8 {
        U32x8(map(self.0, |a| a as u32))
    }
    /// Sum of the lanes whose mask is set, added in lane order.
    #[inline(always)]
    pub fn masked_sum(self, m: M32x8) -> f32 {
        // Sequential on purpose: measured faster than a blend + pairwise tree in the lanes
        // bench (the branches are predictable), and the order matches a scalar loop.
        let mut s = 0.0;
        for i in 0..LANES {
            if m.0[i] != 0 {
                s += self.0[i];
            }
        }
        s
    }
    /// Lane `i` of the result is lane `i` of `self`.
    #[inline(always)]
    pub fn lane(self, i: usize) -> f32 {
        self.0[i]
    }
}

impl M32x8 {
    #[inline(always)]
    pub fn splat(v: bool) -> Self {
        Self([mask(v); LANES])
    }
    /// Lane-wise `if self { a } else { b }` as a bit blend: no arithmetic touches the unselected
    /// value, so a NaN there cannot leak.
    #[inline(always)]
    pub fn select_f32(self, a: F32x8, b: F32x8) -> F32x8 {
        let blend =
            |m: u32, (a, b): (f32, f32)| f32::from_bits((m & a.to_bits()) | (!m & b.to_bits()));
        F32x8(zip(self.0, zip(a.0, b.0, |a, b| (a, b)), blend))
    }
    #[inline(always)]
    pub fn select_u32(self, a: U32x8, b: U32x8) -> U32x8 {
        U32x8(zip(self.0, zip(a.0, b.0, |a, b| (a, b)), |m, (a, b)| {
            (m & a) | (!m & b)
        }))
    }
    #[inline(always)]
    pub fn select_i32(self, a: I32x8, b: I32x8) -> I32x8 {
        self.select_u32(a.to_u32(), b.to_u32()).to_i32()
    }
    #[inline(always)]
    pub fn select_mask(self, a: M32x8, b: M32x8) -> M32x8 {
        M32x8(zip(self.0, zip(a.0, b.0, |a, b| (a, b)), |m, (a, b)| {
            (m & a) | (!m & b)
        }))
    }
    #[inline(always)]
    pub fn eq(self, rhs: Self) -> M32x8 {
        M32x8(zip(self.0, rhs.0, |a, b| !(a ^ b)))
    }
    #[inline(always)]
    pub fn ne(self, rhs: Self) -> M32x8 {
        self ^ rhs
    }
    /// 1 where set, 0 elsewhere.
    #[inline(always)]
    pub fn to_u32(self) -> U32x8 {
        U32x8(map(self.0, |a| a & 1))
    }
    #[inline(always)]
    pub fn any(self) -> bool {
        self.0.iter().fold(0, |acc, &m| acc | m) != 0
    }
    #[inline(always)]
    pub fn all(self) -> bool {
        self.0.iter().fold(!0, |acc, &m| acc & m) != 0
    }
    /// Number of set lanes.
    #[inline(always)]
    pub fn count(self) -> u32 {
        self.0.iter().map(|m| m & 1).sum()
    }
    /// Lane `i` as a bool.
    #[inline(always)]
    pub fn lane(self, i: usize) -> bool {
        self.0[i] != 0
    }
}

impl BitAnd for M32x8 {
    type Output = M32x8;
    #[inline(always)]
    fn bitand(self, rhs: M32x8) -> M32x8 {
        M32x8(zip(self.0, rhs.0, |a, b| a & b))
    }
}
impl BitOr for M32x8 {
    type Output = M32x8;
    #[inline(always)]
    fn bitor(self, rhs: M32x8) -> M32x8 {
        M32x8(zip(self.0, rhs.0, |a, b| a | b))
    }
}
impl BitXor for M32x8 {
    type Output = M32x8;
    #[inline(always)]
    fn bitxor(self, rhs: M32x8) -> M32x8 {
        M32x8(zip(self.0, rhs.0, |a, b| a ^ b))
    }
}
impl Not for M32x8 {
    type Output = M32x8;
    #[inline(always)]
    fn not(self) -> M32x8 {
        M32x8(map(self.0, |a| !a))
    }
}

impl From<[f32; LANES]> for F32x8 {
    fn from(v: [f32; LANES]) -> Self {
        F32x8(v)
    }
}
impl From<[bool; LANES]> for M32x8 {
    fn from(v: [bool; LANES]) -> Self {
        M32x8(map(v, mask))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn select_takes_the_masked_lane_even_when_the_other_is_nan() {
        let m = M32x8::from([true, false, true, false, true, false, true, false]);
        let a = F32x8::splat(1.0);
        let b = F32x8::splat(f32::NAN);
        let r = m.select_f32(a, b);
        for i in 0..LANES {
            assert_eq!(r.lane(i).is_nan(), i % 2 == 1);
        }
    }

    #[test]
    fn comparisons_and_masks_round_trip() {
        let a = F32x8([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, f32::NAN]);
        let m = a.lt(F32x8::splat(3.0));
        assert_eq!(m.to_u32().0, [1, 1, 1, 0, 0, 0, 0, 0]);
        assert!(m.any() && !m.all());
        assert_eq!(a.masked_sum(m), 3.0);
        assert!(!(!m).eq(m).any());
    }
}
