//! The method-independent GPU stages: exclusive prefix sum, stable radix sort of
//! (depth bits, tile) keys, tile ranges and trip-count binning. Each records its dispatches
//! into the caller's encoder; buffers are allocated here and checked against device limits.

use super::device::dispatch;
use super::{Gpu, GpuError};

const SCAN: &str = include_str!("shaders/scan.wgsl");
const RADIX: &str = include_str!("shaders/radix.wgsl");
const RANGES: &str = include_str!("shaders/ranges.wgsl");
const BINS: &str = include_str!("shaders/bins.wgsl");

/// Keys per radix-sort workgroup (shaders/radix.wgsl `BLOCK`).
const SORT_BLOCK: u32 = 4096;
/// Bits of the key sorted per pass (16 buckets).
const DIGIT_BITS: u32 = 4;

/// In-place exclusive prefix sum of the first `n` words of `data`.
pub fn exclusive_scan(
    gpu: &Gpu,
    encoder: &mut wgpu::CommandEncoder,
    data: &wgpu::Buffer,
    n: u32,
) -> Result<(), GpuError> {
    let blocks = n.div_ceil(256).max(1);
    let sums = gpu.buffer("prefix-sum block totals", blocks as usize)?;
    let info = gpu.uniform(&[n]);
    let scan = gpu.pipeline(SCAN, "scan_blocks")?;
    dispatch(
        encoder,
        &scan,
        &gpu.bind(&scan, &[data, &sums, &info]),
        blocks,
    );
    if blocks > 1 {
        exclusive_scan(gpu, encoder, &sums, blocks)?;
        let add = gpu.pipeline(SCAN, "add_block_offsets")?;
        dispatch(
            encoder,
            &add,
            &gpu.bind(&add, &[data, &sums, &info]),
            blocks,
        );
    }
    Ok(())
}

/// Sorts `n` keys (`vec2(depth bits, tile)`) with their values by tile, then depth, keeping
/// the input order among equal keys. Returns the sorted keys and values (ping-pong buffers).
pub fn sort_by_tile_and_depth(
    gpu: &Gpu,
    encoder: &mut wgpu::CommandEncoder,
    keys: wgpu::Buffer,
    vals: wgpu::Buffer,
    n: u32,
    tiles: u32,
) -> Result<(wgpu::Buffer, wgpu::Buffer), GpuError> {
    let tile_bits = 32 - tiles.saturating_sub(1).leading_zeros();
    let blocks = n.div_ceil(SORT_BLOCK).max(1);
    let hist = gpu.buffer("radix-sort histograms", 16 * blocks as usize)?;
    let (mut keys, mut vals) = (keys, vals);
    let mut keys_out = gpu.buffer("sorted keys", 2 * n.max(1) as usize)?;
    let mut vals_out = gpu.buffer("sorted values", n as usize)?;
    let histogram = gpu.pipeline(RADIX, "radix_histogram")?;
    let scatter = gpu.pipeline(RADIX, "radix_scatter")?;
    // Least significant digit first: depth (word 0), then tile (word 1).
    let digits = (0..32 / DIGIT_BITS)
        .map(|d| (0, d * DIGIT_BITS))
        .chain((0..tile_bits.div_ceil(DIGIT_BITS)).map(|d| (1, d * DIGIT_BITS)));
    for (word, shift) in digits {
        let info = gpu.uniform(&[n, shift, word, blocks]);
        let bind = gpu.bind(&histogram, &[&keys, &hist, &info]);
        dispatch(encoder, &histogram, &bind, blocks);
        exclusive_scan(gpu, encoder, &hist, 16 * blocks)?;
        let bind = gpu.bind(
            &scatter,
            &[&keys, &hist, &info, &vals, &keys_out, &vals_out],
        );
        dispatch(encoder, &scatter, &bind, blocks);
        std::mem::swap(&mut keys, &mut keys_out);
        std::mem::swap(&mut vals, &mut vals_out);
    }
    Ok((keys, vals))
}

/// `[start, end)` of each tile's entries in the sorted keys, two words per tile.
pub fn tile_ranges(
    gpu: &Gpu,
    encoder: &mut wgpu::CommandEncoder,
    keys: &wgpu::Buffer,
    n: u32,
    tiles: u32,
) -> Result<wgpu::Buffer, GpuError> {
    let ranges = gpu.buffer("tile ranges", 2 * tiles as usize)?;
    encoder.clear_buffer(&ranges, 0, None);
    let info = gpu.uniform(&[n]);
    let p = gpu.pipeline(RANGES, "tile_ranges")?;
    dispatch(
        encoder,
        &p,
        &gpu.bind(&p, &[keys, &ranges, &info]),
        n.div_ceil(256),
    );
    Ok(ranges)
}

/// Tile ids ordered by bin of list length (capped at `p_max`), longest first.
pub fn bin_tiles(
    gpu: &Gpu,
    encoder: &mut wgpu::CommandEncoder,
    ranges: &wgpu::Buffer,
    tiles: u32,
    p_max: u32,
) -> Result<wgpu::Buffer, GpuError> {
    let order = gpu.buffer("tile order", tiles as usize)?;
    let info = gpu.uniform(&[tiles, p_max]);
    let p = gpu.pipeline(BINS, "bin_tiles")?;
    dispatch(encoder, &p, &gpu.bind(&p, &[ranges, &order, &info]), 1);
    Ok(order)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scan_matches_a_sequential_sum_across_three_levels() {
        let Some(gpu) = super::super::adapter_or_skip() else {
            return;
        };
        let mut rng = fastrand::Rng::with_seed(3);
        // 70,000 words: 274 blocks of 256, whose sums need a second and a third level.
        let words: Vec<u32> = (0..70_000).map(|_| rng.u32(0..50)).collect();
        let buf = gpu.buffer_from("test", &words).unwrap();
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        exclusive_scan(&gpu, &mut enc, &buf, words.len() as u32).unwrap();
        gpu.finish(enc).unwrap();
        let got = gpu.read(&buf, words.len()).unwrap();
        let mut acc = 0;
        for (i, (w, g)) in words.iter().zip(&got).enumerate() {
            assert_eq!(*g, acc, "word {i}");
            acc += w;
        }
    }

    #[test]
    fn radix_sort_is_stable_and_orders_by_tile_then_depth() {
        let Some(gpu) = super::super::adapter_or_skip() else {
            return;
        };
        let mut rng = fastrand::Rng::with_seed(4);
        let tiles = 300u32;
        // Few distinct depths, so many equal keys test stability; 9,001 keys = 3 blocks.
        let keys: Vec<(u32, u32)> = (0..9001)
            .map(|_| {
                (
                    (rng.u32(0..40) as f32 * 0.25 + 1.0).to_bits(),
                    rng.u32(0..tiles),
                )
            })
            .collect();
        let flat: Vec<u32> = keys.iter().flat_map(|(d, t)| [*d, *t]).collect();
        let vals: Vec<u32> = (0..keys.len() as u32).collect();
        let n = keys.len() as u32;
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        let (k, v) = sort_by_tile_and_depth(
            &gpu,
            &mut enc,
            gpu.buffer_from("keys", &flat).unwrap(),
            gpu.buffer_from("vals", &vals).unwrap(),
            n,
            tiles,
        )
        .unwrap();
        let ranges = tile_ranges(&gpu, &mut enc, &k, n, tiles).unwrap();
        gpu.finish(enc).unwrap();
        let got_vals = gpu.read(&v, n as usize).unwrap();
        let got_keys = gpu.read(&k, 2 * n as usize).unwrap();
        let mut want: Vec<u32> = vals.clone();
        want.sort_by_key(|&i| (keys[i as usize].1, keys[i as usize].0, i));
        assert_eq!(got_vals, want);
        for (i, &val) in want.iter().enumerate() {
            let (d, t) = keys[val as usize];
            assert_eq!((got_keys[2 * i], got_keys[2 * i + 1]), (d, t));
        }
        let ranges = gpu.read(&ranges, 2 * tiles as usize).unwrap();
        for t in 0..tiles {
            let count = keys.iter().filter(|k| k.1 == t).count() as u32;
            let (s, e) = (ranges[2 * t as usize], ranges[2 * t as usize + 1]);
            assert_eq!(e - s, count, "tile {t}");
            assert!(
                want[s as usize..e as usize]
                    .iter()
                    .all(|&i| keys[i as usize].1 == t)
            );
        }
    }

    #[test]
    fn binning_puts_longer_lists_first_and_keeps_every_tile_once() {
        let Some(gpu) = super::super::adapter_or_skip() else {
            return;
        };
        let lens = [0u32, 5, 1, 300, 2, 17, 0, 64, 1000, 3];
        let mut ranges = vec![];
        let mut start = 0;
        for l in lens {
            ranges.extend([start, start + l]);
            start += l;
        }
        let buf = gpu.buffer_from("ranges", &ranges).unwrap();
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        let order = bin_tiles(&gpu, &mut enc, &buf, lens.len() as u32, 100).unwrap();
        gpu.finish(enc).unwrap();
        let order = gpu.read(&order, lens.len()).unwrap();
        let mut sorted = order.clone();
        sorted.sort();
        assert_eq!(sorted, (0..lens.len() as u32).collect::<Vec<_>>());
        let bits = |t: u32| 32 - lens[t as usize].min(100).leading_zeros();
        assert!(
            order.windows(2).all(|w| bits(w[0]) >= bits(w[1])),
            "{order:?}"
        );
    }
}
