//! Adam (Kingma and Ba 2015) over a method's parameter words, with a learning rate per word
//! of `Params` (each field its own rate, as 3DGS trains positions, scales, rotations,
//! opacities and colors at different rates) and bias correction.

use super::checkpoint::AdamState;

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
    /// word `k` of every primitive. `params` and `grads` hold `words` words per primitive.
    pub fn step(&mut self, params: &mut [f32], grads: &[f32], lr: &[f32]) {
        assert_eq!(lr.len(), self.words, "one learning rate per parameter word");
        assert_eq!(params.len(), self.m.len(), "parameters and optimizer state");
        assert_eq!(grads.len(), self.m.len(), "gradients and optimizer state");
        self.step += 1;
        let (b1, b2) = (self.beta1, self.beta2);
        let (c1, c2) = bias_corrections(b1, b2, self.step);
        let words = self.words.max(1);
        for (i, ((p, g), (m, v))) in params
            .iter_mut()
            .zip(grads)
            .zip(self.m.iter_mut().zip(self.v.iter_mut()))
            .enumerate()
        {
            *m = b1 * *m + (1.0 - b1) * g;
            *v = b2 * *v + (1.0 - b2) * g * g;
            *p -= lr[i % words] * (*m / c1) / ((*v / c2).sqrt() + self.eps);
        }
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
}
