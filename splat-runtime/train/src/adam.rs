//! Adam (Kingma and Ba 2015) over a method's parameter words, with a learning rate per word
//! of `Params` (each field its own rate, as 3DGS trains positions, scales, rotations,
//! opacities and colors at different rates) and bias correction.

use rayon::prelude::*;
use splat_core::method::{SplatMethod, word_name};

/// Adam's state: its step count and both moments, one per parameter word.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AdamState {
    pub step: u64,
    pub m: Vec<f32>,
    pub v: Vec<f32>,
}

/// Adam's state for `primitives` x `words` parameter words.
pub struct Adam {
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
    words: usize,
    step: u64,
    m: Vec<f32>,
    v: Vec<f32>,
}

impl Adam {
    /// The usual constants of 3DGS: beta 0.9 / 0.999, epsilon 1e-15.
    pub fn new(primitives: usize, words: usize) -> Adam {
        Adam {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-15,
            words,
            step: 0,
            m: vec![0.0; primitives * words],
            v: vec![0.0; primitives * words],
        }
    }

    /// One step: `params -= lr * m_hat / (sqrt(v_hat) + eps)`, where `lr[k]` is the rate of
    /// word `k` of every primitive; a negative rate freezes the word this step (no move, no
    /// moment update). `params` and `grads` hold `words` words per primitive. Words the step
    /// cannot move are left as [`Faults`] says, and counted there. Chunks of primitives run
    /// in parallel; each word's update is independent of the others, so the result is the
    /// same for any thread count.
    pub fn step(&mut self, params: &mut [f32], grads: &[f32], lr: &[f32]) -> Faults {
        assert_eq!(lr.len(), self.words, "one learning rate per parameter word");
        assert_eq!(params.len(), self.m.len(), "parameters and optimizer state");
        assert_eq!(grads.len(), self.m.len(), "gradients and optimizer state");
        self.step += 1;
        let (b1, b2, eps) = (self.beta1, self.beta2, self.eps);
        let (c1, c2) = bias_corrections(b1, b2, self.step);
        let words = self.words.max(1);
        let chunk = words * 1024;
        params
            .par_chunks_mut(chunk)
            .zip(grads.par_chunks(chunk))
            .zip(self.m.par_chunks_mut(chunk))
            .zip(self.v.par_chunks_mut(chunk))
            .enumerate()
            .map(|(c, (((p, g), m), v))| {
                let mut faults = Faults::default();
                let rows = p
                    .chunks_exact_mut(words)
                    .zip(g.chunks_exact(words))
                    .zip(m.chunks_exact_mut(words).zip(v.chunks_exact_mut(words)));
                for (i, ((p, g), (m, v))) in rows.enumerate() {
                    for k in 0..words {
                        let (rate, g) = (lr[k], g[k]);
                        if rate < 0.0 {
                            continue;
                        }
                        let word = (&mut p[k], &mut m[k], &mut v[k]);
                        if let Err(fault) = step_word(word, g, rate, (b1, b2, eps), (c1, c2)) {
                            faults.add(c * chunk + i * words + k, fault);
                        }
                    }
                }
                faults
            })
            .reduce(Faults::default, Faults::merge)
    }
}

/// One Adam step of one word `(p, m, v)` with gradient `g` at `rate`, under `(beta1, beta2,
/// eps)` and the bias corrections `(c1, c2)`; a word it cannot step is left as [`Fault`] says.
pub(crate) fn step_word(
    (p, m, v): (&mut f32, &mut f32, &mut f32),
    g: f32,
    rate: f32,
    (b1, b2, eps): (f32, f32, f32),
    (c1, c2): (f32, f32),
) -> Result<(), Fault> {
    if !g.is_finite() {
        return Err(Fault::Gradient);
    }
    let mi = b1 * *m + (1.0 - b1) * g;
    let vi = b2 * *v + (1.0 - b2) * g * g;
    let pi = *p - rate * (mi / c1) / ((vi / c2).sqrt() + eps);
    if !(pi.is_finite() && vi.is_finite()) {
        (*m, *v) = (0.0, 0.0);
        return Err(Fault::Step);
    }
    (*m, *v, *p) = (mi, vi, pi);
    Ok(())
}

/// What went wrong with one word in an Adam step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fault {
    /// Its gradient was not finite: the word and its moments keep their values (the step is
    /// skipped for it).
    Gradient,
    /// The step would have made the word or its second moment non-finite (a gradient past
    /// ~6e20 overflows the second moment): the word keeps its value and its moments restart from
    /// zero.
    Step,
}

/// The words an Adam step could not move, by [`Fault`]: training goes on around them, and
/// the caller says which they were.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Faults {
    /// Words with a non-finite gradient ([`Fault::Gradient`]).
    pub gradients: u32,
    /// Words whose step was undone ([`Fault::Step`]).
    pub steps: u32,
    /// The lowest such word (of all primitives' words, one primitive after another).
    pub first: Option<usize>,
}

impl Faults {
    pub(crate) fn add(&mut self, word: usize, fault: Fault) {
        match fault {
            Fault::Gradient => self.gradients += 1,
            Fault::Step => self.steps += 1,
        }
        self.first = Some(self.first.map_or(word, |f| f.min(word)));
    }

    /// Both counts together.
    fn merge(a: Faults, b: Faults) -> Faults {
        let first = match (a.first, b.first) {
            (Some(x), Some(y)) => Some(x.min(y)),
            (x, y) => x.or(y),
        };
        Faults {
            gradients: a.gradients + b.gradients,
            steps: a.steps + b.steps,
            first,
        }
    }

    /// Whether any word was left alone.
    pub fn any(&self) -> bool {
        self.first.is_some()
    }

    /// What happened, naming the first word's primitive and parameter field of `M`: "3
    /// parameter words with a non-finite gradient kept their values (the first: primitive
    /// 17's `log_scale`)".
    pub fn describe<M: SplatMethod>(&self) -> String {
        let words = |n: u32| match n {
            1 => "1 parameter word".to_string(),
            n => format!("{n} parameter words"),
        };
        let mut what = Vec::new();
        if self.gradients > 0 {
            let n = words(self.gradients);
            what.push(format!("{n} with a non-finite gradient kept their values"));
        }
        if self.steps > 0 {
            let n = words(self.steps);
            what.push(format!(
                "{n} that the step would have made non-finite kept their values and restart their moments"
            ));
        }
        format!(
            "{} (the first: {})",
            what.join("; "),
            word_name::<M>(self.first.unwrap_or(0))
        )
    }
}

impl Adam {
    /// Adam for parameters of `words` words per primitive, from a saved state.
    pub fn resume(words: usize, state: AdamState) -> Adam {
        Adam {
            words,
            step: state.step,
            m: state.m,
            v: state.v,
            ..Adam::new(0, words)
        }
    }

    /// The step count and both moments, for a checkpoint.
    pub fn state(&self) -> AdamState {
        AdamState {
            step: self.step,
            m: self.m.clone(),
            v: self.v.clone(),
        }
    }

    /// Follows a change of the primitive set: new primitive `i` keeps the moments of old
    /// primitive `origin[i]`, or starts from zero moments where it is `None`.
    pub fn remap(&mut self, origin: &[Option<usize>]) {
        self.m = remap_rows(&self.m, self.words, origin);
        self.v = remap_rows(&self.v, self.words, origin);
    }

    /// Clears the moments of the words where `changed` (per word, as `params`) is true: a
    /// value reset from outside starts its optimization afresh.
    pub fn forget(&mut self, changed: impl Fn(usize) -> bool) {
        for (k, (m, v)) in self.m.iter_mut().zip(self.v.iter_mut()).enumerate() {
            if changed(k) {
                (*m, *v) = (0.0, 0.0);
            }
        }
    }
}

/// `1 - beta1^t` and `1 - beta2^t`, Adam's bias corrections after `t` steps.
pub fn bias_corrections(beta1: f32, beta2: f32, t: u64) -> (f32, f32) {
    // Past 2^31 steps both are 1 to f32 precision.
    let t = t.min(i32::MAX as u64) as i32;
    (1.0 - beta1.powi(t), 1.0 - beta2.powi(t))
}

/// Rows of `words` values, new row `i` a copy of old row `origin[i]` or zeros where `None`.
pub fn remap_rows(old: &[f32], words: usize, origin: &[Option<usize>]) -> Vec<f32> {
    let mut out = vec![0.0; origin.len() * words];
    for (dst, src) in out.chunks_exact_mut(words.max(1)).zip(origin) {
        if let Some(i) = src {
            dst.copy_from_slice(&old[i * words..(i + 1) * words]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_step_moves_each_word_by_its_rate_against_the_gradient() {
        let mut adam = Adam::new(2, 2);
        let mut p = vec![1.0, 1.0, 1.0, 1.0];
        adam.step(&mut p, &[0.5, -2.0, 3.0, 0.0], &[0.1, 0.01]);
        // Bias-corrected, the first step is lr * g / |g|.
        let want = [0.9, 1.01, 0.9, 1.0];
        for (a, b) in p.iter().zip(want) {
            assert!((a - b).abs() < 1e-6, "{p:?}");
        }
    }

    /// A negative rate freezes its word (3DGS's higher SH bands before their step): it keeps
    /// its value and gathers no moment, whatever its gradient, even a non-finite one.
    #[test]
    fn a_negative_rate_freezes_its_word() {
        let mut adam = Adam::new(2, 2);
        let mut p = vec![1.0; 4];
        let faults = adam.step(&mut p, &[0.5, f32::NAN, 3.0, 2.0], &[0.1, -1.0]);
        assert_eq!(faults, Faults::default());
        assert_eq!((p[1], p[3]), (1.0, 1.0));
        assert!(p[0] < 1.0 && p[2] < 1.0);
        let state = adam.state();
        assert_eq!(
            (state.m[1], state.v[1], state.m[3], state.v[3]),
            (0.0, 0.0, 0.0, 0.0)
        );
    }

    /// Thousands of primitives run in parallel chunks: every word steps as it would alone,
    /// and the faults are counted across chunks with the lowest word first.
    #[test]
    fn chunks_step_as_one_and_count_faults_across_them() {
        let (n, words) = (5000, 3);
        let grads: Vec<f32> = (0..n * words).map(|k| (k % 7) as f32 - 3.0).collect();
        let mut bad = grads.clone();
        (bad[4000 * words + 1], bad[3100 * words]) = (f32::INFINITY, f32::NAN);
        let mut adam = Adam::new(n, words);
        let mut p = vec![0.0; n * words];
        let faults = adam.step(&mut p, &bad, &[0.1, 0.2, 0.3]);
        assert_eq!(
            faults,
            Faults {
                gradients: 2,
                steps: 0,
                first: Some(3100 * words)
            }
        );
        for (k, (x, g)) in p.iter().zip(&bad).enumerate() {
            let want = match g.is_finite() {
                true => -[0.1, 0.2, 0.3][k % words] * g.signum() * (*g != 0.0) as u8 as f32,
                false => 0.0,
            };
            assert!((x - want).abs() < 1e-5, "word {k}: {x} vs {want}");
        }
    }

    #[test]
    fn adam_minimizes_a_quadratic() {
        let target = [3.0f32, -1.0, 0.5];
        let mut p = vec![0.0f32; 3];
        let mut adam = Adam::new(1, 3);
        for _ in 0..2000 {
            let g: Vec<f32> = p.iter().zip(target).map(|(x, t)| 2.0 * (x - t)).collect();
            adam.step(&mut p, &g, &[0.01; 3]);
        }
        for (x, t) in p.iter().zip(target) {
            assert!((x - t).abs() < 1e-2, "{p:?}");
        }
    }

    #[test]
    fn moments_follow_the_primitives_and_reset_words_forget_theirs() {
        let mut adam = Adam::new(2, 2);
        let mut p = vec![0.0; 4];
        adam.step(&mut p, &[1.0, 1.0, 2.0, 2.0], &[0.1, 0.1]);
        // Primitive 0 is dropped, 1 kept (now first), one new one appended.
        adam.remap(&[Some(1), None]);
        adam.forget(|k| k == 1);
        let mut p = vec![0.0; 4];
        adam.step(&mut p, &[0.0; 4], &[0.1, 0.1]);
        // With a zero gradient only remembered moments move a word.
        assert!(p[0] < 0.0, "{p:?}");
        assert_eq!(&p[1..], [0.0; 3], "forgotten and new words stay");
    }

    #[test]
    fn words_it_cannot_step_keep_their_values_and_are_counted() {
        let mut adam = Adam::new(2, 3);
        let mut p = vec![1.0; 6];
        adam.step(&mut p, &[1.0; 6], &[0.1; 3]);
        let (before, moments) = (p.clone(), adam.state());
        // Word 4's gradient is not finite; word 2's squares to infinity.
        let faults = adam.step(&mut p, &[1.0, 1.0, 1e30, 1.0, f32::NAN, 1.0], &[0.1; 3]);
        assert_eq!(
            faults,
            Faults {
                gradients: 1,
                steps: 1,
                first: Some(2)
            }
        );
        assert!(p.iter().all(|x| x.is_finite()), "{p:?}");
        assert_eq!(
            (p[2], p[4]),
            (before[2], before[4]),
            "both words stand still"
        );
        let after = adam.state();
        assert_eq!((after.m[4], after.v[4]), (moments.m[4], moments.v[4]));
        assert_eq!(
            (after.m[2], after.v[2]),
            (0.0, 0.0),
            "an undone step restarts"
        );
        assert!(p[0] < before[0] && p[5] < before[5], "the others step");
    }
}
