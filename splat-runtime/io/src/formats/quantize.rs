//! The tables SOG stores values through (`docs/formats-spec.md` §4.2): a codebook of 256
//! scalars (1-D k-means), and a palette of vectors (k-means) for the SH past the DC term.

use rayon::prelude::*;

/// Entries of a scalar codebook: its indices are bytes.
pub const CODEBOOK: usize = 256;

/// 256 values, ascending, that the finite `values` sit close to: 1-D k-means (Lloyd) from the
/// quantiles, each step exact through prefix sums over the sorted values. Fewer distinct
/// values than entries are kept as they are (the last repeated).
pub fn codebook(values: &[f32]) -> [f32; CODEBOOK] {
    let mut sorted: Vec<f32> = values.iter().copied().filter(|v| v.is_finite()).collect();
    sorted.sort_by(f32::total_cmp);
    let mut distinct = sorted.clone();
    distinct.dedup();
    let mut book = [0.0f32; CODEBOOK];
    if distinct.len() <= CODEBOOK {
        let last = distinct.last().copied().unwrap_or(0.0);
        for (k, entry) in book.iter_mut().enumerate() {
            *entry = distinct.get(k).copied().unwrap_or(last);
        }
        return book;
    }
    let n = sorted.len();
    let mut prefix = Vec::with_capacity(n + 1);
    prefix.push(0.0f64);
    for v in &sorted {
        prefix.push(prefix.last().unwrap() + f64::from(*v));
    }
    let mut centres: Vec<f64> = (0..CODEBOOK)
        .map(|k| f64::from(sorted[((k as f64 + 0.5) / CODEBOOK as f64 * n as f64) as usize]))
        .collect();
    for _ in 0..64 {
        // Each centre takes the values closer to it than to its neighbours.
        let mut edges = vec![0];
        for pair in centres.windows(2) {
            let mid = 0.5 * (pair[0] + pair[1]);
            edges.push(sorted.partition_point(|v| f64::from(*v) < mid));
        }
        edges.push(n);
        let mut moved = false;
        for (k, centre) in centres.iter_mut().enumerate() {
            let (a, b) = (edges[k], edges[k + 1]);
            if b > a {
                let mean = (prefix[b] - prefix[a]) / (b - a) as f64;
                moved |= mean != *centre;
                *centre = mean;
            }
        }
        if !moved {
            break;
        }
    }
    centres.sort_by(f64::total_cmp);
    for (entry, c) in book.iter_mut().zip(&centres) {
        *entry = *c as f32;
    }
    book
}

/// The index of the entry of the ascending `book` nearest `v`.
pub fn nearest(book: &[f32; CODEBOOK], v: f32) -> u8 {
    let above = book.partition_point(|e| *e < v).min(CODEBOOK - 1);
    let below = above.saturating_sub(1);
    let pick = if (v - book[below]).abs() <= (book[above] - v).abs() {
        below
    } else {
        above
    };
    pick as u8
}

/// A palette of `k` vectors of `dim` values for the rows of `points` (`dim` values a row),
/// and each row's entry: k-means (Lloyd, `steps` steps) from rows spread evenly through the
/// input's order. Returns (palette, labels).
pub fn palette(points: &[f32], dim: usize, k: usize, steps: usize) -> (Vec<f32>, Vec<u32>) {
    let n = points.len() / dim;
    let k = k.clamp(1, n.max(1));
    let row = |i: usize| &points[i * dim..(i + 1) * dim];
    let mut centres: Vec<f32> = (0..k).flat_map(|c| row(c * n / k).to_vec()).collect();
    let mut labels = vec![0u32; n];
    for step in 0..=steps {
        let assigned: Vec<u32> = (0..n)
            .into_par_iter()
            .map(|i| {
                let p = row(i);
                let mut best = (f32::INFINITY, 0);
                for (c, centre) in centres.chunks_exact(dim).enumerate() {
                    let d: f32 = p.iter().zip(centre).map(|(a, b)| (a - b) * (a - b)).sum();
                    if d < best.0 {
                        best = (d, c as u32);
                    }
                }
                best.1
            })
            .collect();
        let settled = assigned == labels;
        labels = assigned;
        if step == steps || (settled && step > 0) {
            break;
        }
        let mut sums = vec![0.0f64; k * dim];
        let mut counts = vec![0usize; k];
        for (i, &c) in labels.iter().enumerate() {
            counts[c as usize] += 1;
            for (s, v) in sums[c as usize * dim..].iter_mut().zip(row(i)) {
                *s += f64::from(*v);
            }
        }
        // An entry no row took keeps its place.
        for c in (0..k).filter(|c| counts[*c] > 0) {
            for d in 0..dim {
                centres[c * dim + d] = (sums[c * dim + d] / counts[c] as f64) as f32;
            }
        }
    }
    (centres, labels)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_codebook_keeps_few_values_exactly_and_fits_many() {
        let few = [3.0, -1.0, 3.0, 0.5];
        let book = codebook(&few);
        assert_eq!(&book[..4], [-1.0, 0.5, 3.0, 3.0]);
        assert!(few.iter().all(|v| book[nearest(&book, *v) as usize] == *v));

        // 100,000 values spread over [-5, 5]: 256 entries leave each within half a spacing.
        let many: Vec<f32> = (0..100_000)
            .map(|i| ((i * 7919) % 100_000) as f32 / 1e4 - 5.0)
            .collect();
        let book = codebook(&many);
        assert!(book.windows(2).all(|w| w[0] <= w[1]));
        let worst = (many.iter())
            .map(|v| (book[nearest(&book, *v) as usize] - v).abs())
            .fold(0.0, f32::max);
        assert!(worst < 10.0 / 256.0, "{worst}");
        assert_eq!(codebook(&[f32::NAN, f32::INFINITY])[0], 0.0);
    }

    #[test]
    fn a_palette_finds_separate_clusters() {
        // Three tight clusters in 2-D, 40 rows each, interleaved.
        let centres = [[0.0, 0.0], [5.0, 5.0], [-4.0, 6.0]];
        let points: Vec<f32> = (0..120)
            .flat_map(|i| {
                let c = centres[i % 3];
                let jitter = (i as f32 * 0.37).sin() * 0.1;
                [c[0] + jitter, c[1] - jitter]
            })
            .collect();
        let (palette, labels) = palette(&points, 2, 3, 10);
        for i in 0..120 {
            let got = &palette[labels[i] as usize * 2..][..2];
            let want = centres[i % 3];
            assert!(
                (got[0] - want[0]).abs() < 0.2 && (got[1] - want[1]).abs() < 0.2,
                "{got:?}"
            );
        }
    }
}
