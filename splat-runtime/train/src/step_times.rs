//! Where a training step's time goes, stage by stage, so that a run says what to speed up.
//! The GPU loop times its stages with GPU timestamps (zero on an adapter without them), the
//! CPU loop with the host's clock around each; both time the whole step on the host, and what
//! no stage accounts for (host work, submissions, waits, an idle GPU) is the difference.

use std::time::Duration;

/// One step's times.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepTimes {
    /// The forward pass: `project`, then tile lists, then the blend.
    pub preprocess: Duration,
    pub rasterize: Duration,
    pub shade: Duration,
    /// The loss and its gradient (compositing on the background and SSIM's included).
    pub loss: Duration,
    /// The backward pass: the blend's adjoint (with the CPU's per-primitive reduction), then
    /// `project`'s.
    pub blend: Duration,
    pub project: Duration,
    /// Adam, with MCMC's regularizer and noise.
    pub optimizer: Duration,
    /// Density control's per-step statistics.
    pub statistics: Duration,
    /// Waiting for the other processes' views of the batch (`splat fit` under MPI), which
    /// also holds the time the slowest rank took beyond this one.
    pub exchange: Duration,
    /// On the host, on the steps that do it: refining the primitive set or resetting
    /// opacities (on the GPU with the scene and moments down and back up).
    pub densify: Duration,
    /// Rendering and scoring the test views, on the steps that do it.
    pub evaluation: Duration,
    /// The whole step on the host's clock.
    pub wall: Duration,
}

impl StepTimes {
    /// The stages, named, in the order a step runs them (`wall` aside).
    pub fn stages(&self) -> [(&'static str, Duration); 11] {
        [
            ("preprocess", self.preprocess),
            ("rasterize", self.rasterize),
            ("shade", self.shade),
            ("loss", self.loss),
            ("backward blend", self.blend),
            ("project adjoint", self.project),
            ("optimizer", self.optimizer),
            ("statistics", self.statistics),
            ("exchange", self.exchange),
            ("densify", self.densify),
            ("evaluation", self.evaluation),
        ]
    }

    /// The part of the wall time no stage accounts for.
    pub fn unaccounted(&self) -> Duration {
        let staged: Duration = self.stages().iter().map(|s| s.1).sum();
        self.wall.saturating_sub(staged)
    }
}

impl std::ops::AddAssign for StepTimes {
    fn add_assign(&mut self, o: StepTimes) {
        self.preprocess += o.preprocess;
        self.rasterize += o.rasterize;
        self.shade += o.shade;
        self.loss += o.loss;
        self.blend += o.blend;
        self.project += o.project;
        self.optimizer += o.optimizer;
        self.statistics += o.statistics;
        self.exchange += o.exchange;
        self.densify += o.densify;
        self.evaluation += o.evaluation;
        self.wall += o.wall;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sums_add_field_by_field_and_the_rest_is_what_no_stage_took() {
        let ms = Duration::from_millis;
        let step = StepTimes {
            preprocess: ms(1),
            rasterize: ms(2),
            shade: ms(3),
            loss: ms(4),
            blend: ms(5),
            project: ms(6),
            optimizer: ms(7),
            statistics: ms(8),
            exchange: ms(11),
            densify: ms(9),
            evaluation: ms(10),
            wall: ms(71),
        };
        let mut total = StepTimes::default();
        total += step;
        total += step;
        let want: Vec<_> = step.stages().iter().map(|s| 2 * s.1).collect();
        let got: Vec<_> = total.stages().iter().map(|s| s.1).collect();
        assert_eq!(got, want);
        assert_eq!(total.wall, ms(142));
        assert_eq!(step.unaccounted(), ms(5));
        // Stages timed on the GPU can overlap the host's clock: never negative.
        assert_eq!(
            StepTimes {
                wall: ms(1),
                ..step
            }
            .unaccounted(),
            ms(0)
        );
    }
}
