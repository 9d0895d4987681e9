//! Sharded training in one process: ranks as threads (a team whose exchanges meet at a
//! barrier) each holding a slice of the scene train the scene one process trains, bit for
//! bit, through density control's refinements, the slices' evening out after them, the
//! evaluations and the checkpoints. (`splat fit --sharded` under a real `mpirun`:
//! `splat-cli`'s tests/cli/mpi.rs.)

use crate::fit::{known_dataset, options, truth};
use splat_methods::gs3d::{Method, Params};
use splat_runtime::glam::Vec3;
use splat_runtime::train::fit::{FitError, FitOptions, fit_from};
use splat_runtime::train::sharded::fit_sharded;
use splat_runtime::train::team::Team;
use splat_runtime::train::{Checkpoint, DensifyOptions, Strategy, Trainable};
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

/// Ranks as threads of one process: each exchange leaves every rank's messages on a board
/// and waits for the others (failing, not hanging, when one never comes).
struct Board {
    ranks: usize,
    state: Mutex<Round>,
    turn: Condvar,
}

#[derive(Default)]
struct Round {
    /// `posts[from][to]`, this round's.
    posts: Vec<Option<Vec<Vec<u8>>>>,
    /// Ranks that posted, then ranks that read, this round.
    posted: usize,
    read: usize,
    round: u64,
}

struct Member {
    rank: usize,
    board: Arc<Board>,
}

impl Team for Member {
    fn rank(&self) -> usize {
        self.rank
    }

    fn ranks(&self) -> usize {
        self.board.ranks
    }

    fn all_gather(&self, mine: Vec<u8>) -> Result<Vec<Vec<u8>>, FitError> {
        self.all_to_all(vec![mine; self.ranks()])
    }

    fn all_to_all(&self, to_each: Vec<Vec<u8>>) -> Result<Vec<Vec<u8>>, FitError> {
        let b = &self.board;
        let late = || FitError::Unsupported("a rank never came to the exchange".into());
        let wait = |s, until: &dyn Fn(&Round) -> bool| {
            let (s, timeout) = (b.turn)
                .wait_timeout_while(s, Duration::from_secs(120), |r| !until(r))
                .unwrap();
            match timeout.timed_out() {
                true => Err(late()),
                false => Ok(s),
            }
        };
        let mut s = b.state.lock().unwrap();
        // The last round's readers are done before its posts are replaced.
        s = wait(s, &|r: &Round| r.read == 0)?;
        let round = s.round;
        s.posts.resize(b.ranks, None);
        s.posts[self.rank] = Some(to_each);
        s.posted += 1;
        b.turn.notify_all();
        s = wait(s, &|r: &Round| r.round != round || r.posted == b.ranks)?;
        let got = (s.posts.iter())
            .map(|p| p.as_ref().unwrap()[self.rank].clone())
            .collect();
        s.read += 1;
        if s.read == b.ranks {
            *s = Round {
                round: round + 1,
                ..Round::default()
            };
        }
        b.turn.notify_all();
        Ok(got)
    }
}

/// What a run reports, step by step, and its checkpoints.
#[derive(Debug, Default, PartialEq)]
struct Trace {
    steps: Vec<Step>,
    checkpoints: Vec<Checkpoint>,
}

/// A step's last view, its loss's bits, the primitive count, the evaluation's bits.
#[derive(Debug, PartialEq)]
struct Step(usize, u64, usize, Option<(u64, u64)>);

#[test]
fn ranks_each_holding_a_slice_train_the_scene_one_process_trains_bit_for_bit() {
    let data = known_dataset();
    // From a few large primitives, so that density control splits and clones.
    let start: Vec<Params> = (truth().iter().step_by(8))
        .map(|g| Method::from_point(g.mean, Vec3::splat(0.5), 0.3))
        .collect();
    let opts = FitOptions {
        batch: 3,
        densify: Some(Strategy::Adc(DensifyOptions {
            start: 30,
            every: 30,
            reset_every: 90,
            ..Default::default()
        })),
        eval_every: Some(60),
        checkpoint_every: Some(75),
        ..options(180)
    };
    let first = Checkpoint::start::<Method>(&start, opts.steps, opts.seed);
    let extent = 3.5;
    let record = |trace: &mut Trace, r: &splat_runtime::train::fit::StepReport| {
        let e = r.evaluation.map(|e| (e.psnr.to_bits(), e.ssim.to_bits()));
        (trace.steps).push(Step(r.step, r.loss.loss.to_bits(), r.primitives, e));
        trace.checkpoints.extend(r.checkpoint.cloned());
    };

    let mut alone = Trace::default();
    let mut whole = first.clone();
    fit_from::<Method>(&data, &mut whole, extent, &opts, |r| record(&mut alone, r)).unwrap();
    let grown = whole.primitives();
    assert!(grown > 2 * start.len(), "{} -> {grown}", start.len());

    for ranks in [2, 3] {
        let board = Arc::new(Board {
            ranks,
            state: Mutex::default(),
            turn: Condvar::new(),
        });
        let runs: Vec<(Trace, Checkpoint)> = std::thread::scope(|scope| {
            let runs: Vec<_> = (0..ranks)
                .map(|rank| {
                    let team = Member {
                        rank,
                        board: board.clone(),
                    };
                    let (data, opts) = (&data, &opts);
                    // Only rank 0's first state is read.
                    let mut state = match rank {
                        0 => first.clone(),
                        _ => Checkpoint::start::<Method>(&[], 0, 0),
                    };
                    scope.spawn(move || {
                        let mut trace = Trace::default();
                        fit_sharded::<Method>(&team, data, &mut state, extent, opts, |r| {
                            record(&mut trace, r)
                        })
                        .unwrap();
                        (trace, state)
                    })
                })
                .collect();
            runs.into_iter().map(|r| r.join().unwrap()).collect()
        });
        let (trace, state) = &runs[0];
        assert!(*state == whole, "{ranks} ranks' scene");
        assert!(*trace == alone, "{ranks} ranks' steps");
        // Each rank ends with its share of the scene, and no more.
        for (rank, (trace, slice)) in runs.iter().enumerate().skip(1) {
            let share = (rank + 1) * grown / ranks - rank * grown / ranks;
            assert_eq!(slice.primitives(), share, "rank {rank} of {ranks}");
            assert!(
                trace.checkpoints.is_empty(),
                "rank 0 alone holds checkpoints"
            );
        }
    }
}
