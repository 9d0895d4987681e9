//! What a method declares to take part in training ([`Trainable`]): how each parameter word is
//! trained ([`Rate`]), how a primitive starts from a point, and its shape as density control
//! sees it ([`Shape`]). The loops, density control and checkpoints all read a method through
//! this, and a method implements it in its own file.

use glam::{Quat, Vec2, Vec3, Vec4};
use splat_core::method::SplatMethod;

/// How one parameter word is trained: its learning rate decays exponentially from `first` to
/// `last` over the run, and it stays fixed (no gradient, no moment) before step `from_step`
/// (3DGS unlocks one SH band every 1,000 steps).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rate {
    pub first: f32,
    pub last: f32,
    pub from_step: usize,
}

impl Rate {
    /// A word that is never trained.
    pub const FROZEN: Rate = Rate {
        first: 0.0,
        last: 0.0,
        from_step: usize::MAX,
    };

    /// A rate that neither decays nor waits.
    pub const fn fixed(lr: f32) -> Rate {
        Rate {
            first: lr,
            last: lr,
            from_step: 0,
        }
    }

    /// The rate at `step` of `steps`.
    pub fn at(&self, step: usize, steps: usize) -> f32 {
        let t = step as f32 / steps.max(1) as f32;
        match (
            step < self.from_step,
            self.first == self.last || self.first == 0.0,
        ) {
            (true, _) => 0.0,
            (false, true) => self.first,
            (false, false) => self.first * (self.last / self.first).powf(t),
        }
    }
}

/// What a method declares to be trained.
pub trait Trainable: SplatMethod {
    /// How each word of `Params` is trained; `extent` is the scene's radius (3DGS scales
    /// position rates by it).
    fn learning_rates(extent: f32) -> Vec<Rate>;

    /// A primitive at `point` with linear RGB `color` and size `scale` (world units).
    fn from_point(point: Vec3, color: Vec3, scale: f32) -> Self::Params;

    /// Where the primitive is, how large, how turned and how opaque (for density control).
    fn shape(p: &Self::Params) -> Shape;

    /// `p` with its shape replaced, everything else (color) kept.
    fn with_shape(p: &Self::Params, shape: &Shape) -> Self::Params;

    /// The gradient of the position, read from a gradient of `Params`.
    fn position_gradient(g: &Self::Params) -> Vec3;

    /// The gradient of where the primitive lands on the image (pixels), read from a gradient
    /// of `Shade`, for a method whose shade data holds that point (3DGS's `center`). Density
    /// control grows from it, as 3DGS does; without it (`None`), from the position gradient
    /// pulled back through the pinhole Jacobian, which also counts what reaches the position
    /// through the footprint's shape and view-dependent color.
    fn screen_gradient(_: &Self::Shade) -> Option<Vec2> {
        None
    }
}

/// A primitive as density control sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shape {
    pub position: Vec3,
    /// Extent along each local axis (a Gaussian's standard deviations), world units.
    pub scale: Vec3,
    pub rotation: Quat,
    /// In [0, 1].
    pub opacity: f32,
}

impl Shape {
    /// The shape of a Gaussian in 3DGS's parameterization: log scales, a (w, x, y, z)
    /// rotation quaternion (normalized here), an opacity logit.
    pub fn from_gaussian(mean: Vec3, log_scale: Vec3, rotation: Vec4, opacity_logit: f32) -> Shape {
        let r = rotation;
        Shape {
            position: mean,
            scale: log_scale.exp(),
            rotation: Quat::from_xyzw(r.y, r.z, r.w, r.x).normalize(),
            opacity: 1.0 / (1.0 + (-opacity_logit).exp()),
        }
    }

    /// Back to that parameterization: (mean, log scales, (w, x, y, z) rotation, opacity
    /// logit), with the opacity kept inside (0, 1) and the scales above zero.
    pub fn to_gaussian(&self) -> (Vec3, Vec3, Vec4, f32) {
        let o = self.opacity.clamp(1e-6, 1.0 - 1e-6);
        let q = self.rotation;
        (
            self.position,
            self.scale.max(Vec3::splat(1e-12)).ln(),
            Vec4::new(q.w, q.x, q.y, q.z),
            (o / (1.0 - o)).ln(),
        )
    }
}
