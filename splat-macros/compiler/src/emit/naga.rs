//! The naga backend: every kernel (forward and adjoint) of a module becomes a WGSL function in
//! one `naga::Module`, built directly from the IR, validated, and written by naga's WGSL
//! backend.
//!
//! Each IR parameter slot is a function argument (`bool`, `u32`, `i32`, `f32`); the results
//! come back in a struct with one member per result slot (`bool` as `u32` 0/1, like the flat
//! Rust forms). Values leaving an `if` go through local variables; every non-pre-emitted
//! expression is covered by exactly one `Emit`, flushed before each statement. Where WGSL's
//! built-ins differ from Rust's (`round` ties, `fract` and `sign` of negatives, integer division
//! by zero, shift amounts), the Rust meaning is spelled out so both backends agree.

use crate::ir::{Binary, Block, Const, Function, Op, Scalar, Stmt, Unary, Var};
use crate::ops::Wgsl;
use naga::{
    Arena, BinaryOperator as B, Expression as E, Handle, Literal, MathFunction as M, ScalarKind,
    Span, Statement, StructMember, Type, TypeInner, UnaryOperator,
};
use std::collections::HashMap;

/// The coefficients of `splat_runtime::math::erf` (its `ERF_SERIES` and `ERFC_FIT`, which
/// codegen-tests' `wgsl.rs` holds equal to these), for the WGSL form of `erf`.
pub const ERF_SERIES: [f32; 7] = [
    1.0 / 9360.0,
    -1.0 / 1320.0,
    1.0 / 216.0,
    -1.0 / 42.0,
    1.0 / 10.0,
    -1.0 / 3.0,
    1.0,
];
#[allow(clippy::excessive_precision)] // as published
pub const ERFC_FIT: [f32; 10] = [
    0.170_872_77,
    -0.822_152_23,
    1.488_515_87,
    -1.135_203_98,
    0.278_868_07,
    -0.186_288_06,
    0.096_784_18,
    0.374_091_96,
    1.000_023_68,
    -1.265_512_23,
];

/// A written WGSL function as the runtime calls it: the kernel it came from, its name in the
/// WGSL, its argument types and its result members.
pub struct Signature {
    pub kernel: String,
    pub name: String,
    pub args: Vec<Scalar>,
    pub results: Vec<(String, Scalar)>,
}

/// Builds, validates and writes the WGSL of `kernels` (each function with the names of its
/// result slots) as one module, and the signature of each function as written. The text is
/// parsed back (the validator does not catch every emit mistake), which also gives the names
/// naga's writer chose, so the runtime never has to parse it.
pub fn wgsl(kernels: &[(&Function, Vec<String>)]) -> Result<(String, Vec<Signature>), String> {
    let mut module = naga::Module::default();
    for (f, names) in kernels {
        let func = FnBuilder::build(&mut module, f, names);
        module.functions.append(func, Span::UNDEFINED);
    }
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::empty(),
    )
    .validate(&module)
    .map_err(|e| format!("naga validation failed: {}", e.emit_to_string("")))?;
    let text =
        naga::back::wgsl::write_string(&module, &info, naga::back::wgsl::WriterFlags::empty())
            .map_err(|e| format!("WGSL writer failed: {e}"))?;
    let written = naga::front::wgsl::parse_str(&text).map_err(|e| {
        format!(
            "the written WGSL does not parse: {}",
            e.emit_to_string(&text)
        )
    })?;
    let kind = |ty: Handle<Type>| match written.types[ty].inner {
        TypeInner::Scalar(s) => Ok(match s.kind {
            ScalarKind::Float => Scalar::F32,
            ScalarKind::Uint => Scalar::U32,
            ScalarKind::Sint => Scalar::I32,
            _ => Scalar::Bool,
        }),
        ref other => Err(format!("unexpected WGSL type {other:?}")),
    };
    let mut signatures = vec![];
    // The writer keeps the module's function order.
    for ((f, _), (_, w)) in kernels.iter().zip(written.functions.iter()) {
        let args = w
            .arguments
            .iter()
            .map(|a| kind(a.ty))
            .collect::<Result<_, _>>()?;
        let result = w.result.as_ref().ok_or("a kernel returns nothing")?;
        let TypeInner::Struct { members, .. } = &written.types[result.ty].inner else {
            return Err("a kernel does not return a struct".into());
        };
        let results = members
            .iter()
            .map(|m| Ok((m.name.clone().unwrap_or_default(), kind(m.ty)?)))
            .collect::<Result<_, String>>()?;
        signatures.push(Signature {
            kernel: f.name.clone(),
            name: w.name.clone().unwrap_or_default(),
            args,
            results,
        });
    }
    Ok((text, signatures))
}

fn scalar(s: Scalar) -> naga::Scalar {
    match s {
        Scalar::F32 => naga::Scalar::F32,
        Scalar::Bool => naga::Scalar::BOOL,
        Scalar::U32 => naga::Scalar::U32,
        Scalar::I32 => naga::Scalar::I32,
    }
}

fn ty(module: &mut naga::Module, s: naga::Scalar) -> Handle<Type> {
    module.types.insert(
        Type {
            name: None,
            inner: TypeInner::Scalar(s),
        },
        Span::UNDEFINED,
    )
}

/// WGSL identifiers may not start with `__` and must not be keywords; naga's namer
/// handles the keywords, this keeps hints readable.
fn wgsl_name(hint: &str) -> String {
    let s = hint.trim_start_matches('_');
    if s.is_empty() {
        "v".into()
    } else {
        s.to_string()
    }
}

struct FnBuilder<'f> {
    ir: &'f Function,
    exprs: Arena<E>,
    locals: Arena<naga::LocalVariable>,
    named: naga::FastIndexMap<Handle<E>, String>,
    values: HashMap<Var, Handle<E>>,
    /// Start of the open `Emit` range, and closed ranges not yet pushed to a block.
    emit_start: Option<usize>,
    pending: Vec<std::ops::Range<u32>>,
    types: HashMap<naga::Scalar, Handle<Type>>,
}

impl<'f> FnBuilder<'f> {
    fn build(
        module: &mut naga::Module,
        ir: &'f Function,
        result_names: &[String],
    ) -> naga::Function {
        let mut types = HashMap::new();
        for s in [
            naga::Scalar::F32,
            naga::Scalar::BOOL,
            naga::Scalar::U32,
            naga::Scalar::I32,
        ] {
            types.insert(s, ty(module, s));
        }
        let mut b = FnBuilder {
            ir,
            exprs: Arena::new(),
            locals: Arena::new(),
            named: Default::default(),
            values: HashMap::new(),
            emit_start: None,
            pending: vec![],
            types,
        };
        let arguments = ir
            .params
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let h = b
                    .exprs
                    .append(E::FunctionArgument(i as u32), Span::UNDEFINED);
                b.values.insert(*p, h);
                naga::FunctionArgument {
                    name: Some(wgsl_name(ir.name(*p))),
                    ty: b.types[&scalar(ir.ty(*p))],
                    binding: None,
                }
            })
            .collect();
        // The result struct: one member per result slot.
        let results = ir.results();
        let members: Vec<StructMember> = results
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let s = if ir.ty(*r) == Scalar::Bool {
                    naga::Scalar::U32
                } else {
                    scalar(ir.ty(*r))
                };
                let name = result_names
                    .get(i)
                    .map_or_else(|| format!("out{i}"), |n| wgsl_name(n));
                StructMember {
                    name: Some(name),
                    ty: b.types[&s],
                    binding: None,
                    offset: 4 * i as u32,
                }
            })
            .collect();
        let out_ty = module.types.insert(
            Type {
                name: Some(format!("{}_out", wgsl_name(&ir.name))),
                inner: TypeInner::Struct {
                    members,
                    span: 4 * results.len() as u32,
                },
            },
            Span::UNDEFINED,
        );
        let mut body = naga::Block::new();
        b.block(&ir.body, &mut body);
        let components: Vec<Handle<E>> = results
            .iter()
            .map(|r| {
                let v = b.get(*r);
                if ir.ty(*r) == Scalar::Bool {
                    b.bool_to_u32(v)
                } else {
                    v
                }
            })
            .collect();
        let ret = b.add(E::Compose {
            ty: out_ty,
            components,
        });
        b.flush(&mut body);
        body.push(Statement::Return { value: Some(ret) }, Span::UNDEFINED);
        naga::Function {
            name: Some(wgsl_name(&ir.name)),
            arguments,
            result: Some(naga::FunctionResult {
                ty: out_ty,
                binding: None,
            }),
            local_variables: b.locals,
            expressions: b.exprs,
            named_expressions: b.named,
            body,
            diagnostic_filter_leaf: None,
        }
    }

    /// Appends an expression. Expressions that are not pre-emitted join the open `Emit` range;
    /// a pre-emitted one (literal, argument, local) closes it, since a range must not cover it.
    fn add(&mut self, e: E) -> Handle<E> {
        if e.needs_pre_emit() {
            self.close_range();
        } else if self.emit_start.is_none() {
            self.emit_start = Some(self.exprs.len());
        }
        self.exprs.append(e, Span::UNDEFINED)
    }

    fn close_range(&mut self) {
        if let Some(start) = self.emit_start.take() {
            self.pending.push(start as u32..self.exprs.len() as u32);
        }
    }

    /// Pushes the `Emit`s of everything appended so far into `block`; called before any
    /// statement is pushed, so every expression is emitted before its first use.
    fn flush(&mut self, block: &mut naga::Block) {
        self.close_range();
        for r in self.pending.drain(..) {
            if !r.is_empty() {
                let range = naga::Range::from_index_range(r, &self.exprs);
                block.push(Statement::Emit(range), Span::UNDEFINED);
            }
        }
    }

    fn get(&self, v: Var) -> Handle<E> {
        self.values[&v]
    }

    fn lit_f32(&mut self, x: f32) -> Handle<E> {
        if x.is_finite() {
            return self.add(E::Literal(Literal::F32(x)));
        }
        // WGSL literals cannot be infinite or NaN: bitcast the pattern.
        let bits = self.add(E::Literal(Literal::U32(x.to_bits())));
        self.add(E::As {
            expr: bits,
            kind: ScalarKind::Float,
            convert: None,
        })
    }

    fn konst(&mut self, c: Const) -> Handle<E> {
        match c {
            Const::F(x) => self.lit_f32(x as f32),
            Const::B(b) => self.add(E::Literal(Literal::Bool(b))),
            Const::U(u) => self.add(E::Literal(Literal::U32(u))),
            Const::I(i) => self.add(E::Literal(Literal::I32(i))),
        }
    }

    fn bool_to_u32(&mut self, b: Handle<E>) -> Handle<E> {
        let one = self.add(E::Literal(Literal::U32(1)));
        let zero = self.add(E::Literal(Literal::U32(0)));
        self.add(E::Select {
            condition: b,
            accept: one,
            reject: zero,
        })
    }

    fn bin(&mut self, op: B, left: Handle<E>, right: Handle<E>) -> Handle<E> {
        self.add(E::Binary { op, left, right })
    }

    fn math(&mut self, fun: M, arg: Handle<E>, arg1: Option<Handle<E>>) -> Handle<E> {
        self.add(E::Math {
            fun,
            arg,
            arg1,
            arg2: None,
            arg3: None,
        })
    }

    fn zero_of(&mut self, s: Scalar) -> Handle<E> {
        match s {
            Scalar::F32 => self.lit_f32(0.0),
            Scalar::U32 => self.add(E::Literal(Literal::U32(0))),
            Scalar::I32 => self.add(E::Literal(Literal::I32(0))),
            Scalar::Bool => self.add(E::Literal(Literal::Bool(false))),
        }
    }

    fn name(&mut self, v: Var, h: Handle<E>) {
        if !self.exprs[h].needs_pre_emit() && !self.named.contains_key(&h) {
            self.named.insert(h, wgsl_name(self.ir.name(v)));
        }
    }

    fn block(&mut self, b: &Block, out: &mut naga::Block) {
        for s in &b.stmts {
            match s {
                Stmt::Let { var, op } => {
                    let h = self.op(*var, op);
                    self.values.insert(*var, h);
                }
                Stmt::If {
                    cond,
                    then_block,
                    else_block,
                    outs,
                } => {
                    // Values leave the branches through local variables.
                    let locals: Vec<Handle<E>> = outs
                        .iter()
                        .map(|o| {
                            let lv = self.locals.append(
                                naga::LocalVariable {
                                    name: Some(wgsl_name(self.ir.name(*o))),
                                    ty: self.types[&scalar(self.ir.ty(*o))],
                                    init: None,
                                },
                                Span::UNDEFINED,
                            );
                            self.add(E::LocalVariable(lv))
                        })
                        .collect();
                    let c = self.get(*cond);
                    self.flush(out);
                    let mut accept = naga::Block::new();
                    self.branch(then_block, &locals, &mut accept);
                    let mut reject = naga::Block::new();
                    self.branch(else_block, &locals, &mut reject);
                    out.push(
                        Statement::If {
                            condition: c,
                            accept,
                            reject,
                        },
                        Span::UNDEFINED,
                    );
                    for (o, p) in outs.iter().zip(locals) {
                        let h = self.add(E::Load { pointer: p });
                        self.values.insert(*o, h);
                    }
                }
                Stmt::Call { outs, body, .. } => {
                    self.block(body, out);
                    for (o, y) in outs.iter().zip(&body.yields) {
                        let h = self.get(*y);
                        self.values.insert(*o, h);
                    }
                }
            }
        }
    }

    fn branch(&mut self, b: &Block, locals: &[Handle<E>], out: &mut naga::Block) {
        self.block(b, out);
        let values: Vec<Handle<E>> = b.yields.iter().map(|y| self.get(*y)).collect();
        self.flush(out);
        for (p, v) in locals.iter().zip(values) {
            out.push(
                Statement::Store {
                    pointer: *p,
                    value: v,
                },
                Span::UNDEFINED,
            );
        }
    }

    fn op(&mut self, r: Var, op: &Op) -> Handle<E> {
        let h = match *op {
            Op::Const(c) => return self.konst(c),
            Op::Select(c, a, b) => {
                let (c, a, b) = (self.get(c), self.get(a), self.get(b));
                self.add(E::Select {
                    condition: c,
                    accept: a,
                    reject: b,
                })
            }
            Op::Unary(u, a) => self.unary(u, a),
            Op::Binary(b, x, y) => self.binary(b, x, y),
        };
        self.name(r, h);
        h
    }

    fn unary(&mut self, u: Unary, a: Var) -> Handle<E> {
        let from = self.ir.ty(a);
        let x = self.get(a);
        let one = |s: &mut Self| s.lit_f32(1.0);
        if let Some(f) = u.info().wgsl {
            return self.math(f, x, None);
        }
        match u {
            Unary::Neg => self.add(E::Unary {
                op: UnaryOperator::Negate,
                expr: x,
            }),
            Unary::Not if from == Scalar::Bool => self.add(E::Unary {
                op: UnaryOperator::LogicalNot,
                expr: x,
            }),
            Unary::Not => self.add(E::Unary {
                op: UnaryOperator::BitwiseNot,
                expr: x,
            }),
            Unary::NoDiff => x,
            Unary::Ln1p => {
                // ln(u) * x / (u - 1) with u = 1 + x, and x itself where u rounds to 1 (as on the CPU).
                let o = one(self);
                let u = self.bin(B::Add, o, x);
                let o2 = one(self);
                let d = self.bin(B::Subtract, u, o2);
                let z = self.lit_f32(0.0);
                let is_one = self.bin(B::Equal, d, z);
                let o3 = one(self);
                let safe = self.add(E::Select {
                    condition: is_one,
                    accept: o3,
                    reject: d,
                });
                let l = self.math(M::Log, u, None);
                let q = self.bin(B::Divide, x, safe);
                let r = self.bin(B::Multiply, l, q);
                self.add(E::Select {
                    condition: is_one,
                    accept: x,
                    reject: r,
                })
            }
            Unary::Rsqrt => {
                let s = self.math(M::Sqrt, x, None);
                let o = one(self);
                self.bin(B::Divide, o, s)
            }
            Unary::Recip => {
                let o = one(self);
                self.bin(B::Divide, o, x)
            }
            Unary::Round => {
                // Rust rounds ties away from zero; WGSL's round() rounds them to even.
                let a = self.math(M::Abs, x, None);
                let h = self.lit_f32(0.5);
                let s = self.bin(B::Add, a, h);
                let f = self.math(M::Floor, s, None);
                let sign = self.signum(x);
                self.bin(B::Multiply, sign, f)
            }
            Unary::Fract => {
                // Rust: x - trunc(x); WGSL fract is x - floor(x).
                let t = self.math(M::Trunc, x, None);
                self.bin(B::Subtract, x, t)
            }
            Unary::Signum => self.signum(x),
            Unary::Erf => self.erf(x),
            Unary::Cast(to) => self.cast(x, from, to),
            _ => unreachable!(
                "no WGSL form for {u:?}: write one here, or name its built-in in `Unary::info`"
            ),
        }
    }

    /// `splat_runtime::math::erf`, step for step: the Maclaurin series below |x| = 0.5, else
    /// 1 - erfc from Numerical Recipes' fit.
    fn erf(&mut self, x: Handle<E>) -> Handle<E> {
        let a = self.math(M::Abs, x, None);
        let z = self.bin(B::Multiply, a, a);
        let series = self.horner(&ERF_SERIES, z);
        let k = self.lit_f32(std::f32::consts::FRAC_2_SQRT_PI);
        let ka = self.bin(B::Multiply, k, a);
        let near = self.bin(B::Multiply, ka, series);
        let (one, half) = (self.lit_f32(1.0), self.lit_f32(0.5));
        let ha = self.bin(B::Multiply, half, a);
        let den = self.bin(B::Add, one, ha);
        let t = self.bin(B::Divide, one, den);
        let fit = self.horner(&ERFC_FIT, t);
        let arg = self.bin(B::Subtract, fit, z);
        let e = self.math(M::Exp, arg, None);
        let te = self.bin(B::Multiply, t, e);
        let far = self.bin(B::Subtract, one, te);
        let small = self.bin(B::Less, a, half);
        let r = self.add(E::Select {
            condition: small,
            accept: near,
            reject: far,
        });
        let zero = self.lit_f32(0.0);
        let negative = self.bin(B::Less, x, zero);
        let nr = self.add(E::Unary {
            op: UnaryOperator::Negate,
            expr: r,
        });
        self.add(E::Select {
            condition: negative,
            accept: nr,
            reject: r,
        })
    }

    /// The polynomial with coefficients `c` (highest power first) at `x`, by Horner's rule.
    fn horner(&mut self, c: &[f32], x: Handle<E>) -> Handle<E> {
        let mut p = self.lit_f32(c[0]);
        for &k in &c[1..] {
            let px = self.bin(B::Multiply, p, x);
            let k = self.lit_f32(k);
            p = self.bin(B::Add, px, k);
        }
        p
    }

    /// Rust's `signum`: -1 when the sign bit is set (including -0.0), else 1.
    fn signum(&mut self, x: Handle<E>) -> Handle<E> {
        let bits = self.add(E::As {
            expr: x,
            kind: ScalarKind::Uint,
            convert: None,
        });
        let mask = self.add(E::Literal(Literal::U32(0x8000_0000)));
        let sign = self.bin(B::And, bits, mask);
        let zero = self.add(E::Literal(Literal::U32(0)));
        let neg = self.bin(B::NotEqual, sign, zero);
        let m1 = self.lit_f32(-1.0);
        let p1 = self.lit_f32(1.0);
        self.add(E::Select {
            condition: neg,
            accept: m1,
            reject: p1,
        })
    }

    fn cast(&mut self, x: Handle<E>, from: Scalar, to: Scalar) -> Handle<E> {
        if from == to {
            return x;
        }
        match (from, to) {
            (Scalar::Bool, Scalar::U32) => self.bool_to_u32(x),
            (Scalar::Bool, _) => {
                let u = self.bool_to_u32(x);
                let kind = scalar(to).kind;
                self.add(E::As {
                    expr: u,
                    kind,
                    convert: Some(4),
                })
            }
            (_, Scalar::Bool) => {
                let z = self.zero_of(from);
                self.bin(B::NotEqual, x, z)
            }
            _ => self.add(E::As {
                expr: x,
                kind: scalar(to).kind,
                convert: Some(4),
            }),
        }
    }

    fn binary(&mut self, b: Binary, x: Var, y: Var) -> Handle<E> {
        let ty = self.ir.ty(x);
        let (l, r) = (self.get(x), self.get(y));
        let int = matches!(ty, Scalar::U32 | Scalar::I32);
        match b {
            Binary::Div | Binary::Rem if int => {
                // Rust's generated code gives 0 for a zero divisor; WGSL gives the dividend.
                let z = self.zero_of(ty);
                let nz = self.bin(B::NotEqual, r, z);
                let q = self.bin(wgsl_operator(b), l, r);
                let z2 = self.zero_of(ty);
                self.add(E::Select {
                    condition: nz,
                    accept: q,
                    reject: z2,
                })
            }
            Binary::And if ty == Scalar::Bool => self.bin(B::LogicalAnd, l, r),
            Binary::Or if ty == Scalar::Bool => self.bin(B::LogicalOr, l, r),
            Binary::Xor if ty == Scalar::Bool => self.bin(B::NotEqual, l, r),
            Binary::Shl | Binary::Shr => {
                // The shift amount is a u32 taken modulo 32, like Rust's wrapping shifts.
                let amount = if ty == Scalar::I32 {
                    self.add(E::As {
                        expr: r,
                        kind: ScalarKind::Uint,
                        convert: Some(4),
                    })
                } else {
                    r
                };
                let m = self.add(E::Literal(Literal::U32(31)));
                let amount = self.bin(B::And, amount, m);
                self.bin(wgsl_operator(b), l, amount)
            }
            _ => match b.info().wgsl {
                Wgsl::Operator(op) => self.bin(op, l, r),
                Wgsl::Function(f) => self.math(f, l, Some(r)),
            },
        }
    }
}

/// The WGSL operator computing `b` (one WGSL writes as an operator).
fn wgsl_operator(b: Binary) -> naga::BinaryOperator {
    match b.info().wgsl {
        Wgsl::Operator(op) => op,
        Wgsl::Function(f) => unreachable!("{b:?} is the WGSL function {f:?}"),
    }
}
