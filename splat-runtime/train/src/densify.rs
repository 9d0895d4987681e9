//! Adaptive density control (Kerbl et al. 2023, §5), with the defaults of gsplat's
//! `DefaultStrategy`: primitives whose position keeps being pulled across the screen are
//! cloned (when small) or split in two (when large), faint ones and (after the first opacity
//! reset) huge ones are pruned, and every few thousand steps opacities are lowered so that
//! occluders must earn their opacity again.
//!
//! It reads a method's primitives through [`Trainable::shape`], so any method whose primitives
//! have a position, an oriented scale and an opacity densifies without code of its own.

use super::mcmc::hashed_normal3;
use super::trainable::{Shape, Trainable};
use glam::{Vec2, Vec3};
use splat_core::flat::{Flat, flatten};
use splat_core::types::Camera;

/// The gradient of the loss with respect to where primitive `p` lands on the image, in NDC
/// units (pixels times half the image size, as gsplat scales it), given the gradient of its
/// parameters `grad` and of its shade data `shade` (`M::Shade::LEN` words).
///
/// From the shade data where the method says where the point is in it
/// ([`Trainable::screen_gradient`], 3DGS's `center`): then it is the gradient 3DGS grows from.
/// Otherwise a method's projection is its own, so it is recovered from the world-space
/// position gradient through the pinhole Jacobian: for x_cam = R p + t and u = f x/z + c,
/// dL/dx_cam = (f / z) dL/du exactly when u is the only use of x_cam (the x column of the
/// Jacobian has no other term), so dL/du = (z / f) dL/dx_cam. What reaches the position
/// through the footprint's shape and view-dependent color is counted too.
pub fn screen_gradient<M: Trainable>(
    p: &M::Params,
    grad: &M::Params,
    shade: &[f32],
    camera: &Camera,
) -> Vec2 {
    let half = camera.size / 2.0;
    if let Some(g) = M::screen_gradient(&M::Shade::read_words(shade)) {
        return g * half;
    }
    let x = camera.rotation * M::shape(p).position + camera.translation;
    let g = camera.rotation * M::position_gradient(grad);
    g.truncate() * x.z.max(1e-6) / camera.focal * half
}

/// When and how density control acts; scales are relative to the scene's extent.
#[derive(Clone, Debug)]
pub struct DensifyOptions {
    /// Refine every `every` steps from `start` until `stop`.
    pub start: usize,
    pub stop: usize,
    pub every: usize,
    /// Lower every opacity to `2 * prune_opacity` every `reset_every` steps (before `stop`);
    /// huge primitives are pruned from the first of those steps on.
    pub reset_every: usize,
    /// Whether those resets happen (huge primitives are pruned after `reset_every` either
    /// way). gsplat 1.5.3's never do: its test reads `step % reset_every == 0 & step > 0`,
    /// and `&` binds before the comparisons.
    pub opacity_resets: bool,
    pub prune_opacity: f32,
    /// Grow where the mean screen-space position gradient (in NDC units) passes this.
    pub grow_grad2d: f32,
    /// Clone up to this largest scale (times the extent), split above it.
    pub grow_scale3d: f32,
    /// After step `reset_every`, prune above this largest scale (times the extent).
    pub prune_scale3d: f32,
    /// No growth past this many primitives.
    pub max_primitives: usize,
}

impl Default for DensifyOptions {
    fn default() -> Self {
        DensifyOptions {
            start: 500,
            stop: 15_000,
            every: 100,
            reset_every: 3000,
            opacity_resets: true,
            prune_opacity: 0.005,
            grow_grad2d: 0.0002,
            grow_scale3d: 0.01,
            prune_scale3d: 0.1,
            max_primitives: 4_000_000,
        }
    }
}

/// What one refinement did; `origin[i]` is the index before it of new primitive `i`, or `None`
/// for a primitive created by it (whose optimizer state starts from zero).
#[derive(Clone, Debug, Default)]
pub struct Refinement {
    pub origin: Vec<Option<usize>>,
    pub cloned: usize,
    pub split: usize,
    pub pruned: usize,
    /// Moved onto another primitive (MCMC).
    pub relocated: usize,
}

/// The statistics density control gathers between refinements.
pub struct Densifier {
    pub opts: DensifyOptions,
    /// Per primitive: the sum over views of the screen-space position gradient's norm, and
    /// the number of views that saw it.
    grad2d: Vec<f32>,
    count: Vec<u32>,
}

impl Densifier {
    pub fn new(opts: DensifyOptions, primitives: usize) -> Densifier {
        Densifier {
            opts,
            grad2d: vec![0.0; primitives],
            count: vec![0; primitives],
        }
    }

    /// Density control going on from saved statistics (`grad2d` and `seen` per primitive, as
    /// [`Densifier::statistics`] gives them), or from none when they are empty.
    pub fn resume(
        opts: DensifyOptions,
        primitives: usize,
        grad2d: &[f32],
        seen: &[u32],
    ) -> Densifier {
        let mut d = Densifier::new(opts, primitives);
        d.add_observations(grad2d, seen);
        d
    }

    /// The statistics gathered since the last refinement, per primitive: the summed
    /// screen-space gradient norms and the views that saw it.
    pub fn statistics(&self) -> (Vec<f32>, Vec<u32>) {
        (self.grad2d.clone(), self.count.clone())
    }

    /// Adds one view's screen-space position gradient norm (NDC units, [`screen_gradient`])
    /// of each primitive the view shows.
    pub fn observe(&mut self, seen: impl IntoIterator<Item = (usize, f32)>) {
        for (i, norm) in seen {
            // A gradient Adam skips (not finite) does not count either.
            if norm.is_finite() {
                self.grad2d[i] += norm;
                self.count[i] += 1;
            }
        }
    }

    /// Adds statistics gathered elsewhere (on the device), per primitive: the summed
    /// screen-space gradient norms and the views that saw it.
    pub fn add_observations(&mut self, grad2d: &[f32], seen: &[u32]) {
        for (a, g) in self.grad2d.iter_mut().zip(grad2d) {
            *a += g;
        }
        for (a, s) in self.count.iter_mut().zip(seen) {
            *a += s;
        }
    }

    /// Whether step `step` (0-based, after its optimizer step) refines.
    pub fn refines_at(&self, step: usize) -> bool {
        let o = &self.opts;
        step > o.start && step < o.stop && step.is_multiple_of(o.every.max(1))
    }

    /// Whether step `step` resets opacities.
    pub fn resets_at(&self, step: usize) -> bool {
        let o = &self.opts;
        o.opacity_resets && step > 0 && step < o.stop && step.is_multiple_of(o.reset_every.max(1))
    }

    /// Grows then prunes `params` from the statistics since the last refinement (then
    /// cleared); `extent` is the scene's radius; `step` decides whether huge primitives go.
    pub fn refine<M: Trainable>(
        &mut self,
        params: &mut Vec<M::Params>,
        step: usize,
        extent: f32,
        rng: &mut fastrand::Rng,
    ) -> Refinement {
        // Each growth adds one primitive: where the cap leaves room for fewer than pass the
        // threshold, it is spent where the image asks most, not on whichever come first.
        let room = self.opts.max_primitives.saturating_sub(params.len());
        let mut grows = vec![false; params.len()];
        for i in strongest(self.pulls(), room) {
            grows[i] = true;
        }
        let draws = Draws {
            seed: rng.u32(..),
            first: 0,
        };
        self.refine_growing::<M>(params, &grows, step, extent, draws)
    }

    /// [`Densifier::refine`] growing the primitives `grows` says (a slice of a scene sharded
    /// among processes: chosen from the whole scene's pulls, [`Densifier::pulls`]), its
    /// splits drawn from `draws`. New primitives take their origin's place in the order (a
    /// copy right after it, a split's two in its place), so slices refined apart and put
    /// back together in order are the whole scene refined.
    pub fn refine_growing<M: Trainable>(
        &mut self,
        params: &mut Vec<M::Params>,
        grows: &[bool],
        step: usize,
        extent: f32,
        draws: Draws,
    ) -> Refinement {
        let o = self.opts.clone();
        let n = params.len();
        let mut r = Refinement::default();
        let mut grown: Vec<(M::Params, Option<usize>)> = Vec::with_capacity(n);
        for (i, p) in params.iter().enumerate() {
            let shape = M::shape(p);
            let small = shape.scale.max_element() <= o.grow_scale3d * extent;
            match (grows[i], small) {
                (false, _) => grown.push((*p, Some(i))),
                // Small under a strong pull: a copy where it is (the next steps' gradients
                // move the two apart).
                (true, true) => {
                    grown.extend([(*p, Some(i)), (*p, None)]);
                    r.cloned += 1;
                }
                // Large: two smaller ones drawn from it, in its place.
                (true, false) => {
                    for child in 0..2 {
                        let local = shape.scale * draws.normal3(i, child);
                        let child = Shape {
                            position: shape.position + shape.rotation * local,
                            scale: shape.scale / 1.6,
                            ..shape
                        };
                        grown.push((M::with_shape(p, &child), None));
                    }
                    r.split += 1;
                }
            }
        }
        // Huge primitives go only after the first reset step (once a reset, if resets are on,
        // has given them a chance to fade).
        let huge = (step > o.reset_every).then_some(o.prune_scale3d * extent);
        let before = grown.len();
        grown.retain(|(p, _)| {
            let s = M::shape(p);
            s.opacity >= o.prune_opacity
                && huge.is_none_or(|h| s.scale.max_element() <= h)
                && s.position.is_finite()
        });
        r.pruned = before - grown.len();
        (*params, r.origin) = grown.into_iter().unzip();
        self.grad2d = vec![0.0; params.len()];
        self.count = vec![0; params.len()];
        r
    }

    /// The primitives whose mean screen-space gradient passes the growth threshold, with that
    /// mean: the candidates [`Densifier::refine`] grows (the strongest of them where the cap
    /// leaves room for fewer).
    pub fn pulls(&self) -> Vec<(usize, f32)> {
        let mean = |i: usize| self.grad2d[i] / self.count[i].max(1) as f32;
        (0..self.grad2d.len())
            .map(|i| (i, mean(i)))
            .filter(|&(_, m)| m > self.opts.grow_grad2d)
            .collect()
    }

    /// Lowers every opacity above `2 * prune_opacity` to it.
    pub fn reset_opacity<M: Trainable>(&self, params: &mut [M::Params]) {
        let ceiling = 2.0 * self.opts.prune_opacity;
        let words = |p: &M::Params| flatten(std::slice::from_ref(p));
        for p in params.iter_mut() {
            let shape = M::shape(p);
            if shape.opacity > ceiling {
                // Only the words the opacity moves change: the round trip through `Shape` also
                // normalizes the rotation and rounds the scales, and the training loop forgets
                // the Adam moments of every word that changed (gsplat resets opacities alone).
                let same = words(&M::with_shape(p, &shape));
                let lowered = M::with_shape(
                    p,
                    &Shape {
                        opacity: ceiling,
                        ..shape
                    },
                );
                let mut out = words(p);
                for ((o, l), s) in out.iter_mut().zip(words(&lowered)).zip(same) {
                    if l.to_bits() != s.to_bits() {
                        *o = l;
                    }
                }
                *p = M::Params::read_words(&out);
            }
        }
    }
}

/// Of `pulled` (a primitive's place and its mean pull), the places of the `room` most
/// strongly pulled, or all where there is room for all. Ties go to the earlier place, so
/// that the choice is the same on every run.
pub fn strongest(mut pulled: Vec<(usize, f32)>, room: usize) -> impl Iterator<Item = usize> {
    if pulled.len() > room {
        pulled.sort_unstable_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        pulled.truncate(room);
    }
    pulled.into_iter().map(|(i, _)| i)
}

/// Where a refinement's splits draw their children's offsets: from a hash of the
/// refinement's `seed` and the parent's place in the whole scene (`first` is the place of a
/// slice's first primitive), so that a scene refined in slices draws what it draws whole.
#[derive(Clone, Copy, Debug)]
pub struct Draws {
    pub seed: u32,
    pub first: usize,
}

impl Draws {
    /// Three standard normal samples for child `child` (0 or 1) of the slice's primitive `i`.
    fn normal3(&self, i: usize, child: u32) -> Vec3 {
        let place = (self.first + i) as u32;
        hashed_normal3(self.seed, place.wrapping_mul(2).wrapping_add(child))
    }
}
