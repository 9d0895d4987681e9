//! Morton (Z-order) of positions, as splat-transform orders Gaussians before it writes a
//! compressed PLY or SOG (`docs/formats-spec.md` §2.5): nearby Gaussians end up together, so
//! chunks have small ranges and pictures compress.

use glam::{DVec3, Vec3};

/// Gaussians a compressed PLY chunk holds: a longer run under one code is ordered again.
const RUN: usize = 256;

/// The order splat-transform writes Gaussians in (compressed PLY, SOG): Morton (Z-order) codes of 10 bits an axis
/// over the positions' bounds, sorted stably; a run of more than a chunk sharing one code is
/// ordered again within its own bounds.
pub fn order(means: &[Vec3]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..means.len()).collect();
    sort_morton(means, &mut order);
    order
}

fn sort_morton(means: &[Vec3], indices: &mut [usize]) {
    if indices.is_empty() {
        return;
    }
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for &i in indices.iter() {
        lo = lo.min(means[i].as_dvec3());
        hi = hi.max(means[i].as_dvec3());
    }
    let extent = hi - lo;
    if !extent.is_finite() || extent == DVec3::ZERO {
        return;
    }
    let mul = DVec3::from_array(
        extent
            .to_array()
            .map(|e| if e == 0.0 { 0.0 } else { 1024.0 / e }),
    );
    let code = |i: usize| {
        let cell = ((means[i].as_dvec3() - lo) * mul).min(DVec3::splat(1023.0));
        let [x, y, z] = cell.to_array().map(|c| spread(c as u32));
        (z << 2) + (y << 1) + x
    };
    let mut keyed: Vec<(u32, usize)> = indices.iter().map(|&i| (code(i), i)).collect();
    keyed.sort_by_key(|(c, _)| *c);
    for (slot, (_, i)) in indices.iter_mut().zip(&keyed) {
        *slot = *i;
    }
    let mut start = 0;
    while start < keyed.len() {
        let end = start + keyed[start..].partition_point(|(c, _)| *c == keyed[start].0);
        if end - start > RUN {
            sort_morton(means, &mut indices[start..end]);
        }
        start = end;
    }
}

/// 10 bits spread two apart ("Part1By2").
fn spread(v: u32) -> u32 {
    let mut v = v & 0x3ff;
    v = (v ^ (v << 16)) & 0xff00_00ff;
    v = (v ^ (v << 8)) & 0x0300_f00f;
    v = (v ^ (v << 4)) & 0x030c_30c3;
    (v ^ (v << 2)) & 0x0924_9249
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn morton_order_is_z_order_within_the_bounds() {
        // The corners of a cube: x the fastest axis, then y, then z.
        let corners: Vec<Vec3> = (0..8)
            .rev()
            .map(|k| Vec3::new((k & 1) as f32, (k >> 1 & 1) as f32, (k >> 2) as f32))
            .collect();
        assert_eq!(order(&corners), [7, 6, 5, 4, 3, 2, 1, 0]);
        // Coincident points keep their order; a run of more than a chunk under one code is
        // ordered again within its own bounds.
        let mut points = vec![Vec3::ZERO; 3];
        points.push(Vec3::ONE * 1000.0);
        points.extend((0..300).rev().map(|k| Vec3::splat(k as f32 * 1e-3)));
        let order = order(&points);
        assert_eq!(&order[..3], [0, 1, 2]);
        assert_eq!(order[3], 303, "the smallest of the run of 300 first");
        assert_eq!(order[303], 3);
    }
}
