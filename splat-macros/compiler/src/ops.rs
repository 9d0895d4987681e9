//! What the compiler knows about each operation, kept in one place (as naga keeps the facts
//! about an expression on the expression): for a unary operation the method or function users
//! call, whether glam has it on vectors, how the Rust and the WGSL compute it; for unary and
//! binary operations their derivative, which the reverse sweep (`ad`) and the in-kernel
//! Jacobians (`lower::jacobian`) both build from the same rule; for a binary operation its
//! Rust and WGSL spelling. The tables and the rules are exhaustive `match`es: a new `ir::Unary`
//! or `ir::Binary` variant does not compile until it has a row and a rule, and a named row is
//! callable at once ([`Unary::named`] iterates the variants). A new unary operation also needs
//! `F32x8`'s method of the same name in the runtime (the SIMD kernels call it); where WGSL has
//! no built-in, its form in `emit::naga` (this module's test emits every operation on every
//! operand type, and fails until it has one); where std has none, `splat_runtime::math`
//! functions; and for a free function, its place in the error message's
//! `typeck::rules::INTRINSIC_LIST`.

use crate::ir::{Binary, Const, Op, Unary, Var};
use naga::{BinaryOperator, MathFunction};
use strum::IntoEnumIterator;

/// How the generated code computes a unary operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct UnaryInfo {
    /// The `f32` method users call (`x.exp()`); `None` for operators, for free functions and
    /// for operations only the lowering builds.
    pub method: Option<&'static str>,
    /// The free function users call (`erf(x)`, in `splat_runtime::prelude`) where there is no
    /// method (std has none, or it is unstable).
    pub function: Option<&'static str>,
    /// glam has the method on vectors too, component by component.
    pub on_vectors: bool,
    /// How the generated Rust computes it.
    pub rust: Rust,
    /// The WGSL built-in computing it as the Rust does; `None` where `emit::naga` spells it
    /// out (`ln_1p`, `erf`, `rsqrt`, `recip`, Rust's rounding, `fract` and `signum`).
    pub wgsl: Option<MathFunction>,
}

/// How the generated Rust computes an operation named `name` (its method or function name).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rust {
    /// `x.name()` in every form (`f32`, the `f64` twin, `F32x8` lanes).
    Std,
    /// `splat_runtime::math::name(x)` in `f32` (branch-free, shared with the lanes' `x.name()`
    /// so scalar and lane kernels round alike), std's `x.name()` in the `f64` twin.
    RuntimeF32,
    /// `splat_runtime::math::name(x)` in `f32` and `name_f64(x)` in the twin (std has none).
    Runtime,
    /// Spelled out by `emit::body` (operators, `rsqrt`, `recip`, casts).
    Custom,
}

const fn method(name: &'static str, wgsl: Option<MathFunction>) -> UnaryInfo {
    UnaryInfo {
        method: Some(name),
        function: None,
        on_vectors: false,
        rust: Rust::Std,
        wgsl,
    }
}

const fn function(name: &'static str, rust: Rust) -> UnaryInfo {
    UnaryInfo {
        method: None,
        function: Some(name),
        on_vectors: false,
        rust,
        wgsl: None,
    }
}

const BUILT: UnaryInfo = UnaryInfo {
    method: None,
    function: None,
    on_vectors: false,
    rust: Rust::Custom,
    wgsl: None,
};

impl UnaryInfo {
    const fn on_vectors(self) -> Self {
        UnaryInfo {
            on_vectors: true,
            ..self
        }
    }

    const fn rust(self, rust: Rust) -> Self {
        UnaryInfo { rust, ..self }
    }

    /// The name the generated Rust calls it by.
    pub fn name(self) -> &'static str {
        self.method.or(self.function).expect("a named operation")
    }
}

impl Unary {
    /// The operations users call by name, in the order of `ir::Unary`'s variants.
    pub fn named() -> impl Iterator<Item = Unary> {
        Unary::iter().filter(|u| u.info().method.is_some() || u.info().function.is_some())
    }

    pub fn info(self) -> UnaryInfo {
        use MathFunction as M;
        match self {
            Unary::Neg | Unary::Not | Unary::NoDiff | Unary::Cast(_) => BUILT,
            Unary::Exp => method("exp", Some(M::Exp))
                .on_vectors()
                .rust(Rust::RuntimeF32),
            Unary::Ln => method("ln", Some(M::Log)).rust(Rust::RuntimeF32),
            Unary::Ln1p => method("ln_1p", None).rust(Rust::RuntimeF32),
            Unary::Sqrt => method("sqrt", Some(M::Sqrt)),
            Unary::Rsqrt => function("rsqrt", Rust::Custom),
            Unary::Recip => method("recip", None).on_vectors().rust(Rust::Custom),
            Unary::Erf => function("erf", Rust::Runtime),
            Unary::Abs => method("abs", Some(M::Abs)).on_vectors(),
            Unary::Sin => method("sin", Some(M::Sin)),
            Unary::Cos => method("cos", Some(M::Cos)),
            Unary::Tan => method("tan", Some(M::Tan)),
            Unary::Asin => method("asin", Some(M::Asin)),
            Unary::Acos => method("acos", Some(M::Acos)),
            Unary::Atan => method("atan", Some(M::Atan)),
            Unary::Tanh => method("tanh", Some(M::Tanh)),
            Unary::Floor => method("floor", Some(M::Floor)).on_vectors(),
            Unary::Ceil => method("ceil", Some(M::Ceil)).on_vectors(),
            Unary::Round => method("round", None).on_vectors(),
            Unary::Trunc => method("trunc", Some(M::Trunc)).on_vectors(),
            Unary::Fract => method("fract", None).on_vectors(),
            Unary::Signum => method("signum", None).on_vectors(),
        }
    }

    /// The operation users call as the method `name` on an `f32` (`vector`: on a vector).
    pub fn method(name: &str, vector: bool) -> Option<Unary> {
        Unary::named().find(|u| u.info().method == Some(name) && (!vector || u.info().on_vectors))
    }

    /// The operation users call as the free function `name`.
    pub fn function(name: &str) -> Option<Unary> {
        Unary::named().find(|u| u.info().function == Some(name))
    }

    /// The method names (`vector`: those glam has on vectors).
    pub fn method_names(vector: bool) -> impl Iterator<Item = &'static str> {
        Unary::named()
            .filter(move |u| !vector || u.info().on_vectors)
            .filter_map(|u| u.info().method)
    }
}

/// How the generated code computes a binary operation. What differs by operand type the
/// emitters special-case before reaching the table: in Rust, integer `+ - * / %` wrap (a zero
/// divisor gives 0) and scalar shifts wrap their count; in WGSL, integer `/ %` give 0 for a
/// zero divisor too, shift counts are masked to 0..32, and booleans' `& | ^` are logical.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BinaryInfo {
    /// The Rust spelling: `x + y` for an operator (as users write it, but `&&` and `||`,
    /// which the generated code writes `&` and `|`), `x.min(y)` for a method.
    pub rust: Spelling,
    /// For a comparison (and only for one: its result is a `bool`), the `F32x8` method
    /// comparing lanes into a mask.
    pub comparison: Option<&'static str>,
    /// The WGSL computing it.
    pub wgsl: Wgsl,
}

/// How Rust writes a binary operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Spelling {
    Operator(&'static str),
    Method(&'static str),
}

/// How WGSL writes a binary operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wgsl {
    Operator(BinaryOperator),
    Function(MathFunction),
}

impl Binary {
    pub fn info(self) -> BinaryInfo {
        use BinaryOperator as O;
        use MathFunction as M;
        let op = |rust, wgsl| BinaryInfo {
            rust: Spelling::Operator(rust),
            comparison: None,
            wgsl: Wgsl::Operator(wgsl),
        };
        let method = |rust, wgsl| BinaryInfo {
            rust: Spelling::Method(rust),
            comparison: None,
            wgsl: Wgsl::Function(wgsl),
        };
        let cmp = |rust, lanes, wgsl| BinaryInfo {
            comparison: Some(lanes),
            ..op(rust, wgsl)
        };
        match self {
            Binary::Add => op("+", O::Add),
            Binary::Sub => op("-", O::Subtract),
            Binary::Mul => op("*", O::Multiply),
            Binary::Div => op("/", O::Divide),
            Binary::Rem => op("%", O::Modulo),
            Binary::Min => method("min", M::Min),
            Binary::Max => method("max", M::Max),
            Binary::Atan2 => method("atan2", M::Atan2),
            Binary::Powf => method("powf", M::Pow),
            Binary::And => op("&", O::And),
            Binary::Or => op("|", O::InclusiveOr),
            Binary::Xor => op("^", O::ExclusiveOr),
            Binary::Shl => op("<<", O::ShiftLeft),
            Binary::Shr => op(">>", O::ShiftRight),
            Binary::Lt => cmp("<", "lt", O::Less),
            Binary::Le => cmp("<=", "le", O::LessEqual),
            Binary::Gt => cmp(">", "gt", O::Greater),
            Binary::Ge => cmp(">=", "ge", O::GreaterEqual),
            Binary::Eq => cmp("==", "eq", O::Equal),
            Binary::Ne => cmp("!=", "ne", O::NotEqual),
        }
    }

    pub fn is_comparison(self) -> bool {
        self.info().comparison.is_some()
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

/// An [`Emit`] that writes each distinct operation once, so the parts of a binary rule share
/// what they have in common (a quotient, a guard's comparison) as a hand-written rule would.
pub struct Shared<'a, E> {
    pub inner: &'a mut E,
    seen: Vec<(Op, Var)>,
}

impl<'a, E: Emit> Shared<'a, E> {
    pub fn new(inner: &'a mut E) -> Self {
        Shared {
            inner,
            seen: vec![],
        }
    }

    fn once(&mut self, op: Op, emit: impl FnOnce(&mut E) -> Var) -> Var {
        if let Some((_, v)) = self.seen.iter().find(|(o, _)| *o == op) {
            return *v;
        }
        let v = emit(self.inner);
        self.seen.push((op, v));
        v
    }
}

impl<E: Emit> Emit for Shared<'_, E> {
    fn konst(&mut self, x: f64) -> Var {
        self.once(Op::Const(Const::F(x)), |e| e.konst(x))
    }
    fn un(&mut self, u: Unary, a: Var, name: &str) -> Var {
        self.once(Op::Unary(u, a), |e| e.un(u, a, name))
    }
    fn bin(&mut self, b: Binary, x: Var, y: Var, name: &str) -> Var {
        self.once(Op::Binary(b, x, y), |e| e.bin(b, x, y, name))
    }
    fn select(&mut self, c: Var, x: Var, y: Var, name: &str) -> Var {
        self.once(Op::Select(c, x, y), |e| e.select(c, x, y, name))
    }
}

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
        U::Erf => {
            // 2 / sqrt(pi) e^(-a^2)
            let a2 = e.bin(B::Mul, a, a, "a2");
            let n = e.un(U::Neg, a2, "neg_a2");
            let g = e.un(U::Exp, n, "gauss");
            let k = e.konst(std::f64::consts::FRAC_2_SQRT_PI);
            let q = e.bin(B::Mul, d, k, out);
            e.bin(B::Mul, q, g, out)
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

/// `d` times the partial derivative of `r = x b y` by operand `operand` (0: `x`, 1: `y`), where
/// `d` is that operand's tangent (forward: the tangent of `r` sums both) or the adjoint of `r`
/// (reverse: each operand receives its own). `None` where it is zero (comparisons and bit
/// operations have no float result).
#[allow(clippy::too_many_arguments)]
pub fn binary_derivative(
    e: &mut impl Emit,
    b: Binary,
    x: Var,
    y: Var,
    r: Var,
    operand: usize,
    d: Var,
) -> Option<Var> {
    use Binary as B;
    use Unary as U;
    let out = DERIVATIVE;
    let first = operand == 0;
    Some(match b {
        B::Add => d,
        B::Sub if first => d,
        B::Sub => e.un(U::Neg, d, out),
        B::Mul => e.bin(B::Mul, d, if first { y } else { x }, out),
        B::Div => {
            let q = e.bin(B::Div, d, y, out);
            let q = match first {
                true => q,
                false => {
                    let qr = e.bin(B::Mul, q, r, out);
                    e.un(U::Neg, qr, out)
                }
            };
            guarded(e, y, B::Ne, 0.0, q, "nz")
        }
        B::Rem if first => d,
        B::Rem => {
            let q = e.bin(B::Div, x, y, "q");
            let t = e.un(U::Trunc, q, "q");
            let dt = e.bin(B::Mul, d, t, out);
            let n = e.un(U::Neg, dt, out);
            guarded(e, y, B::Ne, 0.0, n, "nz")
        }
        B::Min | B::Max => {
            // Ties go to the first operand.
            let cmp = if b == B::Min { B::Le } else { B::Ge };
            let x_wins = e.bin(cmp, x, y, "first");
            let z = e.konst(0.0);
            match first {
                true => e.select(x_wins, d, z, out),
                false => e.select(x_wins, z, d, out),
            }
        }
        B::Atan2 => {
            // atan2(x, y): (dx y - x dy) / (x^2 + y^2), zero at the origin.
            let x2 = e.bin(B::Mul, x, x, "x2");
            let y2 = e.bin(B::Mul, y, y, "y2");
            let den = e.bin(B::Add, x2, y2, "den");
            let q = e.bin(B::Mul, d, if first { y } else { x }, out);
            let q = e.bin(B::Div, q, den, out);
            let q = if first { q } else { e.un(U::Neg, q, out) };
            guarded(e, den, B::Gt, 0.0, q, "pos")
        }
        // x^y: y r / x (zero at x = 0) and r ln x (zero for x <= 0).
        B::Powf if first => {
            let dy = e.bin(B::Mul, d, y, out);
            let dyr = e.bin(B::Mul, dy, r, out);
            let q = e.bin(B::Div, dyr, x, out);
            guarded(e, x, B::Ne, 0.0, q, "nz")
        }
        B::Powf => {
            let l = e.un(U::Ln, x, "ln");
            let dr = e.bin(B::Mul, d, r, out);
            let q = e.bin(B::Mul, dr, l, out);
            guarded(e, x, B::Gt, 0.0, q, "pos")
        }
        B::And
        | B::Or
        | B::Xor
        | B::Shl
        | B::Shr
        | B::Lt
        | B::Le
        | B::Gt
        | B::Ge
        | B::Eq
        | B::Ne => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ir::Scalar;

    #[test]
    fn every_operation_is_found_by_its_name_and_only_vector_ones_on_vectors() {
        for u in Unary::named() {
            let info = u.info();
            if let Some(name) = info.method {
                assert_eq!(Unary::method(name, false), Some(u), "{name}");
                let on_vectors = Unary::method(name, true) == Some(u);
                assert_eq!(on_vectors, info.on_vectors, "{name}");
            }
            if let Some(name) = info.function {
                assert_eq!(Unary::function(name), Some(u), "{name}");
                assert!(!info.on_vectors, "{name}: functions take an f32");
            }
            assert!(info.method.is_some() != info.function.is_some(), "{u:?}");
        }
        assert_eq!(Unary::method("nope", false), None);
    }

    /// The operand types the lowering applies `op` to.
    fn operand_types(op: &Op) -> Vec<Scalar> {
        use crate::ir::Scalar::*;
        use Binary as B;
        use Unary as U;
        match op {
            Op::Unary(U::Not, _) => vec![Bool, U32, I32],
            Op::Unary(U::Neg | U::Abs, _) => vec![F32, I32],
            Op::Unary(U::Cast(_), _) => Scalar::iter().collect(),
            Op::Unary(..) => vec![F32],
            Op::Binary(B::Atan2 | B::Powf, ..) => vec![F32],
            Op::Binary(B::Shl | B::Shr, ..) => vec![U32, I32],
            Op::Binary(B::And | B::Or | B::Xor, ..) => vec![Bool, U32, I32],
            Op::Binary(B::Eq | B::Ne, ..) => vec![F32, Bool, U32, I32],
            Op::Binary(..) => vec![F32, U32, I32],
            Op::Const(_) | Op::Select(..) => unreachable!("not an operation of a table"),
        }
    }

    /// Every operation, on every operand type the lowering gives it, through both emitters: a
    /// new operation WGSL has no built-in for fails here until `emit::naga` spells it out, and
    /// the Rust of each flavor must parse as statements (whether its methods exist is for the
    /// codegen tests, which compile the methods).
    #[test]
    fn every_operation_emits_wgsl_and_rust() {
        use crate::emit::body::{BodyEmitter, Flavor};
        use crate::ir::{Function, Stmt};
        let (x, y) = (Var(0), Var(1));
        let casts = Scalar::iter().map(|t| Op::Unary(Unary::Cast(t), x));
        let unary = (Unary::iter())
            .filter(|u| !matches!(u, Unary::Cast(_)))
            .map(|u| Op::Unary(u, x));
        let binary = Binary::iter().map(|b| Op::Binary(b, x, y));
        for op in casts.chain(unary).chain(binary) {
            for ty in operand_types(&op) {
                let mut f = Function::new("t");
                f.params = vec![f.new_var(ty, "x"), f.new_var(ty, "y")];
                let r = f.new_var(op.result_ty(|_| ty), "r");
                f.body.stmts.push(Stmt::Let {
                    var: r,
                    op: op.clone(),
                });
                f.body.yields.push(r);
                if let Err(e) = crate::emit::naga::wgsl(&[(&f, vec!["r".into()])]) {
                    panic!("{op:?} on {ty:?}: {e}");
                }
                for flavor in [Flavor::F32, Flavor::F64, Flavor::Lanes] {
                    let body = BodyEmitter::new(&f, flavor, &[]).block(&f.body);
                    let parsed = syn::parse2::<syn::Block>(quote::quote!({ #body }));
                    assert!(
                        parsed.is_ok_and(|b| !b.stmts.is_empty()),
                        "{op:?} on {ty:?} ({flavor:?}): {body}"
                    );
                }
            }
        }
    }
}
