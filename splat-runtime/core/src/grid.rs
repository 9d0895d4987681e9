//! The tile grid: which tiles a pixel-space box covers, and a tile's bounds.

use crate::types::Tile;
use glam::Vec2;

/// Tiles are squares of `size` pixels; the last row and column may hang over the image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileGrid {
    pub size: u32,
    pub width: u32,
    pub height: u32,
    pub tiles_x: u32,
    pub tiles_y: u32,
}

/// A half-open rectangle of tiles `[x0, x1) x [y0, y1)`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TileRect {
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
}

impl TileRect {
    #[inline]
    pub fn count(&self) -> u32 {
        (self.x1 - self.x0) * (self.y1 - self.y0)
    }
}

impl TileGrid {
    pub fn new(width: u32, height: u32, size: u32) -> Self {
        TileGrid {
            size,
            width,
            height,
            tiles_x: width.div_ceil(size),
            tiles_y: height.div_ceil(size),
        }
    }

    #[inline]
    pub fn tile_count(&self) -> usize {
        (self.tiles_x * self.tiles_y) as usize
    }

    /// The tiles holding a pixel whose centre `(j + 0.5, i + 0.5)` lies in `[min, max]`;
    /// `None` if there is none (off screen, empty or non-finite box).
    #[inline]
    pub fn rect(&self, min: Vec2, max: Vec2) -> Option<TileRect> {
        if !(min.is_finite() && max.is_finite()) {
            return None;
        }
        // First and last pixel column / row whose centre is inside the box.
        let first = (min - 0.5).ceil().max(Vec2::ZERO);
        let last = (max - 0.5)
            .floor()
            .min(Vec2::new(self.width as f32 - 1.0, self.height as f32 - 1.0));
        if first.x > last.x || first.y > last.y {
            return None;
        }
        let s = self.size;
        Some(TileRect {
            x0: first.x as u32 / s,
            y0: first.y as u32 / s,
            x1: last.x as u32 / s + 1,
            y1: last.y as u32 / s + 1,
        })
    }

    /// The bounds of tile `(tx, ty)` as the centres of its first and last pixels inside the
    /// image: exactly the points `evaluate` will be called at.
    #[inline]
    pub fn bounds(&self, tx: u32, ty: u32) -> Tile {
        let (x0, y0) = (tx * self.size, ty * self.size);
        let x1 = (x0 + self.size).min(self.width);
        let y1 = (y0 + self.size).min(self.height);
        Tile {
            min: Vec2::new(x0 as f32 + 0.5, y0 as f32 + 0.5),
            max: Vec2::new(x1 as f32 - 0.5, y1 as f32 - 0.5),
        }
    }

    #[inline]
    pub fn tile_xy(&self, id: u32) -> (u32, u32) {
        (id % self.tiles_x, id / self.tiles_x)
    }
}

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
    #[inline]
    pub fn list(&self, tile: usize) -> &[u32] {
        &self.prims[self.ranges[tile] as usize..self.ranges[tile + 1] as usize]
    }

    #[inline]
    pub fn intersections(&self) -> usize {
        self.prims.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boxes_map_to_the_tiles_of_the_pixels_they_contain() {
        let g = TileGrid::new(40, 20, 16);
        assert_eq!((g.tiles_x, g.tiles_y), (3, 2));
        // Pixel centres 15.5 and 16.5 straddle the boundary between tiles 0 and 1.
        let r = g.rect(Vec2::new(15.2, 0.0), Vec2::new(16.6, 3.0)).unwrap();
        assert_eq!(
            r,
            TileRect {
                x0: 0,
                y0: 0,
                x1: 2,
                y1: 1
            }
        );
        // A box between two pixel centres holds no pixel.
        assert_eq!(g.rect(Vec2::new(3.6, 3.6), Vec2::new(4.4, 4.4)), None);
        // Off screen and non-finite boxes hold none either.
        assert_eq!(g.rect(Vec2::new(-9.0, -9.0), Vec2::new(-1.0, -1.0)), None);
        assert_eq!(g.rect(Vec2::new(f32::NAN, 0.0), Vec2::new(1.0, 1.0)), None);
        // Clipped to the image.
        let r = g
            .rect(Vec2::new(-100.0, -100.0), Vec2::new(1e6, 1e6))
            .unwrap();
        assert_eq!(
            r,
            TileRect {
                x0: 0,
                y0: 0,
                x1: 3,
                y1: 2
            }
        );
        let b = g.bounds(2, 1);
        assert_eq!(
            (b.min, b.max),
            (Vec2::new(32.5, 16.5), Vec2::new(39.5, 19.5))
        );
    }
}
