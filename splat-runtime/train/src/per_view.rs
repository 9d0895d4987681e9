//! What a run learns for each training view besides the scene: so far its exposure, a gain
//! per color channel (as INRIA 3DGS's exposure compensation, which learns a 3x4 map). Each view's words
//! train by Adam from the gradients of the passes that drew it, and only then: a view not in a
//! batch keeps its words and moments (its own step count gives its bias correction). Held-out
//! views are rendered without a correction, as INRIA's trainer does; the training views'
//! log-gains are kept at a mean of zero per channel, so that is their mean exposure (the
//! scene's brightness and the gains' mean are one freedom, which nothing else would hold).
//!
//! Every option is off by default, and a run without any takes the steps it took before they
//! existed, bit for bit: nothing here runs.

use super::adam::{Faults, bias_corrections, step_word};
use super::fit::FitError;
use splat_core::frame::Image;

/// What a run learns per training view.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PerViewOptions {
    /// A gain per color channel per training view ([`Exposure`]).
    pub exposure: bool,
}

/// INRIA's exposure learning rate: log-linear from the first to the second over the run,
/// after [`EXPOSURE_DELAY`].
const EXPOSURE_RATE: (f32, f32) = (0.01, 0.001);

/// The part of a run before exposures train (INRIA's preset for real captures waits 5,000 of
/// 30,000 steps): the scene takes the views' common brightness first. Trained from the first
/// step, every view's exposure rises or falls with the scene's early error alike and keeps
/// that shift (the scene's brightness and the exposures' mean are one freedom), which the
/// held-out views, rendered without a correction, then show.
const EXPOSURE_DELAY: f32 = 1.0 / 6.0;

impl PerViewOptions {
    /// Whether the run learns anything per view.
    pub fn any(&self) -> bool {
        self.exposure
    }

    /// Words per view.
    pub fn words(&self) -> usize {
        match self.exposure {
            true => Exposure::WORDS,
            false => 0,
        }
    }

    /// What each view learns, as the command line names it (for the run's settings).
    pub fn names(&self) -> Vec<&'static str> {
        self.exposure.then_some("exposure").into_iter().collect()
    }

    /// Each view's words' rate where `step` of `steps` starts; negative before they train.
    fn rate(&self, step: usize, steps: usize) -> f32 {
        let t = step as f32 / steps.max(1) as f32;
        let t = (t - EXPOSURE_DELAY) / (1.0 - EXPOSURE_DELAY);
        let (from, to) = EXPOSURE_RATE;
        match t < 0.0 {
            true => -1.0,
            false => (from.ln() + t * (to.ln() - from.ln())).exp(),
        }
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
}

/// A view's exposure and white balance: a gain per color channel on the scene's radiance,
/// held as its logarithm (a word per channel, 0 for none: Adam's steps are relative changes,
/// and a gain stays positive). On a premultiplied render it scales each channel, so the
/// background a transparent view is composited on keeps its color.
///
/// Why gains rather than INRIA's 3x4 affine map (which the issue allowed): a change of
/// exposure time, aperture, ISO or white balance multiplies each channel of linear sensor
/// values; the map's other 9 numbers per picture (channel mixing, offsets) follow no change
/// of exposure, and whatever they absorb the scene gives up, which the held-out views,
/// rendered without a correction, show: on the known scene's gained views the 3x4 map trained
/// the views as well as gains do but lost 5.9 dB on the held-out views
/// (`methods/tests/per_view.rs`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Exposure {
    /// Each channel's log-gain.
    pub log_gain: [f32; 3],
}

impl Exposure {
    pub const WORDS: usize = 3;
    pub const IDENTITY: Exposure = Exposure { log_gain: [0.0; 3] };

    /// The exposure in its 3 words.
    pub fn from_words(words: &[f32]) -> Exposure {
        Exposure {
            log_gain: [words[0], words[1], words[2]],
        }
    }

    pub fn words(&self) -> [f32; 3] {
        self.log_gain
    }

    /// Each channel's gain.
    pub fn gains(&self) -> [f32; 3] {
        self.log_gain.map(f32::exp)
    }

    /// `color` (premultiplied, on black) scaled.
    pub fn apply(&self, color: &mut Image) {
        let gains = self.gains();
        for px in color.data.chunks_exact_mut(3) {
            for (c, g) in px.iter_mut().zip(gains) {
                *c *= g;
            }
        }
    }

    /// The backward pass: given the render before it (`color`) and the gradient `d_out` by
    /// its output, `d_out` becomes the gradient by `color`, and the gradient by the words is
    /// returned (summed over pixels in f64, in order).
    pub fn backward(&self, color: &Image, d_out: &mut [f32]) -> [f32; 3] {
        let gains = self.gains();
        let mut words = [0.0f64; 3];
        for (d, x) in d_out.chunks_exact_mut(3).zip(color.data.chunks_exact(3)) {
            for c in 0..3 {
                // d out / d log-gain = gain * color.
                words[c] += (d[c] * x[c] * gains[c]) as f64;
                d[c] *= gains[c];
            }
        }
        words.map(|w| w as f32)
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
        let one: Vec<f32> = match opts.exposure {
            true => Exposure::IDENTITY.words().to_vec(),
            false => vec![],
        };
        let words = one.repeat(views);
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

    /// Moves every view's log-gains by the same amount so that each channel's mean over the
    /// views is zero (`n` words per view, the exposure's first).
    fn center(&mut self, n: usize) {
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
    /// batch has its gradients summed in their order) at the rate for `step` of `steps`.
    /// A word whose gradient is not finite, or that the step would make non-finite, keeps
    /// its value (counted in the returned faults, by the view's first word).
    pub fn step<'a>(
        &mut self,
        opts: &PerViewOptions,
        grads: impl IntoIterator<Item = (usize, &'a [f32])>,
        (step, steps): (usize, usize),
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
        let rate = opts.rate(step, steps);
        if rate < 0.0 {
            return faults;
        }
        let (b1, b2, eps) = (0.9, 0.999, 1e-15);
        for (view, g) in sums {
            self.steps[view] += 1;
            let corrections = bias_corrections(b1, b2, self.steps[view]);
            let at = view * n;
            for (k, &g) in g.iter().enumerate().take(n) {
                let i = at + k;
                let word = (&mut self.words[i], &mut self.m[i], &mut self.v[i]);
                if let Err(fault) = step_word(word, g, rate, (b1, b2, eps), corrections) {
                    faults.add(i, fault);
                }
            }
        }
        self.center(n);
        faults
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(data: Vec<f32>) -> Image {
        Image {
            width: (data.len() / 3) as u32,
            height: 1,
            channels: 3,
            data,
        }
    }

    /// The backward pass against f64 finite differences of `sum w * out` by every word and
    /// color.
    #[test]
    fn exposure_gradients_match_finite_differences() {
        let words = vec![0.3f32, -0.2, 0.1];
        let color = image(vec![0.2, 0.5, 0.7, 0.9, 0.1, 0.4]);
        let weights = [0.7f32, -1.1, 0.4, 0.2, 0.9, -0.5];
        let loss = |words: &[f32], color: &Image| -> f64 {
            let mut out = color.clone();
            Exposure::from_words(words).apply(&mut out);
            (out.data.iter().zip(&weights))
                .map(|(o, w)| (o * w) as f64)
                .sum()
        };
        let mut d = weights.to_vec();
        let by_words = Exposure::from_words(&words).backward(&color, &mut d);
        let h = 1e-3;
        let fd = |f: &dyn Fn(f32) -> f64| (f(h) - f(-h)) / (2.0 * h as f64);
        for k in 0..3 {
            let want = fd(&|x| {
                let mut w = words.clone();
                w[k] += x;
                loss(&w, &color)
            });
            assert!((by_words[k] as f64 - want).abs() < 1e-3, "word {k}");
        }
        for (i, got) in d.iter().enumerate() {
            let want = fd(&|x| {
                let mut c = color.clone();
                c.data[i] += x;
                loss(&words, &c)
            });
            assert!((*got as f64 - want).abs() < 1e-3, "color {i}");
        }
    }

    #[test]
    fn the_identity_leaves_colors_and_gradients_as_they_are() {
        let mut color = image(vec![0.2, 0.5, 0.7, 0.9, 0.1, 0.4]);
        let before = color.clone();
        Exposure::IDENTITY.apply(&mut color);
        assert_eq!(color, before);
        let mut d = vec![0.5, -0.25, 1.0, 2.0, -3.0, 0.125];
        let want = d.clone();
        Exposure::IDENTITY.backward(&color, &mut d);
        assert_eq!(d, want);
    }

    /// Only the views given step, each by its own count (the others move with the mean alone);
    /// a view twice sums its gradients.
    #[test]
    fn views_not_drawn_keep_their_words_and_moments() {
        let opts = PerViewOptions { exposure: true };
        let mut state = PerViewState::start(&opts, 3);
        let start = state.clone();
        let g = [1.0f32; 3];
        state.step(&opts, [(2, &g[..])], (0, 100));
        assert_eq!(state, start, "nothing trains before the delay");
        state.step(&opts, [(2, &g[..]), (2, &g[..])], (20, 100));
        assert_eq!(state.steps, [0, 0, 1]);
        // Bias-corrected, the first step moves every word by the rate against its gradient;
        // then all views move by a third of it back, the mean log-gain kept at zero.
        let rate = opts.rate(20, 100);
        assert!(rate > 0.0 && rate < 0.01);
        let moved = |state: &PerViewState, k| state.of(&opts, k)[0];
        let want = [rate / 3.0, rate / 3.0, -rate + rate / 3.0];
        for (k, want) in want.into_iter().enumerate() {
            assert!((moved(&state, k) - want).abs() < 1e-6, "view {k}");
        }
        let (before, moments) = (state.of(&opts, 0).to_vec(), state.m[..3].to_vec());
        let faults = state.step(&opts, [(0, &[f32::NAN; 3][..])], (21, 100));
        assert_eq!((faults.gradients, faults.first), (3, Some(0)));
        assert_eq!(&state.m[..3], &moments[..]);
        // Its words kept (up to the rounding of the mean they move with).
        let kept = state.of(&opts, 0).iter().zip(&before);
        assert!(kept.into_iter().all(|(a, b)| (a - b).abs() < 1e-7));
    }
}
