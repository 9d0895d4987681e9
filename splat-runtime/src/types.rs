//! The built-in values that cross the boundary between a method's single-element functions and
//! the runtime. The `#[splat_method]` compiler knows these layouts by name (see
//! `splat-compiler/src/types.rs`, `builtin_struct`); the generated code builds and reads them
//! by field name, so a change here that the compiler does not mirror fails to compile.

use crate::lanes::{F32x8, M32x8};
use glam::{Mat3, Vec2, Vec3, Vec4};

/// How a camera maps camera-space directions to pixels (3DGEER, Huang et al. 2025, §3.3).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum CameraModel {
    /// `focal * (x / z, y / z) + principal`.
    #[default]
    Pinhole = 0,
    /// OpenCV fisheye: θ = atan2(√(x² + y²), z), r = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸),
    /// pixel = `focal * r * (x, y) / √(x² + y²) + principal`; valid past 180° field of view.
    KannalaBrandt = 1,
    /// Equiangular (BEAP): `focal * (atan2(x, z), atan2(y, z)) + principal`.
    Equiangular = 2,
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
            CameraModel::Pinhole => "pinhole",
            CameraModel::KannalaBrandt => "kannala_brandt",
            CameraModel::Equiangular => "equiangular",
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

impl std::fmt::Display for CameraModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A camera in the OpenCV convention (x right, y down, z forward).
///
/// A world point `p` maps to camera space as `rotation * p + translation`, and to a pixel by
/// the camera `model` ([`Camera::project_point`]); pixel (col j, row i) is sampled at
/// `(j + 0.5, i + 0.5)`. Methods reach the model through `cam.project_point(p)` and
/// `cam.pixel_ray(pixel)`, which the `#[splat_method]` compiler knows (and differentiates);
/// a method that uses neither is pinhole-only, and the runtime refuses other models for it.
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
    pub model: CameraModel,
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
            model: self.model,
        }
    }

    /// The camera centre in world space, `-rotation^T * translation`.
    pub fn center(&self) -> Vec3 {
        -(self.rotation.transpose() * self.translation)
    }

    /// The pixel of a camera-space point. The `#[splat_method]` compiler's version of this
    /// function (`splat-compiler/src/builtins.rs`) is the one kernels run; tests keep the two equal.
    pub fn project_point(&self, p: Vec3) -> Vec2 {
        let (f, c) = (self.focal, self.principal);
        match self.model {
            CameraModel::Pinhole => f * Vec2::new(p.x, p.y) / p.z + c,
            CameraModel::KannalaBrandt => {
                let rxy = (p.x * p.x + p.y * p.y).sqrt();
                let theta = rxy.atan2(p.z);
                let scale = if rxy > 1e-20 {
                    self.kb_distort(theta) / rxy
                } else {
                    1.0 / p.z
                };
                f * Vec2::new(p.x, p.y) * scale + c
            }
            CameraModel::Equiangular => f * Vec2::new(p.x.atan2(p.z), p.y.atan2(p.z)) + c,
        }
    }

    /// The camera-space unit direction through a pixel position (the inverse of
    /// [`Camera::project_point`]). For Kannala-Brandt, θ is found by Newton's method.
    pub fn pixel_ray(&self, pixel: Vec2) -> Vec3 {
        let m = (pixel - self.principal) / self.focal;
        match self.model {
            CameraModel::Pinhole => m.extend(1.0).normalize(),
            CameraModel::KannalaBrandt => {
                let r = m.length();
                let mut theta = r;
                for _ in 0..KB_NEWTON_STEPS {
                    let k = self.distortion;
                    let t2 = theta * theta;
                    let slope = 1.0
                        + t2 * (3.0 * k.x + t2 * (5.0 * k.y + t2 * (7.0 * k.z + t2 * 9.0 * k.w)));
                    // Past the polynomial's fold the steps would run off: keep a direction.
                    theta = (theta - (self.kb_distort(theta) - r) / slope)
                        .clamp(0.0, std::f32::consts::PI);
                }
                let dir = if r > 1e-20 { m / r } else { Vec2::ZERO };
                (dir * theta.sin()).extend(theta.cos())
            }
            CameraModel::Equiangular => Vec3::new(
                m.x.sin() * m.y.cos(),
                m.x.cos() * m.y.sin(),
                m.x.cos() * m.y.cos(),
            )
            .normalize(),
        }
    }

    /// Whether [`Camera::project_point`] maps the camera-space point `p` to a meaningful pixel:
    /// in front of the image plane (pinhole, equiangular), or up to 3 rad (172°) off axis for
    /// the fisheye, whose polynomial folds back near 180°.
    pub fn can_project(&self, p: Vec3) -> bool {
        match self.model {
            CameraModel::KannalaBrandt => (p.x * p.x + p.y * p.y).sqrt().atan2(p.z) < 3.0,
            _ => p.z > 0.0,
        }
    }

    /// r(θ) = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸).
    fn kb_distort(&self, theta: f32) -> f32 {
        let k = self.distortion;
        let t2 = theta * theta;
        theta * (1.0 + t2 * (k.x + t2 * (k.y + t2 * (k.z + t2 * k.w))))
    }
}

/// Newton steps that invert the Kannala-Brandt distortion in [`Camera::pixel_ray`] (from
/// θ = r; converges to f32 precision in a few steps for the usual coefficients).
pub const KB_NEWTON_STEPS: usize = 8;

/// What `project` returns for one primitive.
///
/// The runtime sorts the visible primitives of each tile by `depth` and blends them front to
/// back: a pixel takes a pair when `evaluate` says it is `valid`, accumulates `alpha * T *
/// color` and `T *= 1 - alpha`, and stops before T would fall to
/// [`T_MIN`](crate::pipeline::shade::T_MIN) (the pair that would cross it is not taken).
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
