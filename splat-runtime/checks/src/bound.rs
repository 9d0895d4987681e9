//! The one rule every check holds a computed value to: each element within `rel` of its own
//! reference value, plus `abs` of the largest reference value in its group, plus `sum` of the
//! magnitude of the terms it was summed from (where the check knows them):
//!
//! ```text
//! |got - want| <= rel |want| + abs max_group |want| + sum gross
//! ```
//!
//! So a small element is held near its own size (an error of 1e-3 of the largest gradient no
//! longer hides a wrong SH coefficient beside a large mean gradient), an element that is zero
//! is held to its group's scale, and a gradient summed over many pixels whose terms cancel is
//! held to the rounding of its terms (`gross`, see
//! [`ReferenceGrad::gross_params`](super::adjoint::ReferenceGrad)), the only scale an f32 sum
//! can be held to. A group is what shares a unit and a scale: one parameter field over every
//! primitive, one camera field, one output.

/// How far a value may be from its reference (see the module).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bound {
    pub rel: f64,
    pub abs: f64,
    pub sum: f64,
}

/// How a group's worst element compares with its [`Bound`].
#[derive(Clone, Copy, Debug)]
pub struct Fit {
    /// The largest |got - want| / allowed over the group: the group passes at 1 or below
    /// (infinite where a value is not finite).
    pub of_bound: f64,
    /// The index of that element, and its values.
    pub at: usize,
    pub got: f64,
    pub want: f64,
    /// The group's largest |want|.
    pub scale: f64,
}

impl Fit {
    pub fn passes(&self) -> bool {
        self.of_bound <= 1.0
    }
}

impl Bound {
    /// `rel` of each element plus `abs` of its group's largest.
    pub const fn new(rel: f64, abs: f64) -> Self {
        Bound { rel, abs, sum: 0.0 }
    }

    /// This bound plus `sum` of the magnitude of each element's terms.
    pub const fn with_sum(self, sum: f64) -> Self {
        Bound { sum, ..self }
    }

    /// The group `got` against its reference `want` (of the same length), with the magnitude
    /// of each element's terms where known (`gross`, of the same length).
    pub fn fit(&self, got: &[f64], want: &[f64], gross: Option<&[f64]>) -> Fit {
        assert_eq!(
            got.len(),
            want.len(),
            "a group and its reference differ in length"
        );
        let scale = want.iter().fold(0.0f64, |m, w| m.max(w.abs()));
        // An all-zero reference still allows f64 noise, not f32 noise.
        let floor = (self.abs * scale).max(f64::MIN_POSITIVE);
        let mut fit = Fit {
            of_bound: 0.0,
            at: 0,
            got: got.first().copied().unwrap_or(0.0),
            want: want.first().copied().unwrap_or(0.0),
            scale,
        };
        for (i, (&g, &w)) in got.iter().zip(want).enumerate() {
            let terms = gross.map_or(0.0, |t| self.sum * t[i]);
            let ratio = match g.is_finite() && w.is_finite() {
                true => (g - w).abs() / (self.rel * w.abs() + floor + terms),
                false => f64::INFINITY,
            };
            if ratio > fit.of_bound || i == 0 {
                fit = Fit {
                    of_bound: ratio,
                    at: i,
                    got: g,
                    want: w,
                    scale,
                };
            }
        }
        fit
    }

    /// [`Self::fit`], printed as `what: ...` and panicking past the bound, naming the worst
    /// element through `name(index)`.
    pub fn check(
        &self,
        what: &str,
        got: &[f64],
        want: &[f64],
        gross: Option<&[f64]>,
        name: impl Fn(usize) -> String,
    ) -> Fit {
        let fit = self.fit(got, want, gross);
        let worst = format!(
            "worst {:.3} of the bound at {}: {:e} vs reference {:e}, group's largest {:e}",
            fit.of_bound,
            name(fit.at),
            fit.got,
            fit.want,
            fit.scale
        );
        println!("{what}: {worst}");
        assert!(
            fit.passes(),
            "{what}: past |got - want| <= {:e} |want| + {:e} max|want| + {:e} gross: {worst}",
            self.rel,
            self.abs,
            self.sum
        );
        fit
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_small_element_is_held_to_its_own_size() {
        let bound = Bound::new(1e-3, 1e-6);
        let want = [100.0, 1e-2];
        // 1e-3 of the largest would allow 0.1 on the small one; its own size allows 1e-5.
        assert!(bound.fit(&[100.0, 1e-2 + 5e-6], &want, None).passes());
        let fit = bound.fit(&[100.0, 1e-2 + 2e-4], &want, None);
        assert!(!fit.passes());
        assert_eq!(fit.at, 1);
    }

    #[test]
    fn zero_elements_are_held_to_the_groups_scale_and_nan_fails() {
        let bound = Bound::new(1e-3, 1e-6);
        assert!(bound.fit(&[1.0, 5e-7], &[1.0, 0.0], None).passes());
        assert!(!bound.fit(&[1.0, 5e-6], &[1.0, 0.0], None).passes());
        assert!(!bound.fit(&[f64::NAN, 0.0], &[1.0, 0.0], None).passes());
        assert!(bound.fit(&[0.0, 0.0], &[0.0, 0.0], None).passes());
        assert!(!bound.fit(&[1e-9], &[0.0], None).passes());
    }

    #[test]
    fn a_cancelled_sum_is_held_to_its_terms() {
        // 1 = 1e4 - (1e4 - 1): rounding of 1e-3 is 1e-7 of the terms.
        let bound = Bound::new(1e-6, 1e-6).with_sum(1e-6);
        assert!(!bound.fit(&[1.001], &[1.0], None).passes());
        assert!(bound.fit(&[1.001], &[1.0], Some(&[2e4])).passes());
        assert!(!bound.fit(&[1.1], &[1.0], Some(&[2e4])).passes());
    }
}
