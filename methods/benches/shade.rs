//! The CPU's shade stage per (pixel, primitive) pair beside a plain loop doing the same work
//! written by hand: 3DGS's `evaluate` and the blend for eight lanes of a tile row, compiled for
//! AVX2 + FMA as the stage is, walking the same tile lists with the same box test, stop rule
//! and exp. Prints ns per pair per core for the stage as `render` times it (the tiles and the
//! image assembled from them), the tile kernel alone, and the plain loop, with their ratios to
//! the plain loop (issue 62: the stage within 1.5x of it).
//!
//! `cargo bench -p splat-methods --bench shade [-- N WIDTH HEIGHT]` (x86-64 with AVX2 + FMA)

use rayon::prelude::*;
use splat_methods::gs3d::{self, Method};
use splat_runtime::blend::Blend;
use splat_runtime::grid::{TileGrid, TileLists};
use splat_runtime::pipeline::preprocess::{Preprocessed, preprocess};
use splat_runtime::pipeline::{rasterize, shade};
use splat_runtime::precision::Precision;
use splat_runtime::{RenderOptions, render};
use std::time::{Duration, Instant};

mod common;
use common::{camera, scene, size_args};

/// The best of three runs of `f`, with what it returned.
fn best<T>(mut f: impl FnMut() -> T) -> (Duration, T) {
    let mut out = None;
    let mut fastest = Duration::MAX;
    for _ in 0..3 {
        let t = Instant::now();
        let r = f();
        fastest = fastest.min(t.elapsed());
        out = Some(r);
    }
    (fastest, out.expect("three runs"))
}

/// Tiles longest list first, one per task, as the stage schedules them.
fn tile_order(grid: &TileGrid, lists: &TileLists) -> Vec<u32> {
    let mut order: Vec<u32> = (0..grid.tile_count() as u32).collect();
    order.sort_by_key(|&t| std::cmp::Reverse(lists.list(t as usize).len()));
    order
}

fn main() {
    let (n, w, h) = size_args(200_000, 960, 540);
    let cam = camera(w, h);
    let params = scene(n);
    let opts = RenderOptions::default();
    let cores = rayon::current_num_threads();
    let grid = TileGrid::new(w as u32, h as u32, opts.tile_size);
    let pre = preprocess::<Method>(&params, &cam, &grid, Precision::F32);
    let lists = rasterize::rasterize::<Method>(&pre, &grid, opts.tile_cull).unwrap();
    let order = tile_order(&grid, &lists);
    let blend = opts.blend;
    println!("{n} Gaussians at {w}x{h}, {cores} threads");

    // The stage's own clock: the best of three renders.
    let renders: Vec<_> = (0..3)
        .map(|_| render::<Method>(&params, &cam, &opts).unwrap().stats)
        .collect();
    let stage = renders
        .iter()
        .map(|s| s.shade)
        .min()
        .expect("three renders");
    let pairs = renders[0].pairs;
    let (kernel, kernel_pairs) = best(|| {
        (order.par_iter().with_max_len(1))
            .map(|&t| {
                let list = lists.list(t as usize);
                shade::shade_tile::<Method>(&grid, &cam, t, list, &pre, false, blend).pairs
            })
            .sum::<u64>()
    });
    let (plain, plain_pairs) = best(|| {
        (order.par_iter().with_max_len(1))
            .map(|&t| plain_tile(&grid, t, lists.list(t as usize), &pre, blend))
            .sum::<u64>()
    });
    assert_eq!(
        kernel_pairs, pairs,
        "the kernel evaluates the stage's pairs"
    );
    assert_eq!(
        plain_pairs, pairs,
        "the plain loop evaluates the stage's pairs"
    );
    let per = |d: Duration| d.as_secs_f64() * 1e9 * cores as f64 / pairs as f64;
    println!("{pairs} pairs evaluated");
    let base = per(plain);
    for (what, d) in [
        ("shade stage (as render times it)", stage),
        ("tile kernel alone", kernel),
        ("plain loop", plain),
    ] {
        println!(
            "{what:>34}: {:7.1} ms | {:.2} ns per pair per core | {:.2}x the plain loop",
            d.as_secs_f64() * 1e3,
            per(d),
            per(d) / base
        );
    }
}

/// One tile blended by the plain loop: its pairs (as the stage counts them).
fn plain_tile(
    grid: &TileGrid,
    tile: u32,
    list: &[u32],
    pre: &Preprocessed<Method>,
    blend: Blend,
) -> u64 {
    assert!(
        splat_runtime::lanes::has_avx2(),
        "the plain loop is written for AVX2 + FMA"
    );
    // SAFETY: the CPU supports the features the function is compiled for.
    unsafe { plain_tile_avx2(grid, tile, list, pre, blend) }
}

/// The plain loop in AVX2 intrinsics: eight pixels of a tile row per vector, 3DGS's
/// `evaluate` and the blend's rule written out, `splat_runtime::math::exp`'s arithmetic
/// operation for operation (so that the same pairs are taken), the output kept in a buffer
/// per tile as the stage's is.
#[target_feature(enable = "avx2,fma")]
fn plain_tile_avx2(
    grid: &TileGrid,
    tile: u32,
    list: &[u32],
    pre: &Preprocessed<Method>,
    blend: Blend,
) -> u64 {
    use std::arch::x86_64::*;
    let s = grid.size as usize;
    let mut out = vec![0.0f32; s * s * 4];
    let (tx, ty) = grid.tile_xy(tile);
    let splat = _mm256_set1_ps;
    let offsets = _mm256_setr_ps(0.5, 1.5, 2.5, 3.5, 4.5, 5.5, 6.5, 7.5);
    let ones = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
    let mut pairs = 0u64;
    for row in 0..s {
        for gx in (0..s).step_by(8) {
            let (x0, y) = (tx * grid.size + gx as u32, ty * grid.size + row as u32);
            let px = _mm256_add_ps(splat(x0 as f32), offsets);
            let py = splat(y as f32 + 0.5);
            let inside = _mm256_cmp_ps::<_CMP_LT_OQ>(px, splat(grid.width as f32));
            let mut done = match y < grid.height {
                true => _mm256_xor_ps(inside, ones),
                false => ones,
            };
            let mut t = splat(1.0);
            let mut color = [_mm256_setzero_ps(); 3];
            for &prim in list {
                let done_bits = _mm256_movemask_ps(done);
                if done_bits == 0xff {
                    break;
                }
                let p = &pre.projected[prim as usize];
                if shade::misses_group(p, x0, y) {
                    continue;
                }
                pairs += 8 - done_bits.count_ones() as u64;
                let sh = &p.shade;
                let dx = _mm256_sub_ps(px, splat(sh.center.x));
                let dy = _mm256_sub_ps(py, splat(sh.center.y));
                let xx = _mm256_mul_ps(_mm256_mul_ps(splat(sh.conic.x), dx), dx);
                let yy = _mm256_mul_ps(_mm256_mul_ps(splat(sh.conic.z), dy), dy);
                let xy = _mm256_mul_ps(_mm256_mul_ps(splat(sh.conic.y), dx), dy);
                let power = _mm256_add_ps(_mm256_mul_ps(splat(0.5), _mm256_add_ps(xx, yy)), xy);
                let e = exp8(_mm256_sub_ps(_mm256_setzero_ps(), power));
                let alpha = _mm256_min_ps(_mm256_mul_ps(splat(sh.opacity), e), splat(0.99));
                // 3DGS's `valid`, then the blend's own threshold.
                let valid = _mm256_and_ps(
                    _mm256_cmp_ps::<_CMP_GE_OQ>(power, _mm256_setzero_ps()),
                    _mm256_cmp_ps::<_CMP_GE_OQ>(alpha, splat(gs3d::ALPHA_MIN)),
                );
                let counts = _mm256_and_ps(
                    valid,
                    _mm256_cmp_ps::<_CMP_GE_OQ>(alpha, splat(blend.alpha_min)),
                );
                let live = _mm256_andnot_ps(done, counts);
                let next = _mm256_mul_ps(t, _mm256_sub_ps(splat(1.0), alpha));
                let stop = _mm256_and_ps(
                    live,
                    _mm256_cmp_ps::<_CMP_LE_OQ>(next, splat(blend.stop_at())),
                );
                let take = _mm256_andnot_ps(stop, live);
                let weight = _mm256_and_ps(take, _mm256_mul_ps(alpha, t));
                for (c, v) in color.iter_mut().zip([sh.color.x, sh.color.y, sh.color.z]) {
                    *c = _mm256_add_ps(*c, _mm256_mul_ps(weight, splat(v)));
                }
                t = _mm256_blendv_ps(t, next, take);
                done = _mm256_or_ps(done, stop);
            }
            let lanes = |v: __m256| -> [f32; 8] {
                // SAFETY: __m256 is eight f32s.
                unsafe { std::mem::transmute(v) }
            };
            let (c, t) = (color.map(lanes), lanes(t));
            for l in 0..8 {
                let px = (row * s + gx + l) * 4;
                out[px..px + 4].copy_from_slice(&[c[0][l], c[1][l], c[2][l], t[l]]);
            }
        }
    }
    std::hint::black_box(&out);
    pairs
}

/// `splat_runtime::math::exp` on eight lanes, operation for operation.
#[target_feature(enable = "avx2,fma")]
#[allow(clippy::excessive_precision)]
fn exp8(x: std::arch::x86_64::__m256) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    const MAGIC: f32 = 12_582_912.0;
    let (add, sub, mul, splat) = (_mm256_add_ps, _mm256_sub_ps, _mm256_mul_ps, _mm256_set1_ps);
    let xc = _mm256_max_ps(_mm256_min_ps(x, splat(89.0)), splat(-104.0));
    let t = add(mul(xc, splat(std::f32::consts::LOG2_E)), splat(MAGIC));
    let n = sub(t, splat(MAGIC));
    let ni = _mm256_sub_epi32(
        _mm256_castps_si256(t),
        _mm256_set1_epi32(MAGIC.to_bits() as i32),
    );
    let r = sub(
        sub(xc, mul(n, splat(0.693_359_4))),
        mul(n, splat(-2.121_944_4e-4)),
    );
    let mut p = splat(1.987_569_1e-4);
    for c in [
        1.398_199_9e-3,
        8.333_452e-3,
        4.166_579_6e-2,
        1.666_666_5e-1,
        5.000_000_1e-1,
    ] {
        p = add(mul(p, r), splat(c));
    }
    let e = add(add(mul(p, mul(r, r)), r), splat(1.0));
    let h = _mm256_srai_epi32::<1>(ni);
    let bias = _mm256_set1_epi32(127);
    let a = _mm256_castsi256_ps(_mm256_slli_epi32::<23>(_mm256_add_epi32(h, bias)));
    let b = _mm256_sub_epi32(ni, h);
    let b = _mm256_castsi256_ps(_mm256_slli_epi32::<23>(_mm256_add_epi32(b, bias)));
    let y = mul(mul(e, a), b);
    _mm256_blendv_ps(y, x, _mm256_cmp_ps::<_CMP_UNORD_Q>(x, x))
}
