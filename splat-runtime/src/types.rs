//! The built-in values that cross the boundary between a method's single-element functions and
//! the runtime. The `#[splat_method]` compiler knows these layouts by name (see
//! `splat-compiler/src/types.rs`, `builtin_struct`); the generated code builds and reads them
//! by field name, so a change here that the compiler does not mirror fails to compile.

use crate::lanes::{F32x8, M32x8};
use glam::{Mat3, Vec2, Vec3};

/// A pinhole camera in the OpenCV convention (x right, y down, z forward).
///
/// A world point `p` maps to camera space as `rotation * p + translation`, and to the pixel
/// `focal * (x / z, y / z) + principal`, where pixel (col j, row i) is sampled at
/// `(j + 0.5, i + 0.5)`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Camera {
    /// World-to-camera rotation.
    pub rotation: Mat3,
    /// World-to-camera translation.
    pub translation: Vec3,
    /// Focal lengths (fx, fy) in pixels.
    pub focal: Vec2,
    /// Principal point (cx, cy) in pixels.
    pub principal: Vec2,
    /// Image size (width, height) in pixels.
    pub size: Vec2,
}

impl Camera {
    /// All fields zero: the zero cotangent of a camera (`default()` has an identity rotation).
    pub const ZERO: Camera = Camera {
        rotation: Mat3::ZERO,
        translation: Vec3::ZERO,
        focal: Vec2::ZERO,
        principal: Vec2::ZERO,
        size: Vec2::ZERO,
    };

    /// The camera centre in world space, `-rotation^T * translation`.
    pub fn center(&self) -> Vec3 {
        -(self.rotation.transpose() * self.translation)
    }
}

/// What `project` returns for one primitive.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Projected<C, S> {
    /// False culls the primitive (behind the camera, degenerate, off screen).
    pub visible: bool,
    /// Sort key for front-to-back blending.
    pub depth: f32,
    /// Pixel-space bounding box of the primitive's footprint, inclusive of `bbox_min`.
    pub bbox_min: Vec2,
    pub bbox_max: Vec2,
    /// Data for `tile_cull`.
    pub cull: C,
    /// Data for `evaluate`.
    pub shade: S,
}

/// A tile's pixel-space bounds, as seen by `tile_cull`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Tile {
    pub min: Vec2,
    pub max: Vec2,
}

/// What `evaluate` returns for one (pixel, primitive) pair.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Contribution<F> {
    /// Opacity of this primitive at this pixel, in [0, 1).
    pub alpha: f32,
    /// Color or feature vector.
    pub color: F,
    /// False skips the pair (e.g. alpha below 1/255).
    pub valid: bool,
}

/// Eight [`Contribution`]s, one per lane; `C` is `[F32x8; channels]`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContributionLanes<C> {
    pub alpha: F32x8,
    pub color: C,
    pub valid: M32x8,
}
