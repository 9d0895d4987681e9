//! Method calls on the supported types and the free intrinsic functions, lowered to scalar IR.
//!
//! The rules at kinks and singular points (the "Derivative rules" table of
//! `splat-macros/README.md`): `normalize(0) = 0` with zero gradient; `length` and `sqrt` have
//! zero gradient at 0; `min`/`max`/`clamp` send the gradient to the first argument on ties;
//! division, `recip`, `ln`, `rsqrt`, `asin`, `acos`, `atan2` and `powf` have zero gradient
//! where the derivative is infinite; `select` and `if` differentiate only the side taken.

use super::{Failed, Lowerer, R, Val};
use crate::builtins::{SH_COEFFICIENTS, camera_helper, model_aware, sh_helper, shutter_aware};
use crate::ir::{Binary, Const, Unary, Var};
use crate::types::Ty;
use proc_macro2::Span;
use syn::spanned::Spanned;

/// The methods [`Lowerer::method`] accepts on a receiver of type `t` (for suggestions; a
/// unit test checks that each is accepted).
pub(crate) fn method_names(t: &Ty) -> Vec<&'static str> {
    let vector_and_quat = [
        "dot",
        "length",
        "length_squared",
        "normalize",
        "normalize_or_zero",
    ];
    let mut names: Vec<&'static str> = match t {
        Ty::F32 => {
            let own = [
                "log2",
                "log10",
                "to_radians",
                "to_degrees",
                "min",
                "max",
                "clamp",
            ];
            let more = ["atan2", "powf", "powi", "mul_add", "sin_cos", "hypot"];
            let unary = Unary::method_names(false);
            own.into_iter().chain(more).chain(unary).collect()
        }
        Ty::U32 => vec!["min", "max"],
        Ty::I32 => vec!["min", "max", "abs"],
        Ty::Vec(n) => {
            let own = [
                "min",
                "max",
                "clamp",
                "distance",
                "distance_squared",
                "powf",
                "lerp",
            ];
            let reductions = [
                "min_element",
                "max_element",
                "element_sum",
                "element_product",
            ];
            let sized = [(*n == 3, "cross"), (*n < 4, "extend"), (*n > 2, "truncate")];
            let unary = Unary::method_names(true);
            (own.into_iter()
                .chain(reductions)
                .chain(vector_and_quat)
                .chain(unary))
            .chain(sized.into_iter().filter(|(on, _)| *on).map(|(_, n)| n))
            .collect()
        }
        Ty::Mat(n) => {
            let own = [
                "transpose",
                "determinant",
                "inverse",
                "col",
                "row",
                "mul_scalar",
            ];
            let sized = if *n == 2 {
                ["mul_vec2", "mul_mat2"]
            } else {
                ["mul_vec3", "mul_mat3"]
            };
            own.into_iter().chain(sized).collect()
        }
        Ty::Quat => {
            let own = ["conjugate", "inverse", "mul_vec3"];
            vector_and_quat.into_iter().chain(own).collect()
        }
        _ => vec![],
    };
    names.sort_unstable();
    names.dedup();
    names
}

/// What was probably meant by an unknown method `name` on `t`: a method of `t` that other
/// libraries spell `name`, or one within two edits of it.
fn suggestion(t: &Ty, name: &str) -> Option<&'static str> {
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

/// Free functions and the method they stand for (receiver = first argument).
const FREE_AS_METHOD: &[(&str, &str)] = &[
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

pub const INTRINSIC_LIST: &str = "exp, log/ln, log1p, sqrt, rsqrt, erf, abs, min, max, clamp, select, sin, \
    cos, tan, atan2, dot, cross, length, normalize, transpose, inverse, determinant, sigmoid, no_diff, \
    spherical_harmonics, jacobian, and the camera methods project_point, pixel_ray, can_project, center";

impl Lowerer<'_> {
    fn f(&self, v: &Val) -> Var {
        v.comps[0]
    }

    fn scalar(v: Var) -> Val {
        Val {
            ty: Ty::F32,
            comps: vec![v],
        }
    }

    fn args_of(
        &mut self,
        args: &syn::punctuated::Punctuated<syn::Expr, syn::Token![,]>,
    ) -> R<Vec<Val>> {
        let vals: Vec<R<Val>> = args.iter().map(|a| self.expr(a)).collect();
        vals.into_iter().collect()
    }

    pub(super) fn method_call(&mut self, m: &syn::ExprMethodCall) -> R<Val> {
        if m.turbofish.is_some() {
            return self.err(m.span(), "turbofish arguments are not supported");
        }
        let recv = self.expr(&m.receiver)?;
        let args = self.args_of(&m.args)?;
        let name = m.method.to_string();
        self.method(&name, recv, args, m.method.span(), &m.args)
    }

    fn method(
        &mut self,
        name: &str,
        recv: Val,
        args: Vec<Val>,
        span: Span,
        arg_exprs: &syn::punctuated::Punctuated<syn::Expr, syn::Token![,]>,
    ) -> R<Val> {
        let want = |s: &Self, n: usize| -> R<()> {
            if args.len() == n {
                Ok(())
            } else {
                s.err(
                    span,
                    format!("`{name}` takes {n} argument(s), found {}", args.len()),
                )
            }
        };
        let same =
            |s: &Self, a: &Val| s.check_ty(a, &recv.ty, span, &format!("the argument of `{name}`"));
        match (&recv.ty, name) {
            (Ty::Error, _) => Err(Failed),
            (Ty::Struct(s), _) if s.display == "Camera" && camera_helper(name).is_some() => {
                let helper = camera_helper(name).unwrap();
                let def = self
                    .module
                    .find_fn(&helper)
                    .expect("builtin camera helpers are in every module");
                self.camera_model |= model_aware(name);
                self.rolling_shutter |= shutter_aware(name);
                let mut all = vec![recv];
                all.extend(args);
                self.call_helper(def, all, span)
            }
            (Ty::F32, _) if let Some(op) = Unary::method(name, false) => {
                want(self, 0)?;
                Ok(self.map(&recv, op))
            }
            (Ty::F32, "log2" | "log10") => {
                want(self, 0)?;
                let l = self.un(Unary::Ln, self.f(&recv));
                let k = if name == "log2" {
                    std::f64::consts::LOG2_E
                } else {
                    std::f64::consts::LOG10_E
                };
                let k = self.fconst(k);
                Ok(Self::scalar(self.bin(Binary::Mul, l, k)))
            }
            (Ty::F32, "to_radians" | "to_degrees") => {
                want(self, 0)?;
                let k = if name == "to_radians" {
                    std::f64::consts::PI / 180.0
                } else {
                    180.0 / std::f64::consts::PI
                };
                let k = self.fconst(k);
                Ok(Self::scalar(self.bin(Binary::Mul, self.f(&recv), k)))
            }
            (Ty::F32 | Ty::U32 | Ty::I32 | Ty::Vec(_), "min" | "max") => {
                want(self, 1)?;
                same(self, &args[0])?;
                let op = if name == "min" {
                    Binary::Min
                } else {
                    Binary::Max
                };
                let comps = recv
                    .comps
                    .iter()
                    .zip(&args[0].comps)
                    .map(|(&a, &b)| self.bin(op, a, b))
                    .collect();
                Ok(Val {
                    ty: recv.ty.clone(),
                    comps,
                })
            }
            (Ty::F32 | Ty::Vec(_), "clamp") => {
                want(self, 2)?;
                same(self, &args[0])?;
                same(self, &args[1])?;
                let comps = (0..recv.comps.len())
                    .map(|i| {
                        let lo = self.bin(Binary::Max, recv.comps[i], args[0].comps[i]);
                        self.bin(Binary::Min, lo, args[1].comps[i])
                    })
                    .collect();
                Ok(Val {
                    ty: recv.ty.clone(),
                    comps,
                })
            }
            (Ty::F32, "atan2" | "powf") => {
                want(self, 1)?;
                same(self, &args[0])?;
                let op = if name == "atan2" {
                    Binary::Atan2
                } else {
                    Binary::Powf
                };
                Ok(Self::scalar(self.bin(op, self.f(&recv), self.f(&args[0]))))
            }
            (Ty::F32, "powi") => {
                want(self, 1)?;
                let Some(n) = self.int_const(&args[0]) else {
                    return self.err(
                        arg_exprs[0].span(),
                        "the exponent of `powi` must be a compile-time integer",
                    );
                };
                Ok(Self::scalar(self.powi(self.f(&recv), n)))
            }
            (Ty::F32, "mul_add") => {
                want(self, 2)?;
                same(self, &args[0])?;
                same(self, &args[1])?;
                let p = self.bin(Binary::Mul, self.f(&recv), self.f(&args[0]));
                Ok(Self::scalar(self.bin(Binary::Add, p, self.f(&args[1]))))
            }
            (Ty::F32, "sin_cos") => {
                want(self, 0)?;
                let s = self.un(Unary::Sin, self.f(&recv));
                let c = self.un(Unary::Cos, self.f(&recv));
                Ok(Val {
                    ty: Ty::Tuple(vec![Ty::F32, Ty::F32]),
                    comps: vec![s, c],
                })
            }
            (Ty::F32, "hypot") => {
                want(self, 1)?;
                let v = Val {
                    ty: Ty::Vec(2),
                    comps: vec![self.f(&recv), self.f(&args[0])],
                };
                Ok(self.length(&v))
            }
            (Ty::Vec(_) | Ty::Quat, "dot") => {
                want(self, 1)?;
                same(self, &args[0])?;
                Ok(Self::scalar(self.dot(&recv.comps, &args[0].comps)))
            }
            (Ty::Vec(3), "cross") => {
                want(self, 1)?;
                same(self, &args[0])?;
                Ok(self.cross(&recv, &args[0]))
            }
            (Ty::Vec(_) | Ty::Quat, "length") => {
                want(self, 0)?;
                Ok(self.length(&recv))
            }
            (Ty::Vec(_) | Ty::Quat, "length_squared") => {
                want(self, 0)?;
                Ok(Self::scalar(self.dot(&recv.comps, &recv.comps)))
            }
            (Ty::Vec(_) | Ty::Quat, "normalize" | "normalize_or_zero") => {
                want(self, 0)?;
                Ok(self.normalize(&recv))
            }
            (Ty::Vec(_), "distance" | "distance_squared") => {
                want(self, 1)?;
                same(self, &args[0])?;
                let d = self.binary(Binary::Sub, "-", recv.clone(), args[0].clone(), span)?;
                if name == "distance" {
                    Ok(self.length(&d))
                } else {
                    Ok(Self::scalar(self.dot(&d.comps, &d.comps)))
                }
            }
            (Ty::Vec(_), _) if let Some(op) = Unary::method(name, true) => {
                want(self, 0)?;
                Ok(self.map(&recv, op))
            }
            (Ty::Vec(_), "powf") => {
                want(self, 1)?;
                self.check_ty(&args[0], &Ty::F32, span, "the exponent")?;
                let e = self.f(&args[0]);
                let comps = recv
                    .comps
                    .iter()
                    .map(|&c| self.bin(Binary::Powf, c, e))
                    .collect();
                Ok(Val {
                    ty: recv.ty.clone(),
                    comps,
                })
            }
            (Ty::Vec(_), "lerp") => {
                want(self, 2)?;
                same(self, &args[0])?;
                self.check_ty(&args[1], &Ty::F32, span, "the interpolation factor")?;
                let t = self.f(&args[1]);
                let comps = recv
                    .comps
                    .iter()
                    .zip(&args[0].comps)
                    .map(|(&a, &b)| {
                        let d = self.bin(Binary::Sub, b, a);
                        let s = self.bin(Binary::Mul, d, t);
                        self.bin(Binary::Add, a, s)
                    })
                    .collect();
                Ok(Val {
                    ty: recv.ty.clone(),
                    comps,
                })
            }
            (Ty::Vec(_), "min_element" | "max_element" | "element_sum" | "element_product") => {
                want(self, 0)?;
                let op = match name {
                    "min_element" => Binary::Min,
                    "max_element" => Binary::Max,
                    "element_sum" => Binary::Add,
                    _ => Binary::Mul,
                };
                let mut acc = recv.comps[0];
                for &c in &recv.comps[1..] {
                    acc = self.bin(op, acc, c);
                }
                Ok(Self::scalar(acc))
            }
            (Ty::Vec(n), "extend") if *n < 4 => {
                want(self, 1)?;
                self.check_ty(&args[0], &Ty::F32, span, "the new component")?;
                let mut comps = recv.comps.clone();
                comps.push(self.f(&args[0]));
                Ok(Val {
                    ty: Ty::Vec(n + 1),
                    comps,
                })
            }
            (Ty::Vec(n), "truncate") if *n > 2 => {
                want(self, 0)?;
                Ok(Val {
                    ty: Ty::Vec(n - 1),
                    comps: recv.comps[..n - 1].to_vec(),
                })
            }
            (Ty::Vec(n), s)
                if (2..=4).contains(&s.len()) && s.chars().all(|c| "xyzw"[..*n].contains(c)) =>
            {
                want(self, 0)?;
                let comps = s
                    .chars()
                    .map(|c| recv.comps["xyzw".find(c).unwrap()])
                    .collect();
                Ok(Val {
                    ty: Ty::Vec(s.len()),
                    comps,
                })
            }
            (Ty::Mat(_), "transpose") => {
                want(self, 0)?;
                Ok(self.transpose(&recv))
            }
            (Ty::Mat(_), "determinant") => {
                want(self, 0)?;
                Ok(Self::scalar(self.determinant(&recv)))
            }
            (Ty::Mat(_), "inverse") => {
                want(self, 0)?;
                Ok(self.inverse(&recv))
            }
            (Ty::Mat(n), "col" | "row") => {
                want(self, 1)?;
                let Some(i) = self.int_const(&args[0]).filter(|i| (*i as usize) < *n) else {
                    return self.err(
                        span,
                        format!("`{name}` needs a compile-time index below {n}"),
                    );
                };
                let i = i as usize;
                let comps = (0..*n)
                    .map(|k| {
                        if name == "col" {
                            recv.comps[i * n + k]
                        } else {
                            recv.comps[k * n + i]
                        }
                    })
                    .collect();
                Ok(Val {
                    ty: Ty::Vec(*n),
                    comps,
                })
            }
            (Ty::Mat(n), "mul_vec2" | "mul_vec3") => {
                want(self, 1)?;
                self.check_ty(&args[0], &Ty::Vec(*n), span, "the vector")?;
                Ok(self.mat_vec(&recv, &args[0]))
            }
            (Ty::Mat(_), "mul_mat2" | "mul_mat3") => {
                want(self, 1)?;
                same(self, &args[0])?;
                Ok(self.mat_mul(&recv, &args[0]))
            }
            (Ty::Mat(_), "mul_scalar") => {
                want(self, 1)?;
                self.binary(Binary::Mul, "*", recv.clone(), args[0].clone(), span)
            }
            (Ty::Quat, "conjugate" | "inverse") => {
                want(self, 0)?;
                let mut comps = recv.comps.clone();
                for c in comps.iter_mut().take(3) {
                    *c = self.un(Unary::Neg, *c);
                }
                Ok(Val {
                    ty: Ty::Quat,
                    comps,
                })
            }
            (Ty::Quat, "mul_vec3") => {
                want(self, 1)?;
                self.check_ty(&args[0], &Ty::Vec(3), span, "the vector")?;
                Ok(self.quat_rotate(&recv, &args[0]))
            }
            (Ty::I32, "abs") => {
                want(self, 0)?;
                let z = self.konst(Const::I(0));
                let neg = self.bin(Binary::Lt, recv.comps[0], z);
                let n = self.un(Unary::Neg, recv.comps[0]);
                Ok(Val {
                    ty: Ty::I32,
                    comps: vec![self.select(neg, n, recv.comps[0])],
                })
            }
            (t, _) => {
                let hint = match suggestion(t, name) {
                    Some(s) => format!(": did you mean `{s}`?"),
                    None => " (see the intrinsic list in the splat-macros docs)".to_string(),
                };
                self.err(
                    span,
                    format!("no method `{name}` on `{t}` in the supported subset{hint}"),
                )
            }
        }
    }

    fn int_const(&self, v: &Val) -> Option<i64> {
        match self.const_of(*v.comps.first()?)? {
            Const::U(x) => Some(x as i64),
            Const::I(x) => Some(x as i64),
            _ => None,
        }
    }

    pub(super) fn call(&mut self, c: &syn::ExprCall) -> R<Val> {
        let syn::Expr::Path(p) = &*c.func else {
            return self.err(c.func.span(), "only calls of named functions are supported");
        };
        let segs: Vec<String> = p
            .path
            .segments
            .iter()
            .map(|s| s.ident.to_string())
            .collect();
        let span = p.span();
        if segs.len() == 1 {
            let name = segs[0].as_str();
            if let Some(b) = self.lookup(name) {
                if b.val.ty == Ty::Error {
                    return Err(Failed);
                }
                return self.err(span, format!("`{name}` is a value, not a function"));
            }
            if let Some(def) = self.module.find_fn(name) {
                let args = self.args_of(&c.args)?;
                return self.call_helper(def, args, span);
            }
            return self.free_intrinsic(name, c, span);
        }
        let (owner, item) = (segs[segs.len() - 2].as_str(), segs[segs.len() - 1].as_str());
        let args = self.args_of(&c.args)?;
        self.constructor(owner, item, args, span, c)
    }

    fn free_intrinsic(&mut self, name: &str, c: &syn::ExprCall, span: Span) -> R<Val> {
        match name {
            "select" => {
                if c.args.len() != 3 {
                    return self.err(span, "`select(cond, a, b)` takes 3 arguments");
                }
                let cond = self.expr(&c.args[0])?;
                self.check_ty(
                    &cond,
                    &Ty::Bool,
                    c.args[0].span(),
                    "the condition of `select`",
                )?;
                self.lazy_select(cond.comps[0], &c.args[1], &c.args[2], span)
            }
            _ if matches!(name, "no_diff" | "sigmoid") || Unary::function(name).is_some() => {
                let args = self.args_of(&c.args)?;
                if args.len() != 1 {
                    return self.err(span, format!("`{name}` takes 1 argument"));
                }
                let v = &args[0];
                match name {
                    "no_diff" => Ok(self.map(v, Unary::NoDiff)),
                    _ if v.ty != Ty::F32 => {
                        self.err(span, format!("`{name}` takes an `f32`, found `{}`", v.ty))
                    }
                    "sigmoid" => Ok(Self::scalar(self.sigmoid(v.comps[0]))),
                    _ => Ok(self.map(v, Unary::function(name).expect("a function"))),
                }
            }
            "jacobian" => self.jacobian(c, span),
            "spherical_harmonics" => {
                let args = self.args_of(&c.args)?;
                let n = match args.first().map(|a| &a.ty) {
                    Some(Ty::Array(t, n)) if **t == Ty::Vec(3) && SH_COEFFICIENTS.contains(n) => *n,
                    _ => {
                        return self.err(
                            span,
                            "`spherical_harmonics(sh, dir)` takes `[Vec3; N]` with N = 1, 4, 9 or 16 (degree 0 to 3) and a `Vec3`",
                        );
                    }
                };
                let def = self
                    .module
                    .find_fn(&sh_helper(n))
                    .expect("builtin SH helpers are in every module");
                self.call_helper(def, args, span)
            }
            _ => {
                if let Some((_, m)) = FREE_AS_METHOD.iter().find(|(f, _)| *f == name) {
                    let mut args = self.args_of(&c.args)?;
                    if args.is_empty() {
                        return self.err(span, format!("`{name}` needs an argument"));
                    }
                    let recv = args.remove(0);
                    return self.method(m, recv, args, span, &c.args);
                }
                self.err(
                    span,
                    format!(
                        "cannot find function `{name}`: a kernel may call helpers of the same module and the \
                         intrinsics {INTRINSIC_LIST}"
                    ),
                )
            }
        }
    }

    /// `select(c, a, b)`: the operands are lowered inside the two sides of a branch, so only
    /// the chosen one is differentiated (no NaN leaks from the other side).
    fn lazy_select(&mut self, cond: Var, a: &syn::Expr, b: &syn::Expr, span: Span) -> R<Val> {
        if let Some(Const::B(k)) = self.const_of(cond) {
            return self.expr(if k { a } else { b });
        }
        self.branch(cond, |s| s.expr(a), |s| s.expr(b), span)
    }

    fn constructor(
        &mut self,
        owner: &str,
        item: &str,
        args: Vec<Val>,
        span: Span,
        c: &syn::ExprCall,
    ) -> R<Val> {
        let all = |s: &Self, t: &Ty| -> R<()> {
            for a in &args {
                s.check_ty(a, t, span, &format!("an argument of `{owner}::{item}`"))?;
            }
            Ok(())
        };
        let count = |s: &Self, n: usize| -> R<()> {
            if args.len() == n {
                Ok(())
            } else {
                s.err(
                    span,
                    format!(
                        "`{owner}::{item}` takes {n} argument(s), found {}",
                        args.len()
                    ),
                )
            }
        };
        let flat = |args: &[Val]| {
            args.iter()
                .flat_map(|a| a.comps.iter().copied())
                .collect::<Vec<_>>()
        };
        match (owner, item) {
            ("Vec2" | "Vec3" | "Vec4", "new") => {
                let n = owner[3..].parse().unwrap();
                count(self, n)?;
                all(self, &Ty::F32)?;
                Ok(Val {
                    ty: Ty::Vec(n),
                    comps: flat(&args),
                })
            }
            ("Vec2" | "Vec3" | "Vec4", "splat") => {
                let n = owner[3..].parse().unwrap();
                count(self, 1)?;
                all(self, &Ty::F32)?;
                Ok(Val {
                    ty: Ty::Vec(n),
                    comps: vec![args[0].comps[0]; n],
                })
            }
            ("Mat2" | "Mat3", "from_cols") => {
                let n = if owner == "Mat2" { 2 } else { 3 };
                count(self, n)?;
                all(self, &Ty::Vec(n))?;
                Ok(Val {
                    ty: Ty::Mat(n),
                    comps: flat(&args),
                })
            }
            ("Mat2" | "Mat3", "from_diagonal") => {
                let n = if owner == "Mat2" { 2 } else { 3 };
                count(self, 1)?;
                all(self, &Ty::Vec(n))?;
                let z = self.fconst(0.0);
                let mut comps = vec![z; n * n];
                for i in 0..n {
                    comps[i * n + i] = args[0].comps[i];
                }
                Ok(Val {
                    ty: Ty::Mat(n),
                    comps,
                })
            }
            ("Mat3", "from_quat") => {
                count(self, 1)?;
                all(self, &Ty::Quat)?;
                Ok(self.mat3_from_quat(&args[0]))
            }
            ("Quat", "from_xyzw") => {
                count(self, 4)?;
                all(self, &Ty::F32)?;
                Ok(Val {
                    ty: Ty::Quat,
                    comps: flat(&args),
                })
            }
            ("f32" | "u32" | "i32" | "Vec2" | "Vec3" | "Vec4" | "Mat2" | "Mat3" | "Quat", m) => {
                // Method called as a path: `f32::max(a, b)`.
                let mut args = args;
                if args.is_empty() {
                    return self.err(span, format!("`{owner}::{m}` needs an argument"));
                }
                let recv = args.remove(0);
                self.method(m, recv, args, span, &c.args)
            }
            _ => self.err(span, format!("unknown function `{owner}::{item}`")),
        }
    }

    // ---- linear algebra on flattened components ----------------------------------------------

    fn dot(&mut self, a: &[Var], b: &[Var]) -> Var {
        let mut acc = self.bin(Binary::Mul, a[0], b[0]);
        for i in 1..a.len() {
            let p = self.bin(Binary::Mul, a[i], b[i]);
            acc = self.bin(Binary::Add, acc, p);
        }
        acc
    }

    fn length(&mut self, v: &Val) -> Val {
        let d = self.dot(&v.comps, &v.comps);
        Self::scalar(self.un(Unary::Sqrt, d))
    }

    /// `v / |v|`, and 0 for the zero vector (its gradient is then 0 too: the reciprocal length
    /// is selected away before anything multiplies it).
    fn normalize(&mut self, v: &Val) -> Val {
        let d = self.dot(&v.comps, &v.comps);
        let zero = self.fconst(0.0);
        let pos = self.bin(Binary::Gt, d, zero);
        let r = self.un(Unary::Rsqrt, d);
        let inv = self.select(pos, r, zero);
        let comps = v
            .comps
            .iter()
            .map(|&c| self.bin(Binary::Mul, c, inv))
            .collect();
        Val {
            ty: v.ty.clone(),
            comps,
        }
    }

    fn cross(&mut self, a: &Val, b: &Val) -> Val {
        let (a, b) = (&a.comps, &b.comps);
        let mut term = |i: usize, j: usize| {
            let p = self.bin(Binary::Mul, a[i], b[j]);
            let q = self.bin(Binary::Mul, a[j], b[i]);
            self.bin(Binary::Sub, p, q)
        };
        let comps = vec![term(1, 2), term(2, 0), term(0, 1)];
        Val {
            ty: Ty::Vec(3),
            comps,
        }
    }

    pub(super) fn mat_vec(&mut self, m: &Val, v: &Val) -> Val {
        let n = v.comps.len();
        let comps = (0..n)
            .map(|r| {
                let row: Vec<Var> = (0..n).map(|c| m.comps[c * n + r]).collect();
                self.dot(&row, &v.comps)
            })
            .collect();
        Val {
            ty: Ty::Vec(n),
            comps,
        }
    }

    pub(super) fn mat_mul(&mut self, a: &Val, b: &Val) -> Val {
        let Ty::Mat(n) = a.ty else { unreachable!() };
        let mut comps = vec![];
        for c in 0..n {
            for r in 0..n {
                let row: Vec<Var> = (0..n).map(|k| a.comps[k * n + r]).collect();
                let col: Vec<Var> = (0..n).map(|k| b.comps[c * n + k]).collect();
                comps.push(self.dot(&row, &col));
            }
        }
        Val {
            ty: a.ty.clone(),
            comps,
        }
    }

    fn transpose(&mut self, m: &Val) -> Val {
        let Ty::Mat(n) = m.ty else { unreachable!() };
        let comps = (0..n * n).map(|i| m.comps[(i % n) * n + i / n]).collect();
        Val {
            ty: m.ty.clone(),
            comps,
        }
    }

    fn determinant(&mut self, m: &Val) -> Var {
        let c = &m.comps;
        if c.len() == 4 {
            let p = self.bin(Binary::Mul, c[0], c[3]);
            let q = self.bin(Binary::Mul, c[2], c[1]);
            return self.bin(Binary::Sub, p, q);
        }
        let col = |i: usize| Val {
            ty: Ty::Vec(3),
            comps: c[i * 3..i * 3 + 3].to_vec(),
        };
        let x = self.cross(&col(0), &col(1));
        self.dot(&col(2).comps, &x.comps)
    }

    /// Adjugate over determinant, like glam; a singular matrix gives non-finite entries.
    fn inverse(&mut self, m: &Val) -> Val {
        let c = m.comps.clone();
        if c.len() == 4 {
            let det = self.determinant(m);
            let inv = self.un(Unary::Recip, det);
            let adj = [
                c[3],
                self.un(Unary::Neg, c[1]),
                self.un(Unary::Neg, c[2]),
                c[0],
            ];
            let comps = adj.iter().map(|&a| self.bin(Binary::Mul, a, inv)).collect();
            return Val {
                ty: Ty::Mat(2),
                comps,
            };
        }
        let col = |i: usize| Val {
            ty: Ty::Vec(3),
            comps: c[i * 3..i * 3 + 3].to_vec(),
        };
        let t0 = self.cross(&col(1), &col(2));
        let t1 = self.cross(&col(2), &col(0));
        let t2 = self.cross(&col(0), &col(1));
        let det = self.dot(&col(2).comps, &t2.comps);
        let inv = self.un(Unary::Recip, det);
        // Rows of the inverse are t0, t1, t2 (scaled): transpose into columns.
        let rows = [t0.comps, t1.comps, t2.comps];
        let mut comps = vec![];
        for cidx in 0..3 {
            for row in &rows {
                comps.push(self.bin(Binary::Mul, row[cidx], inv));
            }
        }
        Val {
            ty: Ty::Mat(3),
            comps,
        }
    }

    /// Rotation of `v` by quaternion `q` (x, y, z, w): v + w t + u x t with t = 2 u x v.
    pub(super) fn quat_rotate(&mut self, q: &Val, v: &Val) -> Val {
        let u = Val {
            ty: Ty::Vec(3),
            comps: q.comps[..3].to_vec(),
        };
        let w = q.comps[3];
        let uv = self.cross(&u, v);
        let two = self.fconst(2.0);
        let t = Val {
            ty: Ty::Vec(3),
            comps: uv
                .comps
                .iter()
                .map(|&c| self.bin(Binary::Mul, c, two))
                .collect(),
        };
        let ut = self.cross(&u, &t);
        let comps = (0..3)
            .map(|i| {
                let wt = self.bin(Binary::Mul, w, t.comps[i]);
                let s = self.bin(Binary::Add, v.comps[i], wt);
                self.bin(Binary::Add, s, ut.comps[i])
            })
            .collect();
        Val {
            ty: Ty::Vec(3),
            comps,
        }
    }

    /// Hamilton product, (x, y, z, w) layout.
    pub(super) fn quat_mul(&mut self, a: &Val, b: &Val) -> Val {
        let (a, b) = (&a.comps, &b.comps);
        let (ax, ay, az, aw) = (a[0], a[1], a[2], a[3]);
        let (bx, by, bz, bw) = (b[0], b[1], b[2], b[3]);
        let mut sum4 = |terms: [(Var, Var, bool); 4]| {
            let mut acc: Option<Var> = None;
            for (p, q, neg) in terms {
                let m = self.bin(Binary::Mul, p, q);
                acc = Some(match acc {
                    None if neg => self.un(Unary::Neg, m),
                    None => m,
                    Some(s) => self.bin(if neg { Binary::Sub } else { Binary::Add }, s, m),
                });
            }
            acc.unwrap()
        };
        let x = sum4([
            (aw, bx, false),
            (ax, bw, false),
            (ay, bz, false),
            (az, by, true),
        ]);
        let y = sum4([
            (aw, by, false),
            (ax, bz, true),
            (ay, bw, false),
            (az, bx, false),
        ]);
        let z = sum4([
            (aw, bz, false),
            (ax, by, false),
            (ay, bx, true),
            (az, bw, false),
        ]);
        let w = sum4([
            (aw, bw, false),
            (ax, bx, true),
            (ay, by, true),
            (az, bz, true),
        ]);
        Val {
            ty: Ty::Quat,
            comps: vec![x, y, z, w],
        }
    }

    /// The rotation matrix of a unit quaternion (same formula as glam's `Mat3::from_quat`).
    fn mat3_from_quat(&mut self, q: &Val) -> Val {
        let [x, y, z, w] = [q.comps[0], q.comps[1], q.comps[2], q.comps[3]];
        let x2 = self.bin(Binary::Add, x, x);
        let y2 = self.bin(Binary::Add, y, y);
        let z2 = self.bin(Binary::Add, z, z);
        let mut m = |a: Var, b: Var| self.bin(Binary::Mul, a, b);
        let (xx, xy, xz) = (m(x, x2), m(x, y2), m(x, z2));
        let (yy, yz, zz) = (m(y, y2), m(y, z2), m(z, z2));
        let (wx, wy, wz) = (m(w, x2), m(w, y2), m(w, z2));
        let one = self.fconst(1.0);
        let mut add = |a: Var, b: Var| self.bin(Binary::Add, a, b);
        let (yy_zz, xx_zz, xx_yy) = (add(yy, zz), add(xx, zz), add(xx, yy));
        let comps = vec![
            self.bin(Binary::Sub, one, yy_zz),
            self.bin(Binary::Add, xy, wz),
            self.bin(Binary::Sub, xz, wy),
            self.bin(Binary::Sub, xy, wz),
            self.bin(Binary::Sub, one, xx_zz),
            self.bin(Binary::Add, yz, wx),
            self.bin(Binary::Add, xz, wy),
            self.bin(Binary::Sub, yz, wx),
            self.bin(Binary::Sub, one, xx_yy),
        ];
        Val {
            ty: Ty::Mat(3),
            comps,
        }
    }

    /// x^n for a compile-time integer n, by repeated squaring.
    fn powi(&mut self, x: Var, n: i64) -> Var {
        if n == 0 {
            return self.fconst(1.0);
        }
        let mut base = x;
        let mut e = n.unsigned_abs();
        let mut acc: Option<Var> = None;
        while e > 0 {
            if e & 1 == 1 {
                acc = Some(match acc {
                    None => base,
                    Some(a) => self.bin(Binary::Mul, a, base),
                });
            }
            e >>= 1;
            if e > 0 {
                base = self.bin(Binary::Mul, base, base);
            }
        }
        let p = acc.unwrap();
        if n < 0 { self.un(Unary::Recip, p) } else { p }
    }

    /// 1 / (1 + e^-x), computed on the side of 0 where the exponential cannot overflow.
    fn sigmoid(&mut self, x: Var) -> Var {
        let zero = self.fconst(0.0);
        let pos = self.bin(Binary::Ge, x, zero);
        let one = |s: &mut Self| s.fconst(1.0);
        let v = self.branch(
            pos,
            |s| {
                let n = s.un(Unary::Neg, x);
                let e = s.un(Unary::Exp, n);
                let o = one(s);
                let d = s.bin(Binary::Add, o, e);
                Ok(Self::scalar(s.un(Unary::Recip, d)))
            },
            |s| {
                let e = s.un(Unary::Exp, x);
                let o = one(s);
                let d = s.bin(Binary::Add, o, e);
                Ok(Self::scalar(s.bin(Binary::Div, e, d)))
            },
            Span::call_site(),
        );
        v.map(|v| v.comps[0]).unwrap_or(x)
    }
}
