//! The method-independent GPU stages: exclusive prefix sum, stable radix sort of u32 keys,
//! tile ranges and trip-count binning. Each stage owns the buffers it needs between frames
//! (grown to the largest frame so far, never re-created for a steady one): `prepare` sizes
//! them and writes the frame's uniforms, `record` adds the dispatches to the caller's encoder.

use super::device::{Grown, Kernel, dispatch};
use super::{Gpu, GpuError};

const SCAN: &str = include_str!("shaders/scan.wgsl");
const RADIX: &str = include_str!("shaders/radix.wgsl");
const RANGES: &str = include_str!("shaders/ranges.wgsl");
const BINS: &str = include_str!("shaders/bins.wgsl");

/// Keys per radix-sort workgroup (shaders/radix.wgsl `BLOCK`).
const SORT_BLOCK: u32 = 4096;
/// Bits of the key sorted per pass, and the buckets they make (shaders/radix.wgsl `RADIX`).
const DIGIT_BITS: u32 = 8;
const BUCKETS: u32 = 1 << DIGIT_BITS;
/// Words per prefix-sum block (shaders/scan.wgsl).
const SCAN_BLOCK: u32 = 256;

/// In-place exclusive prefix sum: one level per 256-fold reduction, each with its block
/// totals and its uniform.
pub struct Scan {
    blocks: Kernel,
    offsets: Kernel,
    /// Per level: block totals, `[words]` uniform, words at this level.
    levels: Vec<(Grown, wgpu::Buffer, u32)>,
}

impl Scan {
    pub fn new(gpu: &Gpu) -> Result<Scan, GpuError> {
        Ok(Scan {
            blocks: gpu.kernel(SCAN, "scan_blocks")?,
            offsets: gpu.kernel(SCAN, "add_block_offsets")?,
            levels: vec![],
        })
    }

    /// Sizes the levels for a scan of `n` words.
    pub fn prepare(&mut self, gpu: &Gpu, n: u32) -> Result<(), GpuError> {
        let mut words = n;
        let mut level = 0;
        loop {
            let blocks = words.div_ceil(SCAN_BLOCK).max(1);
            if self.levels.len() == level {
                self.levels.push((
                    Grown::new(gpu, "prefix-sum block totals", blocks as usize)?,
                    gpu.uniform_buffer(4),
                    0,
                ));
            }
            let (sums, info, at) = &mut self.levels[level];
            sums.ensure(gpu, blocks as usize)?;
            gpu.write(info, &[words, 0, 0, 0]);
            *at = words;
            if blocks == 1 {
                self.levels.truncate(level + 1);
                return Ok(());
            }
            words = blocks;
            level += 1;
        }
    }

    /// Records the scan of `data` (the size given to [`Scan::prepare`]).
    pub fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        data: &wgpu::Buffer,
    ) -> Result<(), GpuError> {
        self.record_level(gpu, encoder, data, 0)
    }

    fn record_level(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        data: &wgpu::Buffer,
        level: usize,
    ) -> Result<(), GpuError> {
        let (sums, info, words) = &self.levels[level];
        let blocks = words.div_ceil(SCAN_BLOCK).max(1);
        let bind = |k| gpu.bind_named(k, &[("data", data), ("sums", sums), ("info", info)]);
        dispatch(encoder, &self.blocks.pipeline, &bind(&self.blocks)?, blocks);
        if blocks > 1 {
            self.record_level(gpu, encoder, sums, level + 1)?;
            dispatch(
                encoder,
                &self.offsets.pipeline,
                &bind(&self.offsets)?,
                blocks,
            );
        }
        Ok(())
    }
}

/// Bits of a tile index among `tiles`: the bits a sort of tile keys sorts.
pub(crate) fn tile_bits(tiles: u32) -> u32 {
    32 - tiles.saturating_sub(1).leading_zeros()
}

/// Stable LSD radix sort of u32 keys with u32 values, over as many low key bits as the caller
/// says. Sorts in place: the keys end where they started (an odd pass count ends with a copy
/// back). Sized on the host for the buffers' room, it sorts as many keys as a count on the
/// device says.
pub struct RadixSort {
    histogram: Kernel,
    scatter: Kernel,
    hist: Grown,
    keys_tmp: Grown,
    vals_tmp: Grown,
    scan: Scan,
    /// `[shift, blocks]` per pass.
    passes: Vec<wgpu::Buffer>,
    /// Keys the buffers hold.
    room: u32,
    /// Passes the prepared sort takes.
    digits: u32,
}

impl RadixSort {
    pub fn new(gpu: &Gpu) -> Result<RadixSort, GpuError> {
        Ok(RadixSort {
            histogram: gpu.kernel(RADIX, "radix_histogram")?,
            scatter: gpu.kernel(RADIX, "radix_scatter")?,
            hist: Grown::new(gpu, "radix-sort histograms", BUCKETS as usize)?,
            keys_tmp: Grown::new(gpu, "sorted keys", 1)?,
            vals_tmp: Grown::new(gpu, "sorted values", 1)?,
            scan: Scan::new(gpu)?,
            passes: vec![],
            room: 0,
            digits: 0,
        })
    }

    /// Bytes a sort of `n` keys on their low `key_bits` holds: the keys and values, and their
    /// scratch copies when it takes a pass (the digit histograms aside).
    pub fn bytes_for(n: usize, key_bits: u32) -> usize {
        let copies = if key_bits > 0 { 2 } else { 1 };
        8 * n * copies
    }

    /// Sizes the buffers for up to `room` keys sorted on their low `key_bits` and writes each
    /// pass's uniform.
    pub fn prepare(&mut self, gpu: &Gpu, room: u32, key_bits: u32) -> Result<(), GpuError> {
        self.digits = key_bits.min(32).div_ceil(DIGIT_BITS);
        self.room = room;
        if self.digits == 0 {
            return Ok(());
        }
        let blocks = room.div_ceil(SORT_BLOCK).max(1);
        self.hist.ensure(gpu, (BUCKETS * blocks) as usize)?;
        self.keys_tmp.ensure(gpu, room as usize)?;
        self.vals_tmp.ensure(gpu, room as usize)?;
        self.scan.prepare(gpu, BUCKETS * blocks)?;
        while self.passes.len() < self.digits as usize {
            self.passes.push(gpu.uniform_buffer(4));
        }
        for (d, info) in self.passes[..self.digits as usize].iter().enumerate() {
            gpu.write(info, &[d as u32 * DIGIT_BITS, blocks, 0, 0]);
        }
        Ok(())
    }

    /// Records the sort in place of the first `key_count[0]` keys and values (at most the
    /// room prepared).
    pub fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        keys: &wgpu::Buffer,
        vals: &wgpu::Buffer,
        key_count: &wgpu::Buffer,
    ) -> Result<(), GpuError> {
        let blocks = self.room.div_ceil(SORT_BLOCK).max(1);
        let (mut from, mut to) = ((keys, vals), (&*self.keys_tmp, &*self.vals_tmp));
        for info in &self.passes[..self.digits as usize] {
            let (h, s) = (&self.histogram, &self.scatter);
            let bind = gpu.bind_named(
                h,
                &[
                    ("keys_in", from.0),
                    ("hist", &self.hist),
                    ("info", info),
                    ("key_count", key_count),
                ],
            )?;
            dispatch(encoder, &h.pipeline, &bind, blocks);
            self.scan.record(gpu, encoder, &self.hist)?;
            let bind = gpu.bind_named(
                s,
                &[
                    ("keys_in", from.0),
                    ("hist", &self.hist),
                    ("info", info),
                    ("vals_in", from.1),
                    ("keys_out", to.0),
                    ("vals_out", to.1),
                    ("key_count", key_count),
                ],
            )?;
            dispatch(encoder, &s.pipeline, &bind, blocks);
            std::mem::swap(&mut from, &mut to);
        }
        // The whole room: the count is on the device.
        if self.digits % 2 == 1 && self.room > 0 {
            let bytes = 4 * self.room as u64;
            encoder.copy_buffer_to_buffer(from.0, 0, keys, 0, bytes);
            encoder.copy_buffer_to_buffer(from.1, 0, vals, 0, bytes);
        }
        Ok(())
    }
}

/// Per tile `[start, end)` of its entries in the sorted keys, then the tiles ordered by bin of
/// list length (capped at `P_max`), longest first.
pub struct TileRanges {
    ranges_kernel: Kernel,
    bins_kernel: Kernel,
    pub ranges: Grown,
    pub order: Grown,
    bins_info: wgpu::Buffer,
    /// Keys the buffers hold.
    room: u32,
    tiles: u32,
}

impl TileRanges {
    pub fn new(gpu: &Gpu) -> Result<TileRanges, GpuError> {
        Ok(TileRanges {
            ranges_kernel: gpu.kernel(RANGES, "tile_ranges")?,
            bins_kernel: gpu.kernel(BINS, "bin_tiles")?,
            ranges: Grown::new(gpu, "tile ranges", 2)?,
            order: Grown::new(gpu, "tile order", 1)?,
            bins_info: gpu.uniform_buffer(4),
            room: 0,
            tiles: 0,
        })
    }

    /// Sizes the ranges for `tiles` tiles of up to `room` sorted keys.
    pub fn prepare(
        &mut self,
        gpu: &Gpu,
        room: u32,
        tiles: u32,
        p_max: u32,
    ) -> Result<(), GpuError> {
        self.ranges.ensure(gpu, 2 * tiles as usize)?;
        self.order.ensure(gpu, tiles as usize)?;
        gpu.write(&self.bins_info, &[tiles, p_max, 0, 0]);
        (self.room, self.tiles) = (room, tiles);
        Ok(())
    }

    /// Records the ranges of the first `key_count[0]` sorted `keys` and the binned tile order.
    pub fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        keys: &wgpu::Buffer,
        key_count: &wgpu::Buffer,
    ) -> Result<(), GpuError> {
        encoder.clear_buffer(&self.ranges, 0, Some(8 * self.tiles as u64));
        let k = &self.ranges_kernel;
        let named = [
            ("keys", keys),
            ("ranges", &self.ranges),
            ("key_count", key_count),
        ];
        let bind = gpu.bind_named(k, &named)?;
        dispatch(encoder, &k.pipeline, &bind, self.room.div_ceil(256));
        self.record_bins(gpu, encoder)
    }

    fn record_bins(&self, gpu: &Gpu, encoder: &mut wgpu::CommandEncoder) -> Result<(), GpuError> {
        let k = &self.bins_kernel;
        let named = [
            ("ranges", &*self.ranges),
            ("order", &self.order),
            ("info", &self.bins_info),
        ];
        let bind = gpu.bind_named(k, &named)?;
        dispatch(encoder, &k.pipeline, &bind, 1);
        Ok(())
    }
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
        let mut scan = Scan::new(&gpu).unwrap();
        // Sized for a smaller scan first: the levels grow.
        scan.prepare(&gpu, 300).unwrap();
        scan.prepare(&gpu, words.len() as u32).unwrap();
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        scan.record(&gpu, &mut enc, &buf).unwrap();
        gpu.finish(enc).unwrap();
        let got = gpu.read(&buf, words.len()).unwrap();
        let mut acc = 0;
        for (i, (w, g)) in words.iter().zip(&got).enumerate() {
            assert_eq!(*g, acc, "word {i}");
            acc += w;
        }
    }

    #[test]
    fn radix_sort_is_stable_and_orders_by_the_bits_asked() {
        let Some(gpu) = super::super::adapter_or_skip() else {
            return;
        };
        // Depth bits: four passes over random bits in every byte. 300 tiles: nine bits, two
        // passes, with the ranges. 200 tiles: one pass (the keys end in the scratch buffers
        // and are copied back).
        let mut rng = fastrand::Rng::with_seed(4);
        let depths: Vec<u32> = (0..40)
            .map(|_| (0.1 + 100.0 * rng.f32()).to_bits())
            .collect();
        sorts_stably(&gpu, 32, &depths, None);
        for tiles in [300, 200] {
            let keys: Vec<u32> = (0..tiles).collect();
            sorts_stably(&gpu, tile_bits(tiles), &keys, Some(tiles));
        }
    }

    /// Sorts 9,001 keys (3 blocks) drawn from `distinct` (few, so many are equal and the sort
    /// must keep their order) on their low `bits`; with `tiles`, the keys are tiles and their
    /// ranges are checked too.
    fn sorts_stably(gpu: &Gpu, bits: u32, distinct: &[u32], tiles: Option<u32>) {
        let mut rng = fastrand::Rng::with_seed(5);
        let keys: Vec<u32> = (0..9001)
            .map(|_| distinct[rng.usize(0..distinct.len())])
            .collect();
        let n = keys.len() as u32;
        // The buffers hold 5,000 more keys than the count on the device says to sort: zero,
        // they would move ahead of every key if sorted.
        let room = n + 5000;
        let vals: Vec<u32> = (0..n).collect();
        let pad = |v: &[u32]| [v, &vec![0; (room - n) as usize]].concat();
        let (k, v) = (
            gpu.buffer_from("keys", &pad(&keys)).unwrap(),
            gpu.buffer_from("vals", &pad(&vals)).unwrap(),
        );
        let count = gpu.buffer_from("key count", &[n, 0]).unwrap();
        let mut sort = RadixSort::new(gpu).unwrap();
        sort.prepare(gpu, room, bits).unwrap();
        // Ranges only where the keys are tiles (a depth key is no tile index).
        let mut ranges = TileRanges::new(gpu).unwrap();
        ranges
            .prepare(gpu, room, tiles.unwrap_or(1), u32::MAX)
            .unwrap();
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        sort.record(gpu, &mut enc, &k, &v, &count).unwrap();
        if tiles.is_some() {
            ranges.record(gpu, &mut enc, &k, &count).unwrap();
        }
        gpu.finish(enc).unwrap();
        let got_vals = gpu.read(&v, n as usize).unwrap();
        let got_keys = gpu.read(&k, n as usize).unwrap();
        let mut want: Vec<u32> = vals.clone();
        want.sort_by_key(|&i| (keys[i as usize], i));
        assert_eq!(got_vals, want, "{bits} bits");
        let want_keys: Vec<u32> = want.iter().map(|&i| keys[i as usize]).collect();
        assert_eq!(got_keys, want_keys);
        let Some(tiles) = tiles else {
            return;
        };
        let ranges = gpu.read(&ranges.ranges, 2 * tiles as usize).unwrap();
        for t in 0..tiles {
            let count = keys.iter().filter(|&&k| k == t).count() as u32;
            let (s, e) = (ranges[2 * t as usize], ranges[2 * t as usize + 1]);
            assert_eq!(e - s, count, "tile {t}");
            assert!(want_keys[s as usize..e as usize].iter().all(|&k| k == t));
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
        let mut bins = TileRanges::new(&gpu).unwrap();
        bins.prepare(&gpu, start, lens.len() as u32, 100).unwrap();
        gpu.write(&bins.ranges, &ranges);
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        bins.record_bins(&gpu, &mut enc).unwrap();
        gpu.finish(enc).unwrap();
        let order = gpu.read(&bins.order, lens.len()).unwrap();
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
