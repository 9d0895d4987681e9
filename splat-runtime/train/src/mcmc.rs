//! MCMC density control (Kheradmand et al. 2024, "3D Gaussian Splatting as Markov Chain Monte
//! Carlo"), with the defaults of gsplat's `MCMCStrategy`: the primitives are samples that
//! never get pruned or split. Every hundred steps the dead ones (opacity at the floor) move
//! onto live ones drawn by opacity, and 5% more are added the same way; a primitive copied
//! `n - 1` times shares its opacity and size with its copies so that the stack looks as it did.
//! Every step, faint primitives wander by noise shaped by their covariance, and small
//! opacity and scale penalties make unused primitives fade until they are reused.
//!
//! Relocation reads a method's primitives through [`Trainable::shape`]; the per-step terms
//! work on the parameter words ([`GaussianWords`]), on the host and on the device alike.

use super::densify::Refinement;
use super::trainable::{Shape, Trainable};
use glam::{Mat3, Vec3, Vec4};
use splat_core::flat::Flat;

/// When and how MCMC acts.
#[derive(Clone, Debug)]
pub struct McmcOptions {
    /// Relocate and grow every `every` steps from `start` until `stop`.
    pub start: usize,
    pub stop: usize,
    pub every: usize,
    /// Dead at or below this opacity.
    pub min_opacity: f32,
    /// Each refinement adds this fraction of the primitives, up to `max_primitives`.
    pub growth: f32,
    pub max_primitives: usize,
    /// The position noise's scale relative to the position's learning rate.
    pub noise_lr: f32,
    /// Weights of the mean opacity and the mean scale added to the loss.
    pub opacity_reg: f32,
    pub scale_reg: f32,
}

impl Default for McmcOptions {
    fn default() -> Self {
        McmcOptions {
            start: 500,
            stop: 25_000,
            every: 100,
            min_opacity: 0.005,
            growth: 0.05,
            max_primitives: 1_000_000,
            noise_lr: 5e5,
            opacity_reg: 0.01,
            scale_reg: 0.01,
        }
    }
}

impl McmcOptions {
    /// Whether step `step` (0-based, after its optimizer step) relocates and grows.
    pub fn refines_at(&self, step: usize) -> bool {
        step > self.start && step < self.stop && step.is_multiple_of(self.every.max(1))
    }

    /// A run's first primitives as the MCMC paper starts them (gsplat's MCMC settings):
    /// opacity 0.5, a tenth of the size.
    pub fn prepare<M: Trainable>(params: &mut [M::Params]) {
        for p in params.iter_mut() {
            let s = M::shape(p);
            let started = Shape {
                opacity: 0.5,
                scale: s.scale * 0.1,
                ..s
            };
            *p = M::with_shape(p, &started);
        }
    }
}

/// Where a Gaussian's parameters sit among a method's words: the first word of the position
/// (3), the log scales (3), the (w, x, y, z) rotation (4) and the opacity logit, as
/// [`Shape::from_gaussian`] reads them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GaussianWords {
    pub position: usize,
    pub log_scale: usize,
    pub rotation: usize,
    pub opacity: usize,
}

impl GaussianWords {
    /// The layout of `M`'s words, found by moving one word at a time and watching which part
    /// of [`Trainable::shape`] follows; `None` unless the layout then reproduces `shape` on
    /// random parameters (a method parameterized otherwise).
    pub fn of<M: Trainable>() -> Option<GaussianWords> {
        let words = M::Params::LEN;
        let mut base = vec![0.0f32; words];
        M::from_point(Vec3::new(0.1, 0.2, 0.3), Vec3::splat(0.5), 0.1).write_words(&mut base);
        // Off the start's special values (an identity rotation does not move when its w does).
        let mut rng = fastrand::Rng::with_seed(7);
        for w in base.iter_mut() {
            *w += 0.2 * rng.f32() - 0.1;
        }
        let shape_of = |w: &[f32]| M::shape(&M::Params::read_words(w));
        let first = shape_of(&base);
        let moves = |k: usize, part: fn(&Shape) -> Vec4| {
            let mut w = base.clone();
            w[k] += 0.25;
            (part(&shape_of(&w)) - part(&first))
                .abs()
                .cmpgt(Vec4::splat(1e-6))
        };
        let find = |part: fn(&Shape) -> Vec4, lane: usize| {
            (0..words).find(|&k| moves(k, part).bitmask() == 1 << lane)
        };
        let layout = GaussianWords {
            position: find(|s| s.position.extend(0.0), 0)?,
            log_scale: find(|s| s.scale.extend(0.0), 0)?,
            rotation: (0..words).find(|&k| moves(k, |s| Vec4::from(s.rotation)).any())?,
            opacity: find(|s| Vec4::new(s.opacity, 0.0, 0.0, 0.0), 0)?,
        };
        let last = [
            layout.position + 3,
            layout.log_scale + 3,
            layout.rotation + 4,
            layout.opacity + 1,
        ];
        if last.iter().any(|&end| end > words) {
            return None;
        }
        let reproduces = (0..8).all(|_| {
            let w: Vec<f32> = base.iter().map(|x| x + rng.f32() - 0.5).collect();
            let (want, got) = (shape_of(&w), layout.shape(&w));
            let close = |a: Vec4, b: Vec4| {
                (a - b).abs().max_element() <= 1e-5 * a.abs().max_element().max(1.0)
            };
            close(
                want.position.extend(want.opacity),
                got.position.extend(got.opacity),
            ) && close(want.scale.extend(0.0), got.scale.extend(0.0))
                && close(Vec4::from(want.rotation), Vec4::from(got.rotation))
        });
        reproduces.then_some(layout)
    }

    /// The shape held by one primitive's words.
    pub fn shape(&self, w: &[f32]) -> Shape {
        let v3 = |k: usize| Vec3::new(w[k], w[k + 1], w[k + 2]);
        let r = self.rotation;
        let rotation = Vec4::new(w[r], w[r + 1], w[r + 2], w[r + 3]);
        Shape::from_gaussian(
            v3(self.position),
            v3(self.log_scale),
            rotation,
            w[self.opacity],
        )
    }
}

/// MCMC for one method: its options and where its Gaussians' words are.
#[derive(Clone, Debug)]
pub struct Mcmc {
    pub opts: McmcOptions,
    pub words: GaussianWords,
}

/// The most copies one relocation shares a primitive among (gsplat's table size).
const MAX_SHARES: usize = 51;

impl Mcmc {
    /// MCMC for `M`, or why it cannot run.
    pub fn new<M: Trainable>(opts: McmcOptions) -> Result<Mcmc, String> {
        let words = GaussianWords::of::<M>().ok_or_else(|| {
            format!(
                "{}: MCMC needs a Gaussian's parameters among its words (a position, log scales, a (w, x, y, z) rotation and an opacity logit, as Shape::from_gaussian reads them)",
                M::NAME
            )
        })?;
        Ok(Mcmc { opts, words })
    }

    /// The penalties' value for `n` primitives, and their gradients added to `grads`:
    /// `opacity_reg * mean(opacity) + scale_reg * mean(scale)`, the mean scale over every
    /// axis of every primitive, once per view of the step (`views`: each view's loss carries
    /// them, and a batch sums its views' losses).
    pub fn regularize(&self, flat: &[f32], grads: &mut [f32], words: usize, views: usize) -> f32 {
        let n = flat.len() / words.max(1);
        if n == 0 {
            return 0.0;
        }
        let (o, s) = (self.words.opacity, self.words.log_scale);
        let per_view = |reg: f32, count: usize| reg * views as f32 / count as f32;
        let (wo, ws) = (
            per_view(self.opts.opacity_reg, n),
            per_view(self.opts.scale_reg, 3 * n),
        );
        let mut value = 0.0f64;
        for (p, g) in flat.chunks_exact(words).zip(grads.chunks_exact_mut(words)) {
            let sigma = 1.0 / (1.0 + (-p[o]).exp());
            g[o] += wo * sigma * (1.0 - sigma);
            value += (wo * sigma) as f64;
            for k in s..s + 3 {
                let scale = p[k].exp();
                g[k] += ws * scale;
                value += (ws * scale) as f64;
            }
        }
        value as f32
    }

    /// Moves each primitive's position by `Σ ε * noise_lr * position_lr * gate(opacity)`
    /// (Σ its covariance, ε standard normal, the gate [`noise_gate`]), drawn from `seed` and the primitive's index so that any thread
    /// (or the device) draws the same.
    pub fn perturb(&self, flat: &mut [f32], words: usize, position_lr: f32, seed: u32) {
        use rayon::prelude::*;
        let scaler = self.opts.noise_lr * position_lr;
        let layout = self.words;
        flat.par_chunks_exact_mut(words.max(1))
            .enumerate()
            .for_each(|(i, p)| {
                let s = layout.shape(p);
                let gate = noise_gate(s.opacity);
                if gate * scaler == 0.0 {
                    return;
                }
                let r = Mat3::from_quat(s.rotation);
                let covariance = r * Mat3::from_diagonal(s.scale * s.scale) * r.transpose();
                let step = covariance * hashed_normal3(seed, i as u32) * (gate * scaler);
                for (k, d) in step.to_array().into_iter().enumerate() {
                    p[layout.position + k] += d;
                }
            });
    }

    /// Moves the dead primitives onto live ones and adds `growth` more, both drawn by
    /// opacity; the primitives drawn share their opacity and size with their copies. The
    /// drawn ones and their copies start their optimizer state afresh.
    pub fn refine<M: Trainable>(
        &self,
        params: &mut Vec<M::Params>,
        rng: &mut fastrand::Rng,
    ) -> Refinement {
        let o = &self.opts;
        let n = params.len();
        let mut r = Refinement {
            origin: (0..n).map(Some).collect(),
            ..Default::default()
        };
        let alive = |s: &Shape| s.opacity > o.min_opacity && s.position.is_finite();
        let shapes: Vec<Shape> = params.iter().map(M::shape).collect();
        let dead: Vec<usize> = (0..n).filter(|&i| !alive(&shapes[i])).collect();
        let weights: Vec<f32> = (shapes.iter())
            .map(|s| if alive(s) { s.opacity } else { 0.0 })
            .collect();
        if let Some(drawn) = draw(&weights, dead.len(), rng) {
            self.share::<M>(params, &drawn);
            for (&d, &s) in dead.iter().zip(&drawn) {
                params[d] = params[s];
                (r.origin[d], r.origin[s]) = (None, None);
            }
            r.relocated = dead.len();
        }
        let target = ((n as f64 * (1.0 + o.growth as f64)) as usize).min(o.max_primitives);
        let weights: Vec<f32> = params.iter().map(|p| M::shape(p).opacity).collect();
        if let Some(drawn) = draw(&weights, target.saturating_sub(n), rng) {
            self.share::<M>(params, &drawn);
            for &s in &drawn {
                params.push(params[s]);
                r.origin[s] = None;
                r.origin.push(None);
            }
            r.cloned = drawn.len();
        }
        r
    }

    /// Shares the opacity and size of each primitive in `drawn` (with repeats) with the copies
    /// about to be made of it.
    fn share<M: Trainable>(&self, params: &mut [M::Params], drawn: &[usize]) {
        let mut copies = std::collections::BTreeMap::<usize, usize>::new();
        for &i in drawn {
            *copies.entry(i).or_default() += 1;
        }
        for (i, c) in copies {
            let s = M::shape(&params[i]);
            let (opacity, factor) = shared(s.opacity, (c + 1).min(MAX_SHARES));
            let opacity = opacity.clamp(self.opts.min_opacity, 1.0 - f32::EPSILON);
            let s = Shape {
                opacity,
                scale: s.scale * factor,
                ..s
            };
            params[i] = M::with_shape(&params[i], &s);
        }
    }
}

/// The opacity and the scale factor of each of `n` copies of a primitive of opacity `o`
/// (eq. 9 of the MCMC paper): `1 - (1 - o')^n = o` keeps the stack's opacity at its centre,
/// and the factor keeps its integrated opacity.
pub fn shared(o: f32, n: usize) -> (f32, f32) {
    let o = o as f64;
    let o_new = 1.0 - (1.0 - o).powf(1.0 / n as f64);
    let mut sum = 0.0;
    for i in 1..=n {
        let mut binomial = 1.0; // C(i - 1, k)
        for k in 0..i {
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            sum += binomial * sign * o_new.powi(k as i32 + 1) / ((k + 1) as f64).sqrt();
            binomial *= (i - 1 - k) as f64 / (k + 1) as f64;
        }
    }
    (o_new as f32, (o / sum) as f32)
}

/// `count` indices drawn with replacement, each with probability proportional to its
/// weight; `None` when nothing is asked or every weight is zero.
fn draw(weights: &[f32], count: usize, rng: &mut fastrand::Rng) -> Option<Vec<usize>> {
    let cumulative: Vec<f64> = weights
        .iter()
        .scan(0.0f64, |acc, w| {
            *acc += w.max(0.0) as f64;
            Some(*acc)
        })
        .collect();
    let total = *cumulative.last()?;
    if count == 0 || total <= 0.0 {
        return None;
    }
    let pick = |u: f64| cumulative.partition_point(|c| *c <= u * total);
    Some(
        (0..count)
            .map(|_| pick(rng.f64()).min(weights.len() - 1))
            .collect(),
    )
}

/// The noise's weight for a primitive of opacity `o`: a steep sigmoid of `1 - o` about 0.995
/// (0.62 at opacity 0, 0.5 at the dead threshold 0.005, 0.01 at 0.05).
pub fn noise_gate(o: f32) -> f32 {
    1.0 / (1.0 + (-100.0 * (1.0 - o - 0.995)).exp())
}

/// Three standard normal samples from a hash of `seed` and `i` (PCG's output function, then
/// Box-Muller), the same draws as the device's `mcmc.wgsl`.
pub fn hashed_normal3(seed: u32, i: u32) -> Vec3 {
    let mut state = pcg(seed ^ pcg(i));
    let mut uniform = || {
        state = pcg(state);
        (state >> 8) as f32 / 16_777_216.0
    };
    let mut normal = || {
        let u = 1.0 - uniform(); // in (0, 1]: ln(u) is finite
        (-2.0 * u.ln()).sqrt() * (std::f32::consts::TAU * uniform()).cos()
    };
    Vec3::new(normal(), normal(), normal())
}

/// PCG's RXS-M-XS hash of one word.
fn pcg(v: u32) -> u32 {
    let state = v.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277_803_737);
    (word >> 22) ^ word
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One copy is the primitive itself; n copies keep the centre's opacity.
    #[test]
    fn shared_opacity_keeps_the_stack_and_one_copy_is_unchanged() {
        let (o, f) = shared(0.7, 1);
        assert!((o - 0.7).abs() < 1e-6 && (f - 1.0).abs() < 1e-6, "{o} {f}");
        for n in [2, 3, 10, MAX_SHARES] {
            for opacity in [0.01f32, 0.3, 0.9, 0.999] {
                let (o, f) = shared(opacity, n);
                let stack = 1.0 - (1.0 - o as f64).powi(n as i32);
                assert!(
                    (stack - opacity as f64).abs() < 1e-5,
                    "{n} {opacity}: {stack}"
                );
                assert!(f.is_finite() && f > 0.0, "{n} {opacity}: factor {f}");
            }
        }
        // Two copies of a faint primitive: each about half as opaque, about as large (the
        // sum of two faint Gaussians is one of twice the opacity).
        let (o, f) = shared(0.01, 2);
        assert!(
            (o - 0.005).abs() < 1e-4 && (f - 1.0).abs() < 0.01,
            "{o} {f}"
        );
    }

    #[test]
    fn draws_follow_the_weights() {
        let mut rng = fastrand::Rng::with_seed(1);
        let drawn = draw(&[0.0, 1.0, 3.0, 0.0], 4000, &mut rng).expect("weights");
        let count = |i| drawn.iter().filter(|&&d| d == i).count();
        assert_eq!(count(0) + count(3), 0);
        assert!(
            (count(2) as f64 / 4000.0 - 0.75).abs() < 0.03,
            "{}",
            count(2)
        );
        assert!(draw(&[0.0, 0.0], 3, &mut rng).is_none());
        assert!(draw(&[1.0], 0, &mut rng).is_none());
    }

    #[test]
    fn hashed_normals_are_standard() {
        let samples: Vec<f32> = (0..20_000)
            .flat_map(|i| hashed_normal3(9, i).to_array())
            .collect();
        let mean = samples.iter().sum::<f32>() / samples.len() as f32;
        let var = samples.iter().map(|x| (x - mean).powi(2)).sum::<f32>() / samples.len() as f32;
        assert!(
            mean.abs() < 0.02 && (var - 1.0).abs() < 0.03,
            "{mean} {var}"
        );
        assert_ne!(hashed_normal3(9, 0), hashed_normal3(10, 0));
    }

    #[test]
    fn the_noise_gate_opens_for_faint_primitives_only() {
        assert!(
            (noise_gate(0.0) - 0.622).abs() < 1e-3,
            "{}",
            noise_gate(0.0)
        );
        assert!((noise_gate(0.005) - 0.5).abs() < 1e-3);
        assert!(noise_gate(0.05) < 0.012 && noise_gate(0.1) < 1e-3 && noise_gate(1.0) < 1e-20);
    }
}
