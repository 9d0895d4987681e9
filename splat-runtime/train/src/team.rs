//! The processes a run is shared among. Each renders its share of a batch's views
//! ([`super::batch::Batch::share`]) and every one applies all of the batch's views in view
//! order, so all hold the same scene after every step: the same sums in the same order as one
//! process taking the whole batch, bit for bit. One process is a [`Solo`] team; the command
//! line's MPI team (`splat fit` under `mpirun`) gathers the views' results over MPI.

use super::fit::FitError;
use super::loss::LossValue;

/// What one view of a batch contributes to its step: its loss, its loss's gradient of every
/// parameter word, and (while density control gathers them) the screen-space gradient norm of
/// each primitive it shows.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewPass {
    pub loss: LossValue,
    pub grads: Vec<f32>,
    /// `(primitive, screen-space gradient norm)` in the order the view lists them.
    pub seen: Vec<(u32, f32)>,
    /// The training view it was (its index).
    pub view: usize,
    /// The gradient by the view's per-view words and its camera's ([`super::per_view`]);
    /// empty where the run learns none.
    pub corrections: Vec<f32>,
}

/// What a rank contributes to a batch: the passes of its views, and whether it was asked to
/// stop (every rank then ends after this batch, so that none waits for the others). A rank
/// that sums its views' gradients itself (on the GPU) sends that sum as its first pass's
/// `grads`, and none in the others.
#[derive(Clone, Debug, PartialEq)]
pub struct Share {
    pub passes: Vec<ViewPass>,
    pub stop: bool,
}

/// A run's processes, as the training loop sees them.
pub trait Team {
    /// This process's rank, from 0.
    fn rank(&self) -> usize;
    /// How many processes share the run.
    fn ranks(&self) -> usize;
    /// Every rank's `mine`, in rank order.
    fn all_gather(&self, mine: Vec<u8>) -> Result<Vec<Vec<u8>>, FitError>;
    /// What every rank sent this one, in rank order, given what this one sends each
    /// (`to_each[r]` goes to rank `r`; one per rank).
    fn all_to_all(&self, to_each: Vec<Vec<u8>>) -> Result<Vec<Vec<u8>>, FitError>;

    /// Every rank's share of the batch, in rank order (and so their passes in view order),
    /// given this rank's.
    fn gather(&self, mine: Share) -> Result<Vec<Share>, FitError> {
        if self.ranks() == 1 {
            return Ok(vec![mine]);
        }
        let all = self.all_gather(mine.encode())?;
        (all.iter().enumerate())
            .map(|(r, bytes)| {
                Share::decode(bytes)
                    .map_err(|e| FitError::Unsupported(format!("rank {r}'s share: {e}")))
            })
            .collect()
    }
}

/// One process: it renders every view of a batch.
pub struct Solo;

impl Team for Solo {
    fn rank(&self) -> usize {
        0
    }

    fn ranks(&self) -> usize {
        1
    }

    fn all_gather(&self, mine: Vec<u8>) -> Result<Vec<Vec<u8>>, FitError> {
        Ok(vec![mine])
    }

    fn all_to_all(&self, to_each: Vec<Vec<u8>>) -> Result<Vec<Vec<u8>>, FitError> {
        Ok(to_each)
    }
}

/// Density control's statistics (per primitive, the summed screen-space gradient norms and
/// the views that saw it) of every rank, summed in rank order: the same on every rank.
pub fn gather_statistics(
    team: &dyn Team,
    (grad2d, seen): (Vec<f32>, Vec<u32>),
) -> Result<(Vec<f32>, Vec<u32>), FitError> {
    if team.ranks() == 1 {
        return Ok((grad2d, seen));
    }
    let n = grad2d.len();
    let mut mine = Vec::with_capacity(8 * n);
    put_words(&mut mine, &grad2d);
    put_words(&mut mine, &seen);
    let (mut grad2d, mut seen) = (vec![0.0f32; n], vec![0u32; n]);
    for (r, bytes) in team.all_gather(mine)?.iter().enumerate() {
        if bytes.len() != 8 * n {
            return Err(FitError::Unsupported(format!(
                "rank {r} sent statistics of {} bytes, not {} for {n} primitives",
                bytes.len(),
                8 * n
            )));
        }
        let (g, c) = bytes.split_at(4 * n);
        for (sum, x) in grad2d.iter_mut().zip(get_words::<f32>(g)) {
            *sum += x;
        }
        for (sum, x) in seen.iter_mut().zip(get_words::<u32>(c)) {
            *sum += x;
        }
    }
    Ok((grad2d, seen))
}

impl Share {
    /// The share as bytes: the stop flag (a byte), the passes' count, then for each the loss
    /// (three f64), the gradient's length and words, the seen primitives' count and pairs,
    /// the view's index, the per-view gradient's length and words, little-endian.
    pub fn encode(&self) -> Vec<u8> {
        let size = |p: &ViewPass| {
            3 * 8 + 8 + 4 * p.grads.len() + 8 + 8 * p.seen.len() + 16 + 4 * p.corrections.len()
        };
        let mut out = Vec::with_capacity(9 + self.passes.iter().map(size).sum::<usize>());
        out.push(self.stop as u8);
        out.extend((self.passes.len() as u64).to_le_bytes());
        for p in &self.passes {
            for x in [p.loss.loss, p.loss.l1, p.loss.ssim] {
                out.extend(x.to_le_bytes());
            }
            out.extend((p.grads.len() as u64).to_le_bytes());
            put_words(&mut out, &p.grads);
            out.extend((p.seen.len() as u64).to_le_bytes());
            for (i, norm) in &p.seen {
                out.extend(i.to_le_bytes());
                out.extend(norm.to_le_bytes());
            }
            out.extend((p.view as u64).to_le_bytes());
            out.extend((p.corrections.len() as u64).to_le_bytes());
            put_words(&mut out, &p.corrections);
        }
        out
    }

    /// The share [`Share::encode`] wrote, or why `bytes` are not one.
    pub fn decode(bytes: &[u8]) -> Result<Share, String> {
        let mut r = Reader { bytes, at: 0 };
        let stop = match r.take::<1>()? {
            [0] => false,
            [1] => true,
            [b] => return Err(format!("a stop flag of {b}")),
        };
        let count = r.len(3 * 8 + 32)?;
        let mut passes = Vec::with_capacity(count);
        for _ in 0..count {
            let [loss, l1, ssim] = [r.f64()?, r.f64()?, r.f64()?];
            let words = r.len(4)?;
            let grads = get_words(r.slice(4 * words)?);
            let seen = r.len(8)?;
            let seen = (0..seen)
                .map(|_| Ok((r.u32()?, r.f32()?)))
                .collect::<Result<_, String>>()?;
            let view = usize::try_from(u64::from_le_bytes(r.take()?))
                .map_err(|_| "a view index past this machine's".to_string())?;
            let words = r.len(4)?;
            let corrections = get_words(r.slice(4 * words)?);
            passes.push(ViewPass {
                loss: LossValue { loss, l1, ssim },
                grads,
                seen,
                view,
                corrections,
            });
        }
        match r.at == bytes.len() {
            true => Ok(Share { passes, stop }),
            false => Err(format!("{} bytes past the passes", bytes.len() - r.at)),
        }
    }
}

/// 4-byte `words` (f32 or u32) appended to `out` little-endian: one copy on little-endian
/// machines.
pub(crate) fn put_words<T: bytemuck::Pod>(out: &mut Vec<u8>, words: &[T]) {
    debug_assert_eq!(std::mem::size_of::<T>(), 4);
    let bytes: &[u8] = bytemuck::cast_slice(words);
    match cfg!(target_endian = "little") {
        true => out.extend_from_slice(bytes),
        false => out.extend(bytes.chunks_exact(4).flat_map(|w| [w[3], w[2], w[1], w[0]])),
    }
}

/// The 4-byte words [`put_words`] wrote (`bytes` a multiple of 4 long).
pub(crate) fn get_words<T: bytemuck::Pod>(bytes: &[u8]) -> Vec<T> {
    debug_assert_eq!(std::mem::size_of::<T>(), 4);
    let mut words: Vec<T> = bytemuck::pod_collect_to_vec(bytes);
    if cfg!(target_endian = "big") {
        for w in bytemuck::cast_slice_mut::<T, [u8; 4]>(&mut words) {
            w.reverse();
        }
    }
    words
}

/// Little-endian reads that fail past the end instead of panicking.
pub(crate) struct Reader<'a> {
    pub bytes: &'a [u8],
    pub at: usize,
}

impl Reader<'_> {
    pub(crate) fn take<const N: usize>(&mut self) -> Result<[u8; N], String> {
        self.slice(N).map(|b| b.try_into().expect("N bytes"))
    }

    /// The next `n` bytes.
    pub(crate) fn slice(&mut self, n: usize) -> Result<&[u8], String> {
        let left = self.bytes.len() - self.at;
        let got = (self.bytes.get(self.at..self.at + n))
            .ok_or_else(|| format!("the passes end {left} bytes on, short of {n} more"))?;
        self.at += n;
        Ok(got)
    }

    pub(crate) fn f64(&mut self) -> Result<f64, String> {
        self.take().map(f64::from_le_bytes)
    }

    pub(crate) fn f32(&mut self) -> Result<f32, String> {
        self.take().map(f32::from_le_bytes)
    }

    pub(crate) fn u32(&mut self) -> Result<u32, String> {
        self.take().map(u32::from_le_bytes)
    }

    /// A count of items of at least `item` bytes each, refused where the bytes left cannot
    /// hold that many (so a bad count allocates nothing).
    pub(crate) fn len(&mut self, item: usize) -> Result<usize, String> {
        let n = u64::from_le_bytes(self.take()?);
        let left = (self.bytes.len() - self.at) as u64;
        match n.checked_mul(item as u64).is_some_and(|b| b <= left) {
            true => Ok(n as usize),
            false => Err(format!("a count of {n} with {left} bytes left")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pass(k: u32) -> ViewPass {
        ViewPass {
            loss: LossValue {
                loss: 0.5 + k as f64,
                l1: 0.25,
                ssim: -0.0,
            },
            grads: vec![1.0, f32::MIN_POSITIVE, -3.5e-30, k as f32],
            seen: (0..k).map(|i| (i * 7, i as f32 / 3.0)).collect(),
            view: k as usize * 5,
            corrections: (0..k).map(|i| i as f32 - 0.5).collect(),
        }
    }

    #[test]
    fn shares_come_back_bit_for_bit() {
        for share in [
            Share {
                passes: vec![pass(0), pass(3), pass(1)],
                stop: false,
            },
            Share {
                passes: vec![],
                stop: true,
            },
        ] {
            assert_eq!(Share::decode(&share.encode()).unwrap(), share);
        }
    }

    #[test]
    fn cut_or_padded_bytes_are_refused_not_misread() {
        let share = Share {
            passes: vec![pass(2), pass(1)],
            stop: false,
        };
        let bytes = share.encode();
        for cut in 0..bytes.len() {
            assert!(Share::decode(&bytes[..cut]).is_err(), "cut at {cut}");
        }
        let mut padded = bytes.clone();
        padded.push(0);
        assert!(Share::decode(&padded).is_err());
        let mut flag = bytes.clone();
        flag[0] = 2;
        assert!(Share::decode(&flag).is_err());
        // A count that the bytes cannot hold allocates nothing.
        let mut huge = bytes;
        huge[1..9].copy_from_slice(&u64::MAX.to_le_bytes());
        assert!(Share::decode(&huge).is_err());
    }
}
