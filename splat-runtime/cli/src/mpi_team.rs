//! The ranks of an MPI launch as a training [`Team`]: each batch's shares are gathered on
//! every rank with one `MPI_Allgatherv` (the sizes first, then the bytes), so that every
//! rank sums the same views' gradients in the same order.

use crate::ranks::Traffic;
use anyhow::{Result, anyhow};
use mpi::datatype::{Partition, PartitionMut};
use mpi::environment::Universe;
use mpi::topology::{Communicator, SimpleCommunicator};
use mpi::traits::*;
use splat_runtime::train::fit::FitError;
use splat_runtime::train::team::Team;
use std::cell::Cell;

pub struct MpiTeam {
    world: SimpleCommunicator,
    rank: usize,
    ranks: usize,
    traffic: Cell<Traffic>,
    // Last: finalizes MPI when the team goes.
    _universe: Universe,
}

impl MpiTeam {
    /// Initializes MPI and joins its world; every rank but 0 sends its standard output away.
    pub fn join() -> Result<MpiTeam> {
        let universe = mpi::initialize().ok_or_else(|| anyhow!("MPI was initialized already"))?;
        let world = universe.world();
        let (rank, ranks) = (world.rank() as usize, world.size() as usize);
        if rank > 0 {
            quiet_stdout()?;
        }
        Ok(MpiTeam {
            world,
            rank,
            ranks,
            traffic: Cell::default(),
            _universe: universe,
        })
    }

    /// Every rank's `mine`, in rank order. The bytes travel as 8-byte words, whose counts
    /// MPI takes as 32-bit: up to 16 GiB in all.
    fn exchange(&self, mine: &[u8]) -> Result<Vec<Vec<u8>>, String> {
        let len = mine.len() as u64;
        let mut lens = vec![0u64; self.ranks];
        self.world.all_gather_into(&len, &mut lens[..]);
        let (counts, displs) = layout(&lens)?;
        let send = in_words(&[mine], &[0]);
        let mut recv = vec![0u64; total(&counts)];
        let mut parts = PartitionMut::new(&mut recv[..], &counts[..], &displs[..]);
        self.world.all_gather_varcount_into(&send[..], &mut parts);
        Ok(from_words(&recv, &lens, &displs))
    }

    /// What every rank sent this one, given what this one sends each: the sizes first
    /// (`MPI_Alltoall`), then the bytes in 8-byte words (`MPI_Alltoallv`).
    fn exchange_each(&self, to_each: &[Vec<u8>]) -> Result<Vec<Vec<u8>>, String> {
        let lens: Vec<u64> = to_each.iter().map(|b| b.len() as u64).collect();
        let mut got = vec![0u64; self.ranks];
        self.world.all_to_all_into(&lens[..], &mut got[..]);
        let (send_counts, send_displs) = layout(&lens)?;
        let (recv_counts, recv_displs) = layout(&got)?;
        let parts: Vec<&[u8]> = to_each.iter().map(Vec::as_slice).collect();
        let send = in_words(&parts, &send_displs);
        let mut recv = vec![0u64; total(&recv_counts)];
        let sent = Partition::new(&send[..], &send_counts[..], &send_displs[..]);
        let mut parts = PartitionMut::new(&mut recv[..], &recv_counts[..], &recv_displs[..]);
        self.world.all_to_all_varcount_into(&sent, &mut parts);
        Ok(from_words(&recv, &got, &recv_displs))
    }

    /// Rank 0's `bytes` on every rank.
    pub fn broadcast(&self, bytes: Option<Vec<u8>>) -> Result<Vec<u8>> {
        let root = self.world.process_at_rank(0);
        let mut len = bytes.as_ref().map_or(0, |b| b.len() as u64);
        root.broadcast_into(&mut len);
        let mut buf = bytes.unwrap_or_else(|| vec![0; len as usize]);
        // Broadcast in pieces: MPI counts in 32 bits.
        for piece in buf.chunks_mut(1 << 30) {
            root.broadcast_into(piece);
        }
        Ok(buf)
    }

    /// Every rank's outcome of some step (a value, or why it failed), in rank order.
    pub fn all_outcomes(
        &self,
        mine: &std::result::Result<u64, String>,
    ) -> Result<Vec<std::result::Result<u64, String>>> {
        let bytes = match mine {
            Ok(v) => [&[0u8][..], &v.to_le_bytes()].concat(),
            Err(e) => [&[1u8][..], e.as_bytes()].concat(),
        };
        let all = self.exchange(&bytes).map_err(|e| anyhow!(e))?;
        all.into_iter()
            .map(|b| match b.split_first() {
                Some((0, v)) if v.len() == 8 => Ok(Ok(u64::from_le_bytes(v.try_into()?))),
                Some((1, e)) => Ok(Err(String::from_utf8_lossy(e).into_owned())),
                _ => Err(anyhow!("a rank sent no outcome")),
            })
            .collect()
    }

    /// What this rank's batches exchanged so far.
    pub fn traffic(&self) -> Traffic {
        self.traffic.get()
    }

    /// Prints `error` as this rank's and aborts every rank (`MPI_Abort`): the others would
    /// wait for this one at the next gather.
    pub fn abort(&self, error: &anyhow::Error) -> ! {
        eprintln!("error: rank {} of {}: {error:#}", self.rank, self.ranks);
        self.world.abort(1)
    }
}

impl Team for MpiTeam {
    fn rank(&self) -> usize {
        self.rank
    }

    fn ranks(&self) -> usize {
        self.ranks
    }

    fn all_to_all(&self, to_each: Vec<Vec<u8>>) -> Result<Vec<Vec<u8>>, FitError> {
        if to_each.len() != self.ranks {
            return Err(FitError::Unsupported(format!(
                "{} messages for {} ranks",
                to_each.len(),
                self.ranks
            )));
        }
        let all = self
            .exchange_each(&to_each)
            .map_err(FitError::Unsupported)?;
        let others = |parts: &[Vec<u8>]| {
            let all: usize = parts.iter().map(Vec::len).sum();
            (all - parts[self.rank].len()) as u64
        };
        let t = self.traffic.get();
        self.traffic.set(Traffic {
            sent: t.sent + others(&to_each),
            received: t.received + others(&all),
        });
        Ok(all)
    }

    fn all_gather(&self, mine: Vec<u8>) -> Result<Vec<Vec<u8>>, FitError> {
        let all = self.exchange(&mine).map_err(FitError::Unsupported)?;
        let t = self.traffic.get();
        let others: usize = all.iter().map(Vec::len).sum::<usize>() - mine.len();
        self.traffic.set(Traffic {
            // Every other rank gets this rank's bytes.
            sent: t.sent + (mine.len() * (self.ranks - 1)) as u64,
            received: t.received + others as u64,
        });
        Ok(all)
    }
}

/// Bytes as 8-byte words: a part of `n` bytes takes `n.div_ceil(8)`.
fn words(n: u64) -> u64 {
    n.div_ceil(8)
}

/// The counts and displacements, in words, of parts of `lens` bytes laid one after another,
/// as MPI takes them (32-bit: up to 16 GiB in all).
fn layout(lens: &[u64]) -> Result<(Vec<i32>, Vec<i32>), String> {
    let too_big = || "the ranks' messages pass MPI's 16 GiB per exchange".to_string();
    let counts: Vec<i32> = (lens.iter())
        .map(|&n| i32::try_from(words(n)))
        .collect::<Result<_, _>>()
        .map_err(|_| too_big())?;
    let displs: Vec<i32> = (counts.iter())
        .scan(0i64, |at, &c| {
            let d = *at;
            *at += c as i64;
            Some(i32::try_from(d))
        })
        .collect::<Result<_, _>>()
        .map_err(|_| too_big())?;
    Ok((counts, displs))
}

fn total(counts: &[i32]) -> usize {
    counts.iter().map(|&c| c as usize).sum()
}

/// `parts` copied into words at `displs` (MPI's ranks here share one architecture, so the
/// bytes travel as they are).
fn in_words(parts: &[&[u8]], displs: &[i32]) -> Vec<u64> {
    let len = (parts.iter().zip(displs))
        .map(|(p, &d)| d as u64 + words(p.len() as u64))
        .max()
        .unwrap_or(0);
    let mut out = vec![0u64; len as usize];
    let bytes = bytemuck::cast_slice_mut::<u64, u8>(&mut out);
    for (p, &d) in parts.iter().zip(displs) {
        let at = 8 * d as usize;
        bytes[at..at + p.len()].copy_from_slice(p);
    }
    out
}

/// The parts of `lens` bytes at `displs` words in `words`.
fn from_words(words: &[u64], lens: &[u64], displs: &[i32]) -> Vec<Vec<u8>> {
    let bytes = bytemuck::cast_slice::<u64, u8>(words);
    (lens.iter().zip(displs))
        .map(|(&n, &d)| bytes[8 * d as usize..][..n as usize].to_vec())
        .collect()
}

/// Points standard output at /dev/null: the ranks past 0 print nothing but their errors.
fn quiet_stdout() -> Result<()> {
    use std::os::fd::AsRawFd;
    let null = std::fs::OpenOptions::new().write(true).open("/dev/null")?;
    // SAFETY: dup2 on two open descriptors; stdout's old file is closed by it.
    if unsafe { libc::dup2(null.as_raw_fd(), libc::STDOUT_FILENO) } < 0 {
        return Err(std::io::Error::last_os_error().into());
    }
    Ok(())
}
