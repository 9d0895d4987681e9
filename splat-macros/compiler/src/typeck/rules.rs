//! The type rules of the accepted subset: what each literal, operator, cast, member, index,
//! method and constructor accepts and what type it gives. Pure functions of types, read by the
//! type checker (which reports their errors) and by lowering (which builds the components of a
//! value whose type the rule gave). A rule that accepts what lowering cannot build is a bug
//! that the unit tests of both stages catch.

use crate::ir::{Binary, Const, Scalar, Unary};
use crate::types::Ty;
use std::ops::Range;

/// What a method, constructor or helper expects of one argument.
#[derive(Clone, Debug)]
pub enum Arg {
    /// A value of this type; the text names it in a mismatch (`None`: the callee's default,
    /// such as "the argument of `min`").
    Is(Ty, Option<String>),
    /// An integer whose value lowering needs at compile time; the text is the error when the
    /// argument is not an integer (lowering reports one that is not a constant).
    Integer(String),
}

/// The signature of a method or constructor: its arguments and its result.
#[derive(Clone, Debug)]
pub struct Sig {
    pub args: Vec<Arg>,
    pub ret: Ty,
}

fn sig(args: Vec<Arg>, ret: Ty) -> Option<Sig> {
    Some(Sig { args, ret })
}

/// Whether `name` swizzles a `Vec{n}` (`xy`, `zyx`, ...).
pub fn is_swizzle(n: usize, name: &str) -> bool {
    (2..=4).contains(&name.len()) && name.chars().all(|c| "xyzw"[..n].contains(c))
}

/// The method `name` on a receiver of type `recv` (but the camera's, which are helpers).
pub fn method(recv: &Ty, name: &str) -> Option<Sig> {
    use Ty::*;
    let same = || Arg::Is(recv.clone(), None);
    let float = |what: &str| Arg::Is(F32, Some(what.to_string()));
    match (recv, name) {
        (F32, _) if Unary::method(name, false).is_some() => sig(vec![], F32),
        (F32, "log2" | "log10" | "to_radians" | "to_degrees") => sig(vec![], F32),
        (F32 | U32 | I32 | Vec(_), "min" | "max") => sig(vec![same()], recv.clone()),
        (F32 | Vec(_), "clamp") => sig(vec![same(), same()], recv.clone()),
        (F32, "atan2" | "powf" | "hypot") => sig(vec![same()], F32),
        (F32, "powi") => {
            let msg = "the exponent of `powi` must be a compile-time integer";
            sig(vec![Arg::Integer(msg.into())], F32)
        }
        (F32, "mul_add") => sig(vec![same(), same()], F32),
        (F32, "sin_cos") => sig(vec![], Tuple(vec![F32, F32])),
        (Vec(_) | Quat, "dot") => sig(vec![same()], F32),
        (Vec(3), "cross") => sig(vec![same()], Vec(3)),
        (Vec(_) | Quat, "length" | "length_squared") => sig(vec![], F32),
        (Vec(_) | Quat, "normalize" | "normalize_or_zero") => sig(vec![], recv.clone()),
        (Vec(_), "distance" | "distance_squared") => sig(vec![same()], F32),
        (Vec(_), _) if Unary::method(name, true).is_some() => sig(vec![], recv.clone()),
        (Vec(_), "powf") => sig(vec![float("the exponent")], recv.clone()),
        (Vec(_), "lerp") => sig(
            vec![same(), float("the interpolation factor")],
            recv.clone(),
        ),
        (Vec(_), "min_element" | "max_element" | "element_sum" | "element_product") => {
            sig(vec![], F32)
        }
        (Vec(n), "extend") if *n < 4 => sig(vec![float("the new component")], Vec(n + 1)),
        (Vec(n), "truncate") if *n > 2 => sig(vec![], Vec(n - 1)),
        (Vec(n), s) if is_swizzle(*n, s) => sig(vec![], Vec(s.len())),
        (Mat(_), "transpose" | "inverse") => sig(vec![], recv.clone()),
        (Mat(_), "determinant") => sig(vec![], F32),
        (Mat(n), "col" | "row") => {
            let msg = format!("`{name}` needs a compile-time index below {n}");
            sig(vec![Arg::Integer(msg)], Vec(*n))
        }
        (Mat(2), "mul_vec2") | (Mat(3), "mul_vec3") => {
            let Mat(n) = recv else { unreachable!() };
            sig(vec![Arg::Is(Vec(*n), Some("the vector".into()))], Vec(*n))
        }
        (Mat(2), "mul_mat2") | (Mat(3), "mul_mat3") => sig(vec![same()], recv.clone()),
        (Mat(_), "mul_scalar") => sig(vec![float("the scalar")], recv.clone()),
        (Quat, "conjugate" | "inverse") => sig(vec![], Quat),
        (Quat, "mul_vec3") => sig(vec![Arg::Is(Vec(3), Some("the vector".into()))], Vec(3)),
        (I32, "abs") => sig(vec![], I32),
        _ => None,
    }
}

/// Every method name some receiver has, but the unary operations' (which `ops` lists) and
/// the swizzles: what suggestions for a misspelt method are drawn from.
const METHOD_NAMES: &[&str] = &[
    "log2",
    "log10",
    "to_radians",
    "to_degrees",
    "min",
    "max",
    "clamp",
    "atan2",
    "powf",
    "powi",
    "mul_add",
    "sin_cos",
    "hypot",
    "dot",
    "cross",
    "length",
    "length_squared",
    "normalize",
    "normalize_or_zero",
    "distance",
    "distance_squared",
    "lerp",
    "min_element",
    "max_element",
    "element_sum",
    "element_product",
    "extend",
    "truncate",
    "transpose",
    "determinant",
    "inverse",
    "col",
    "row",
    "mul_vec2",
    "mul_vec3",
    "mul_mat2",
    "mul_mat3",
    "mul_scalar",
    "conjugate",
    "abs",
];

/// The methods a receiver of type `t` has (but swizzles), sorted.
pub fn method_names(t: &Ty) -> Vec<&'static str> {
    let candidates = METHOD_NAMES
        .iter()
        .copied()
        .chain(Unary::method_names(false));
    let mut names: Vec<&'static str> = candidates.filter(|n| method(t, n).is_some()).collect();
    names.sort_unstable();
    names.dedup();
    names
}

/// What was probably meant by an unknown method `name` on `t`: a method of `t` that other
/// libraries spell `name`, or one within two edits of it.
pub fn suggestion(t: &Ty, name: &str) -> Option<&'static str> {
    const OTHER_SPELLINGS: &[(&str, &str)] = &[
        ("magnitude", "length"),
        ("norm", "length"),
        ("len", "length"),
        ("mag", "length"),
        ("squared_length", "length_squared"),
        ("magnitude_squared", "length_squared"),
        ("norm_squared", "length_squared"),
        ("normalise", "normalize"),
        ("normalized", "normalize"),
        ("unit", "normalize"),
        ("cross_product", "cross"),
        ("dot_product", "dot"),
        ("det", "determinant"),
        ("transposed", "transpose"),
        ("inverted", "inverse"),
        ("pow", "powf"),
        ("log", "ln"),
        ("conj", "conjugate"),
    ];
    let names = method_names(t);
    let spelled = OTHER_SPELLINGS.iter().find(|(other, _)| *other == name);
    if let Some(&(_, ours)) = spelled.filter(|(_, ours)| names.contains(ours)) {
        return Some(ours);
    }
    let nearest = names
        .into_iter()
        .map(|n| (crate::diag::edit_distance(n, name), n));
    nearest.min().filter(|(d, _)| *d <= 2).map(|(_, n)| n)
}

/// Free functions that stand for a method of their first argument.
pub const FREE_AS_METHOD: &[(&str, &str)] = &[
    ("exp", "exp"),
    ("log", "ln"),
    ("ln", "ln"),
    ("log1p", "ln_1p"),
    ("sqrt", "sqrt"),
    ("abs", "abs"),
    ("min", "min"),
    ("max", "max"),
    ("clamp", "clamp"),
    ("sin", "sin"),
    ("cos", "cos"),
    ("tan", "tan"),
    ("atan2", "atan2"),
    ("dot", "dot"),
    ("cross", "cross"),
    ("length", "length"),
    ("normalize", "normalize"),
    ("transpose", "transpose"),
    ("inverse", "inverse"),
    ("determinant", "determinant"),
];

/// The method the free function `name` stands for.
pub fn free_as_method(name: &str) -> Option<&'static str> {
    FREE_AS_METHOD
        .iter()
        .find(|(f, _)| *f == name)
        .map(|(_, m)| *m)
}

pub const INTRINSIC_LIST: &str = "exp, log/ln, log1p, sqrt, rsqrt, erf, abs, min, max, clamp, select, sin, \
    cos, tan, atan2, dot, cross, length, normalize, transpose, inverse, determinant, sigmoid, no_diff, \
    spherical_harmonics, jacobian, and the camera methods project_point, pixel_ray, can_project, center";

/// The types whose methods may be called as paths (`f32::max(a, b)`).
const PATH_OWNERS: &[&str] = &[
    "f32", "u32", "i32", "Vec2", "Vec3", "Vec4", "Mat2", "Mat3", "Quat",
];

/// A call `owner::item(..)`.
pub enum Path {
    Constructor(Sig),
    /// A method called as a path: the first argument is the receiver.
    Method,
}

/// The function `owner::item`.
pub fn path_call(owner: &str, item: &str) -> Option<Path> {
    use Ty::*;
    let all = |n: usize, t: Ty, ret: Ty| {
        let args = vec![Arg::Is(t, None); n];
        Some(Path::Constructor(Sig { args, ret }))
    };
    let size = |prefix: &str| owner[prefix.len()..].parse::<usize>().ok();
    match (owner, item) {
        ("Vec2" | "Vec3" | "Vec4", "new") => {
            let n = size("Vec")?;
            all(n, F32, Vec(n))
        }
        ("Vec2" | "Vec3" | "Vec4", "splat") => all(1, F32, Vec(size("Vec")?)),
        ("Mat2" | "Mat3", "from_cols") => {
            let n = size("Mat")?;
            all(n, Vec(n), Mat(n))
        }
        ("Mat2" | "Mat3", "from_diagonal") => {
            let n = size("Mat")?;
            all(1, Vec(n), Mat(n))
        }
        ("Mat3", "from_quat") => all(1, Quat, Mat(3)),
        ("Quat", "from_xyzw") => all(4, F32, Quat),
        (o, _) if PATH_OWNERS.contains(&o) => Some(Path::Method),
        _ => None,
    }
}

/// `Vec3::ZERO`, `Mat3::IDENTITY`, `f32::consts::PI`, `f32::EPSILON`, ...: the type and the
/// components of an associated constant.
pub fn assoc_const(owner: &str, item: &str) -> Option<(Ty, Vec<Const>)> {
    let fl = |x: f64| Some((Ty::F32, vec![Const::F(x)]));
    let floats = |ty: Ty, xs: Vec<f64>| Some((ty, xs.into_iter().map(Const::F).collect()));
    match (owner, item) {
        ("consts", c) => fl(match c {
            "PI" => std::f64::consts::PI,
            "TAU" => std::f64::consts::TAU,
            "E" => std::f64::consts::E,
            "FRAC_PI_2" => std::f64::consts::FRAC_PI_2,
            "FRAC_PI_4" => std::f64::consts::FRAC_PI_4,
            "FRAC_1_PI" => std::f64::consts::FRAC_1_PI,
            "SQRT_2" => std::f64::consts::SQRT_2,
            "LN_2" => std::f64::consts::LN_2,
            _ => return None,
        }),
        ("f32", "EPSILON") => fl(f32::EPSILON as f64),
        ("f32", "MAX") => fl(f32::MAX as f64),
        ("f32", "MIN") => fl(f32::MIN as f64),
        ("f32", "MIN_POSITIVE") => fl(f32::MIN_POSITIVE as f64),
        ("f32", "INFINITY") => fl(f64::INFINITY),
        ("f32", "NEG_INFINITY") => fl(f64::NEG_INFINITY),
        ("u32", "MAX") => Some((Ty::U32, vec![Const::U(u32::MAX)])),
        (v, c) if v.starts_with("Vec") => {
            let n: usize = v[3..].parse().ok().filter(|n| (2..=4).contains(n))?;
            let mut out = vec![0.0; n];
            match c {
                "ZERO" => {}
                "ONE" => out.fill(1.0),
                "X" | "Y" | "Z" | "W" | "NEG_X" | "NEG_Y" | "NEG_Z" | "NEG_W" => {
                    let axis = ["X", "Y", "Z", "W"].iter().position(|a| c.ends_with(a))?;
                    *out.get_mut(axis)? = if c.starts_with("NEG") { -1.0 } else { 1.0 };
                }
                _ => return None,
            }
            floats(Ty::Vec(n), out)
        }
        ("Mat2" | "Mat3", c) => {
            let n = if owner == "Mat2" { 2 } else { 3 };
            let mut out = vec![0.0; n * n];
            match c {
                "ZERO" => {}
                "IDENTITY" => (0..n).for_each(|i| out[i * n + i] = 1.0),
                _ => return None,
            }
            floats(Ty::Mat(n), out)
        }
        ("Quat", "IDENTITY") => floats(Ty::Quat, vec![0.0, 0.0, 0.0, 1.0]),
        _ => None,
    }
}

/// A literal's type and value, or the error it is.
pub fn literal(l: &syn::Lit) -> Result<(Ty, Const), syn::Error> {
    let err = |span, msg: &str| Err(syn::Error::new(span, msg));
    let float = |digits: &str, span| match digits.parse::<f64>() {
        Ok(x) => Ok((Ty::F32, Const::F(x))),
        Err(e) => Err(syn::Error::new(span, e)),
    };
    match l {
        syn::Lit::Float(f) if f.suffix() == "f64" => err(
            f.span(),
            "`f64` literals are not supported: write f32 (the f64 twin is generated)",
        ),
        syn::Lit::Float(f) => float(f.base10_digits(), f.span()),
        syn::Lit::Int(i) => match i.suffix() {
            "" | "usize" => Ok((Ty::Index, Const::U(i.base10_parse()?))),
            "u32" => Ok((Ty::U32, Const::U(i.base10_parse()?))),
            "i32" => Ok((Ty::I32, Const::I(i.base10_parse()?))),
            "f32" => float(i.base10_digits(), i.span()),
            other => err(
                i.span(),
                &format!("integer type `{other}` is not supported"),
            ),
        },
        syn::Lit::Bool(b) => Ok((Ty::Bool, Const::B(b.value))),
        other => err(
            other.span(),
            "only numeric and boolean literals are supported",
        ),
    }
}

/// Whether a value of type `from` may stand where `to` is expected: equal types, an integer
/// literal where a `u32` or `i32` is, and anything that already failed (no cascades).
pub fn coerces(from: &Ty, to: &Ty) -> bool {
    from == to
        || matches!((from, to), (Ty::Index, Ty::U32 | Ty::I32))
        || *from == Ty::Error
        || *to == Ty::Error
}

/// The operation `op` computes (for `x += y`, that of `+`), its spelling in messages, and
/// whether it assigns (`+=`).
pub fn binary_op(op: &syn::BinOp) -> Option<(Binary, &'static str, bool)> {
    use syn::BinOp::*;
    let (b, sym) = match op {
        Add(_) | AddAssign(_) => (Binary::Add, "+"),
        Sub(_) | SubAssign(_) => (Binary::Sub, "-"),
        Mul(_) | MulAssign(_) => (Binary::Mul, "*"),
        Div(_) | DivAssign(_) => (Binary::Div, "/"),
        Rem(_) | RemAssign(_) => (Binary::Rem, "%"),
        And(_) => (Binary::And, "&&"),
        Or(_) => (Binary::Or, "||"),
        BitAnd(_) | BitAndAssign(_) => (Binary::And, "&"),
        BitOr(_) | BitOrAssign(_) => (Binary::Or, "|"),
        BitXor(_) | BitXorAssign(_) => (Binary::Xor, "^"),
        Shl(_) | ShlAssign(_) => (Binary::Shl, "<<"),
        Shr(_) | ShrAssign(_) => (Binary::Shr, ">>"),
        Eq(_) => (Binary::Eq, "=="),
        Lt(_) => (Binary::Lt, "<"),
        Le(_) => (Binary::Le, "<="),
        Ne(_) => (Binary::Ne, "!="),
        Ge(_) => (Binary::Ge, ">="),
        Gt(_) => (Binary::Gt, ">"),
        _ => return None,
    };
    let compound = matches!(
        op,
        AddAssign(_)
            | SubAssign(_)
            | MulAssign(_)
            | DivAssign(_)
            | RemAssign(_)
            | BitXorAssign(_)
            | BitAndAssign(_)
            | BitOrAssign(_)
            | ShlAssign(_)
            | ShrAssign(_)
    );
    Some((b, sym, compound))
}

/// The operand types of `l op r` once an integer literal takes the other side's integer type.
pub fn binary_operands(l: &Ty, r: &Ty) -> (Ty, Ty) {
    match (l, r) {
        (Ty::Index, Ty::U32 | Ty::I32) => (r.clone(), r.clone()),
        (Ty::U32 | Ty::I32, Ty::Index) => (l.clone(), l.clone()),
        _ => (l.clone(), r.clone()),
    }
}

/// The type of `l op r` for operands already through [`binary_operands`].
pub fn binary(op: Binary, l: &Ty, r: &Ty) -> Option<Ty> {
    use Binary::*;
    use Ty::*;
    let arith = matches!(op, Add | Sub | Mul | Div | Rem);
    let integer = |t: &Ty| matches!(t, U32 | I32 | Index);
    Some(match (l, r) {
        (F32, F32) if arith => F32,
        (a, b) if a == b && integer(a) && (arith || matches!(op, And | Or | Xor | Shl | Shr)) => {
            a.clone()
        }
        (Bool, Bool) if matches!(op, And | Or | Xor) => Bool,
        (a, b) if a == b && (integer(a) || *a == F32) && op.is_comparison() => Bool,
        (Bool, Bool) if matches!(op, Eq | Ne) => Bool,
        (Vec(a), Vec(b)) if a == b && arith => l.clone(),
        (Vec(_), F32) if arith => l.clone(),
        (F32, Vec(_)) if arith => r.clone(),
        (Mat(a), Mat(b)) if a == b && matches!(op, Add | Sub | Mul) => l.clone(),
        (Mat(a), Vec(b)) if a == b && op == Mul => r.clone(),
        (Mat(_), F32) if matches!(op, Mul | Div) => l.clone(),
        (F32, Mat(_)) if op == Mul => r.clone(),
        (Quat, Vec(3)) if op == Mul => r.clone(),
        (Quat, Quat) if matches!(op, Add | Sub | Mul) => Quat,
        (Quat, F32) if matches!(op, Mul | Div) => Quat,
        _ => return None,
    })
}

/// The error for `l sym r` that [`binary`] refused.
pub fn binary_error(sym: &str, l: &Ty, r: &Ty) -> String {
    let mixed = matches!(
        (l, r),
        (Ty::F32, Ty::U32 | Ty::I32 | Ty::Index) | (Ty::U32 | Ty::I32 | Ty::Index, Ty::F32)
    );
    let hint = match mixed {
        true => "; convert the integer with `as f32` (and write float literals with a dot: `2.0`)",
        false => "",
    };
    format!("mismatched types: cannot apply `{sym}` to `{l}` and `{r}`{hint}")
}

/// The type of `-x`: an integer literal becomes an `i32`.
pub fn neg(t: &Ty) -> Option<Ty> {
    match t {
        Ty::F32 | Ty::Vec(_) | Ty::Mat(_) | Ty::Quat | Ty::I32 => Some(t.clone()),
        Ty::Index => Some(Ty::I32),
        _ => None,
    }
}

/// Whether `!x` applies to `t`.
pub fn not(t: &Ty) -> bool {
    matches!(t, Ty::Bool | Ty::U32 | Ty::I32)
}

/// What `as T` converts to: a scalar, or `usize` (a compile-time index).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CastTo {
    Scalar(Scalar),
    Index,
}

/// The target of `as T`, or the error (at the type).
pub fn cast_target(t: &syn::Type) -> Result<CastTo, String> {
    let name = match t {
        syn::Type::Path(p) => p.path.get_ident().map(|i| i.to_string()),
        _ => None,
    };
    let Some(name) = name else {
        return Err("only casts between f32, u32, i32, usize and bool are supported".into());
    };
    Ok(match name.as_str() {
        "f32" => CastTo::Scalar(Scalar::F32),
        "u32" => CastTo::Scalar(Scalar::U32),
        "i32" => CastTo::Scalar(Scalar::I32),
        "usize" => CastTo::Index,
        other => return Err(format!("casts to `{other}` are not supported")),
    })
}

/// The type of `x as T` for `x: from`, or the error.
pub fn cast(from: &Ty, to: CastTo) -> Result<Ty, String> {
    let scalar = matches!(from, Ty::F32 | Ty::U32 | Ty::I32 | Ty::Index | Ty::Bool);
    match to {
        CastTo::Index if matches!(from, Ty::U32 | Ty::I32 | Ty::Index) => Ok(Ty::Index),
        CastTo::Index => Err("`as usize` needs a value known at compile time".into()),
        _ if !scalar => Err(format!("cannot cast a `{from}`")),
        CastTo::Scalar(Scalar::F32) if *from == Ty::Bool => {
            Err("cannot cast `bool` to `f32`: use `select(b, 1.0, 0.0)`".into())
        }
        CastTo::Scalar(s) => Ok(Ty::scalar(s)),
    }
}

/// The type and component range of `ty.member` (struct field, vector component, matrix
/// column, tuple element).
pub fn member(ty: &Ty, member: &str) -> Option<(Ty, Range<usize>)> {
    match ty {
        Ty::Struct(s) => {
            let mut at = 0;
            for (name, t) in &s.fields {
                let n = t.slot_count();
                if name == member {
                    return Some((t.clone(), at..at + n));
                }
                at += n;
            }
            None
        }
        Ty::Vec(_) | Ty::Quat => {
            let n = if let Ty::Vec(n) = ty { *n } else { 4 };
            let i = ["x", "y", "z", "w"]
                .iter()
                .take(n)
                .position(|c| *c == member)?;
            Some((Ty::F32, i..i + 1))
        }
        Ty::Mat(n) => {
            let i = ["x_axis", "y_axis", "z_axis"]
                .iter()
                .take(*n)
                .position(|c| *c == member)?;
            Some((Ty::Vec(*n), i * n..(i + 1) * n))
        }
        Ty::Tuple(ts) => {
            let i: usize = member.parse().ok()?;
            let at: usize = ts.iter().take(i).map(Ty::slot_count).sum();
            let t = ts.get(i)?;
            Some((t.clone(), at..at + t.slot_count()))
        }
        _ => None,
    }
}

/// The type of `x[i]` for `x: ty` (array element, vector component).
pub fn element(ty: &Ty) -> Option<Ty> {
    match ty {
        Ty::Array(t, _) => Some((**t).clone()),
        Ty::Vec(_) => Some(Ty::F32),
        _ => None,
    }
}

/// The component range of `x[i]` for `x: ty`, if `i` is in bounds.
pub fn index_range(ty: &Ty, i: usize) -> Option<Range<usize>> {
    let k = element(ty)?.slot_count();
    let n = match ty {
        Ty::Array(_, n) => *n,
        Ty::Vec(n) => *n,
        _ => unreachable!("element() accepted it"),
    };
    (i < n).then(|| i * k..(i + 1) * k)
}

/// Whether `jacobian` differentiates at, and maps to, a value of type `t`.
pub fn differentiable(t: &Ty) -> bool {
    matches!(t, Ty::F32 | Ty::Vec(2..=4))
}

/// The type of `jacobian(|p| body, x)`: the body's value and its Jacobian, one gradient (of
/// `x`'s type) per component of the value.
pub fn jacobian(x: &Ty, value: &Ty) -> Ty {
    let rows = Ty::Array(Box::new(x.clone()), value.slot_count());
    Ty::Tuple(vec![value.clone(), rows])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_listed_method_name_belongs_to_some_receiver() {
        let receivers = [
            Ty::F32,
            Ty::U32,
            Ty::I32,
            Ty::Vec(2),
            Ty::Vec(3),
            Ty::Vec(4),
            Ty::Mat(2),
            Ty::Mat(3),
            Ty::Quat,
        ];
        for name in METHOD_NAMES {
            assert!(
                receivers.iter().any(|t| method(t, name).is_some()),
                "`{name}` is listed but no receiver has it"
            );
        }
    }

    #[test]
    fn integer_literals_take_the_other_operands_integer_type() {
        let (l, r) = binary_operands(&Ty::Index, &Ty::I32);
        assert_eq!((l, r), (Ty::I32, Ty::I32));
        assert_eq!(binary(Binary::Shl, &Ty::U32, &Ty::U32), Some(Ty::U32));
        assert_eq!(binary(Binary::Add, &Ty::F32, &Ty::Index), None);
        assert!(binary_error("+", &Ty::Index, &Ty::F32).contains("as f32"));
        assert!(!binary_error("+", &Ty::Vec(2), &Ty::Vec(3)).contains("as f32"));
    }
}
