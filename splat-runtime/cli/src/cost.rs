//! `splat inspect --cost`: what each kernel a method compiles to computes, counted from its
//! WGSL as naga parses it: the transcendental functions, square roots and divisions (the
//! operations that cost many times an add or a multiply), and every operation. Counts are
//! static: both sides of a branch count, loops are already unrolled by the compiler.

use anyhow::{Context, Result};
use naga::{BinaryOperator, Expression, MathFunction};

/// One kernel's counts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Cost {
    /// `exp` and `exp2`.
    pub exp: usize,
    /// `log` and `log2`.
    pub ln: usize,
    /// `pow`: an `exp` and a `ln` with the rounding care of both.
    pub pow: usize,
    /// Trigonometric functions and their inverses.
    pub trig: usize,
    /// `sqrt` and `inverseSqrt`.
    pub sqrt: usize,
    pub div: usize,
    /// Every arithmetic operation and math function.
    pub ops: usize,
}

/// The cost of every function of `wgsl`, in its order.
pub fn costs(wgsl: &str) -> Result<Vec<(String, Cost)>> {
    let module = naga::front::wgsl::parse_str(wgsl)
        .map_err(|e| anyhow::anyhow!(e.emit_to_string(wgsl)))
        .context("parsing the method's WGSL")?;
    Ok((module.functions.iter())
        .map(|(_, f)| {
            let name = f.name.clone().unwrap_or_default();
            let name = name.strip_suffix('_').unwrap_or(&name).to_string();
            (name, cost_of(&f.expressions))
        })
        .collect())
}

fn cost_of(expressions: &naga::Arena<Expression>) -> Cost {
    use MathFunction as M;
    let mut c = Cost::default();
    for (_, e) in expressions.iter() {
        match e {
            Expression::Math { fun, .. } => {
                c.ops += 1;
                match fun {
                    M::Exp | M::Exp2 => c.exp += 1,
                    M::Log | M::Log2 => c.ln += 1,
                    M::Pow => c.pow += 1,
                    M::Sqrt | M::InverseSqrt => c.sqrt += 1,
                    M::Sin | M::Cos | M::Tan | M::Asin | M::Acos | M::Atan | M::Atan2 => {
                        c.trig += 1
                    }
                    _ => {}
                }
            }
            Expression::Binary { op, .. } => {
                c.ops += 1;
                if *op == BinaryOperator::Divide {
                    c.div += 1;
                }
            }
            Expression::Unary { .. } | Expression::Select { .. } => c.ops += 1,
            _ => {}
        }
    }
    c
}

/// How often a kernel runs in a frame, from its role's name.
fn runs_per(kernel: &str) -> &'static str {
    match kernel.split('_').next() {
        Some("evaluate") => "pair",
        Some("project") => "primitive",
        Some("tile") => "tile hit",
        Some("pixel") => "pixel",
        _ => "call",
    }
}

/// The table `splat inspect --cost` prints.
pub fn table(costs: &[(String, Cost)]) -> String {
    let mut out = String::from(
        "| kernel | runs per | exp | ln | pow | trig | sqrt | div | all ops |\n\
         |---|---|---|---|---|---|---|---|---|\n",
    );
    for (name, c) in costs {
        out += &format!(
            "| {name} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
            runs_per(name),
            c.exp,
            c.ln,
            c.pow,
            c.trig,
            c.sqrt,
            c.div,
            c.ops
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_what_a_function_computes() {
        let wgsl = "fn evaluate_(x: f32, y: f32) -> f32 {
            let a = exp(x) + log(y) + pow(x, y);
            let b = sqrt(x) / inverseSqrt(y) + sin(x) * atan2(x, y);
            return select(a, b, x > y) / 2.0;
        }";
        let got = costs(wgsl).unwrap();
        assert_eq!(got.len(), 1);
        let (name, c) = &got[0];
        assert_eq!(name, "evaluate");
        let want = Cost {
            exp: 1,
            ln: 1,
            pow: 1,
            trig: 2,
            sqrt: 2,
            div: 2,
            ops: 15,
        };
        assert_eq!(*c, want);
        assert!(table(&got).contains("| evaluate | pair | 1 | 1 | 1 | 2 | 2 | 2 | 15 |"));
    }
}
