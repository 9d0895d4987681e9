//! Emits the body of an IR function as Rust, in one of three flavors: scalar `f32`, the `f64`
//! twin, and eight SIMD lanes. Constants are written inline at their uses; every other value
//! becomes a `let` with a readable, unique name.

use crate::ir::{Binary, Block, Const, Function, Op, Scalar, Stmt, Unary, Var};
use crate::ops::{Rust, Spelling};
use proc_macro2::{Ident, Literal, Span, TokenStream};
use quote::{format_ident, quote};
use std::collections::{HashMap, HashSet};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Flavor {
    F32,
    F64,
    Lanes,
}

pub struct BodyEmitter<'f> {
    f: &'f Function,
    pub flavor: Flavor,
    names: HashMap<Var, Ident>,
    used: HashSet<String>,
    consts: HashMap<Var, Const>,
    /// In lane code, the values that are the same on every lane (a gated adjoint's mask and
    /// what is computed from it alone): scalars, and branches on them are real branches.
    uniform: HashSet<Var>,
}

const RT: &str = "::splat_runtime";

impl<'f> BodyEmitter<'f> {
    /// `reserved` are names the emitted body must not shadow (the wrapper's parameters).
    pub fn new(f: &'f Function, flavor: Flavor, reserved: &[String]) -> Self {
        let consts = f.body.constants();
        BodyEmitter {
            f,
            flavor,
            names: HashMap::new(),
            used: reserved.iter().cloned().collect(),
            consts,
            uniform: HashSet::new(),
        }
    }

    /// Declares the parameter `v` the same on every lane (a scalar in lane code).
    pub fn set_uniform(&mut self, v: Var) {
        self.uniform.insert(v);
    }

    /// A lane-code `Let` of a mask or a condition whose operands are uniform (or constant,
    /// with at least one uniform).
    fn computes_uniform(&self, var: Var, op: &Op) -> bool {
        let ops = op.operands();
        self.f.ty(var) != Scalar::F32
            && ops.iter().any(|o| self.uniform.contains(o))
            && ops
                .iter()
                .all(|o| self.uniform.contains(o) || self.is_const(*o))
    }

    /// Claims `name` for `v` (the scalar parameter named like its slot keeps that name).
    pub fn name_as(&mut self, v: Var, name: &str) {
        self.names.insert(v, Ident::new(name, Span::call_site()));
    }

    pub fn ident(&mut self, v: Var) -> Ident {
        if let Some(i) = self.names.get(&v) {
            return i.clone();
        }
        let hint = sanitize(self.f.name(v));
        let mut name = hint.clone();
        let mut k = 1;
        while self.used.contains(&name) || is_keyword(&name) {
            name = format!("{hint}_{k}");
            k += 1;
        }
        self.used.insert(name.clone());
        let id = Ident::new(&name, Span::call_site());
        self.names.insert(v, id.clone());
        id
    }

    fn is_const(&self, v: Var) -> bool {
        self.consts.contains_key(&v)
    }

    /// The scalar literal of a constant (`0.5f32`, `0.5f64`, `true`, `3u32`).
    fn scalar_lit(&self, c: Const) -> TokenStream {
        match c {
            Const::F(x) => {
                let t = if self.flavor == Flavor::F64 {
                    quote!(f64)
                } else {
                    quote!(f32)
                };
                if x.is_nan() {
                    quote!(#t::NAN)
                } else if x == f64::INFINITY {
                    quote!(#t::INFINITY)
                } else if x == f64::NEG_INFINITY {
                    quote!(#t::NEG_INFINITY)
                } else {
                    let lit = if self.flavor == Flavor::F64 {
                        Literal::f64_suffixed(x.abs())
                    } else {
                        Literal::f32_suffixed(x.abs() as f32)
                    };
                    if x.is_sign_negative() {
                        quote!((-#lit))
                    } else {
                        quote!(#lit)
                    }
                }
            }
            Const::B(b) => quote!(#b),
            Const::U(u) => {
                let l = Literal::u32_suffixed(u);
                quote!(#l)
            }
            Const::I(i) => {
                let l = Literal::i32_suffixed(i.unsigned_abs() as i32);
                if i < 0 { quote!((-#l)) } else { quote!(#l) }
            }
        }
    }

    /// A value in a position that needs the full flavor type.
    pub fn val(&mut self, v: Var) -> TokenStream {
        if let Some(&c) = self.consts.get(&v) {
            let lit = self.scalar_lit(c);
            if self.flavor != Flavor::Lanes {
                return lit;
            }
            let ty = lane_type(c.ty());
            return quote!(#ty::splat(#lit));
        }
        let id = self.ident(v);
        quote!(#id)
    }

    /// A value in a float arithmetic position, where lanes accept a scalar operand.
    fn arith(&mut self, v: Var) -> TokenStream {
        match self.consts.get(&v) {
            Some(&c) => self.scalar_lit(c),
            None => self.val(v),
        }
    }

    pub fn block(&mut self, b: &Block) -> TokenStream {
        let mut out = TokenStream::new();
        for s in &b.stmts {
            out.extend(self.stmt(s));
        }
        out
    }

    fn stmt(&mut self, s: &Stmt) -> TokenStream {
        match s {
            Stmt::Let {
                op: Op::Const(_), ..
            } => TokenStream::new(),
            Stmt::Let { var, op }
                if self.flavor == Flavor::Lanes && self.computes_uniform(*var, op) =>
            {
                self.uniform.insert(*var);
                self.flavor = Flavor::F32;
                let rhs = self.op(*var, op);
                self.flavor = Flavor::Lanes;
                let id = self.ident(*var);
                quote!(let #id = #rhs;)
            }
            Stmt::Let { var, op } => {
                let rhs = self.op(*var, op);
                let id = self.ident(*var);
                quote!(let #id = #rhs;)
            }
            Stmt::If {
                cond,
                then_block,
                else_block,
                outs,
            } => {
                if self.flavor == Flavor::Lanes && !self.uniform.contains(cond) {
                    // Both sides run on all lanes; the condition's mask picks per lane.
                    let t = self.block(then_block);
                    let e = self.block(else_block);
                    let c = self.val(*cond);
                    let mut sel = TokenStream::new();
                    for ((o, a), b) in outs.iter().zip(&then_block.yields).zip(&else_block.yields) {
                        let (a, b) = (self.val(*a), self.val(*b));
                        let m = select_method(self.f.ty(*o));
                        let id = self.ident(*o);
                        sel.extend(quote!(let #id = #c.#m(#a, #b);));
                    }
                    return quote!(#t #e #sel);
                }
                let c = self.val(*cond);
                let t = self.block(then_block);
                let ty: Vec<TokenStream> = then_block.yields.iter().map(|y| self.val(*y)).collect();
                let e = self.block(else_block);
                let ey: Vec<TokenStream> = else_block.yields.iter().map(|y| self.val(*y)).collect();
                let ids: Vec<Ident> = outs.iter().map(|o| self.ident(*o)).collect();
                if ids.len() == 1 {
                    let (id, a, b) = (&ids[0], &ty[0], &ey[0]);
                    quote!(let #id = if #c { #t #a } else { #e #b };)
                } else {
                    quote!(let (#(#ids),*) = if #c { #t (#(#ty),*) } else { #e (#(#ey),*) };)
                }
            }
            Stmt::Call { outs, body, .. } => {
                let b = self.block(body);
                let mut binds = TokenStream::new();
                for (o, y) in outs.iter().zip(&body.yields) {
                    let y = self.val(*y);
                    let id = self.ident(*o);
                    binds.extend(quote!(let #id = #y;));
                }
                quote!(#b #binds)
            }
        }
    }

    fn op(&mut self, r: Var, op: &Op) -> TokenStream {
        let lanes = self.flavor == Flavor::Lanes;
        let rt: TokenStream = RT.parse().unwrap();
        match *op {
            Op::Const(_) => unreachable!("constants are inlined"),
            Op::Select(c, a, b) => {
                let (cv, av, bv) = (self.val(c), self.val(a), self.val(b));
                if lanes && !self.uniform.contains(&c) {
                    let m = select_method(self.f.ty(r));
                    quote!(#cv.#m(#av, #bv))
                } else {
                    quote!(if #cv { #av } else { #bv })
                }
            }
            Op::Unary(u, a) => {
                let ty = self.f.ty(a);
                let x = self.val(a);
                let one = if self.flavor == Flavor::F64 {
                    quote!(1.0f64)
                } else {
                    quote!(1.0f32)
                };
                let method = |m: &str| {
                    let m = format_ident!("{m}");
                    quote!(#x.#m())
                };
                // Integers wrap, as in WGSL and the lanes (`-i32::MIN` is `i32::MIN`).
                let int = matches!(ty, Scalar::U32 | Scalar::I32) && !lanes;
                match u {
                    Unary::Neg if int => quote!(#x.wrapping_neg()),
                    Unary::Abs if int && ty == Scalar::I32 => quote!(#x.wrapping_abs()),
                    Unary::Neg => quote!(-#x),
                    Unary::Not => quote!(!#x),
                    Unary::NoDiff => x,
                    Unary::Rsqrt => quote!(#one / #x.sqrt()),
                    Unary::Recip => quote!(#one / #x),
                    Unary::Cast(to) => self.cast(x, ty, to),
                    _ => {
                        let info = u.info();
                        let name = info.name();
                        match (info.rust, self.flavor) {
                            (Rust::RuntimeF32 | Rust::Runtime, Flavor::F32) => {
                                let f = format_ident!("{name}");
                                quote!(#rt::math::#f(#x))
                            }
                            (Rust::Runtime, Flavor::F64) => {
                                let f = format_ident!("{name}_f64");
                                quote!(#rt::math::#f(#x))
                            }
                            _ => method(name),
                        }
                    }
                }
            }
            Op::Binary(b, x, y) => {
                let ty = self.f.ty(x);
                let float = ty == Scalar::F32;
                let arith = matches!(
                    b,
                    Binary::Add | Binary::Sub | Binary::Mul | Binary::Div | Binary::Rem
                );
                let (xv, yv) = if float && arith && !(self.is_const(x) && self.is_const(y)) {
                    (self.arith(x), self.arith(y))
                } else {
                    (self.val(x), self.val(y))
                };
                let int = matches!(ty, Scalar::U32 | Scalar::I32);
                match b {
                    Binary::Add if int && !lanes => quote!(#xv.wrapping_add(#yv)),
                    Binary::Sub if int && !lanes => quote!(#xv.wrapping_sub(#yv)),
                    Binary::Mul if int && !lanes => quote!(#xv.wrapping_mul(#yv)),
                    Binary::Div if int && !lanes => quote!(#xv.checked_div(#yv).unwrap_or(0)),
                    Binary::Rem if int && !lanes => quote!(#xv.checked_rem(#yv).unwrap_or(0)),
                    Binary::Shl if !lanes => quote!(#xv.wrapping_shl(#yv as u32)),
                    Binary::Shr if !lanes => quote!(#xv.wrapping_shr(#yv as u32)),
                    _ => match (b.info().comparison, b.info().rust) {
                        (Some(mask), _) if lanes => {
                            let m = format_ident!("{mask}");
                            quote!(#xv.#m(#yv))
                        }
                        (_, Spelling::Operator(op)) => {
                            let op: syn::BinOp = syn::parse_str(op).expect("a Rust operator");
                            quote!(#xv #op #yv)
                        }
                        (_, Spelling::Method(m)) => {
                            let m = format_ident!("{m}");
                            quote!(#xv.#m(#yv))
                        }
                    },
                }
            }
        }
    }

    fn cast(&self, x: TokenStream, from: Scalar, to: Scalar) -> TokenStream {
        if from == to {
            return x;
        }
        if self.flavor == Flavor::Lanes {
            return match (from, to) {
                (Scalar::Bool, Scalar::I32) => quote!(#x.to_u32().to_i32()),
                (_, Scalar::F32) => quote!(#x.to_f32()),
                (_, Scalar::U32) => quote!(#x.to_u32()),
                (_, Scalar::I32) => quote!(#x.to_i32()),
                (_, Scalar::Bool) => quote!(#x.to_mask()),
            };
        }
        let t = match to {
            Scalar::F32 if self.flavor == Flavor::F64 => quote!(f64),
            Scalar::F32 => quote!(f32),
            Scalar::U32 => quote!(u32),
            Scalar::I32 => quote!(i32),
            Scalar::Bool => return quote!((#x != 0)),
        };
        quote!((#x as #t))
    }
}

pub fn lane_type(s: Scalar) -> TokenStream {
    match s {
        Scalar::F32 => quote!(::splat_runtime::F32x8),
        Scalar::Bool => quote!(::splat_runtime::M32x8),
        Scalar::U32 => quote!(::splat_runtime::U32x8),
        Scalar::I32 => quote!(::splat_runtime::I32x8),
    }
}

fn select_method(s: Scalar) -> Ident {
    format_ident!(
        "{}",
        match s {
            Scalar::F32 => "select_f32",
            Scalar::Bool => "select_mask",
            Scalar::U32 => "select_u32",
            Scalar::I32 => "select_i32",
        }
    )
}

fn sanitize(s: &str) -> String {
    let mut out: String = s
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if out.is_empty() || out.starts_with(|c: char| c.is_ascii_digit()) {
        out.insert(0, 'v');
    }
    out
}

fn is_keyword(s: &str) -> bool {
    matches!(
        s,
        "as" | "break"
            | "const"
            | "continue"
            | "crate"
            | "else"
            | "enum"
            | "extern"
            | "false"
            | "fn"
            | "for"
            | "if"
            | "impl"
            | "in"
            | "let"
            | "loop"
            | "match"
            | "mod"
            | "move"
            | "mut"
            | "pub"
            | "ref"
            | "return"
            | "self"
            | "Self"
            | "static"
            | "struct"
            | "super"
            | "trait"
            | "true"
            | "type"
            | "unsafe"
            | "use"
            | "where"
            | "while"
            | "async"
            | "await"
            | "dyn"
            | "abstract"
            | "become"
            | "box"
            | "do"
            | "final"
            | "macro"
            | "override"
            | "priv"
            | "typeof"
            | "unsized"
            | "virtual"
            | "yield"
            | "try"
            | "gen"
            | "_"
    )
}
