//! What compiling effects in (or leaving them out) saves. The camera model: each model-aware
//! kernel of 3DGUT and 3DGEER timed as the generic kernel (branching on the model inside) and
//! as the variant compiled for that model alone (what the runtime calls), one primitive or
//! pixel at a time, on every camera model. The camera gradient: the whole CPU backward pass
//! with and without it (off in training). The SH degree: `project`, its adjoint and the whole
//! CPU frame (forward and backward, all threads) of each method's full instance against the
//! instance for the scene's degree, on Gaussians of that degree. Gradient groups: `project`'s
//! adjoint and the whole backward pass computing every gradient against computing some
//! (`RenderOptions::gradients`). Storage between stages: 3DGS's forward and backward passes
//! with the shade data packed (f16, unorm16, unorm8) and with the gradient sums held in f16,
//! against f32 (`RenderOptions::shade_precision`, `gradient_precision`). Times are best of 5, the two alternating after a warm-up of
//! each, kernels on a single thread; the ratio is generic (or full) / variant in the same run.
//!
//! `cargo bench -p splat-methods --bench variants [-- N WIDTH HEIGHT] [models|sh|groups|storage]`
//! (the word runs that section alone)

use splat_methods::{
    FromStored, geer, geer_sh0, geer_sh1, gs3d, gs3d_sh0, gs3d_sh1, gut, gut_sh0, gut_sh1,
};
use splat_runtime::checks::variants::unit_cotangent;
use splat_runtime::glam::{Vec2, Vec4};
use splat_runtime::{
    Camera, CameraModel, Flat, FrameGrad, GradientSet, RenderOptions, SplatMethod, backward,
    param_groups, render_for_backward, with_camera_model,
};
use std::hint::black_box;
use std::time::{Duration, Instant};

mod common;
use common::{as_method, camera, scene, size_args};
use splat_methods::gs3d::Params as Gaussian;
use splat_runtime::io::ply::sh_coefficients;

/// (generic, variant): the best of 5 runs of each, the two alternating after a warm-up of
/// each, so neither gains from running second.
fn compare(mut generic: impl FnMut(), mut variant: impl FnMut()) -> (Duration, Duration) {
    let timed = |f: &mut dyn FnMut()| {
        let t = Instant::now();
        f();
        t.elapsed()
    };
    generic();
    variant();
    let (mut g, mut v) = (Duration::MAX, Duration::MAX);
    for _ in 0..5 {
        g = g.min(timed(&mut generic));
        v = v.min(timed(&mut variant));
    }
    (g, v)
}

/// (kernel, (generic, variant)) times for `M` under `cam`.
fn time<M: SplatMethod>(params: &[M::Params], cam: &Camera) -> Vec<(&'static str, Times)> {
    with_camera_model!(cam.model, MODEL => time_as::<M, MODEL>(params, cam))
}

type Times = (Duration, Duration);

fn time_as<M: SplatMethod, const MODEL: u32>(
    params: &[M::Params],
    cam: &Camera,
) -> Vec<(&'static str, Times)> {
    let ones = unit_cotangent::<M>();
    let (w, h) = (cam.size.x as u32, cam.size.y as u32);
    let pixels =
        || (0..h).flat_map(move |y| (0..w).map(move |x| Vec2::new(x as f32 + 0.5, y as f32 + 0.5)));
    let d_pixel = M::Pixel::read_words(&vec![1.0; M::Pixel::LEN]);
    let per_primitive = |f: &dyn Fn(&M::Params)| params.iter().for_each(|p| f(black_box(p)));
    let per_pixel = |f: &dyn Fn(Vec2)| pixels().for_each(|px| f(black_box(px)));
    // The pixel data consumed as the blend consumes it: written out as words.
    let consume = |pixel: M::Pixel| {
        let mut words = [0.0f32; 64];
        pixel.write_words(&mut words);
        black_box(words.iter().sum::<f32>());
    };
    vec![
        (
            "project",
            compare(
                || {
                    per_primitive(&|p| {
                        let _ = black_box(M::project(p, cam));
                    })
                },
                || {
                    per_primitive(&|p| {
                        let _ = black_box(M::project_as::<MODEL>(p, cam));
                    })
                },
            ),
        ),
        (
            "project adjoint",
            compare(
                || {
                    per_primitive(&|p| {
                        let _ = black_box(M::project_adjoint(p, cam, &ones, GradientSet::ALL));
                    })
                },
                || {
                    per_primitive(&|p| {
                        let all = GradientSet::ALL;
                        let _ = black_box(M::project_adjoint_as::<MODEL>(p, cam, &ones, all));
                    })
                },
            ),
        ),
        (
            "pixel_info",
            compare(
                || per_pixel(&|px| consume(M::pixel_info(px, cam))),
                || per_pixel(&|px| consume(M::pixel_info_as::<MODEL>(px, cam))),
            ),
        ),
        (
            "pixel_info adjoint",
            compare(
                || {
                    per_pixel(&|px| {
                        let _ = black_box(M::pixel_info_adjoint(px, cam, &d_pixel));
                    })
                },
                || {
                    per_pixel(&|px| {
                        let _ = black_box(M::pixel_info_adjoint_as::<MODEL>(px, cam, &d_pixel));
                    })
                },
            ),
        ),
    ]
}

/// The CPU backward pass (all threads) computing every gradient and computing `wanted`.
fn backward_times<M: SplatMethod>(
    params: &[M::Params],
    cam: &Camera,
    wanted: GradientSet,
) -> Times {
    let pass = |gradients: GradientSet| {
        let opts = RenderOptions {
            gradients,
            ..Default::default()
        };
        let (frame, state) = render_for_backward::<M>(params, cam, &opts).unwrap();
        let grad = FrameGrad {
            color: vec![1.0; frame.color.data.len()],
            alpha: None,
            depth: None,
        };
        move || {
            let _ = black_box(backward::<M>(&state, params, cam, &grad).unwrap());
        }
    };
    compare(pass(GradientSet::ALL), pass(wanted))
}

/// The gradient sets worth timing: each parameter group alone and everything but the camera.
fn gradient_sets<M: SplatMethod>() -> Vec<(String, GradientSet)> {
    let mut sets = vec![(
        "all but the camera".to_string(),
        GradientSet::ALL.with_camera(false),
    )];
    for (name, _) in param_groups::<M>() {
        let set = GradientSet::params::<M>(&[name]).unwrap();
        sets.push((format!("`{name}` alone"), set));
    }
    sets
}

/// (set, (all, set)) times of `project`'s adjoint, as the backward pass calls it (one thread),
/// computing every gradient and each set of [`gradient_sets`]; and of the whole backward pass
/// for everything but the camera and for the last group alone.
fn group_times<M: SplatMethod>(params: &[M::Params], cam: &Camera) -> Vec<(String, Times)> {
    let ones = unit_cotangent::<M>();
    let sets = gradient_sets::<M>();
    let adjoint = |wanted: GradientSet| {
        let ones = &ones;
        move || {
            with_camera_model!(cam.model, MODEL => for p in params {
                let _ = black_box(M::project_adjoint_as::<MODEL>(black_box(p), cam, ones, wanted));
            })
        }
    };
    let mut rows: Vec<(String, Times)> = sets
        .iter()
        .map(|(what, set)| {
            let times = compare(adjoint(GradientSet::ALL), adjoint(*set));
            (format!("project adjoint, {what}"), times)
        })
        .collect();
    for (what, set) in [&sets[0], sets.last().unwrap()] {
        let times = backward_times::<M>(params, cam, *set);
        rows.push((format!("backward pass, {what}"), times));
    }
    rows
}

/// (kernel, (full, instance)) times of `project`, its adjoint (one thread) and a whole CPU
/// frame (all threads) for `Full` and `Low` (its instance for SH degree `degree`) on
/// `gaussians` cut to that degree.
fn sh_times<Full: SplatMethod, Low: SplatMethod>(
    gaussians: &[Gaussian],
    degree: u32,
    cam: &Camera,
) -> Vec<(&'static str, Times)>
where
    Full::Params: FromStored,
    Low::Params: FromStored,
{
    let mut cut = gaussians.to_vec();
    for g in &mut cut {
        g.sh[sh_coefficients(degree)..].fill(Default::default());
    }
    let (full, low) = (
        as_method::<Full::Params>(&cut),
        as_method::<Low::Params>(&cut),
    );
    let (full_ones, low_ones) = (unit_cotangent::<Full>(), unit_cotangent::<Low>());
    vec![
        (
            "project",
            compare(
                || {
                    for p in &full {
                        let _ = black_box(Full::project(black_box(p), cam));
                    }
                },
                || {
                    for p in &low {
                        let _ = black_box(Low::project(black_box(p), cam));
                    }
                },
            ),
        ),
        (
            "project adjoint",
            compare(
                || {
                    for p in &full {
                        let all = GradientSet::ALL;
                        let _ =
                            black_box(Full::project_adjoint(black_box(p), cam, &full_ones, all));
                    }
                },
                || {
                    for p in &low {
                        let all = GradientSet::ALL;
                        let _ = black_box(Low::project_adjoint(black_box(p), cam, &low_ones, all));
                    }
                },
            ),
        ),
        (
            "frame",
            compare(frame::<Full>(&full, cam), frame::<Low>(&low, cam)),
        ),
    ]
}

/// A whole CPU frame of `M`: the forward pass keeping its state, and the backward pass.
fn frame<'a, M: SplatMethod>(params: &'a [M::Params], cam: &'a Camera) -> impl FnMut() + 'a {
    move || {
        let opts = RenderOptions::default();
        let (frame, state) = render_for_backward::<M>(params, cam, &opts).unwrap();
        let grad = FrameGrad {
            color: vec![1.0; frame.color.data.len()],
            alpha: None,
            depth: None,
        };
        let _ = black_box(backward::<M>(&state, params, cam, &grad).unwrap());
    }
}

fn main() {
    let (n, w, h) = size_args(100_000, 800, 600);
    let gaussians = scene(n);
    let (gut_params, geer_params) = (
        as_method::<gut::Params>(&gaussians),
        as_method::<geer::Params>(&gaussians),
    );
    let only: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| ["models", "sh", "groups", "storage"].contains(&a.as_str()))
        .collect();
    let run = |section: &str| only.is_empty() || only.iter().any(|o| o == section);
    if run("models") {
        models(&gut_params, &geer_params, w, h);
    }
    if run("sh") {
        sh_degrees(&gaussians, w, h);
    }
    if run("groups") {
        groups(&gaussians, &gut_params, &geer_params, w, h);
    }
    if run("storage") {
        storage(&gaussians, w, h);
    }
}

/// 3DGS's passes (all threads) storing the shade data or the gradient sums in a reduced
/// format, against f32.
fn storage(gaussians: &[Gaussian], w: f32, h: f32) {
    use splat_runtime::precision::Precision;
    let cam = camera(w, h);
    println!();
    println!(
        "storage between stages, 3dgs, pinhole; ms ({} threads), f32 / reduced",
        threads()
    );
    println!("| pass | stored reduced | f32 | reduced | ratio |");
    println!("|---|---|---:|---:|---:|");
    let forward = |opts: RenderOptions| {
        let cam = &cam;
        move || {
            let _ =
                black_box(splat_runtime::render::<gs3d::Method>(gaussians, cam, &opts).unwrap());
        }
    };
    let backward_of = |opts: RenderOptions| {
        let (frame, state) = render_for_backward::<gs3d::Method>(gaussians, &cam, &opts).unwrap();
        let grad = FrameGrad {
            color: vec![1.0; frame.color.data.len()],
            alpha: None,
            depth: None,
        };
        let cam = &cam;
        move || {
            let _ = black_box(backward::<gs3d::Method>(&state, gaussians, cam, &grad).unwrap());
        }
    };
    let row = |pass: &str, what: String, (full, reduced): Times| {
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        println!(
            "| {pass} | {what} | {:.2} | {:.2} | {:.2} |",
            ms(full),
            ms(reduced),
            full.as_secs_f64() / reduced.as_secs_f64()
        );
    };
    let f32_opts = RenderOptions::default();
    for p in [Precision::F16, Precision::Unorm16, Precision::Unorm8] {
        let shade = RenderOptions {
            shade_precision: p,
            ..f32_opts
        };
        let what = format!("shade data {}", p.name());
        row(
            "forward",
            what.clone(),
            compare(forward(f32_opts), forward(shade)),
        );
        let times = compare(backward_of(f32_opts), backward_of(shade));
        row("backward", what, times);
    }
    let sums = RenderOptions {
        gradient_precision: Precision::F16,
        ..f32_opts
    };
    let times = compare(backward_of(f32_opts), backward_of(sums));
    row("backward", "gradient sums f16".into(), times);
}

fn models(gut_params: &[gut::Params], geer_params: &[geer::Params], w: f32, h: f32) {
    let n = gut_params.len();
    println!("{n} primitives, {w}x{h} pixels, one thread; ms, generic / variant");
    println!("| method | camera | kernel | generic ms | variant ms | ratio |");
    println!("|---|---|---|---:|---:|---:|");
    for model in CameraModel::ALL {
        let mut cam = camera(w, h);
        cam.model = model;
        if model == CameraModel::KannalaBrandt {
            cam.distortion = Vec4::new(0.02, -0.002, 0.0002, -0.00001);
        }
        for (method, rows) in [
            ("3dgut", time::<gut::Method>(gut_params, &cam)),
            ("3dgeer", time::<geer::Method>(geer_params, &cam)),
        ] {
            for (kernel, (generic, variant)) in rows {
                let ms = |d: Duration| d.as_secs_f64() * 1e3;
                println!(
                    "| {method} | {model} | {kernel} | {:.2} | {:.2} | {:.2} |",
                    ms(generic),
                    ms(variant),
                    generic.as_secs_f64() / variant.as_secs_f64()
                );
            }
        }
    }
    println!();
    println!("the CPU backward pass, {} threads; ms", threads());
    println!("| method | camera | with camera gradient | without | ratio |");
    println!("|---|---|---:|---:|---:|");
    for model in CameraModel::ALL {
        let mut cam = camera(w, h);
        cam.model = model;
        if model == CameraModel::KannalaBrandt {
            cam.distortion = Vec4::new(0.02, -0.002, 0.0002, -0.00001);
        }
        let without = GradientSet::ALL.with_camera(false);
        for (method, (with, without)) in [
            (
                "3dgut",
                backward_times::<gut::Method>(gut_params, &cam, without),
            ),
            (
                "3dgeer",
                backward_times::<geer::Method>(geer_params, &cam, without),
            ),
        ] {
            let ms = |d: Duration| d.as_secs_f64() * 1e3;
            println!(
                "| {method} | {model} | {:.1} | {:.1} | {:.2} |",
                ms(with),
                ms(without),
                with.as_secs_f64() / without.as_secs_f64()
            );
        }
    }
}

fn sh_degrees(gaussians: &[Gaussian], w: f32, h: f32) {
    println!();
    println!("the SH degree: the full instance (degree 3) against the degree's own; ms");
    println!("| method | scene's degree | kernel | full | instance | ratio |");
    println!("|---|---:|---|---:|---:|---:|");
    let cam = camera(w, h);
    for (method, degree, rows) in [
        (
            "3dgs",
            0,
            sh_times::<gs3d::Method, gs3d_sh0::Method>(gaussians, 0, &cam),
        ),
        (
            "3dgs",
            1,
            sh_times::<gs3d::Method, gs3d_sh1::Method>(gaussians, 1, &cam),
        ),
        (
            "3dgut",
            0,
            sh_times::<gut::Method, gut_sh0::Method>(gaussians, 0, &cam),
        ),
        (
            "3dgut",
            1,
            sh_times::<gut::Method, gut_sh1::Method>(gaussians, 1, &cam),
        ),
        (
            "3dgeer",
            0,
            sh_times::<geer::Method, geer_sh0::Method>(gaussians, 0, &cam),
        ),
        (
            "3dgeer",
            1,
            sh_times::<geer::Method, geer_sh1::Method>(gaussians, 1, &cam),
        ),
    ] {
        for (kernel, (full, instance)) in rows {
            let ms = |d: Duration| d.as_secs_f64() * 1e3;
            println!(
                "| {method} | {degree} | {kernel} | {:.2} | {:.2} | {:.2} |",
                ms(full),
                ms(instance),
                full.as_secs_f64() / instance.as_secs_f64()
            );
        }
    }
}

fn groups(
    gaussians: &[Gaussian],
    gut_params: &[gut::Params],
    geer_params: &[geer::Params],
    w: f32,
    h: f32,
) {
    println!();
    println!(
        "gradient groups: every gradient against some, pinhole; ms (adjoint one thread, backward pass {} threads)",
        threads()
    );
    println!("| method | what | all | some | ratio |");
    println!("|---|---|---:|---:|---:|");
    let cam = camera(w, h);
    for (method, rows) in [
        ("3dgs", group_times::<gs3d::Method>(gaussians, &cam)),
        ("3dgut", group_times::<gut::Method>(gut_params, &cam)),
        ("3dgeer", group_times::<geer::Method>(geer_params, &cam)),
    ] {
        for (what, (all, some)) in rows {
            let ms = |d: Duration| d.as_secs_f64() * 1e3;
            println!(
                "| {method} | {what} | {:.2} | {:.2} | {:.2} |",
                ms(all),
                ms(some),
                all.as_secs_f64() / some.as_secs_f64()
            );
        }
    }
}

fn threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}
