//! What a run learns per training view besides the scene (`FitOptions::per_view`), on the
//! known scene's dataset (`super::fit`): views whose colors were changed each its own way
//! train, with the option, as the unchanged views do; without it they do not.

use crate::fit::{known_dataset, moved_start, options, truth};
use splat_methods::gs3d::{Method, Params};
use splat_runtime::io::dataset::{Dataset, View};
use splat_runtime::train::Checkpoint;
use splat_runtime::train::fit::{FitOptions, evaluate, fit, render_training_view};
use splat_runtime::train::loss::psnr;
use splat_runtime::train::per_view::{Exposure, PerViewOptions};

/// Training view `k`'s gain per channel: log-gains spread over [-0.25, 0.25] across the views,
/// tinted per channel, each channel's mean log-gain zero (the scene's own brightness is
/// what the held-out views, rendered without a correction, compare against).
fn gain(k: usize, views: usize) -> [f32; 3] {
    let u = |j: usize| (j % views) as f32 / (views - 1) as f32 * 2.0 - 1.0;
    [0, 3, 7].map(|shift| (0.25 * u(k * 3 + shift)).exp())
}

/// `data` with each training view's colors times its [`gain`].
fn gained(data: &Dataset) -> Dataset {
    let views = data.train.len();
    let train = (data.train.iter().enumerate())
        .map(|(k, v)| {
            let mut image = v.image().into_owned();
            for px in image.data.chunks_exact_mut(3) {
                for (c, g) in px.iter_mut().zip(gain(k, views)) {
                    *c *= g;
                }
            }
            let coverage = v.coverage().map(|c| c.into_owned());
            View::new(v.name.clone(), v.camera, image, coverage, v.background)
        })
        .collect();
    Dataset {
        train,
        test: data.test.clone(),
        points: data.points.clone(),
    }
}

/// The mean PSNR of the training views of `data`, rendered with `params` and each mapped by
/// its exposure in `state` where the run learned one, against their pictures.
fn training_psnr(data: &Dataset, params: &[Params], state: &Checkpoint, opts: &FitOptions) -> f64 {
    let mut sum = 0.0;
    for (k, view) in data.train.iter().enumerate() {
        let corrections = state.per_view.of(&opts.per_view, k);
        let image = render_training_view::<Method>(params, view, opts, corrections).unwrap();
        sum += psnr(&image, &view.image()).unwrap();
    }
    sum / data.train.len() as f64
}

/// The held-out and training PSNR after training 3DGS on `data` with `opts`, and the run's
/// final state.
fn trained(data: &Dataset, opts: &FitOptions) -> (f64, f64, Checkpoint) {
    let mut params = moved_start::<Method>(&truth());
    let mut last = None;
    let opts = FitOptions {
        checkpoint_every: Some(opts.steps),
        ..opts.clone()
    };
    fit::<Method>(data, &mut params, 1.0, &opts, |r| {
        last = r.checkpoint.cloned();
    })
    .unwrap();
    let held_out = evaluate::<Method>(&params, &data.test, &opts).unwrap().psnr;
    let state = last.expect("the last step's state");
    (held_out, training_psnr(data, &params, &state, &opts), state)
}

/// Long enough for each of the 10 views' exposures to take ~125 steps after the delay.
const STEPS: usize = 1500;

#[test]
fn exposure_compensation_trains_views_of_other_gains_as_the_unchanged_ones() {
    let clean = known_dataset();
    let gained = gained(&clean);
    let plain = options(STEPS);
    let exposure = FitOptions {
        per_view: PerViewOptions { exposure: true },
        ..plain.clone()
    };
    let (truth_held_out, truth_training, _) = trained(&clean, &plain);
    let (without, without_training, _) = trained(&gained, &plain);
    let (with, with_training, state) = trained(&gained, &exposure);
    println!(
        "PSNR held out / training views: unchanged views {truth_held_out:.2} / {truth_training:.2} dB; \
         gained views without exposure {without:.2} / {without_training:.2}, with {with:.2} / {with_training:.2}"
    );
    // What each view learned, beside the gain it undoes.
    let views = clean.train.len();
    for k in 0..views {
        let learned = Exposure::from_words(&state.per_view.words[k * 3..(k + 1) * 3]).gains();
        let g = gain(k, views);
        println!(
            "view {k}: gain {:.3} {:.3} {:.3}, learned {:.3} {:.3} {:.3}",
            g[0], g[1], g[2], learned[0], learned[1], learned[2]
        );
    }
    assert!(
        with_training > truth_training - 0.5,
        "with exposure the views train to the unchanged views' PSNR within 0.5 dB"
    );
    assert!(without_training < truth_training - 0.5, "without it, not");
    assert!(
        with > truth_held_out - 0.5,
        "the held-out views, rendered without a correction, keep their PSNR"
    );
}
