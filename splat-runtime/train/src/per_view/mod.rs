//! What a run learns for each training view besides the scene: its exposure, a gain per
//! color channel ([`exposure`]; INRIA 3DGS learns a 3x4 map), and its pose, a rigid motion of
//! its camera in its own frame ([`pose`]; gsplat's `pose_opt`); and for each camera that took
//! them, its intrinsics ([`intrinsics`]: focal lengths, principal point, lens). Pose and
//! intrinsics learn from the camera gradient every backward pass can give, through any camera
//! model.
//!
//! Each view's (and camera's) words train by Adam from the gradients of the passes that drew
//! it, and only then: one not in a batch keeps its moments (its own step count gives its bias
//! correction). They start after a sixth of the run ([`DELAY`]). Held-out views are rendered
//! without a view's correction, as INRIA's and gsplat's trainers do, through their camera's
//! learned intrinsics where a training view shares them; the exposures' log-gains are kept at
//! a mean of zero over the training views, so a held-out view sees their mean exposure (the
//! scene's brightness and the gains' mean are one freedom, which nothing else would hold).
//!
//! Every option is off by default, and a run without any takes the steps it took before they
//! existed, bit for bit: nothing here runs.

mod exposure;
mod intrinsics;
mod pose;

pub use exposure::Exposure;
pub use intrinsics::{Cameras, IntrinsicsCorrection};
pub use pose::{PoseCorrection, angle_between};

use super::adam::{Faults, bias_corrections, step_word};
use super::fit::FitError;
use splat_core::types::Camera;
use splat_io::dataset::View;
use std::borrow::Cow;

/// What a run learns per training view, and per camera.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PerViewOptions {
    /// A gain per color channel per training view ([`Exposure`]).
    pub exposure: bool,
    /// A pose correction per training view ([`PoseCorrection`]).
    pub pose: bool,
    /// An intrinsics correction per camera ([`IntrinsicsCorrection`], [`Cameras`]).
    pub intrinsics: bool,
}

/// INRIA's exposure learning rate: log-linear from the first to the second (after
/// [`DELAY`]).
const EXPOSURE_RATE: (f32, f32) = (0.01, 0.001);

/// The pose corrections' rates, log-linear likewise: radians for the rotation, the scene's
/// extent for the translation. gsplat's 1e-5 moves every view's words at every step (one Adam
/// over all views); here a view moves only when drawn, about steps / views times in a run.
const POSE_RATE: (f32, f32) = (5e-3, 5e-5);

/// The intrinsics corrections' rates, log-linear likewise: for the focal lengths' logs, the
/// principal point in image widths and the lens coefficients. A camera moves at every step
/// that draws one of its views (every step, for a dataset of one camera).
const INTRINSICS_RATE: (f32, f32) = (1e-3, 1e-5);

/// The part of a run before the per-view and per-camera words train (INRIA's preset for real
/// captures waits 5,000 of 30,000 steps for its exposures): the scene takes what the views
/// share first. Trained from the first step, every view's exposure rises or falls with the
/// scene's early error alike and keeps that shift, which the held-out views, rendered without
/// a correction, then show; and poses and intrinsics take up what a scene still far from its
/// views gets wrong: on the built-in dataset (exact cameras, 1,500 steps from random points,
/// 34.37 dB held out without them) pose refinement from the first step ends at 17.03 dB,
/// intrinsics refinement at 18.02 (its focal length 32% off). The price: a scene that first
/// settles into wrong cameras holds them (on the known scene from points near the truth, the
/// focal lengths recover from 10% to 0.3% off without the delay, to 4% with it).
const DELAY: f32 = 1.0 / 6.0;

/// The learned words one view is rendered through: its own (exposure, pose) and its
/// camera's (intrinsics); each empty where the run learns none (`camera` also for a held-out
/// view whose camera took no training view, `view` for every held-out view).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Corrections<'a> {
    pub view: &'a [f32],
    pub camera: &'a [f32],
}

impl PerViewOptions {
    /// Whether the run learns anything per view or per camera.
    pub fn any(&self) -> bool {
        self.exposure || self.pose || self.intrinsics
    }

    /// Words per view: the exposure's, then the pose's.
    pub fn words(&self) -> usize {
        self.exposure as usize * Exposure::WORDS + self.pose as usize * PoseCorrection::WORDS
    }

    /// Words per camera: the intrinsics'.
    pub fn camera_words(&self) -> usize {
        self.intrinsics as usize * IntrinsicsCorrection::WORDS
    }

    /// The words of a view's gradient ([`gradient`](Self::gradient)): its own, then its
    /// camera's.
    pub fn gradient_words(&self) -> usize {
        self.words() + self.camera_words()
    }

    /// What the run learns, as the command line names it (for the run's settings).
    pub fn names(&self) -> Vec<&'static str> {
        [
            (self.exposure, "exposure"),
            (self.pose, "pose"),
            (self.intrinsics, "intrinsics"),
        ]
        .into_iter()
        .filter_map(|(on, name)| on.then_some(name))
        .collect()
    }

    /// Each view word's rate, then each camera word's, where `step` of `steps` starts, in a
    /// scene of `extent`; negative before they train.
    fn rates(&self, step: usize, steps: usize, extent: f32) -> (Vec<f32>, Vec<f32>) {
        let t = step as f32 / steps.max(1) as f32;
        let t = (t - DELAY) / (1.0 - DELAY);
        let at = |(from, to): (f32, f32)| match t < 0.0 {
            true => -1.0,
            false => (from.ln() + t * (to.ln() - from.ln())).exp(),
        };
        let mut view = vec![];
        if self.exposure {
            view.extend([at(EXPOSURE_RATE); 3]);
        }
        if self.pose {
            let pose = at(POSE_RATE);
            let translation = if pose < 0.0 { pose } else { pose * extent };
            view.extend([pose, pose, pose, translation, translation, translation]);
        }
        let camera = vec![at(INTRINSICS_RATE); self.camera_words()];
        (view, camera)
    }

    /// Refuses these options for a loop that does not learn them yet (`which`: "a sharded
    /// run").
    pub(crate) fn refuse(&self, which: &str) -> Result<(), FitError> {
        match self.names()[..] {
            [] => Ok(()),
            ref names => Err(FitError::Unsupported(format!(
                "{which} cannot learn {} yet: train on one process with --backend cpu (or --hardware)",
                names.join(" and ")
            ))),
        }
    }

    /// The exposure in a view's corrections, where the run learns one; `None` for none (a
    /// held-out view).
    pub fn exposure(&self, c: Corrections) -> Option<Exposure> {
        (self.exposure && !c.view.is_empty()).then(|| Exposure::from_words(c.view))
    }

    /// The pose correction in a view's corrections, where the run learns one; `None` for
    /// none.
    pub fn pose(&self, c: Corrections) -> Option<PoseCorrection> {
        let at = self.exposure as usize * Exposure::WORDS;
        (self.pose && !c.view.is_empty()).then(|| PoseCorrection::from_words(&c.view[at..]))
    }

    /// The intrinsics correction in a view's corrections, where the run learns one; `None`
    /// for none.
    pub fn intrinsics(&self, c: Corrections) -> Option<IntrinsicsCorrection> {
        (self.intrinsics && !c.camera.is_empty())
            .then(|| IntrinsicsCorrection::from_words(c.camera))
    }

    /// `camera` as a view with corrections `c` is rendered through: its camera's intrinsics
    /// and its pose corrected, where the run learns them.
    pub fn camera(&self, camera: &Camera, c: Corrections) -> Camera {
        let camera = match self.intrinsics(c) {
            Some(i) => i.apply(camera),
            None => *camera,
        };
        match self.pose(c) {
            Some(p) => p.apply(&camera),
            None => camera,
        }
    }

    /// The gradient by a view's words and its camera's (its corrections `c`, `camera` before
    /// them): the exposure's `by_exposure` (empty without one), then the pose's and the
    /// intrinsics' from the corrected camera's cotangent `d_camera` (the pose moves only the
    /// extrinsics and the intrinsics only the rest, so each reads its part of it).
    pub fn gradient(
        &self,
        (c, camera): (Corrections, &Camera),
        by_exposure: Vec<f32>,
        d_camera: &Camera,
    ) -> Vec<f32> {
        let mut g = by_exposure;
        if let Some(p) = self.pose(c) {
            g.extend(p.backward(camera, d_camera));
        }
        if let Some(i) = self.intrinsics(c) {
            g.extend(i.backward(camera, d_camera));
        }
        g
    }
}

/// Words learned per unit (a training view, a camera) with their Adam moments and step
/// counts: empty where a run learns none.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Learned {
    /// The words of each unit, unit after unit.
    pub words: Vec<f32>,
    pub m: Vec<f32>,
    pub v: Vec<f32>,
    /// Adam steps each unit has taken (the batches that drew it).
    pub steps: Vec<u64>,
}

impl Learned {
    /// `units` units of `words` words each at their start (every kind starts at zero: no
    /// gain (log 0), no motion, no change of intrinsics).
    fn start(words: usize, units: usize) -> Learned {
        let zeros = vec![0.0; words * units];
        Learned {
            words: zeros.clone(),
            m: zeros.clone(),
            v: zeros,
            steps: match words {
                0 => vec![],
                _ => vec![0; units],
            },
        }
    }

    /// How many units it holds words for, if it is whole: `words` words per unit.
    pub fn units(&self, words: usize) -> Option<usize> {
        let n = self.steps.len();
        let whole = self.words.len() == n * words && self.m.len() == n * words;
        (whole && self.v.len() == n * words).then_some(n)
    }

    /// Words per unit (0 for none).
    pub fn words_per_unit(&self) -> usize {
        self.words.len().checked_div(self.steps.len()).unwrap_or(0)
    }

    /// Unit `k`'s words (`n` per unit).
    fn of(&self, n: usize, k: usize) -> &[f32] {
        self.words.get(k * n..(k + 1) * n).unwrap_or(&[])
    }

    /// One Adam step of each unit in `sums` (unit, its summed gradient) at `rates` (one per
    /// word of a unit; negative: not trained yet). A word whose gradient is not finite, or that
    /// the step would make non-finite, keeps its value (added to `faults` by its index past
    /// `first`).
    fn step(
        &mut self,
        sums: Vec<(usize, Vec<f32>)>,
        rates: &[f32],
        (faults, first): (&mut Faults, usize),
    ) {
        if rates.iter().all(|&r| r < 0.0) {
            return;
        }
        let (b1, b2, eps) = (0.9, 0.999, 1e-15);
        for (unit, g) in sums {
            self.steps[unit] += 1;
            let corrections = bias_corrections(b1, b2, self.steps[unit]);
            let at = unit * rates.len();
            for (k, (&g, &rate)) in g.iter().zip(rates).enumerate() {
                if rate < 0.0 {
                    continue;
                }
                let i = at + k;
                let word = (&mut self.words[i], &mut self.m[i], &mut self.v[i]);
                if let Err(fault) = step_word(word, g, rate, (b1, b2, eps), corrections) {
                    faults.add(first + i, fault);
                }
            }
        }
    }
}

/// `grads` (unit, gradient) summed by unit, in the order each unit first comes.
fn sum_by_unit<'a>(grads: impl IntoIterator<Item = (usize, &'a [f32])>) -> Vec<(usize, Vec<f32>)> {
    let mut sums: Vec<(usize, Vec<f32>)> = vec![];
    for (unit, g) in grads {
        match sums.iter_mut().find(|(u, _)| *u == unit) {
            Some((_, sum)) => sum.iter_mut().zip(g).for_each(|(s, g)| *s += g),
            None => sums.push((unit, g.to_vec())),
        }
    }
    sums
}

/// What a run has learned: every training view's words and every camera's.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PerViewState {
    /// [`PerViewOptions::words`] per training view.
    pub views: Learned,
    /// [`PerViewOptions::camera_words`] per camera ([`Cameras`]).
    pub cameras: Learned,
}

impl PerViewState {
    /// The state before a run of `opts` on `views` training views taken by `cameras`
    /// cameras.
    pub fn start(opts: &PerViewOptions, views: usize, cameras: usize) -> PerViewState {
        PerViewState {
            views: Learned::start(opts.words(), views),
            cameras: Learned::start(opts.camera_words(), cameras),
        }
    }

    /// Whether it holds `opts`'s words for `views` views and `cameras` cameras.
    pub fn fits(&self, opts: &PerViewOptions, views: usize, cameras: usize) -> bool {
        let fit = |l: &Learned, words, units| match words {
            0 => l.words.is_empty() && l.steps.is_empty(),
            _ => l.units(words) == Some(units),
        };
        fit(&self.views, opts.words(), views) && fit(&self.cameras, opts.camera_words(), cameras)
    }

    /// Training view `k`'s corrections (its camera's by `cameras`).
    pub fn training<'a>(
        &'a self,
        opts: &PerViewOptions,
        cameras: &Cameras,
        k: usize,
    ) -> Corrections<'a> {
        Corrections {
            view: self.views.of(opts.words(), k),
            camera: match opts.intrinsics {
                true => self.cameras.of(opts.camera_words(), cameras.of_view(k)),
                false => &[],
            },
        }
    }

    /// The corrections of a held-out view taken by `camera`: its camera's, where a training
    /// view shares its intrinsics (`cameras`), and none of its own.
    pub fn held_out<'a>(
        &'a self,
        opts: &PerViewOptions,
        cameras: &Cameras,
        camera: &Camera,
    ) -> Corrections<'a> {
        let found = opts.intrinsics.then(|| cameras.find(camera)).flatten();
        Corrections {
            view: &[],
            camera: found.map_or(&[], |k| self.cameras.of(opts.camera_words(), k)),
        }
    }

    /// Held-out `views` as the run renders them: each through its camera's learned
    /// intrinsics, where a training view shares them ([`held_out`](Self::held_out)).
    pub fn held_out_views<'v>(
        &self,
        opts: &PerViewOptions,
        cameras: &Cameras,
        views: &'v [View],
    ) -> Cow<'v, [View]> {
        if !opts.intrinsics {
            return Cow::Borrowed(views);
        }
        let corrected = |v: &View| {
            let mut v = v.clone();
            v.camera = opts.camera(&v.camera, self.held_out(opts, cameras, &v.camera));
            v
        };
        Cow::Owned(views.iter().map(corrected).collect())
    }

    /// Moves every view's log-gains (where the run learns exposures) by the same amount so
    /// that each channel's mean over the views is zero (`n` words per view, the exposure's
    /// first).
    fn center(&mut self, opts: &PerViewOptions, n: usize) {
        if !opts.exposure {
            return;
        }
        let views = self.views.steps.len().max(1) as f64;
        let words = &mut self.views.words;
        for c in 0..Exposure::WORDS {
            let mean = (words.iter().skip(c).step_by(n))
                .map(|&w| w as f64)
                .sum::<f64>()
                / views;
            for w in words.iter_mut().skip(c).step_by(n) {
                *w -= mean as f32;
            }
        }
    }

    /// One Adam step of each view in `grads` (view, gradient by its words and its camera's;
    /// a view twice in a batch has its gradients summed in their order) and of each of their
    /// `cameras` (the gradients of its views summed likewise) at the rates for `step` of
    /// `steps` in a scene of `extent`.
    /// A word whose gradient is not finite, or that the step would make non-finite, keeps
    /// its value (counted in the returned faults, by its index in the views' words, then in
    /// the cameras' past them).
    pub fn step<'a>(
        &mut self,
        opts: &PerViewOptions,
        cameras: &Cameras,
        grads: impl IntoIterator<Item = (usize, &'a [f32])>,
        (step, steps): (usize, usize),
        extent: f32,
    ) -> Faults {
        let (n, n_camera) = (opts.words(), opts.camera_words());
        let mut faults = Faults::default();
        let (view_rates, camera_rates) = opts.rates(step, steps, extent);
        let grads: Vec<_> = grads.into_iter().collect();
        if n > 0 {
            let sums = sum_by_unit(grads.iter().map(|&(k, g)| (k, &g[..n])));
            self.views.step(sums, &view_rates, (&mut faults, 0));
            self.center(opts, n);
        }
        if n_camera > 0 {
            let by_camera = grads.iter().map(|&(k, g)| (cameras.of_view(k), &g[n..]));
            let first = self.views.words.len();
            self.cameras
                .step(sum_by_unit(by_camera), &camera_rates, (&mut faults, first));
        }
        faults
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// `got`, a gradient at the words `at`, matches the central f64 finite differences of
    /// `loss` to 1e-4 (relative above 1).
    pub(crate) fn assert_finite_differences<const N: usize>(
        what: &str,
        at: [f64; N],
        got: [f32; N],
        loss: impl Fn(&[f64; N]) -> f64,
    ) {
        for k in 0..N {
            let h = 1e-6;
            let (mut up, mut down) = (at, at);
            up[k] += h;
            down[k] -= h;
            let want = (loss(&up) - loss(&down)) / (2.0 * h);
            assert!(
                (got[k] as f64 - want).abs() < 1e-4 * want.abs().max(1.0),
                "{what}, word {k}: {} vs {want}",
                got[k]
            );
        }
    }

    /// Only the views given step, each by its own count (the others move with the mean alone);
    /// a view twice sums its gradients.
    #[test]
    fn views_not_drawn_keep_their_words_and_moments() {
        let opts = PerViewOptions {
            exposure: true,
            ..Default::default()
        };
        let cameras = Cameras::of(&[Camera::default(); 3]);
        let mut state = PerViewState::start(&opts, 3, 1);
        let start = state.clone();
        let g = [1.0f32; 3];
        state.step(&opts, &cameras, [(2, &g[..])], (0, 100), 1.0);
        assert_eq!(state, start, "nothing trains before the delay");
        state.step(&opts, &cameras, [(2, &g[..]), (2, &g[..])], (20, 100), 1.0);
        assert_eq!(state.views.steps, [0, 0, 1]);
        // Bias-corrected, the first step moves every word by the rate against its gradient;
        // then all views move by a third of it back, the mean log-gain kept at zero.
        let rate = opts.rates(20, 100, 1.0).0[0];
        assert!(rate > 0.0 && rate < 0.01);
        let moved = |state: &PerViewState, k| state.training(&opts, &cameras, k).view[0];
        let want = [rate / 3.0, rate / 3.0, -rate + rate / 3.0];
        for (k, want) in want.into_iter().enumerate() {
            assert!((moved(&state, k) - want).abs() < 1e-6, "view {k}");
        }
        let before = state.training(&opts, &cameras, 0).view.to_vec();
        let moments = state.views.m[..3].to_vec();
        let nan = [f32::NAN; 3];
        let faults = state.step(&opts, &cameras, [(0, &nan[..])], (21, 100), 1.0);
        assert_eq!((faults.gradients, faults.first), (3, Some(0)));
        assert_eq!(&state.views.m[..3], &moments[..]);
        // Its words kept (up to the rounding of the mean they move with).
        let kept = state.training(&opts, &cameras, 0).view.iter().zip(&before);
        assert!(kept.into_iter().all(|(a, b)| (a - b).abs() < 1e-7));
    }

    /// A camera steps once per batch from the sum of its views' gradients; a held-out view of
    /// its intrinsics renders through its words, one of other intrinsics through none.
    #[test]
    fn a_camera_learns_from_all_its_views() {
        let opts = PerViewOptions {
            intrinsics: true,
            ..Default::default()
        };
        let other = Camera {
            focal: glam::Vec2::splat(2.0),
            ..Default::default()
        };
        let cameras = Cameras::of(&[Camera::default(), other, Camera::default()]);
        let mut state = PerViewState::start(&opts, 3, 2);
        assert!(state.fits(&opts, 3, 2) && !state.fits(&opts, 3, 1));
        let (up, down) = ([1.0f32; 8], [-3.0f32; 8]);
        // Views 0 and 2 (camera 0) sum to -2 per word; view 1 alone moves camera 1.
        let grads = [(0, &up[..]), (1, &up[..]), (2, &down[..])];
        state.step(&opts, &cameras, grads, (50, 100), 1.0);
        assert_eq!(state.cameras.steps, [1, 1]);
        let rate = opts.rates(50, 100, 1.0).1[0];
        let words = |k| state.training(&opts, &cameras, k).camera.to_vec();
        assert!(
            words(0).iter().all(|&w| (w - rate).abs() < 1e-6),
            "{:?}",
            words(0)
        );
        assert!(
            words(1).iter().all(|&w| (w + rate).abs() < 1e-6),
            "{:?}",
            words(1)
        );
        assert_eq!(words(0), words(2));
        assert_eq!(
            state.held_out(&opts, &cameras, &other).camera,
            &words(1)[..]
        );
        let unseen = Camera {
            focal: glam::Vec2::splat(3.0),
            ..Default::default()
        };
        assert_eq!(
            state.held_out(&opts, &cameras, &unseen),
            Corrections::default()
        );
    }
}
