//! Lens distortion taken out of a picture as it is read, so a photograph from a camera with
//! distortion (COLMAP's SIMPLE_RADIAL, RADIAL, OPENCV and FULL_OPENCV cameras, nerfstudio's
//! OPENCV) trains as a pinhole view. gsplat undistorts such pictures on load too, with OpenCV,
//! which picks new focal lengths; here the picture's are kept.
//!
//! The view keeps the picture's focal lengths and principal point: its pixels are the
//! picture's pixel grid, cropped to the pixels whose rays the picture saw (the lens puts them
//! between the picture's pixel centres). Each of them is mapped through the lens into the
//! picture and interpolated there bilinearly (`Picture::blend`: colors weighted by coverage,
//! 8-bit pictures kept 8-bit). The crop is found from the camera alone, before any pixel is
//! read.

use super::picture::Picture;
use glam::{DVec2, UVec2, Vec2};
use splat_core::types::Camera;

/// OpenCV's lens model, on points `(x/z, y/z)` of the normalized image plane: a rational
/// radial factor and Brown-Conrady tangential terms. A point `p` at `r² = |p|²` is seen at
/// `p · radial + tangential(p)`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Lens {
    /// The radial factor's numerator `1 + a1 r² + a2 r⁴ + a3 r⁶ + a4 r⁸`: OpenCV's `k1, k2,
    /// k3`, and nerfstudio's `k4` as `a4`.
    pub numerator: [f64; 4],
    /// Its denominator `1 + b1 r² + b2 r⁴ + b3 r⁶`: OpenCV's `k4, k5, k6`.
    pub denominator: [f64; 3],
    /// `p1, p2`: `x` moves by `2 p1 x y + p2 (r² + 2 x²)`, `y` by `p1 (r² + 2 y²) + 2 p2 x y`.
    pub tangential: [f64; 2],
}

impl Lens {
    /// Whether the lens leaves every point where it is.
    pub fn is_identity(&self) -> bool {
        *self == Lens::default()
    }

    /// The radial factor's numerator and denominator at `r2` = r².
    fn radial(&self, r2: f64) -> (f64, f64) {
        // 1 + c1 r² + c2 r⁴ + ..., by Horner.
        let poly = |c: &[f64]| 1.0 + r2 * c.iter().rev().fold(0.0, |sum, k| sum * r2 + k);
        (poly(&self.numerator), poly(&self.denominator))
    }

    /// Where the lens puts the point `p` of the normalized image plane.
    pub fn distort(&self, p: DVec2) -> DVec2 {
        let r2 = p.length_squared();
        let (num, den) = self.radial(r2);
        let [p1, p2] = self.tangential;
        let xy = p.x * p.y;
        p * (num / den)
            + DVec2::new(
                2.0 * p1 * xy + p2 * (r2 + 2.0 * p.x * p.x),
                p1 * (r2 + 2.0 * p.y * p.y) + 2.0 * p2 * xy,
            )
    }

    /// The radius within which the lens's radial map `r -> r · radial(r²)` grows (with a
    /// positive denominator), searched up to `limit` (infinite when it grows that far).
    /// Beyond it the polynomial folds rays back into the picture at places that saw other
    /// rays, so no view pixel lies there.
    fn unfolded_radius(&self, limit: f64) -> f64 {
        const STEPS: u32 = 4096;
        let mut last = 0.0;
        for k in 1..=STEPS {
            let r = limit * f64::from(k) / f64::from(STEPS);
            let (num, den) = self.radial(r * r);
            let seen = r * num / den;
            if den <= 0.0 || seen <= last || !seen.is_finite() {
                return limit * f64::from(k - 1) / f64::from(STEPS);
            }
            last = seen;
        }
        f64::INFINITY
    }
}

/// How a pinhole view is cut from a picture taken through a lens.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Undistortion {
    pub lens: Lens,
    /// The picture's camera as it is sampled (after any downscale): its focal lengths,
    /// principal point and size, and the view's pose.
    pub picture: Camera,
    /// The view's first pixel in the picture's pixel grid.
    pub offset: UVec2,
    /// The view's width and height.
    pub size: UVec2,
    /// Within this radius of the normalized plane the lens does not fold ([`Lens::distort`]).
    unfolded: f64,
}

impl Undistortion {
    /// The pinhole view of the picture that `picture` saw through `lens`: a rectangle of the
    /// picture's pixel grid whose every ray the picture saw. Every side with an unseen pixel
    /// is cropped by a pixel at a time until none has one, then each side grows back while its
    /// next row or column is seen (a side cut for an unseen corner its neighbour also had).
    /// Only the border is checked: a lens that does not fold maps the rectangle's inside
    /// between its border's images (`Undistortion::apply` refuses a pixel that falls
    /// outside). An error when no rectangle is left, as for a principal point far off the
    /// picture.
    pub fn new(picture: Camera, lens: Lens) -> Result<Undistortion, String> {
        let (size, f, c) = (
            picture.size.as_dvec2(),
            picture.focal.as_dvec2(),
            picture.principal.as_dvec2(),
        );
        let corners =
            [DVec2::ZERO, DVec2::X, DVec2::Y, DVec2::ONE].map(|k| ((k * size - c) / f).length());
        let mut cut = Undistortion {
            lens,
            picture,
            offset: UVec2::ZERO,
            size: picture.size.as_uvec2(),
            unfolded: lens.unfolded_radius(corners.into_iter().fold(0.0, f64::max)),
        };
        let full = cut.size;
        // The rectangle [lo, hi), and whether its column x or row y is seen over its extent.
        let (mut lo, mut hi) = (UVec2::ZERO, full);
        let seen = |x: u32, y: u32| cut.source(UVec2::new(x, y)).is_some();
        let column = |x: u32, lo: UVec2, hi: UVec2| (lo.y..hi.y).all(|y| seen(x, y));
        let row = |y: u32, lo: UVec2, hi: UVec2| (lo.x..hi.x).all(|x| seen(x, y));
        loop {
            if !(lo.x < hi.x && lo.y < hi.y) {
                return Err(format!(
                    "finds no rectangle of the {}x{} picture's pixels whose rays it puts inside the picture",
                    full.x, full.y
                ));
            }
            let left = !column(lo.x, lo, hi);
            let right = !column(hi.x - 1, lo, hi);
            let top = !row(lo.y, lo, hi);
            let bottom = !row(hi.y - 1, lo, hi);
            if !(left || right || top || bottom) {
                break;
            }
            lo += UVec2::new(left.into(), top.into());
            hi -= UVec2::new(right.into(), bottom.into());
        }
        loop {
            let before = (lo, hi);
            if lo.x > 0 && column(lo.x - 1, lo, hi) {
                lo.x -= 1;
            }
            if hi.x < full.x && column(hi.x, lo, hi) {
                hi.x += 1;
            }
            if lo.y > 0 && row(lo.y - 1, lo, hi) {
                lo.y -= 1;
            }
            if hi.y < full.y && row(hi.y, lo, hi) {
                hi.y += 1;
            }
            if (lo, hi) == before {
                break;
            }
        }
        cut.offset = lo;
        cut.size = hi - lo;
        Ok(cut)
    }

    /// The view's camera: the picture's, with the principal point moved to the crop.
    pub fn view(&self) -> Camera {
        Camera {
            principal: self.picture.principal - self.offset.as_vec2(),
            size: self.size.as_vec2(),
            ..self.picture
        }
    }

    /// Where the centre of pixel `p` of the picture's grid (undistorted) lies in the picture,
    /// in pixels; `None` when the picture did not see its ray: it falls outside the picture's
    /// pixel centres (where only an edge pixel could be repeated) or where the lens folds.
    fn source(&self, p: UVec2) -> Option<DVec2> {
        let (f, c) = (
            self.picture.focal.as_dvec2(),
            self.picture.principal.as_dvec2(),
        );
        let ray = (p.as_dvec2() + 0.5 - c) / f;
        let at = self.lens.distort(ray) * f + c;
        // Between the picture's pixel centres, so every view pixel is interpolated.
        let inside =
            at.cmpge(DVec2::splat(0.5)).all() && at.cmple(self.picture.size.as_dvec2() - 0.5).all();
        (ray.length() < self.unfolded && inside).then_some(at)
    }

    /// The view's pixels: `picture` (of `self.picture`'s size) sampled through the lens at
    /// each view pixel's source, bilinearly. An error names a view pixel the picture did not
    /// see (from a lens that is not one-to-one over the view: its tangential terms fold it).
    pub(super) fn apply(&self, picture: &Picture) -> Result<Picture, String> {
        let (w, h) = (picture.width, picture.height);
        debug_assert_eq!(Vec2::new(w as f32, h as f32), self.picture.size);
        picture.made((self.size.x, self.size.y), |x, y| {
            let p = self.offset + UVec2::new(x as u32, y as u32);
            let at = self.source(p).ok_or_else(|| {
                format!("maps its pixel ({x}, {y}) outside the picture through its lens")
            })?;
            // Pixel centres at + 0.5. At the last centre the next pixel's weight is 0.
            let t = at - 0.5;
            let (x0, fx) = (t.x.floor(), (t.x - t.x.floor()) as f32);
            let (y0, fy) = (t.y.floor(), (t.y - t.y.floor()) as f32);
            let index = |dx: f64, dy: f64| {
                let sx = (x0 + dx).clamp(0.0, f64::from(w - 1)) as usize;
                let sy = (y0 + dy).clamp(0.0, f64::from(h - 1)) as usize;
                sy * w as usize + sx
            };
            Ok(picture.blend([
                (index(0.0, 0.0), (1.0 - fx) * (1.0 - fy)),
                (index(1.0, 0.0), fx * (1.0 - fy)),
                (index(0.0, 1.0), (1.0 - fx) * fy),
                (index(1.0, 1.0), fx * fy),
            ]))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> Camera {
        Camera {
            focal: Vec2::new(20.0, 21.0),
            principal: Vec2::new(15.5, 11.0),
            size: Vec2::new(32.0, 24.0),
            ..Default::default()
        }
    }

    /// A lens that moves nothing cuts nothing and samples every pixel where it is, bit for bit.
    #[test]
    fn a_lens_without_distortion_gives_the_picture() {
        let cut = Undistortion::new(camera(), Lens::default()).unwrap();
        assert_eq!((cut.offset, cut.size), (UVec2::ZERO, UVec2::new(32, 24)));
        assert_eq!(cut.view(), camera());
        let picture = Picture::from_bytes(
            32,
            24,
            (0..32 * 24 * 4).map(|k| (k * 7 % 256) as u8).collect(),
        );
        assert_eq!(cut.apply(&picture).unwrap(), picture);
    }

    /// `r (1 + k1 r²)` with k1 < 0 grows up to r = 1 / sqrt(-3 k1), then folds back; with
    /// k1 > 0 it never folds.
    #[test]
    fn a_lens_is_used_only_where_it_does_not_fold() {
        let lens = |k1| Lens {
            numerator: [k1, 0.0, 0.0, 0.0],
            ..Lens::default()
        };
        let r = lens(-0.5).unfolded_radius(2.0);
        let want = 1.0 / 1.5f64.sqrt();
        assert!(r <= want && want - r < 2.0 / 4096.0, "{r} vs {want}");
        assert_eq!(lens(0.5).unfolded_radius(2.0), f64::INFINITY);
    }
}
