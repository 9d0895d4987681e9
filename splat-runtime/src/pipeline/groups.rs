//! Which entries of a tile's list meet each group of eight pixels: the blend then walks only
//! those, instead of testing every entry's box against every group (on a trained 200x200
//! scene that test was a quarter of the backward blend: a scattered read of the primitive's
//! box per group and entry). Built once per tile from the same test,
//! [`misses_group`](super::shade::misses_group), split into its row and column halves.

use crate::lanes::LANES;
use crate::types::Projected;

/// Per group (row-major: `row * groups_per_row + column`), the positions in the tile's list
/// of the entries whose box holds one of the group's pixel centres, ascending.
pub struct GroupEntries {
    starts: Vec<u32>,
    positions: Vec<u32>,
}

impl GroupEntries {
    /// For the tile of side `size` whose first pixel is `(x0, y0)`, from the entries `list`
    /// (indices into `projected`).
    pub fn of<C, S>(
        projected: &[Projected<C, S>],
        list: &[u32],
        x0: u32,
        y0: u32,
        size: u32,
    ) -> Self {
        let per_row = size as usize / LANES;
        let groups = size as usize * per_row;
        // Each entry's rectangle of groups: rows r0..r1, columns c0..c1 (empty when r0 == r1).
        let rects: Vec<[u8; 4]> = list
            .iter()
            .map(|&i| {
                let p = &projected[i as usize];
                let (r0, r1) = span(
                    size as usize,
                    |r| row_below(p, y0 + r as u32),
                    |r| row_above(p, y0 + r as u32),
                );
                let (c0, c1) = span(
                    per_row,
                    |c| columns_left(p, x0 + (c * LANES) as u32),
                    |c| columns_right(p, x0 + (c * LANES) as u32),
                );
                match r0 < r1 && c0 < c1 {
                    true => [r0 as u8, r1 as u8, c0 as u8, c1 as u8],
                    false => [0; 4],
                }
            })
            .collect();
        let mut starts = vec![0u32; groups + 1];
        for &[r0, r1, c0, c1] in &rects {
            for r in r0 as usize..r1 as usize {
                for c in c0 as usize..c1 as usize {
                    starts[r * per_row + c + 1] += 1;
                }
            }
        }
        for g in 0..groups {
            starts[g + 1] += starts[g];
        }
        let mut next = starts.clone();
        let mut positions = vec![0u32; starts[groups] as usize];
        for (k, &[r0, r1, c0, c1]) in rects.iter().enumerate() {
            for r in r0 as usize..r1 as usize {
                for c in c0 as usize..c1 as usize {
                    let at = &mut next[r * per_row + c];
                    positions[*at as usize] = k as u32;
                    *at += 1;
                }
            }
        }
        GroupEntries { starts, positions }
    }

    /// The list positions of the entries that meet group `g`, ascending.
    pub fn group(&self, g: usize) -> &[u32] {
        &self.positions[self.starts[g] as usize..self.starts[g + 1] as usize]
    }
}

/// The run `first..last` of `0..n` between the indices `before` holds for (a prefix) and
/// those `after` holds for (a suffix): the rows or columns a box meets.
fn span(n: usize, before: impl Fn(usize) -> bool, after: impl Fn(usize) -> bool) -> (usize, usize) {
    let first = (0..n).find(|&i| !before(i)).unwrap_or(n);
    let last = (first..n).find(|&i| after(i)).unwrap_or(n);
    (first, last)
}

// The four halves of `misses_group`'s test, each monotone along its axis.

fn row_below<C, S>(p: &Projected<C, S>, y: u32) -> bool {
    (y as f32 + 0.5) < p.bbox_min.y
}

fn row_above<C, S>(p: &Projected<C, S>, y: u32) -> bool {
    (y as f32 + 0.5) > p.bbox_max.y
}

fn columns_left<C, S>(p: &Projected<C, S>, x0: u32) -> bool {
    (x0 as f32 + 0.5) + ((LANES - 1) as f32) < p.bbox_min.x
}

fn columns_right<C, S>(p: &Projected<C, S>, x0: u32) -> bool {
    (x0 as f32 + 0.5) > p.bbox_max.x
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::shade::misses_group;
    use glam::Vec2;

    /// Every group's entries are exactly those `misses_group` keeps, in list order, for boxes
    /// inside, across and around a tile, on and off pixel centres, and NaN boxes.
    #[test]
    fn groups_hold_exactly_the_entries_whose_box_meets_them() {
        let (x0, y0, size) = (32u32, 48u32, 16u32);
        let mut projected = vec![];
        let edges = [
            -5.0,
            31.5,
            32.0,
            32.5,
            39.4,
            39.5,
            40.0,
            47.5,
            48.0,
            48.5,
            55.5,
            63.5,
            64.0,
            70.0,
            f32::NAN,
        ];
        for &a in &edges {
            for &b in &edges {
                projected.push(Projected {
                    visible: true,
                    depth: 1.0,
                    bbox_min: Vec2::new(a, a + 16.0),
                    bbox_max: Vec2::new(b, b + 16.0),
                    cull: (),
                    shade: (),
                });
            }
        }
        let list: Vec<u32> = (0..projected.len() as u32).rev().collect();
        let groups = GroupEntries::of(&projected, &list, x0, y0, size);
        let per_row = size as usize / LANES;
        for row in 0..size as usize {
            for c in 0..per_row {
                let (x, y) = (x0 + (c * LANES) as u32, y0 + row as u32);
                let want: Vec<u32> = (0..list.len() as u32)
                    .filter(|&k| !misses_group(&projected[list[k as usize] as usize], x, y))
                    .collect();
                assert_eq!(
                    groups.group(row * per_row + c),
                    want,
                    "row {row}, column {c}"
                );
            }
        }
    }
}
