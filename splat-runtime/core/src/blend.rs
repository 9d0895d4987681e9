//! The blend's thresholds: where a pixel stops and which pairs it skips.

/// Blending stops once transmittance would fall to this value (gsplat's and 3DGS's).
pub const T_MIN: f32 = 1e-4;

/// The blend's two thresholds, shared by the forward pass, the backward pass (which takes
/// the pairs it took) and both backends. Raising either trades accuracy for time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Blend {
    /// A pixel stops before the primitive that would bring its transmittance to this or below.
    pub t_min: f32,
    /// Pairs whose alpha is below this are skipped, on top of the method's own `valid`
    /// (1/255 for the built-in methods): only a value above the method's threshold changes
    /// anything, since a primitive's box only holds the pixels the method keeps.
    pub alpha_min: f32,
}

impl Blend {
    /// The transmittance at or below which a pixel stops: `t_min`, but never below the
    /// smallest normal f32. Under it T has lost its precision (with `t_min` 0 it sticks at the
    /// smallest denormal and the pixel walks every primitive), and the backward pass, which
    /// recovers T by dividing the last one back, overflows to inf and NaN.
    #[inline]
    pub fn stop_at(&self) -> f32 {
        self.t_min.max(f32::MIN_POSITIVE)
    }
}

impl Default for Blend {
    fn default() -> Self {
        Blend {
            t_min: T_MIN,
            alpha_min: 0.0,
        }
    }
}
