//! The processes `splat fit` runs as: one, or the ranks an MPI launcher (`mpirun`, `srun`)
//! started, which share each batch's views ([`splat_runtime::train::team`]). Rank 0 reads the
//! checkpoint, prints, and writes every output; the others train beside it silently.

use anyhow::{Result, bail};
use splat_runtime::train::team::{Solo, Team};

/// This process's place in the run.
pub enum Ranks {
    Alone,
    #[cfg(feature = "mpi")]
    Mpi(crate::mpi_team::MpiTeam),
}

/// Whether an MPI launcher started this process, and with how many ranks where it says:
/// OpenMPI's `mpirun` sets `OMPI_COMM_WORLD_SIZE`, MPICH's Hydra and Slurm's PMI-2 `PMI_SIZE`,
/// a PMIx launcher (`srun --mpi=pmix`) `PMIX_RANK`.
fn launched() -> Option<Option<usize>> {
    let size = |name| std::env::var(name).ok().and_then(|s| s.parse().ok());
    match size("OMPI_COMM_WORLD_SIZE").or_else(|| size("PMI_SIZE")) {
        Some(n) => Some(Some(n)),
        None => std::env::var_os("PMIX_RANK").map(|_| None),
    }
}

impl Ranks {
    /// The run's ranks: MPI's when a launcher started this process (the ranks' standard
    /// output then goes to rank 0's alone), else this process alone.
    pub fn join() -> Result<Ranks> {
        let Some(size) = launched() else {
            return Ok(Ranks::Alone);
        };
        #[cfg(feature = "mpi")]
        {
            let _ = size;
            crate::mpi_team::MpiTeam::join().map(Ranks::Mpi)
        }
        #[cfg(not(feature = "mpi"))]
        match size {
            Some(1) => Ok(Ranks::Alone),
            _ => bail!(
                "started by an MPI launcher, but this splat was built without MPI: every rank would train alone and write the same files. Build it with `--features mpi` (docs/distributed.md)"
            ),
        }
    }

    pub fn rank(&self) -> usize {
        self.team().rank()
    }

    pub fn count(&self) -> usize {
        self.team().ranks()
    }

    /// This rank's place among the ranks on its machine (where several share it), as the
    /// launcher says: OpenMPI's `OMPI_COMM_WORLD_LOCAL_RANK`, MPICH's `MPI_LOCALRANKID`,
    /// Slurm's `SLURM_LOCALID`. `None` alone.
    pub fn local_rank(&self) -> Option<usize> {
        match self {
            Ranks::Alone => None,
            #[cfg(feature = "mpi")]
            Ranks::Mpi(_) => [
                "OMPI_COMM_WORLD_LOCAL_RANK",
                "MPI_LOCALRANKID",
                "SLURM_LOCALID",
            ]
            .iter()
            .find_map(|name| std::env::var(name).ok()?.parse().ok()),
        }
    }

    /// Whether this rank prints and writes the run's outputs.
    pub fn is_root(&self) -> bool {
        self.rank() == 0
    }

    /// The ranks as the training loop shares a batch among them.
    pub fn team(&self) -> &dyn Team {
        match self {
            Ranks::Alone => &Solo,
            #[cfg(feature = "mpi")]
            Ranks::Mpi(t) => t,
        }
    }

    /// Rank 0's `bytes` on every rank (the others pass `None`).
    pub fn broadcast(&self, bytes: Option<Vec<u8>>) -> Result<Vec<u8>> {
        match self {
            Ranks::Alone => bytes.ok_or_else(|| anyhow::anyhow!("nothing to broadcast")),
            #[cfg(feature = "mpi")]
            Ranks::Mpi(t) => t.broadcast(bytes),
        }
    }

    /// Goes on when every rank got `what` and the same value of it (a hash); otherwise fails
    /// on every rank, naming the ranks that failed and why, or the first that disagrees, with
    /// `same` saying how they come to agree.
    pub fn agree(
        &self,
        what: &str,
        mine: &std::result::Result<u64, String>,
        same: &str,
    ) -> Result<()> {
        let all = match self {
            Ranks::Alone => vec![mine.clone()],
            #[cfg(feature = "mpi")]
            Ranks::Mpi(t) => t.all_outcomes(mine)?,
        };
        let failed: Vec<String> = (all.iter().enumerate())
            .filter_map(|(r, o)| o.as_ref().err().map(|e| format!("rank {r}: {e}")))
            .collect();
        if !failed.is_empty() {
            let why = match (all.len(), &failed[..]) {
                (1, [_]) => return Err(anyhow::anyhow!(mine.clone().unwrap_err())),
                _ => format!(
                    "{} of {} ranks could not get {what}:\n  {}",
                    failed.len(),
                    all.len(),
                    failed.join("\n  ")
                ),
            };
            bail!(OnEveryRank(why));
        }
        let values: Vec<u64> = all
            .iter()
            .filter_map(|o| o.as_ref().ok().copied())
            .collect();
        if let Some(r) = values.iter().position(|v| *v != values[0]) {
            bail!(OnEveryRank(format!(
                "rank {r} has another {what} than rank 0: {same}"
            )));
        }
        Ok(())
    }

    /// Ends the run on every rank after `error` on this one. Alone, it is returned as it is.
    /// Among ranks, an error they all met alike ([`Ranks::agree`]) is rank 0's to report, the
    /// others end quietly; any other is printed with this rank's number and MPI aborts every
    /// rank, which would otherwise wait for this one.
    pub fn fail(&self, error: anyhow::Error) -> Result<()> {
        match self {
            Ranks::Alone => Err(error),
            #[cfg(feature = "mpi")]
            Ranks::Mpi(t) => match error.is::<OnEveryRank>() {
                // Printed now, before MPI finalizes: a launcher ending on a signal stops
                // forwarding the ranks' output once they have.
                true if t.rank() == 0 => {
                    eprintln!("error: {error:#}");
                    Err(Reported.into())
                }
                true => Ok(()),
                false => t.abort(&error),
            },
        }
    }

    /// What the batches exchanged among the ranks, on this rank.
    pub fn traffic(&self) -> Option<Traffic> {
        match self {
            Ranks::Alone => None,
            #[cfg(feature = "mpi")]
            Ranks::Mpi(t) => Some(t.traffic()),
        }
    }
}

/// The bytes a rank's gathers sent to the other ranks and received from them, as the gathers
/// move them (what crosses the wire depends on MPI's algorithm: a ring forwards others' bytes).
#[derive(Clone, Copy, Debug, Default)]
pub struct Traffic {
    pub sent: u64,
    pub received: u64,
}

/// An error every rank met alike: rank 0 reports it, the others end quietly
/// ([`Ranks::fail`]).
pub fn on_every_rank(message: String) -> anyhow::Error {
    OnEveryRank(message).into()
}

#[derive(Debug)]
struct OnEveryRank(String);

/// A failure whose error was printed already: the program exits with a failure, quietly.
#[derive(Debug)]
pub struct Reported;

impl std::fmt::Display for Reported {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("(reported above)")
    }
}

impl std::error::Error for Reported {}

impl std::fmt::Display for OnEveryRank {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for OnEveryRank {}

/// A hash of `text`, for [`Ranks::agree`].
pub fn hash(text: &str) -> u64 {
    use std::hash::{DefaultHasher, Hash, Hasher};
    let mut h = DefaultHasher::new();
    text.hash(&mut h);
    h.finish()
}
