//! What the compiler knows about each unary operation, kept in one place (as naga keeps the
//! facts about an expression on the expression): the method users call, whether glam has it
//! on vectors, how the Rust and the WGSL compute it, and its derivative, which both the
//! reverse sweep (`ad`) and the in-kernel Jacobians (`lower::jacobian`) build from the same
//! rule. Every table here is an exhaustive `match`: a new `ir::Unary` variant does not compile
//! until it has a row and a rule. Beyond this file it needs only `F32x8`'s method of the same
//! name in the runtime (the SIMD kernels call it).

use crate::ir::{Binary, Unary, Var};
use naga::MathFunction;

/// How the generated code computes a unary operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct UnaryInfo {
    /// The `f32` method users call (`x.exp()`) and the emitted Rust calls; `None` for
    /// operators and for operations only the lowering builds.
    pub method: Option<&'static str>,
    /// glam has the method on vectors too, component by component.
    pub on_vectors: bool,
    /// The generated `f32` Rust calls `splat_runtime::math`'s version (shared with the SIMD
    /// lanes, so a scalar and a lane kernel round alike) instead of `std`'s.
    pub runtime_math: bool,
    /// The WGSL built-in computing it exactly as the Rust does; `None` where `emit::naga`
    /// spells it out (`ln_1p`, `rsqrt`, `recip`, Rust's rounding and `fract` and `signum`).
    pub wgsl: Option<MathFunction>,
}

const fn op(method: &'static str, wgsl: Option<MathFunction>) -> UnaryInfo {
    UnaryInfo {
        method: Some(method),
        on_vectors: false,
        runtime_math: false,
        wgsl,
    }
}

const BUILT: UnaryInfo = UnaryInfo {
    method: None,
    on_vectors: false,
    runtime_math: false,
    wgsl: None,
};

impl UnaryInfo {
    const fn on_vectors(self) -> Self {
        UnaryInfo {
            on_vectors: true,
            ..self
        }
    }

    const fn runtime_math(self) -> Self {
        UnaryInfo {
            runtime_math: true,
            ..self
        }
    }
}

impl Unary {
    /// The operations users call as `f32` methods, in the order suggestions list them.
    pub const METHODS: [Unary; 19] = [
        Unary::Exp,
        Unary::Ln,
        Unary::Ln1p,
        Unary::Sqrt,
        Unary::Recip,
        Unary::Abs,
        Unary::Sin,
        Unary::Cos,
        Unary::Tan,
        Unary::Asin,
        Unary::Acos,
        Unary::Atan,
        Unary::Tanh,
        Unary::Floor,
        Unary::Ceil,
        Unary::Round,
        Unary::Trunc,
        Unary::Fract,
        Unary::Signum,
    ];

    pub fn info(self) -> UnaryInfo {
        use MathFunction as M;
        match self {
            Unary::Neg | Unary::Not | Unary::NoDiff | Unary::Rsqrt | Unary::Cast(_) => BUILT,
            Unary::Exp => op("exp", Some(M::Exp)).on_vectors().runtime_math(),
            Unary::Ln => op("ln", Some(M::Log)).runtime_math(),
            Unary::Ln1p => op("ln_1p", None).runtime_math(),
            Unary::Sqrt => op("sqrt", Some(M::Sqrt)),
            Unary::Recip => op("recip", None).on_vectors(),
            Unary::Abs => op("abs", Some(M::Abs)).on_vectors(),
            Unary::Sin => op("sin", Some(M::Sin)),
            Unary::Cos => op("cos", Some(M::Cos)),
            Unary::Tan => op("tan", Some(M::Tan)),
            Unary::Asin => op("asin", Some(M::Asin)),
            Unary::Acos => op("acos", Some(M::Acos)),
            Unary::Atan => op("atan", Some(M::Atan)),
            Unary::Tanh => op("tanh", Some(M::Tanh)),
            Unary::Floor => op("floor", Some(M::Floor)).on_vectors(),
            Unary::Ceil => op("ceil", Some(M::Ceil)).on_vectors(),
            Unary::Round => op("round", None).on_vectors(),
            Unary::Trunc => op("trunc", Some(M::Trunc)).on_vectors(),
            Unary::Fract => op("fract", None).on_vectors(),
            Unary::Signum => op("signum", None).on_vectors(),
        }
    }

    /// The operation users call as the method `name` on an `f32` (`vector`: on a vector).
    pub fn method(name: &str, vector: bool) -> Option<Unary> {
        Unary::METHODS
            .into_iter()
            .find(|u| u.info().method == Some(name) && (!vector || u.info().on_vectors))
    }

    /// The method names of [`Unary::METHODS`] (`vector`: those glam has on vectors).
    pub fn method_names(vector: bool) -> impl Iterator<Item = &'static str> {
        (Unary::METHODS.into_iter())
            .filter(move |u| !vector || u.info().on_vectors)
            .filter_map(|u| u.info().method)
    }
}

/// What a derivative rule writes its operations with: the reverse sweep and the tangent
/// builder each append them to their own code. `name` is a readable name for the result;
/// [`DERIVATIVE`] names the rule's own result (the builder knows whose derivative it is).
pub trait Emit {
    fn konst(&mut self, x: f64) -> Var;
    fn un(&mut self, u: Unary, a: Var, name: &str) -> Var;
    fn bin(&mut self, b: Binary, x: Var, y: Var, name: &str) -> Var;
    fn select(&mut self, c: Var, x: Var, y: Var, name: &str) -> Var;
}

/// The name a rule gives its result.
pub const DERIVATIVE: &str = "";

/// `value` where `v cmp k`, zero elsewhere: the kink rule, a zero derivative where the true
/// one is infinite or undefined.
fn guarded(e: &mut impl Emit, v: Var, cmp: Binary, k: f64, value: Var, name: &str) -> Var {
    let k = e.konst(k);
    let ok = e.bin(cmp, v, k, name);
    let z = e.konst(0.0);
    e.select(ok, value, z, DERIVATIVE)
}

/// `d` times the derivative of `r = u(a)`, where `d` is a tangent of `a` (forward) or the
/// adjoint of `r` (reverse): one linear rule serves both. `None` where the derivative is zero
/// (piecewise constants, casts, `no_diff`).
pub fn unary_derivative(e: &mut impl Emit, u: Unary, a: Var, r: Var, d: Var) -> Option<Var> {
    use Binary as B;
    use Unary as U;
    let out = DERIVATIVE;
    Some(match u {
        U::NoDiff | U::Floor | U::Ceil | U::Round | U::Trunc | U::Signum | U::Cast(_) | U::Not => {
            return None;
        }
        U::Neg => e.un(U::Neg, d, out),
        U::Fract => d,
        U::Exp => e.bin(B::Mul, d, r, out),
        U::Ln => {
            let q = e.bin(B::Div, d, a, out);
            guarded(e, a, B::Gt, 0.0, q, "pos")
        }
        U::Ln1p => {
            let one = e.konst(1.0);
            let den = e.bin(B::Add, one, a, "den");
            let q = e.bin(B::Div, d, den, out);
            guarded(e, a, B::Gt, -1.0, q, "ok")
        }
        U::Sqrt => {
            let half = e.konst(0.5);
            let h = e.bin(B::Mul, half, d, out);
            let q = e.bin(B::Div, h, r, out);
            guarded(e, a, B::Gt, 0.0, q, "pos")
        }
        U::Rsqrt => {
            let k = e.konst(-0.5);
            let r2 = e.bin(B::Mul, r, r, "r2");
            let r3 = e.bin(B::Mul, r2, r, "r3");
            let kd = e.bin(B::Mul, k, d, out);
            let q = e.bin(B::Mul, kd, r3, out);
            guarded(e, a, B::Gt, 0.0, q, "pos")
        }
        U::Recip => {
            let r2 = e.bin(B::Mul, r, r, "r2");
            let q = e.bin(B::Mul, d, r2, out);
            let q = e.un(U::Neg, q, out);
            guarded(e, a, B::Ne, 0.0, q, "nz")
        }
        U::Abs => {
            let z = e.konst(0.0);
            let nonneg = e.bin(B::Ge, a, z, "nonneg");
            let neg = e.un(U::Neg, d, out);
            e.select(nonneg, d, neg, out)
        }
        U::Sin => {
            let c = e.un(U::Cos, a, "cos");
            e.bin(B::Mul, d, c, out)
        }
        U::Cos => {
            let s = e.un(U::Sin, a, "sin");
            let q = e.bin(B::Mul, d, s, out);
            e.un(U::Neg, q, out)
        }
        U::Tan | U::Tanh => {
            let one = e.konst(1.0);
            let r2 = e.bin(B::Mul, r, r, "r2");
            let k = match u {
                U::Tan => e.bin(B::Add, one, r2, "sec2"),
                _ => e.bin(B::Sub, one, r2, "sech2"),
            };
            e.bin(B::Mul, d, k, out)
        }
        U::Atan => {
            let one = e.konst(1.0);
            let a2 = e.bin(B::Mul, a, a, "a2");
            let den = e.bin(B::Add, one, a2, "den");
            e.bin(B::Div, d, den, out)
        }
        U::Asin | U::Acos => {
            let one = e.konst(1.0);
            let a2 = e.bin(B::Mul, a, a, "a2");
            let t = e.bin(B::Sub, one, a2, "t");
            let s = e.un(U::Sqrt, t, "s");
            let q = e.bin(B::Div, d, s, out);
            let q = if u == U::Acos {
                e.un(U::Neg, q, out)
            } else {
                q
            };
            guarded(e, t, B::Gt, 0.0, q, "inside")
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_method_is_found_by_its_name_and_only_vector_ones_on_vectors() {
        for u in Unary::METHODS {
            let name = u.info().method.expect("a method has a name");
            assert_eq!(Unary::method(name, false), Some(u), "{name}");
            let on_vectors = Unary::method(name, true) == Some(u);
            assert_eq!(on_vectors, u.info().on_vectors, "{name}");
        }
        assert_eq!(Unary::method("nope", false), None);
    }
}
