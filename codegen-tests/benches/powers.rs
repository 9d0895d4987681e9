//! What a constant exponent costs: Student's t falloff `(1 + q / 3)^-2.5` written naively
//! (`powf` with the exponent known, which the compiler turns into a square root, a division
//! and a multiplication), by hand (`rsqrt(r) / (r * r)`), and with the exponent as a value
//! (`powf` through `exp` and `ln`, what the naive form cost before the compiler knew better);
//! forward and adjoint, scalar and eight lanes, in ns per evaluation, each against the form
//! written by hand in the same run; then what each intrinsic costs in eight lanes against a
//! multiply-add. `cargo bench -p codegen-tests --bench powers`

use splat_macros::splat_functions;
use splat_runtime::F32x8;
use std::hint::black_box;
use std::time::Instant;

#[splat_functions]
mod falloffs {
    use splat_runtime::prelude::*;

    pub fn naive(q: f32) -> f32 {
        (1.0 + q / 3.0).powf(-2.5)
    }

    pub fn by_hand(q: f32) -> f32 {
        let r = 1.0 + q / 3.0;
        rsqrt(r) / (r * r)
    }

    pub fn through_powf(q: f32, e: f32) -> f32 {
        (1.0 + q / 3.0).powf(e)
    }
}

/// One intrinsic each, on an input in [0.1, 40] (and a second operand where it takes one).
#[splat_functions]
mod intrinsics {
    use splat_runtime::prelude::*;

    pub fn mul_add(x: f32, y: f32) -> f32 {
        x * y + 0.5
    }

    pub fn div(x: f32, y: f32) -> f32 {
        y / x
    }

    pub fn sqrt_of(x: f32, _y: f32) -> f32 {
        x.sqrt()
    }

    pub fn rsqrt_of(x: f32, _y: f32) -> f32 {
        rsqrt(x)
    }

    pub fn exp_of(x: f32, _y: f32) -> f32 {
        (-x).exp()
    }

    pub fn ln_of(x: f32, _y: f32) -> f32 {
        x.ln()
    }

    pub fn sin_of(x: f32, _y: f32) -> f32 {
        x.sin()
    }

    pub fn atan2_of(x: f32, y: f32) -> f32 {
        x.atan2(y)
    }

    pub fn powf_of(x: f32, y: f32) -> f32 {
        x.powf(y)
    }
}

const N: usize = 1 << 14;
const ROUNDS: usize = 100;

/// One timed pass of `f` over every input, in ns per evaluation.
fn once(f: &dyn Fn() -> f32) -> f64 {
    let start = Instant::now();
    let mut acc = 0.0;
    for _ in 0..ROUNDS {
        acc += f();
    }
    black_box(acc);
    start.elapsed().as_nanos() as f64 / (ROUNDS * N) as f64
}

type Lanes2 =
    fn(&[F32x8; 2], &[splat_runtime::U32x8; 0]) -> ([F32x8; 1], [splat_runtime::U32x8; 0]);
type Adjoint2 = fn(&[F32x8; 2], &[splat_runtime::U32x8; 0], &[F32x8; 1]) -> [F32x8; 2];

/// Each intrinsic's eight-lane form and adjoint, per lane, against a multiply-add's.
fn intrinsic_table(xs: &[F32x8]) {
    use intrinsics::lanes as l;
    let y = F32x8::splat(black_box(-1.3));
    let kernels: [(&str, Lanes2, Adjoint2); 9] = [
        ("x * y + c", l::mul_add, l::mul_add_adjoint),
        ("y / x", l::div, l::div_adjoint),
        ("sqrt", l::sqrt_of, l::sqrt_of_adjoint),
        ("rsqrt", l::rsqrt_of, l::rsqrt_of_adjoint),
        ("exp", l::exp_of, l::exp_of_adjoint),
        ("ln", l::ln_of, l::ln_of_adjoint),
        ("sin", l::sin_of, l::sin_of_adjoint),
        ("atan2", l::atan2_of, l::atan2_of_adjoint),
        ("powf (exponent a value)", l::powf_of, l::powf_of_adjoint),
    ];
    let d = [F32x8::splat(1.0)];
    let forward: Vec<Box<dyn Fn() -> f32 + '_>> = (kernels.iter())
        .map(|(_, f, _)| -> Box<dyn Fn() -> f32> {
            Box::new(move || xs.iter().map(|x| f(&[*x, y], &[]).0[0].0[0]).sum())
        })
        .collect();
    let adjoint: Vec<Box<dyn Fn() -> f32 + '_>> = (kernels.iter())
        .map(|(_, _, a)| -> Box<dyn Fn() -> f32> {
            Box::new(move || xs.iter().map(|x| a(&[*x, y], &[], &d)[0].0[0]).sum())
        })
        .collect();
    let f = medians(&forward.iter().map(|b| b.as_ref()).collect::<Vec<_>>());
    let a = medians(&adjoint.iter().map(|b| b.as_ref()).collect::<Vec<_>>());
    println!("\nEach intrinsic in 8 lanes, ns per lane (ratio to a multiply-add)");
    println!("| intrinsic | forward | adjoint |");
    println!("|---|---|---|");
    for (i, (name, ..)) in kernels.iter().enumerate() {
        println!(
            "| {name} | {:.2} ({:.1}x) | {:.2} ({:.1}x) |",
            f[i],
            f[i] / f[0],
            a[i],
            a[i] / a[0]
        );
    }
}

/// The median of 9 passes of each of `forms`, taken in turn (so no form is timed on a colder
/// or hotter machine than the others).
fn medians(forms: &[&dyn Fn() -> f32]) -> Vec<f64> {
    forms.iter().for_each(|f| {
        once(f);
    });
    let mut runs = vec![vec![]; forms.len()];
    for _ in 0..9 {
        for (f, r) in forms.iter().zip(&mut runs) {
            r.push(once(*f));
        }
    }
    (runs.into_iter())
        .map(|mut r| {
            r.sort_by(f64::total_cmp);
            r[4]
        })
        .collect()
}

fn main() {
    use falloffs::{lanes as l, scalar as s};
    let mut rng = fastrand::Rng::with_seed(3);
    let qs: Vec<f32> = (0..N).map(|_| rng.f32() * 40.0).collect();
    let lanes: Vec<F32x8> = qs
        .chunks(8)
        .map(|c| F32x8(std::array::from_fn(|l| c[l])))
        .collect();
    let positive: Vec<F32x8> = lanes.iter().map(|x| *x + F32x8::splat(0.1)).collect();
    let e = black_box(-2.5f32);
    let (d, le) = (F32x8::splat(1.0), F32x8::splat(e));
    let columns: [Vec<f64>; 4] = [
        medians(&[
            &|| qs.iter().map(|q| s::by_hand(&[*q], &[]).0[0]).sum(),
            &|| qs.iter().map(|q| s::naive(&[*q], &[]).0[0]).sum(),
            &|| qs.iter().map(|q| s::through_powf(&[*q, e], &[]).0[0]).sum(),
        ]),
        medians(&[
            &|| {
                qs.iter()
                    .map(|q| s::by_hand_adjoint(&[*q], &[], &[1.0])[0])
                    .sum()
            },
            &|| {
                qs.iter()
                    .map(|q| s::naive_adjoint(&[*q], &[], &[1.0])[0])
                    .sum()
            },
            &|| {
                qs.iter()
                    .map(|q| s::through_powf_adjoint(&[*q, e], &[], &[1.0])[0])
                    .sum()
            },
        ]),
        medians(&[
            &|| lanes.iter().map(|q| l::by_hand(&[*q], &[]).0[0].0[0]).sum(),
            &|| lanes.iter().map(|q| l::naive(&[*q], &[]).0[0].0[0]).sum(),
            &|| {
                lanes
                    .iter()
                    .map(|q| l::through_powf(&[*q, le], &[]).0[0].0[0])
                    .sum()
            },
        ]),
        medians(&[
            &|| {
                lanes
                    .iter()
                    .map(|q| l::by_hand_adjoint(&[*q], &[], &[d])[0].0[0])
                    .sum()
            },
            &|| {
                lanes
                    .iter()
                    .map(|q| l::naive_adjoint(&[*q], &[], &[d])[0].0[0])
                    .sum()
            },
            &|| {
                (lanes.iter())
                    .map(|q| l::through_powf_adjoint(&[*q, le], &[], &[d])[0].0[0])
                    .sum()
            },
        ]),
    ];
    println!("ns per evaluation (ratio to by hand), {N} inputs, median of 9 passes of {ROUNDS}");
    println!(
        "| form | scalar | scalar adjoint | 8 lanes (per lane) | 8 lanes adjoint (per lane) |"
    );
    println!("|---|---|---|---|---|");
    let forms = [
        "by hand: rsqrt(r) / (r * r)",
        "naive: r.powf(-2.5)",
        "exponent as a value: powf",
    ];
    for (i, name) in forms.iter().enumerate() {
        let cells: Vec<String> = (columns.iter())
            .map(|c| format!("{:.2} ({:.2}x)", c[i], c[i] / c[0]))
            .collect();
        println!("| {name} | {} |", cells.join(" | "));
    }
    intrinsic_table(&positive);
}
