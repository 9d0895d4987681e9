//! The built-in values that cross the boundary between a method's single-element functions and
//! the runtime. The `#[splat_method]` compiler knows these layouts by name (see
//! `splat-macros/compiler/src/types.rs`, `builtin_struct`); the generated code builds and reads
//! them by field name, so a change here that the compiler does not mirror fails to compile.

use crate::cameras;
use crate::lanes::{F32x8, M32x8};
use glam::{Mat3, Vec2, Vec3, Vec4};

/// How a camera maps camera-space directions to pixels (3DGEER, Huang et al. 2025, §3.3).
/// Each model is defined in [`cameras`] (its code, name and functions); this enum names them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum CameraModel {
    /// [`cameras::pinhole`].
    #[default]
    Pinhole = cameras::pinhole::CODE,
    /// [`cameras::kannala_brandt`]: the OpenCV fisheye.
    KannalaBrandt = cameras::kannala_brandt::CODE,
    /// [`cameras::equiangular`].
    Equiangular = cameras::equiangular::CODE,
}

impl CameraModel {
    pub const ALL: [CameraModel; 3] = [
        CameraModel::Pinhole,
        CameraModel::KannalaBrandt,
        CameraModel::Equiangular,
    ];

    /// The name used in camera files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            CameraModel::Pinhole => cameras::pinhole::NAME,
            CameraModel::KannalaBrandt => cameras::kannala_brandt::NAME,
            CameraModel::Equiangular => cameras::equiangular::NAME,
        }
    }

    /// Whether the model reads the camera's `distortion` coefficients.
    pub fn has_distortion(self) -> bool {
        match self {
            CameraModel::Pinhole => cameras::pinhole::DISTORTION,
            CameraModel::KannalaBrandt => cameras::kannala_brandt::DISTORTION,
            CameraModel::Equiangular => cameras::equiangular::DISTORTION,
        }
    }

    pub fn from_name(name: &str) -> Option<CameraModel> {
        CameraModel::ALL.into_iter().find(|m| m.name() == name)
    }

    /// The model with code `code` (its `u32` word in GPU buffers and generated code).
    pub fn from_code(code: u32) -> Option<CameraModel> {
        CameraModel::ALL.into_iter().find(|m| *m as u32 == code)
    }
}

/// Evaluates `$body` with `$code` a `const u32` equal to the code of `$model` (a
/// [`CameraModel`]), so generic code in it that calls a method's `*_as::<$code>` functions
/// (e.g. [`SplatMethod::project_as`](crate::SplatMethod::project_as)) is compiled once per
/// model, each copy with only its model's code. The model is matched once, outside the loop.
#[macro_export]
macro_rules! with_camera_model {
    ($model:expr, $code:ident => $body:expr) => {
        match $model {
            $crate::CameraModel::Pinhole => {
                const $code: u32 = $crate::CameraModel::Pinhole as u32;
                $body
            }
            $crate::CameraModel::KannalaBrandt => {
                const $code: u32 = $crate::CameraModel::KannalaBrandt as u32;
                $body
            }
            $crate::CameraModel::Equiangular => {
                const $code: u32 = $crate::CameraModel::Equiangular as u32;
                $body
            }
        }
    };
}

/// [`with_camera_model!`] for the blend of `$method`: `$code` is the camera's model where the
/// method's pixel data depends on it ([`SplatMethod::PIXELS_BY_MODEL`](crate::SplatMethod)),
/// otherwise pinhole's for every model (the code is the same; compiling it once per model
/// only costs build time).
#[macro_export]
macro_rules! with_pixel_model {
    ($method:ty, $model:expr, $code:ident => $body:expr) => {
        if <$method as $crate::SplatMethod>::PIXELS_BY_MODEL {
            $crate::with_camera_model!($model, $code => $body)
        } else {
            const $code: u32 = $crate::CameraModel::Pinhole as u32;
            $body
        }
    };
}

impl std::fmt::Display for CameraModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A camera in the OpenCV convention (x right, y down, z forward).
///
/// A world point `p` maps to camera space as `rotation * p + translation`, and to a pixel by
/// the camera `model` ([`Camera::project_point`]); pixel (col j, row i) is sampled at
/// `(j + 0.5, i + 0.5)`. Methods reach the model through `cam.project_point(p)`,
/// `cam.pixel_ray(pixel)` and `cam.is_{model}()`, which the `#[splat_method]` compiler knows
/// (and differentiates) from [`cameras`]; a method that uses none of them is pinhole-only, and
/// the runtime refuses other models for it.
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
    /// Kannala-Brandt coefficients (k1, k2, k3, k4); unused by the other models.
    pub distortion: Vec4,
    /// Rolling shutter: how the camera turns while the sensor reads its rows out, top to
    /// bottom (see [`cameras::rotation_at`]); `rotation` and `translation` are the pose of the
    /// first row. Zero with `shutter_shift`: a global shutter.
    pub shutter_turn: Vec3,
    /// Rolling shutter: how far the camera centre moves (world space) during the readout.
    pub shutter_shift: Vec3,
    pub model: CameraModel,
}

/// What keeps a pose's 3x3 part from being a rotation (scale or shear would distort every
/// render, a mirror flip it).
pub enum NotRotation {
    /// The largest entry of R^T R - I, past 1e-3.
    Off(f32),
    /// A negative determinant.
    Mirror,
}

/// Whether `rotation` is a rotation, within 1e-3 per entry of R^T R - I (what f32 poses
/// written to text keep).
pub fn rotation_defect(rotation: &Mat3) -> Option<NotRotation> {
    let off = (rotation.transpose() * *rotation - Mat3::IDENTITY)
        .to_cols_array()
        .iter()
        .fold(0.0f32, |a, v| a.max(v.abs()));
    if off > 1e-3 {
        Some(NotRotation::Off(off))
    } else if rotation.determinant() < 0.0 {
        Some(NotRotation::Mirror)
    } else {
        None
    }
}

impl Camera {
    /// All fields zero: the zero cotangent of a camera (`default()` has an identity rotation).
    pub const ZERO: Camera = Camera {
        rotation: Mat3::ZERO,
        translation: Vec3::ZERO,
        focal: Vec2::ZERO,
        principal: Vec2::ZERO,
        size: Vec2::ZERO,
        distortion: Vec4::ZERO,
        shutter_turn: Vec3::ZERO,
        shutter_shift: Vec3::ZERO,
        model: CameraModel::Pinhole,
    };

    /// The sum of two camera cotangents (every float field; the model is not a cotangent and
    /// stays `self`'s).
    pub fn add_cotangent(&self, other: &Camera) -> Camera {
        Camera {
            rotation: self.rotation + other.rotation,
            translation: self.translation + other.translation,
            focal: self.focal + other.focal,
            principal: self.principal + other.principal,
            size: self.size + other.size,
            distortion: self.distortion + other.distortion,
            shutter_turn: self.shutter_turn + other.shutter_turn,
            shutter_shift: self.shutter_shift + other.shutter_shift,
            model: self.model,
        }
    }

    /// The camera centre in world space, `-rotation^T * translation` (of the first row).
    pub fn center(&self) -> Vec3 {
        cameras::center(self)
    }

    /// Whether the camera moves during the readout (a rolling shutter).
    pub fn has_rolling_shutter(&self) -> bool {
        self.shutter_turn != Vec3::ZERO || self.shutter_shift != Vec3::ZERO
    }

    /// When the sensor reads the row of `pixel`: 0 the top edge, 1 the bottom.
    pub fn shutter_time(&self, pixel: Vec2) -> f32 {
        cameras::shutter_time(self, pixel)
    }

    /// The world-to-camera rotation at shutter time `t`.
    pub fn rotation_at(&self, t: f32) -> Mat3 {
        cameras::rotation_at(self, t)
    }

    /// The world-to-camera translation at shutter time `t`.
    pub fn translation_at(&self, t: f32) -> Vec3 {
        cameras::translation_at(self, t)
    }

    /// The pixel of a camera-space point under the camera's model.
    pub fn project_point(&self, p: Vec3) -> Vec2 {
        match self.model {
            CameraModel::Pinhole => cameras::pinhole::project_point(self, p),
            CameraModel::KannalaBrandt => cameras::kannala_brandt::project_point(self, p),
            CameraModel::Equiangular => cameras::equiangular::project_point(self, p),
        }
    }

    /// The camera-space unit direction through a pixel position (the inverse of
    /// [`Camera::project_point`]).
    pub fn pixel_ray(&self, pixel: Vec2) -> Vec3 {
        match self.model {
            CameraModel::Pinhole => cameras::pinhole::pixel_ray(self, pixel),
            CameraModel::KannalaBrandt => cameras::kannala_brandt::pixel_ray(self, pixel),
            CameraModel::Equiangular => cameras::equiangular::pixel_ray(self, pixel),
        }
    }

    /// Whether [`Camera::project_point`] maps the camera-space point `p` to a meaningful pixel.
    pub fn can_project(&self, p: Vec3) -> bool {
        match self.model {
            CameraModel::Pinhole => cameras::pinhole::can_project(self, p),
            CameraModel::KannalaBrandt => cameras::kannala_brandt::can_project(self, p),
            CameraModel::Equiangular => cameras::equiangular::can_project(self, p),
        }
    }

    pub fn is_pinhole(&self) -> bool {
        self.model == CameraModel::Pinhole
    }

    pub fn is_kannala_brandt(&self) -> bool {
        self.model == CameraModel::KannalaBrandt
    }

    pub fn is_equiangular(&self) -> bool {
        self.model == CameraModel::Equiangular
    }
}

/// What `project` returns for one primitive.
///
/// The runtime sorts the visible primitives of each tile by `depth` and blends them front to
/// back: a pixel takes a pair when `evaluate` says it is `valid`, accumulates `alpha * T *
/// color` and `T *= 1 - alpha`, and stops before T would fall to
/// [`T_MIN`](crate::blend::T_MIN) (the pair that would cross it is not taken).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Projected<C, S> {
    /// False culls the primitive (behind the camera, degenerate, off screen).
    pub visible: bool,
    /// Sort key for front-to-back blending; also what the depth output averages (weighted by
    /// each pair's alpha * T).
    pub depth: f32,
    /// Pixel-space box (`bbox_min` to `bbox_max`, inclusive) that must hold every pixel centre
    /// where `evaluate` can return a valid pair: the tiles it overlaps are the only ones the
    /// primitive is listed in. Too small cuts the footprint off; too large only costs time.
    /// `checks::forward::boxes_hold_every_contributing_pixel` tests it.
    pub bbox_min: Vec2,
    pub bbox_max: Vec2,
    /// Data for `tile_cull`, which may drop box tiles the footprint does not reach. A method
    /// without `tile_cull` declares any small type and fills it with a placeholder (3DGUT:
    /// `Projected<f32, Shade>` with `cull: 0.0`); every box tile is then kept.
    pub cull: C,
    /// Data for `evaluate` (and, on the GPU, what is stored per primitive for shading).
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
