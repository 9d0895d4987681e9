//! Stage 3: tile lists. Count the tiles each visible primitive keeps (per chunk of primitives,
//! into the chunk's own tile histogram: no counter shared between threads), prefix-sum the
//! counts into tile ranges and each chunk's slots in them, emit every (primitive, tile) pair
//! into its chunk's slots, then sort each tile's range by depth. `tile_cull` runs once per
//! candidate tile: emitting replays the tiles counting kept, so the two cannot disagree.
//! Bucketing by tile first replaces a global sort of all intersections by many small
//! independent sorts.

use crate::preprocess::Preprocessed;
use rayon::prelude::*;
use splat_core::frame::RenderError;
use splat_core::grid::{MAX_INTERSECTIONS, TileLists};
use splat_core::grid::{TileGrid, TileRect};
use splat_core::method::SplatMethod;

/// Calls `f(tile_id)` for every tile of `rect` that `tile_cull` keeps (every tile when the
/// method has none or `use_cull` is false).
pub fn for_each_kept_tile<M: SplatMethod>(
    grid: &TileGrid,
    rect: &TileRect,
    cull: &M::Cull,
    use_cull: bool,
    mut f: impl FnMut(u32),
) {
    let use_cull = use_cull && M::HAS_TILE_CULL;
    for ty in rect.y0..rect.y1 {
        for tx in rect.x0..rect.x1 {
            if !use_cull || M::tile_cull(&grid.bounds(tx, ty), cull) {
                f(ty * grid.tiles_x + tx);
            }
        }
    }
}

/// Depth in the high half, primitive in the low half: sorting these orders a tile's list
/// front to back, ties broken by index. Depths are positive (the near plane), and the bit
/// patterns of positive floats sort like their values.
fn entry(depth: f32, prim: u32) -> u64 {
    ((depth.max(0.0).to_bits() as u64) << 32) | prim as u64
}

/// Visible primitives per chunk: each chunk counts and emits on its own tile histogram, so no
/// counter is shared between threads, and the lists come out the same whatever the thread count.
const CHUNK: usize = 4096;

pub fn rasterize<M: SplatMethod>(
    pre: &Preprocessed<M>,
    grid: &TileGrid,
    use_cull: bool,
) -> Result<TileLists, RenderError> {
    let tiles = grid.tile_count();
    // The count below keeps each pair's tile (4 bytes) before the total is known: where the
    // boxes alone could pass the limit, the pairs are counted first (the boxes are the pairs
    // where no `tile_cull` runs), so that a frame over it is refused without holding them.
    let boxed: u64 = pre.visible.par_iter().map(|(_, r)| r.count() as u64).sum();
    if boxed > MAX_INTERSECTIONS {
        let count: u64 = match use_cull && M::HAS_TILE_CULL {
            false => boxed,
            true => (pre.visible.par_iter())
                .map(|(i, rect)| {
                    let mut n = 0u64;
                    let cull = &pre.projected[*i as usize].cull;
                    for_each_kept_tile::<M>(grid, rect, cull, use_cull, |_| n += 1);
                    n
                })
                .sum(),
        };
        if count > MAX_INTERSECTIONS {
            return Err(RenderError::TooManyIntersections {
                count,
                limit: MAX_INTERSECTIONS,
            });
        }
    }
    // Count: per chunk, the tiles each primitive keeps (`tile_cull` runs once per candidate
    // tile) and the pairs of each tile.
    let chunks: Vec<&[(u32, TileRect)]> = pre.visible.chunks(CHUNK).collect();
    let (mut histograms, kept): (Vec<Vec<u32>>, Vec<Kept>) = chunks
        .par_iter()
        .map(|chunk| {
            let mut h = vec![0u32; tiles];
            let mut kept = Kept::default();
            for (i, rect) in chunk.iter() {
                let before = kept.tiles.len();
                let cull = &pre.projected[*i as usize].cull;
                for_each_kept_tile::<M>(grid, rect, cull, use_cull, |t| {
                    h[t as usize] += 1;
                    kept.tiles.push(t);
                });
                kept.counts.push((kept.tiles.len() - before) as u32);
            }
            (h, kept)
        })
        .unzip();
    // Each tile's range, then each chunk's first slot in it (chunks in order), in place.
    let mut ranges = Vec::with_capacity(tiles + 1);
    ranges.push(0u64);
    for t in 0..tiles {
        let mut at = *ranges.last().unwrap();
        for h in histograms.iter_mut() {
            let n = h[t] as u64;
            h[t] = at as u32;
            at += n;
        }
        if at > MAX_INTERSECTIONS {
            return Err(RenderError::TooManyIntersections {
                count: at,
                limit: MAX_INTERSECTIONS,
            });
        }
        ranges.push(at);
    }
    let total = *ranges.last().unwrap() as usize;
    // Emit: every chunk writes only its own slots of each tile.
    let mut entries = Vec::new();
    entries
        .try_reserve_exact(total)
        .map_err(|_| RenderError::Memory {
            what: "tile lists",
            bytes: total as u64 * 8,
        })?;
    entries.resize(total, 0u64);
    let out = SharedSlots(entries.as_mut_ptr());
    (chunks, kept, histograms.as_mut_slice())
        .into_par_iter()
        .for_each(|(chunk, kept, cursor)| {
            let mut tiles = kept.tiles.iter();
            for ((i, _), &count) in chunk.iter().zip(&kept.counts) {
                let e = entry(pre.projected[*i as usize].depth, *i);
                for &t in tiles.by_ref().take(count as usize) {
                    let k = &mut cursor[t as usize];
                    // SAFETY: slot k lies in this chunk's own part of tile t's range (the
                    // counts above), which no other chunk writes, and below `total`.
                    unsafe { out.write(*k as usize, e) };
                    *k += 1;
                }
            }
        });
    // Sort every tile's range by depth (ties by index).
    let mut segments = Vec::with_capacity(tiles);
    let mut rest = entries.as_mut_slice();
    for t in 0..tiles {
        let (head, tail) = rest.split_at_mut((ranges[t + 1] - ranges[t]) as usize);
        segments.push(head);
        rest = tail;
    }
    segments.into_par_iter().for_each(|s| s.sort_unstable());
    let prims = entries.into_par_iter().map(|e| e as u32).collect();
    let ranges = ranges.into_iter().map(|r| r as u32).collect();
    Ok(TileLists { prims, ranges })
}

/// The tiles a chunk's primitives keep, in order, and how many each keeps.
#[derive(Default)]
struct Kept {
    tiles: Vec<u32>,
    counts: Vec<u32>,
}

/// The entries buffer, written from several threads at disjoint indices.
struct SharedSlots(*mut u64);

// SAFETY: every write goes to an index no other thread writes (see `rasterize`).
unsafe impl Sync for SharedSlots {}

impl SharedSlots {
    /// # Safety
    /// `k` is in bounds and no other thread reads or writes it.
    unsafe fn write(&self, k: usize, e: u64) {
        unsafe { *self.0.add(k) = e };
    }
}
