//! Stage 3: tile lists. Count the tiles each visible primitive keeps, prefix-sum the counts,
//! emit one (tile, depth) key per kept tile, sort, and find each tile's range. Counting and
//! emitting go through the same [`for_each_kept_tile`], so they cannot disagree.

use super::RenderError;
use super::grid::{TileGrid, TileRect};
use super::preprocess::Preprocessed;
use crate::method::SplatMethod;
use rayon::prelude::*;

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

/// Calls `f(tile_id)` for every tile of `rect` that `tile_cull` keeps.
pub fn for_each_kept_tile<M: SplatMethod>(
    grid: &TileGrid,
    rect: &TileRect,
    cull: &M::Cull,
    mut f: impl FnMut(u32),
) {
    for ty in rect.y0..rect.y1 {
        for tx in rect.x0..rect.x1 {
            if !M::HAS_TILE_CULL || M::tile_cull(&grid.bounds(tx, ty), cull) {
                f(ty * grid.tiles_x + tx);
            }
        }
    }
}

/// Sort key: tile in the high half, depth in the low half. Depths are positive finite floats
/// (checked by the caller), whose bit patterns sort like the values.
fn key(tile: u32, depth: f32) -> u64 {
    ((tile as u64) << 32) | depth.max(0.0).to_bits() as u64
}

pub fn rasterize<M: SplatMethod>(
    pre: &Preprocessed<M>,
    grid: &TileGrid,
) -> Result<TileLists, RenderError> {
    let counts: Vec<u32> = pre
        .visible
        .par_iter()
        .map(|(i, rect)| {
            let mut n = 0;
            for_each_kept_tile::<M>(grid, rect, &pre.projected[*i as usize].cull, |_| n += 1);
            n
        })
        .collect();
    let total: u64 = counts.iter().map(|&c| c as u64).sum();
    if total > MAX_INTERSECTIONS {
        return Err(RenderError::TooManyIntersections {
            count: total,
            limit: MAX_INTERSECTIONS,
        });
    }
    // Replicate: each primitive writes its keys into its own slice.
    let mut entries = vec![(0u64, 0u32); total as usize];
    let mut slices = Vec::with_capacity(counts.len());
    let mut rest = entries.as_mut_slice();
    for &c in &counts {
        let (head, tail) = rest.split_at_mut(c as usize);
        slices.push(head);
        rest = tail;
    }
    pre.visible
        .par_iter()
        .zip(slices)
        .for_each(|((i, rect), out)| {
            let p = &pre.projected[*i as usize];
            let mut k = 0;
            for_each_kept_tile::<M>(grid, rect, &p.cull, |t| {
                out[k] = (key(t, p.depth), *i);
                k += 1;
            });
        });
    // Ties in depth are broken by primitive index, so the order is deterministic.
    entries.par_sort_unstable();
    let mut ranges = vec![0u32; grid.tile_count() + 1];
    for (k, (key, _)) in entries.iter().enumerate() {
        ranges[(key >> 32) as usize + 1] = k as u32 + 1;
    }
    // Tiles without entries take the end of the previous tile.
    for t in 1..ranges.len() {
        ranges[t] = ranges[t].max(ranges[t - 1]);
    }
    Ok(TileLists {
        prims: entries.into_iter().map(|(_, p)| p).collect(),
        ranges,
    })
}
