//! Stage 4: per tile, per group of eight pixels, blend the tile's list front to back.
//!
//! A group is eight consecutive pixels of one row of the tile; each lane carries its own
//! transmittance and stops on its own (a lane is done once the next primitive would bring its
//! transmittance to [`Blend::t_min`] or below, the gsplat rule). The loop leaves a group when
//! every lane is done. `P_max` caps how many entries of a tile's list are visited.

use crate::preprocess::Preprocessed;
use glam::Vec2;
use splat_core::blend::Blend;
use splat_core::flat::Flat;
use splat_core::grid::TileGrid;
use splat_core::lanes::{F32x8, LANES, M32x8, U32x8};
use splat_core::method::SplatMethod;
use splat_core::types::{Camera, Projected};

/// What one tile's blend produced, in the tile's pixel order (row-major over the full tile,
/// including pixels past the image edge, which stay zero).
pub struct TileOutput {
    pub color: Vec<f32>,
    /// Final transmittance per pixel.
    pub transmittance: Vec<f32>,
    /// Per pixel, how far into the list its walk went: the index of the last entry it took,
    /// plus one (zero when it took none). The backward pass walks back from there.
    pub ends: Vec<u32>,
    /// Sum of weight * depth per pixel (only when depth is requested).
    pub depth: Vec<f32>,
    /// Number of (pixel, primitive) evaluations on pixels still blending.
    pub pairs: u64,
}

/// The pixel data of the eight pixels of a group, as lanes, and the lanes inside the image.
pub fn group_pixels<M: SplatMethod, const MODEL: u32>(
    grid: &TileGrid,
    camera: &Camera,
    x0: u32,
    y: u32,
) -> (M::PixelLanes, M32x8) {
    let mut lanes = M::PixelLanes::default();
    let mut inside = [false; LANES];
    let mut words = [0.0f32; 64];
    assert!(
        M::Pixel::LEN <= words.len(),
        "pixel data larger than 64 words"
    );
    for (l, ok) in inside.iter_mut().enumerate() {
        let x = x0 + l as u32;
        *ok = x < grid.width && y < grid.height;
        let pixel = M::pixel_info_as::<MODEL>(Vec2::new(x as f32 + 0.5, y as f32 + 0.5), camera);
        pixel.write_words(&mut words);
        for (w, lane) in lanes.as_mut().iter_mut().enumerate() {
            lane.0[l] = words[w];
        }
    }
    (lanes, M32x8::from(inside))
}

/// The lanes on which a pair counts at all: the method keeps it and its alpha reaches
/// [`Blend::alpha_min`]. Of the entries a pixel walks before it stops, it takes exactly
/// these, which is how the backward pass replays the forward's choice.
#[inline(always)]
pub fn counts(alpha: F32x8, valid: M32x8, blend: Blend) -> M32x8 {
    valid & alpha.ge(F32x8::splat(blend.alpha_min))
}

/// One step of the blend for a group: which lanes take this primitive, and which stop here.
pub struct Step {
    pub alpha: F32x8,
    /// alpha * T on the lanes that take the primitive, zero on every other lane: what the
    /// primitive adds to any blended quantity (color, depth, the backward pass's prefixes).
    pub weight: F32x8,
    /// Lanes that blend the primitive in.
    pub take: M32x8,
    /// Lanes that end before it.
    pub stop: M32x8,
}

/// The forward blend's rule.
#[inline(always)]
pub fn step(alpha: F32x8, valid: M32x8, done: M32x8, t: F32x8, blend: Blend) -> Step {
    let live = counts(alpha, valid, blend) & !done;
    let next = t * (1.0 - alpha);
    let stop = live & next.le(F32x8::splat(blend.stop_at()));
    let take = live & !stop;
    Step {
        alpha,
        weight: take.select_f32(alpha * t, F32x8::splat(0.0)),
        take,
        stop,
    }
}

/// Whether `p`'s box misses every pixel centre of the group of eight pixels from `(x0, y)`:
/// `evaluate` is then invalid on all its lanes (the box's contract), so the pair can be
/// skipped without computing it, in the forward and the backward pass alike.
#[inline(always)]
pub fn misses_group<C, S>(p: &Projected<C, S>, x0: u32, y: u32) -> bool {
    let (x, y) = (x0 as f32 + 0.5, y as f32 + 0.5);
    let last = x + (LANES - 1) as f32;
    y < p.bbox_min.y || y > p.bbox_max.y || last < p.bbox_min.x || x > p.bbox_max.x
}

/// Blends one tile, in code compiled for AVX2 + FMA where the CPU has them.
pub fn shade_tile<M: SplatMethod>(
    grid: &TileGrid,
    camera: &Camera,
    tile: u32,
    list: &[u32],
    pre: &Preprocessed<M>,
    want_depth: bool,
    blend: Blend,
) -> TileOutput {
    splat_core::with_pixel_model!(M, camera.model, MODEL => {
        #[cfg(target_arch = "x86_64")]
        if splat_core::lanes::has_avx2() {
            // SAFETY: the CPU supports the features the function is compiled for.
            return unsafe {
                shade_tile_avx2::<M, MODEL>(grid, camera, tile, list, pre, want_depth, blend)
            };
        }
        shade_tile_body::<M, MODEL>(grid, camera, tile, list, pre, want_depth, blend)
    })
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn shade_tile_avx2<M: SplatMethod, const MODEL: u32>(
    grid: &TileGrid,
    camera: &Camera,
    tile: u32,
    list: &[u32],
    pre: &Preprocessed<M>,
    want_depth: bool,
    blend: Blend,
) -> TileOutput {
    shade_tile_body::<M, MODEL>(grid, camera, tile, list, pre, want_depth, blend)
}

#[inline(always)]
fn shade_tile_body<M: SplatMethod, const MODEL: u32>(
    grid: &TileGrid,
    camera: &Camera,
    tile: u32,
    list: &[u32],
    pre: &Preprocessed<M>,
    want_depth: bool,
    blend: Blend,
) -> TileOutput {
    let s = grid.size as usize;
    // Reduced-precision shade data is decoded once per tile, not per pixel group.
    let mut shades = pre.tile_shades(list);
    let channels = M::Color::LEN;
    let mut out = TileOutput {
        color: vec![0.0; s * s * channels],
        transmittance: vec![1.0; s * s],
        ends: vec![0; s * s],
        depth: if want_depth { vec![0.0; s * s] } else { vec![] },
        pairs: 0,
    };
    let (tx, ty) = grid.tile_xy(tile);
    for row in 0..s {
        for gx in (0..s).step_by(LANES) {
            let (x0, y) = (tx * grid.size + gx as u32, ty * grid.size + row as u32);
            let (pixels, inside) = group_pixels::<M, MODEL>(grid, camera, x0, y);
            let mut done = !inside;
            let mut t = F32x8::splat(1.0);
            let mut color = M::ColorLanes::default();
            let mut depth = F32x8::splat(0.0);
            let mut ends = U32x8::splat(0);
            // Pairs per lane, summed once the group is done (a sum per pair costs a
            // horizontal add in the hottest loop).
            let mut pairs = U32x8::splat(0);
            for (k, &prim) in list.iter().enumerate() {
                if done.all() {
                    break;
                }
                let p = &pre.projected[prim as usize];
                if misses_group(p, x0, y) {
                    continue;
                }
                let c = M::evaluate_lanes(&pixels, shades.get(k));
                pairs = pairs + (!done).to_u32();
                let st = step(c.alpha, c.valid, done, t, blend);
                let w = st.weight;
                for (acc, ch) in color.as_mut().iter_mut().zip(c.color.as_ref()) {
                    *acc = *acc + w * *ch;
                }
                if want_depth {
                    depth = depth + w * p.depth;
                }
                t = st.take.select_f32(t * (1.0 - st.alpha), t);
                done = done | st.stop;
                ends = st.take.select_u32(U32x8::splat(k as u32 + 1), ends);
            }
            out.pairs += pairs.0.iter().map(|&p| p as u64).sum::<u64>();
            for (l, end) in ends.0.into_iter().enumerate() {
                let px = row * s + gx + l;
                out.transmittance[px] = t.lane(l);
                out.ends[px] = end;
                for (ch, v) in color.as_ref().iter().enumerate() {
                    out.color[px * channels + ch] = v.lane(l);
                }
                if want_depth {
                    out.depth[px] = depth.lane(l);
                }
            }
        }
    }
    out
}
