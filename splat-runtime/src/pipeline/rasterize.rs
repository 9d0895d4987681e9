//! Stage 3: tile lists. Count the tiles each visible primitive keeps (per tile, with atomic
//! counters), prefix-sum the counts into tile ranges, emit every (primitive, tile) pair into its
//! tile's range, then sort each tile's range by depth. Counting and emitting go through the
//! same [`for_each_kept_tile`], so they cannot disagree. Bucketing by tile first replaces a
//! global sort of all intersections by many small independent sorts.

use super::RenderError;
use super::grid::{TileGrid, TileRect};
use super::preprocess::Preprocessed;
use crate::method::SplatMethod;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};

/// Largest number of (primitive, tile) intersections a frame may have: lists are indexed
/// with `u32`.
pub const MAX_INTERSECTIONS: u64 = u32::MAX as u64;

/// Per-tile front-to-back lists of primitive indices.
pub struct TileLists {
    /// Primitive indices, grouped by tile, each group sorted by depth.
    pub prims: Vec<u32>,
    /// `prims[ranges[t]..ranges[t + 1]]` is tile `t`'s list.
    pub ranges: Vec<u32>,
}

impl TileLists {
    pub fn list(&self, tile: usize) -> &[u32] {
        &self.prims[self.ranges[tile] as usize..self.ranges[tile + 1] as usize]
    }

    pub fn intersections(&self) -> usize {
        self.prims.len()
    }
}

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

pub fn rasterize<M: SplatMethod>(
    pre: &Preprocessed<M>,
    grid: &TileGrid,
    use_cull: bool,
) -> Result<TileLists, RenderError> {
    let tiles = grid.tile_count();
    let counts: Vec<AtomicU32> = (0..tiles).map(|_| AtomicU32::new(0)).collect();
    let total = AtomicU64::new(0);
    pre.visible.par_iter().for_each(|(i, rect)| {
        let mut n = 0u64;
        for_each_kept_tile::<M>(
            grid,
            rect,
            &pre.projected[*i as usize].cull,
            use_cull,
            |t| {
                counts[t as usize].fetch_add(1, Ordering::Relaxed);
                n += 1;
            },
        );
        total.fetch_add(n, Ordering::Relaxed);
    });
    let total = total.into_inner();
    if total > MAX_INTERSECTIONS {
        return Err(RenderError::TooManyIntersections {
            count: total,
            limit: MAX_INTERSECTIONS,
        });
    }
    let mut ranges = Vec::with_capacity(tiles + 1);
    ranges.push(0u32);
    for c in &counts {
        ranges.push(ranges.last().unwrap() + c.load(Ordering::Relaxed));
    }
    // Emit: each pair takes the next free slot of its tile.
    let cursors: Vec<AtomicU32> = ranges[..tiles].iter().map(|&r| AtomicU32::new(r)).collect();
    let slots: Vec<AtomicU64> = (0..total).map(|_| AtomicU64::new(0)).collect();
    pre.visible.par_iter().for_each(|(i, rect)| {
        let p = &pre.projected[*i as usize];
        let e = entry(p.depth, *i);
        for_each_kept_tile::<M>(grid, rect, &p.cull, use_cull, |t| {
            let k = cursors[t as usize].fetch_add(1, Ordering::Relaxed);
            slots[k as usize].store(e, Ordering::Relaxed);
        });
    });
    let mut entries: Vec<u64> = slots.into_iter().map(AtomicU64::into_inner).collect();
    // Sort every tile's range (the slot order within a tile depended on thread timing).
    let mut segments = Vec::with_capacity(tiles);
    let mut rest = entries.as_mut_slice();
    for t in 0..tiles {
        let (head, tail) = rest.split_at_mut((ranges[t + 1] - ranges[t]) as usize);
        segments.push(head);
        rest = tail;
    }
    segments.into_par_iter().for_each(|s| s.sort_unstable());
    let prims = entries.into_par_iter().map(|e| e as u32).collect();
    Ok(TileLists { prims, ranges })
}
