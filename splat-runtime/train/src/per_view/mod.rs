//! What a run learns for each training view besides the scene: its exposure, a gain per
//! color channel ([`exposure`]; INRIA 3DGS learns a 3x4 map), and its pose, a rigid motion of
//! its camera in its own frame ([`pose`]; gsplat's `pose_opt`), from the camera gradient
//! every backward pass can give, through any camera model.
//!
//! Each view's words train by Adam from the gradients of the passes that drew it, and only
//! then: a view not in a batch keeps its moments (its own step count gives its bias
//! correction). They start after a sixth of the run ([`DELAY`]). Held-out views are rendered
//! without a correction, as INRIA's and gsplat's trainers do; the exposures' log-gains are
//! kept at a mean of zero over the training views, so a held-out view sees their mean
//! exposure (the scene's brightness and the gains' mean are one freedom, which nothing else
//! would hold).
//!
//! Every option is off by default, and a run without any takes the steps it took before they
//! existed, bit for bit: nothing here runs.

mod exposure;
mod pose;

pub use exposure::Exposure;
pub use pose::{PoseCorrection, angle_between};

use super::adam::{Faults, bias_corrections, step_word};
use super::fit::FitError;
use splat_core::types::Camera;

/// What a run learns per training view.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PerViewOptions {
    /// A gain per color channel per training view ([`Exposure`]).
    pub exposure: bool,
    /// A pose correction per training view ([`PoseCorrection`]).
    pub pose: bool,
}

/// INRIA's exposure learning rate: log-linear from the first to the second (after
/// [`DELAY`]).
const EXPOSURE_RATE: (f32, f32) = (0.01, 0.001);

/// The pose corrections' rates, log-linear likewise: radians for the rotation, the scene's
/// extent for the translation. gsplat's 1e-5 moves every view's words at every step (one Adam
/// over all views); here a view moves only when drawn, about steps / views times in a run.
const POSE_RATE: (f32, f32) = (5e-3, 5e-5);

/// The part of a run before the per-view words train (INRIA's preset for real captures waits
/// 5,000 of 30,000 steps for its exposures): the scene takes what the views share first.
/// Trained from the first step, every view's exposure rises or falls with the scene's early
/// error alike and keeps that shift, which the held-out views, rendered without a correction,
/// then show.
const DELAY: f32 = 1.0 / 6.0;

impl PerViewOptions {
    /// Whether the run learns anything per view.
    pub fn any(&self) -> bool {
        self.exposure || self.pose
    }

    /// Words per view: the exposure's, then the pose's.
    pub fn words(&self) -> usize {
        self.exposure as usize * Exposure::WORDS + self.pose as usize * PoseCorrection::WORDS
    }

    /// What each view learns, as the command line names it (for the run's settings).
    pub fn names(&self) -> Vec<&'static str> {
        let exposure = self.exposure.then_some("exposure");
        exposure
            .into_iter()
            .chain(self.pose.then_some("pose"))
            .collect()
    }

    /// Each word's rate where `step` of `steps` starts, in a scene of `extent`; negative
    /// before they train.
    fn rates(&self, step: usize, steps: usize, extent: f32) -> Vec<f32> {
        let t = step as f32 / steps.max(1) as f32;
        let t = (t - DELAY) / (1.0 - DELAY);
        let at = |(from, to): (f32, f32)| match t < 0.0 {
            true => -1.0,
            false => (from.ln() + t * (to.ln() - from.ln())).exp(),
        };
        let mut rates = vec![];
        if self.exposure {
            rates.extend([at(EXPOSURE_RATE); 3]);
        }
        if self.pose {
            let pose = at(POSE_RATE);
            let translation = if pose < 0.0 { pose } else { pose * extent };
            rates.extend([pose, pose, pose, translation, translation, translation]);
        }
        rates
    }

    /// Refuses these options for a loop that does not learn them yet (`which`: "a sharded
    /// run").
    pub(crate) fn refuse(&self, which: &str) -> Result<(), FitError> {
        match self.names()[..] {
            [] => Ok(()),
            ref names => Err(FitError::Unsupported(format!(
                "{which} cannot learn each view's {} yet: train on one process with --backend cpu (or --hardware)",
                names.join(" and ")
            ))),
        }
    }

    /// The exposure in a view's `words`, where the run learns one; `None` for no words (a
    /// held-out view).
    pub fn exposure(&self, words: &[f32]) -> Option<Exposure> {
        (self.exposure && !words.is_empty()).then(|| Exposure::from_words(words))
    }

    /// The pose correction in a view's `words`, where the run learns one; `None` for no
    /// words.
    pub fn pose(&self, words: &[f32]) -> Option<PoseCorrection> {
        let at = self.exposure as usize * Exposure::WORDS;
        (self.pose && !words.is_empty()).then(|| PoseCorrection::from_words(&words[at..]))
    }

    /// `camera` as a view with `words` is trained through: its pose corrected, where the run
    /// learns poses.
    pub fn camera(&self, camera: &Camera, words: &[f32]) -> Camera {
        match self.pose(words) {
            Some(p) => p.apply(camera),
            None => *camera,
        }
    }

    /// The gradient by a view's words (its `words`, `camera` before the correction): the
    /// exposure's `by_exposure` (empty without one), the pose's from the corrected camera's
    /// cotangent `d_camera`.
    pub fn gradient(
        &self,
        (words, camera): (&[f32], &Camera),
        by_exposure: Vec<f32>,
        d_camera: &Camera,
    ) -> Vec<f32> {
        let mut g = by_exposure;
        if let Some(p) = self.pose(words) {
            g.extend(p.backward(camera, d_camera));
        }
        g
    }
}

/// Every training view's learned words with their Adam moments and step counts: empty where
/// a run learns nothing per view.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PerViewState {
    /// `PerViewOptions::words` per training view, view after view.
    pub words: Vec<f32>,
    pub m: Vec<f32>,
    pub v: Vec<f32>,
    /// Adam steps each view has taken (the views a batch drew).
    pub steps: Vec<u64>,
}

impl PerViewState {
    /// The state before a run of `opts` on `views` training views: every view at its start.
    pub fn start(opts: &PerViewOptions, views: usize) -> PerViewState {
        // Every kind starts at zero: no gain (log 0), no motion.
        let words = vec![0.0; opts.words() * views];
        PerViewState {
            m: vec![0.0; words.len()],
            v: vec![0.0; words.len()],
            words,
            steps: match opts.any() {
                true => vec![0; views],
                false => vec![],
            },
        }
    }

    /// How many views it holds words for, if it is whole: `words` words per view.
    pub fn views(&self, words: usize) -> Option<usize> {
        let n = self.steps.len();
        let whole = self.words.len() == n * words && self.m.len() == n * words;
        (whole && self.v.len() == n * words).then_some(n)
    }

    /// View `k`'s words.
    pub fn of(&self, opts: &PerViewOptions, k: usize) -> &[f32] {
        let n = opts.words();
        self.words.get(k * n..(k + 1) * n).unwrap_or(&[])
    }

    /// Moves every view's log-gains (where the run learns exposures) by the same amount so
    /// that each channel's mean over the views is zero (`n` words per view, the exposure's
    /// first).
    fn center(&mut self, opts: &PerViewOptions, n: usize) {
        if !opts.exposure {
            return;
        }
        let views = self.steps.len().max(1) as f64;
        for c in 0..Exposure::WORDS {
            let mean = self
                .words
                .iter()
                .skip(c)
                .step_by(n)
                .map(|&w| w as f64)
                .sum::<f64>()
                / views;
            for w in self.words.iter_mut().skip(c).step_by(n) {
                *w -= mean as f32;
            }
        }
    }

    /// One Adam step of each view in `grads` (view, gradient by its words; a view twice in a
    /// batch has its gradients summed in their order) at the rates for `step` of `steps` in
    /// a scene of `extent`.
    /// A word whose gradient is not finite, or that the step would make non-finite, keeps
    /// its value (counted in the returned faults, by its index in `words`).
    pub fn step<'a>(
        &mut self,
        opts: &PerViewOptions,
        grads: impl IntoIterator<Item = (usize, &'a [f32])>,
        (step, steps): (usize, usize),
        extent: f32,
    ) -> Faults {
        let n = opts.words();
        let mut faults = Faults::default();
        if n == 0 {
            return faults;
        }
        let mut sums: Vec<(usize, Vec<f32>)> = vec![];
        for (view, g) in grads {
            match sums.iter_mut().find(|(v, _)| *v == view) {
                Some((_, sum)) => sum.iter_mut().zip(g).for_each(|(s, g)| *s += g),
                None => sums.push((view, g.to_vec())),
            }
        }
        let rates = opts.rates(step, steps, extent);
        if rates.iter().all(|&r| r < 0.0) {
            return faults;
        }
        let (b1, b2, eps) = (0.9, 0.999, 1e-15);
        for (view, g) in sums {
            self.steps[view] += 1;
            let corrections = bias_corrections(b1, b2, self.steps[view]);
            let at = view * n;
            for (k, (&g, &rate)) in g.iter().zip(&rates).enumerate() {
                if rate < 0.0 {
                    continue;
                }
                let i = at + k;
                let word = (&mut self.words[i], &mut self.m[i], &mut self.v[i]);
                if let Err(fault) = step_word(word, g, rate, (b1, b2, eps), corrections) {
                    faults.add(i, fault);
                }
            }
        }
        self.center(opts, n);
        faults
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Only the views given step, each by its own count (the others move with the mean alone);
    /// a view twice sums its gradients.
    #[test]
    fn views_not_drawn_keep_their_words_and_moments() {
        let opts = PerViewOptions {
            exposure: true,
            ..Default::default()
        };
        let mut state = PerViewState::start(&opts, 3);
        let start = state.clone();
        let g = [1.0f32; 3];
        state.step(&opts, [(2, &g[..])], (0, 100), 1.0);
        assert_eq!(state, start, "nothing trains before the delay");
        state.step(&opts, [(2, &g[..]), (2, &g[..])], (20, 100), 1.0);
        assert_eq!(state.steps, [0, 0, 1]);
        // Bias-corrected, the first step moves every word by the rate against its gradient;
        // then all views move by a third of it back, the mean log-gain kept at zero.
        let rate = opts.rates(20, 100, 1.0)[0];
        assert!(rate > 0.0 && rate < 0.01);
        let moved = |state: &PerViewState, k| state.of(&opts, k)[0];
        let want = [rate / 3.0, rate / 3.0, -rate + rate / 3.0];
        for (k, want) in want.into_iter().enumerate() {
            assert!((moved(&state, k) - want).abs() < 1e-6, "view {k}");
        }
        let (before, moments) = (state.of(&opts, 0).to_vec(), state.m[..3].to_vec());
        let faults = state.step(&opts, [(0, &[f32::NAN; 3][..])], (21, 100), 1.0);
        assert_eq!((faults.gradients, faults.first), (3, Some(0)));
        assert_eq!(&state.m[..3], &moments[..]);
        // Its words kept (up to the rounding of the mean they move with).
        let kept = state.of(&opts, 0).iter().zip(&before);
        assert!(kept.into_iter().all(|(a, b)| (a - b).abs() < 1e-7));
    }
}
