//! Batches of views: a run's steps count the views it trains on, and `--batch B` groups them B
//! at a time into one Adam step on the sum of their losses (Grendel-GS, Zhao et al. 2024).
//! Every schedule (the learning rates' decay, density control's refinements and opacity
//! resets, MCMC's, evaluations, checkpoints) stays counted in views, so a run of 7,000 steps
//! sees 7,000 views at any batch size; an event due at a view inside a batch happens after
//! that batch.

use std::ops::Range;

/// The views of one Adam step: `first..first + len` of the run's steps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Batch {
    pub first: usize,
    pub len: usize,
}

impl Batch {
    /// The run's steps (views) this batch takes.
    pub fn steps(&self) -> Range<usize> {
        self.first..self.first + self.len
    }

    /// The batch's last step: the one it reports as (a checkpoint after it holds
    /// `last() + 1` steps).
    pub fn last(&self) -> usize {
        self.first + self.len - 1
    }

    /// Whether something due at some step passes `due` within this batch.
    pub fn any(&self, due: impl Fn(usize) -> bool) -> bool {
        self.steps().any(due)
    }

    /// The part of this batch that rank `rank` of `ranks` renders: a contiguous share, in
    /// rank order (a rank may have none when the batch is smaller than the team).
    pub fn share(&self, rank: usize, ranks: usize) -> Range<usize> {
        let ranks = ranks.max(1);
        (rank * self.len / ranks)..((rank + 1) * self.len / ranks)
    }
}

/// The batches from step `from` to `steps`, `size` views each (the last may hold fewer).
pub fn batches(from: usize, steps: usize, size: usize) -> impl Iterator<Item = Batch> {
    let size = size.max(1);
    (from..steps).step_by(size).map(move |first| Batch {
        first,
        len: size.min(steps - first),
    })
}

/// How Adam's settings follow the batch size `views`, as Grendel-GS scales them under its
/// "independent gradients" hypothesis (gradients of different views are uncorrelated): the
/// learning rate by `sqrt(views)` (the sum of `views` such gradients grows by `views`, its
/// noise by `sqrt(views)`: Adam normalizes the magnitude, and the square-root rule keeps the
/// per-view step variance), and each moment's decay `beta` to `beta^views`, so that the
/// moments forget at the same rate per view seen as with one view per step. gsplat takes the
/// same learning rate and the first-order `1 - views (1 - beta)`; the two agree for
/// `views (1 - beta)` small, and `beta^views` stays in (0, 1) for any batch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scaling {
    pub learning_rate: f32,
    pub beta1: f32,
    pub beta2: f32,
}

impl Scaling {
    pub fn for_batch(views: usize, beta1: f32, beta2: f32) -> Scaling {
        let b = views.max(1);
        Scaling {
            learning_rate: (b as f32).sqrt(),
            beta1: beta1.powi(b as i32),
            beta2: beta2.powi(b as i32),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn batches_cover_the_run_once_in_order_and_the_last_takes_what_is_left() {
        let all: Vec<Batch> = batches(2, 13, 4).collect();
        let firsts: Vec<usize> = all.iter().map(|b| b.first).collect();
        assert_eq!(firsts, [2, 6, 10]);
        assert_eq!(all[2].len, 3);
        assert_eq!(all[2].last(), 12);
        let steps: Vec<usize> = all.iter().flat_map(Batch::steps).collect();
        assert_eq!(steps, (2..13).collect::<Vec<_>>());
        // One view per step is the loop without batches.
        assert!(batches(0, 5, 1).all(|b| b.len == 1));
        assert_eq!(batches(5, 5, 3).count(), 0);
    }

    #[test]
    fn an_event_due_inside_a_batch_happens_after_it() {
        let every_100 = |s: usize| (s + 1).is_multiple_of(100);
        let due: Vec<usize> = (batches(0, 1000, 3))
            .filter(|b| b.any(every_100))
            .map(|b| b.last())
            .collect();
        // Step 99 falls in the batch 99..102, step 199 in 198..201, ...
        assert_eq!(due.len(), 10);
        assert_eq!(&due[..3], [101, 200, 299]);
    }

    #[test]
    fn shares_split_a_batch_among_ranks_in_order_without_gaps() {
        for (len, ranks) in [(4, 2), (5, 2), (3, 4), (8, 3), (1, 1)] {
            let b = Batch { first: 10, len };
            let parts: Vec<usize> = (0..ranks).flat_map(|r| b.share(r, ranks)).collect();
            assert_eq!(
                parts,
                (0..len).collect::<Vec<_>>(),
                "{len} views on {ranks}"
            );
        }
    }

    #[test]
    fn one_view_keeps_adams_settings_and_larger_batches_follow_grendel() {
        assert_eq!(
            Scaling::for_batch(1, 0.9, 0.999),
            Scaling {
                learning_rate: 1.0,
                beta1: 0.9,
                beta2: 0.999
            }
        );
        let s = Scaling::for_batch(4, 0.9, 0.999);
        assert_eq!(s.learning_rate, 2.0);
        assert!((s.beta1 - 0.6561).abs() < 1e-6);
        assert!((s.beta2 - 0.999f32.powi(4)).abs() < 1e-7);
    }
}
