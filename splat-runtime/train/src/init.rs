//! Where training starts: primitives from a dataset's point cloud, or random ones in a cube
//! when the dataset has no points, each sized by its neighbours as 3DGS does (or all of one
//! given size and color).

use super::trainable::Trainable;
use glam::Vec3;
use rayon::prelude::*;
use splat_io::dataset::Point;

/// What every first primitive shares, where a run sets it rather than the points do.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Start {
    /// Its size (world units); `None`: the root mean square distance to its 3 nearest
    /// neighbours, as 3DGS sizes its first Gaussians.
    pub size: Option<f32>,
    /// Its color (RGB in [0, 1], as the images store it); `None`: its point's.
    pub color: Option<Vec3>,
}

/// Primitives at (at most `cap`, evenly spaced) `points` with their colors, each sized to its
/// neighbours' distance (a lone point: 0.01), unless `start` sets the size or color.
pub fn from_points<M: Trainable>(points: &[Point], cap: usize, start: Start) -> Vec<M::Params> {
    let points = evenly_spaced(points, cap);
    let sizes = match start.size {
        Some(s) => vec![s; points.len()],
        None => {
            let positions: Vec<Vec3> = points.iter().map(|p| p.position).collect();
            neighbour_spacing(&positions, 0.01)
        }
    };
    points
        .iter()
        .zip(sizes)
        .map(|(p, scale)| M::from_point(p.position, start.color.unwrap_or(p.color), scale))
        .collect()
}

/// At most `n` of `points`, evenly spaced through the list.
fn evenly_spaced(points: &[Point], n: usize) -> Vec<Point> {
    if points.len() <= n {
        return points.to_vec();
    }
    (0..n).map(|k| points[k * points.len() / n]).collect()
}

/// Each point's distance to its neighbours: the root mean square of the distances to its 3
/// nearest other points (fewer when there are fewer; `fallback` when alone), as 3DGS sizes its
/// first Gaussians. A k-d tree keeps this O(n log n) for COLMAP's hundreds of thousands.
fn neighbour_spacing(points: &[Vec3], fallback: f32) -> Vec<f32> {
    let mut tree: Vec<(Vec3, usize)> = points.iter().copied().zip(0..).collect();
    kd_build(&mut tree, 0);
    points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let mut best = [f32::INFINITY; 3];
            kd_nearest(&tree, 0, *p, i, &mut best);
            let found = best.iter().filter(|d| d.is_finite());
            let count = found.clone().count();
            if count == 0 {
                return fallback;
            }
            // 3DGS's floor on the mean squared distance keeps duplicates from a zero size.
            (found.sum::<f32>() / count as f32).max(1e-7).sqrt()
        })
        .collect()
}

/// Arranges `points` as an implicit k-d tree: each range's median along axis `depth % 3` in
/// its middle, the points not above it before, the points not below it after.
fn kd_build(points: &mut [(Vec3, usize)], depth: usize) {
    if points.len() <= 1 {
        return;
    }
    let (mid, axis) = (points.len() / 2, depth % 3);
    points.select_nth_unstable_by(mid, |a, b| a.0[axis].total_cmp(&b.0[axis]));
    let (below, above) = points.split_at_mut(mid);
    kd_build(below, depth + 1);
    kd_build(&mut above[1..], depth + 1);
}

/// Keeps in `best` (ascending) the 3 smallest squared distances from `q` to the points of
/// `tree` other than point `skip`.
fn kd_nearest(tree: &[(Vec3, usize)], depth: usize, q: Vec3, skip: usize, best: &mut [f32; 3]) {
    if tree.is_empty() {
        return;
    }
    let mid = tree.len() / 2;
    let (p, i) = tree[mid];
    let d = p.distance_squared(q);
    if i != skip && d < best[2] {
        best[2] = d;
        best.sort_by(f32::total_cmp);
    }
    let gap = q[depth % 3] - p[depth % 3];
    let (near, far) = if gap < 0.0 {
        (&tree[..mid], &tree[mid + 1..])
    } else {
        (&tree[mid + 1..], &tree[..mid])
    };
    kd_nearest(near, depth + 1, q, skip, best);
    // The far side can only hold closer points when the splitting plane is closer.
    if gap * gap < best[2] {
        kd_nearest(far, depth + 1, q, skip, best);
    }
}

/// `n` primitives at random points of the cube of half-side `half` around `centre`, random
/// colors, unless `start` sets them, sized as [`from_points`] sizes them (gsplat's random
/// start).
pub fn in_cube<M: Trainable>(
    n: usize,
    centre: Vec3,
    half: f32,
    start: Start,
    seed: u64,
) -> Vec<M::Params> {
    let mut rng = fastrand::Rng::with_seed(seed);
    let mut unit = || Vec3::new(rng.f32(), rng.f32(), rng.f32());
    let points: Vec<Point> = (0..n)
        .map(|_| Point {
            position: centre + (unit() * 2.0 - 1.0) * half,
            color: unit(),
        })
        .collect();
    from_points::<M>(&points, n, start)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The k-d tree finds the same 3 nearest neighbours as comparing every pair, duplicates
    /// and clusters included.
    #[test]
    fn neighbour_spacing_matches_brute_force() {
        let mut rng = fastrand::Rng::with_seed(5);
        let mut points: Vec<Vec3> = (0..600)
            .map(|k| {
                let cluster = Vec3::splat((k % 3) as f32 * 10.0);
                cluster + Vec3::new(rng.f32(), rng.f32(), rng.f32())
            })
            .collect();
        points.extend_from_within(..20);
        let got = neighbour_spacing(&points, 1.0);
        for (i, p) in points.iter().enumerate() {
            let mut d: Vec<f32> = (0..points.len())
                .filter(|j| *j != i)
                .map(|j| points[j].distance_squared(*p))
                .collect();
            d.sort_by(f32::total_cmp);
            let want = ((d[0] + d[1] + d[2]) / 3.0).max(1e-7).sqrt();
            assert!((got[i] - want).abs() <= 1e-6 * want.max(1.0), "{i}");
        }
        assert_eq!(neighbour_spacing(&[Vec3::ONE], 0.5), vec![0.5]);
        let pair = neighbour_spacing(&[Vec3::ZERO, Vec3::X * 2.0], 0.5);
        assert_eq!(pair, vec![2.0, 2.0]);
    }
}
