//! A run of `splat fit --view` as its page shows it: the step, the primitive count, the loss
//! and test PSNR so far, and a pause that holds the run between two steps.

use std::sync::{Condvar, Mutex, MutexGuard};

/// How many points of each curve a page is sent: longer curves are thinned evenly.
const CURVE_POINTS: usize = 400;

#[derive(Default)]
struct Run {
    step: usize,
    steps: usize,
    primitives: usize,
    /// (step, loss) of every step, and (step, test PSNR) where measured.
    loss: Vec<(usize, f64)>,
    psnr: Vec<(usize, f64)>,
    paused: bool,
    /// Counts changes, so a tab sends the status only when it moved.
    version: u64,
}

#[derive(Default)]
pub struct Live {
    run: Mutex<Run>,
    resumed: Condvar,
}

impl Live {
    pub fn new(steps: usize, first: usize) -> Live {
        let live = Live::default();
        (live.lock().steps, live.lock().step) = (steps, first);
        live
    }

    fn lock(&self) -> MutexGuard<'_, Run> {
        self.run.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Records a step (1-based count done), its loss, the primitives after it and the test
    /// PSNR where it was measured.
    pub fn step(&self, done: usize, loss: f64, primitives: usize, psnr: Option<f64>) {
        let mut run = self.lock();
        run.step = done;
        run.primitives = primitives;
        run.loss.push((done, loss));
        if let Some(p) = psnr {
            run.psnr.push((done, p));
        }
        run.version += 1;
    }

    /// Holds the calling run while a tab has it paused, unless `stop` says it is to end.
    pub fn wait_while_paused(&self, stop: &dyn Fn() -> bool) {
        let mut run = self.lock();
        while run.paused && !stop() {
            let wait = self
                .resumed
                .wait_timeout(run, std::time::Duration::from_millis(200));
            run = wait.unwrap_or_else(|e| e.into_inner()).0;
        }
    }

    pub fn pause(&self, paused: bool) {
        let mut run = self.lock();
        run.paused = paused;
        run.version += 1;
        self.resumed.notify_all();
    }

    pub fn version(&self) -> u64 {
        self.lock().version
    }

    /// The status as the page reads it.
    pub fn json(&self) -> serde_json::Value {
        let run = self.lock();
        let thin = |points: &[(usize, f64)]| -> Vec<(usize, f64)> {
            let every = points.len().div_ceil(CURVE_POINTS).max(1);
            let mut kept: Vec<_> = points.iter().step_by(every).copied().collect();
            // The newest point always shows.
            if let Some(last) = points.last()
                && kept.last() != Some(last)
            {
                kept.push(*last);
            }
            kept
        };
        serde_json::json!({
            "step": run.step,
            "steps": run.steps,
            "primitives": run.primitives,
            "paused": run.paused,
            "loss": thin(&run.loss),
            "psnr": thin(&run.psnr),
        })
    }
}
