//! Method calls on the supported types and the free intrinsic functions, lowered to scalar IR
//! (their signatures are `typeck::rules`').
//!
//! The rules at kinks and singular points (the "Derivative rules" table of
//! `splat-macros/README.md`): `normalize(0) = 0` with zero gradient; `length` and `sqrt` have
//! zero gradient at 0; `min`/`max`/`clamp` send the gradient to the first argument on ties;
//! division, `recip`, `ln`, `rsqrt`, `asin`, `acos`, `atan2` and `powf` have zero gradient
//! where the derivative is infinite; `select` and `if` differentiate only the side taken.

use super::expr::unchecked;
use super::{Failed, Lowerer, R, Val};
use crate::builtins::{camera_helper, model_aware, sh_helper, shutter_aware};
use crate::ir::{Binary, Const, Unary, Var};
use crate::typeck::rules;
use crate::types::Ty;
use proc_macro2::Span;
use syn::spanned::Spanned;

impl Lowerer<'_> {
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
        let recv = self.expr(&m.receiver)?;
        let args = self.args_of(&m.args)?;
        let spans: Vec<Span> = m.args.iter().map(|a| a.span()).collect();
        let name = m.method.to_string();
        self.method(&name, recv, args, &spans, m.method.span())
    }

    /// The method `name` on `recv`; `spans` are the arguments'.
    fn method(
        &mut self,
        name: &str,
        recv: Val,
        args: Vec<Val>,
        spans: &[Span],
        span: Span,
    ) -> R<Val> {
        if crate::types::is_camera(&recv.ty)
            && let Some(helper) = camera_helper(name)
        {
            let def = self
                .module
                .find_fn(&helper)
                .expect("builtin camera helpers are in every module");
            self.camera_model |= model_aware(name);
            self.rolling_shutter |= shutter_aware(name);
            let mut all = vec![recv];
            all.extend(args);
            return self.call_helper(def, all, span);
        }
        let ty = match rules::method(&recv.ty, name) {
            Some(sig) => sig.ret,
            None => unchecked("an unknown method"),
        };
        let r = &recv.comps;
        let x = r[0];
        let arg = |i: usize| &args[i].comps;
        let comps = match (&recv.ty, name) {
            (Ty::F32, _) if let Some(op) = Unary::method(name, false) => vec![self.un(op, x)],
            (Ty::F32, "log2" | "log10" | "to_radians" | "to_degrees") => {
                let k = match name {
                    "log2" => std::f64::consts::LOG2_E,
                    "log10" => std::f64::consts::LOG10_E,
                    "to_radians" => std::f64::consts::PI / 180.0,
                    _ => 180.0 / std::f64::consts::PI,
                };
                let a = match name {
                    "log2" | "log10" => self.un(Unary::Ln, x),
                    _ => x,
                };
                let k = self.fconst(k);
                vec![self.bin(Binary::Mul, a, k)]
            }
            (_, "min" | "max") => {
                let op = if name == "min" {
                    Binary::Min
                } else {
                    Binary::Max
                };
                r.iter()
                    .zip(arg(0))
                    .map(|(&a, &b)| self.bin(op, a, b))
                    .collect()
            }
            (_, "clamp") => (0..r.len())
                .map(|i| {
                    let lo = self.bin(Binary::Max, r[i], arg(0)[i]);
                    self.bin(Binary::Min, lo, arg(1)[i])
                })
                .collect(),
            (Ty::F32, "atan2") => vec![self.bin(Binary::Atan2, x, arg(0)[0])],
            (Ty::F32, "powf") => vec![self.powf(x, arg(0)[0])],
            (Ty::F32, "powi") => {
                let Some(n) = self.int_const(&args[0]) else {
                    return self.err(
                        spans[0],
                        "the exponent of `powi` must be a compile-time integer",
                    );
                };
                vec![self.powi(x, n)]
            }
            (Ty::F32, "mul_add") => {
                let p = self.bin(Binary::Mul, x, arg(0)[0]);
                vec![self.bin(Binary::Add, p, arg(1)[0])]
            }
            (Ty::F32, "sin_cos") => vec![self.un(Unary::Sin, x), self.un(Unary::Cos, x)],
            (Ty::F32, "hypot") => {
                let v = Val {
                    ty: Ty::Vec(2),
                    comps: vec![x, arg(0)[0]],
                };
                self.length(&v).comps
            }
            (_, "dot") => vec![self.dot(r, arg(0))],
            (_, "cross") => self.cross(&recv, &args[0]).comps,
            (_, "length") => self.length(&recv).comps,
            (_, "length_squared") => vec![self.dot(r, r)],
            (_, "normalize" | "normalize_or_zero") => self.normalize(&recv).comps,
            (_, "distance" | "distance_squared") => {
                let d = self.binary(Binary::Sub, recv.clone(), args[0].clone());
                match name {
                    "distance" => self.length(&d).comps,
                    _ => vec![self.dot(&d.comps, &d.comps)],
                }
            }
            (Ty::Vec(_), _) if let Some(op) = Unary::method(name, true) => {
                self.map(&recv, op).comps
            }
            (Ty::Vec(_), "powf") => {
                let e = arg(0)[0];
                r.iter().map(|&c| self.powf(c, e)).collect()
            }
            (Ty::Vec(_), "lerp") => {
                let t = arg(1)[0];
                r.iter()
                    .zip(arg(0))
                    .map(|(&a, &b)| {
                        let d = self.bin(Binary::Sub, b, a);
                        let s = self.bin(Binary::Mul, d, t);
                        self.bin(Binary::Add, a, s)
                    })
                    .collect()
            }
            (Ty::Vec(_), "min_element" | "max_element" | "element_sum" | "element_product") => {
                let op = match name {
                    "min_element" => Binary::Min,
                    "max_element" => Binary::Max,
                    "element_sum" => Binary::Add,
                    _ => Binary::Mul,
                };
                let mut acc = x;
                for &c in &r[1..] {
                    acc = self.bin(op, acc, c);
                }
                vec![acc]
            }
            (Ty::Vec(_), "extend") => [r.as_slice(), arg(0)].concat(),
            (Ty::Vec(n), "truncate") => r[..n - 1].to_vec(),
            (Ty::Vec(n), s) if rules::is_swizzle(*n, s) => {
                s.chars().map(|c| r["xyzw".find(c).unwrap()]).collect()
            }
            (Ty::Mat(_), "transpose") => self.transpose(&recv).comps,
            (Ty::Mat(_), "determinant") => vec![self.determinant(&recv)],
            (Ty::Mat(_), "inverse") => self.inverse(&recv).comps,
            (Ty::Mat(n), "col" | "row") => {
                let Some(i) = self.int_const(&args[0]).filter(|i| (*i as usize) < *n) else {
                    return self.err(
                        span,
                        format!("`{name}` needs a compile-time index below {n}"),
                    );
                };
                let i = i as usize;
                (0..*n)
                    .map(|k| {
                        if name == "col" {
                            r[i * n + k]
                        } else {
                            r[k * n + i]
                        }
                    })
                    .collect()
            }
            (Ty::Mat(_), "mul_vec2" | "mul_vec3") => self.mat_vec(&recv, &args[0]).comps,
            (Ty::Mat(_), "mul_mat2" | "mul_mat3") => self.mat_mul(&recv, &args[0]).comps,
            (Ty::Mat(_), "mul_scalar") => {
                self.binary(Binary::Mul, recv.clone(), args[0].clone())
                    .comps
            }
            (Ty::Quat, "conjugate" | "inverse") => {
                let mut comps = r.clone();
                for c in comps.iter_mut().take(3) {
                    *c = self.un(Unary::Neg, *c);
                }
                comps
            }
            (Ty::Quat, "mul_vec3") => self.quat_rotate(&recv, &args[0]).comps,
            (Ty::I32, "abs") => {
                let z = self.konst(Const::I(0));
                let neg = self.bin(Binary::Lt, x, z);
                let n = self.un(Unary::Neg, x);
                vec![self.select(neg, n, x)]
            }
            _ => unchecked("a method without a lowering"),
        };
        Ok(Val { ty, comps })
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
            unchecked("a call of an expression")
        };
        let segs: Vec<String> = p
            .path
            .segments
            .iter()
            .map(|s| s.ident.to_string())
            .collect();
        let span = p.span();
        let spans: Vec<Span> = c.args.iter().map(|a| a.span()).collect();
        if let [name] = segs.as_slice() {
            if self.lookup(name).is_some() {
                // A name bound to a value is called only where its `let` failed.
                return Err(Failed);
            }
            if let Some(def) = self.module.find_fn(name) {
                let args = self.args_of(&c.args)?;
                return self.call_helper(def, args, span);
            }
            return self.free_intrinsic(name, c, &spans, span);
        }
        let (owner, item) = (&segs[segs.len() - 2], &segs[segs.len() - 1]);
        if owner == crate::blocks::PATH {
            let def = (self.module.find_fn(&crate::blocks::internal(item)))
                .unwrap_or_else(|| unchecked("an unknown block"));
            let args = self.args_of(&c.args)?;
            return self.call_helper(def, args, span);
        }
        let mut args = self.args_of(&c.args)?;
        match rules::path_call(owner, item) {
            Some(rules::Path::Constructor(sig)) => Ok(self.constructor(owner, item, sig.ret, args)),
            Some(rules::Path::Method) => {
                let recv = args.remove(0);
                self.method(item, recv, args, &spans[1..], span)
            }
            None => unchecked("an unknown function"),
        }
    }

    fn free_intrinsic(
        &mut self,
        name: &str,
        c: &syn::ExprCall,
        spans: &[Span],
        span: Span,
    ) -> R<Val> {
        match name {
            "select" => {
                let cond = self.expr(&c.args[0])?;
                self.lazy_select(cond.comps[0], &c.args[1], &c.args[2])
            }
            "no_diff" => {
                let v = self.expr(&c.args[0])?;
                Ok(self.map(&v, Unary::NoDiff))
            }
            "sigmoid" => {
                let v = self.expr(&c.args[0])?;
                Ok(Self::scalar(self.sigmoid(v.comps[0])))
            }
            _ if let Some(op) = Unary::function(name) => {
                let v = self.expr(&c.args[0])?;
                Ok(self.map(&v, op))
            }
            "jacobian" => self.jacobian(c),
            "spherical_harmonics" => {
                let args = self.args_of(&c.args)?;
                let Ty::Array(_, n) = args[0].ty else {
                    unchecked("spherical harmonics of a non-array")
                };
                let def = self
                    .module
                    .find_fn(&sh_helper(n))
                    .expect("builtin SH helpers are in every module");
                self.call_helper(def, args, span)
            }
            _ => {
                let m =
                    rules::free_as_method(name).unwrap_or_else(|| unchecked("an unknown function"));
                let mut args = self.args_of(&c.args)?;
                let recv = args.remove(0);
                self.method(m, recv, args, &spans[1..], span)
            }
        }
    }

    /// `select(c, a, b)`: the operands are lowered inside the two sides of a branch, so only
    /// the chosen one is differentiated (no NaN leaks from the other side).
    fn lazy_select(&mut self, cond: Var, a: &syn::Expr, b: &syn::Expr) -> R<Val> {
        if let Some(Const::B(k)) = self.const_of(cond) {
            return self.expr(if k { a } else { b });
        }
        self.branch(cond, |s| s.expr(a), |s| s.expr(b))
    }

    /// `owner::item(args)`, a constructor whose type is `ty`.
    fn constructor(&mut self, owner: &str, item: &str, ty: Ty, args: Vec<Val>) -> Val {
        let flat = |args: &[Val]| {
            args.iter()
                .flat_map(|a| a.comps.iter().copied())
                .collect::<Vec<_>>()
        };
        let comps = match (owner, item) {
            (_, "new" | "from_cols" | "from_xyzw") => flat(&args),
            (_, "splat") => vec![args[0].comps[0]; ty.slot_count()],
            (_, "from_diagonal") => {
                let n = args[0].comps.len();
                let z = self.fconst(0.0);
                let mut comps = vec![z; n * n];
                for i in 0..n {
                    comps[i * n + i] = args[0].comps[i];
                }
                comps
            }
            (_, "from_quat") => self.mat3_from_quat(&args[0]).comps,
            _ => unchecked("a constructor without a lowering"),
        };
        Val { ty, comps }
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

    /// x^y: for an exponent known at compile time (a literal, a constant, exact arithmetic on
    /// them) that is an integer or half an odd integer within [`CHEAP_POWERS`], the cheaper
    /// form of [`Self::power_of_constant`]; otherwise `powf` (through `exp` and `ln`).
    fn powf(&mut self, x: Var, y: Var) -> Var {
        if let Some(Const::F(e)) = self.const_of(y)
            && let Some(v) = self.power_of_constant(x, e)
        {
            return v;
        }
        self.bin(Binary::Powf, x, y)
    }

    /// x^e by multiplications and one square root (half-integer e) or division (negative e):
    /// x^n as [`Self::powi`], x^(n + 1/2) = x^n sqrt(x), x^-(n + 1/2) = rsqrt(x) / x^n. Within
    /// 4 ulp of the exact power for |e| <= 4.5 (the rounding of up to 3 multiplications, a
    /// square root and a division; `codegen-tests/tests/powers.rs` measures it), where
    /// libm's `powf` is within 1; the same at ±0 (0 or +infinity), for negative x (NaN for a
    /// half-integer, the signed power for an integer) and in the gradient (zero where `powf`'s
    /// is guarded). `None` for any other exponent.
    fn power_of_constant(&mut self, x: Var, e: f64) -> Option<Var> {
        let twice = e * 2.0;
        if e.abs() > CHEAP_POWERS || twice.fract() != 0.0 {
            return None;
        }
        if e.fract() == 0.0 {
            return Some(self.powi(x, e as i64));
        }
        // x + 0 is x but for -0, which becomes +0: powf(-0, -1/2) is +infinity, and
        // 1 / sqrt(-0) would be -infinity.
        let zero = self.fconst(0.0);
        let x = self.bin(Binary::Add, x, zero);
        let n = e.abs().floor() as i64;
        let power = |s: &mut Self| s.powi(x, n);
        Some(match (e > 0.0, n) {
            (true, 0) => self.un(Unary::Sqrt, x),
            (true, _) => {
                let (p, r) = (power(self), self.un(Unary::Sqrt, x));
                self.bin(Binary::Mul, p, r)
            }
            (false, 0) => self.un(Unary::Rsqrt, x),
            (false, _) => {
                let (r, p) = (self.un(Unary::Rsqrt, x), power(self));
                self.bin(Binary::Div, r, p)
            }
        })
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
        );
        v.map(|v| v.comps[0]).unwrap_or(x)
    }
}

/// The largest |exponent| `powf` by a constant is computed without `powf`
/// ([`Lowerer::power_of_constant`]): past it the multiplications' rounding outgrows libm's.
pub const CHEAP_POWERS: f64 = 4.5;
