//! Every check a method should pass, in one call: [`check_method`] on the built-in scenes of
//! Gaussians, [`check_method_with`] on scenes and bounds of the author's choosing.

use super::bound::Bound;
use super::forward::{
    ImageBound, REFERENCE_IMAGE, boxes_hold_every_contributing_pixel,
    forward_matches_reference_within, tile_cull_is_conservative,
};
use super::gradients::{
    FINITE_DIFFERENCES, REFERENCE_ADJOINT, gradients_match_finite_differences,
    gradients_match_reference_adjoint,
};
use super::reference::{ALPHA_THRESHOLD, render as reference_render};
use super::scenes::{self, as_method};
use super::{CAMERA_GROUPS, extremes};
use splat_core::blend::Blend;
use splat_core::method::{SplatMethod, param_groups};
use splat_core::types::Camera;
use splat_io::ply::FromStored;

/// A scene and the camera it is seen through.
#[derive(Clone, Debug)]
pub struct Scene<P> {
    pub camera: Camera,
    pub params: Vec<P>,
}

/// What [`check_method_with`] runs on, and the bounds it holds the method to (the defaults are
/// the ones every built-in method passes; loosen one only saying how much and why).
#[derive(Clone, Debug)]
pub struct Suite<P> {
    /// A few primitives over a 48 x 32 image: the render against the f64 reference, the
    /// boxes, the tile cull, the GPU against the CPU.
    pub spread: Scene<P>,
    /// Primitives dense enough that lists end at the T-stop and pairs fall below the alpha
    /// threshold mid-list (64 x 48): gradients against the reference's adjoint, the GPU's
    /// against the CPU's.
    pub dense: Scene<P>,
    /// Primitives that cover every pixel clear of the thresholds (24 x 16): gradients against
    /// finite differences.
    pub covering: Scene<P>,
    /// Primitives whose opacity is near the alpha threshold (48 x 32): the boxes and the cull,
    /// where they are decided by the threshold alone.
    pub faint: Scene<P>,
    /// A few primitives (24 x 16) for [`extremes`] to push to their limits.
    pub extremes: Scene<P>,
    /// How many copies of `extremes`' first primitive the extremes stack on one pixel: 1,000
    /// (the built-in methods' own tests stack 10,000, which a heavy-tailed falloff cannot
    /// take: its stack ends at the T-stop on a wide ring of pixels where the reference cannot
    /// tell on which side, 15 of 384 for Student's t, past the 2% a check accepts).
    pub stack: usize,
    /// The CPU's render against the f64 reference.
    pub image: ImageBound,
    /// The CPU's gradients against the reference's analytic adjoint.
    pub adjoint: Bound,
    /// The CPU's gradients against finite differences.
    pub finite_differences: Bound,
}

impl<P> Suite<P> {
    /// Every scene with `edit` applied to each primitive: to set parameters a Gaussian does
    /// not have (a shape, a second color).
    pub fn edited(mut self, mut edit: impl FnMut(&mut P)) -> Suite<P> {
        for scene in [
            &mut self.spread,
            &mut self.dense,
            &mut self.covering,
            &mut self.faint,
            &mut self.extremes,
        ] {
            scene.params.iter_mut().for_each(&mut edit);
        }
        self
    }
}

/// The built-in scenes ([`scenes`]) as `M`'s parameters, with the default bounds.
pub fn gaussian_suite<M: SplatMethod>() -> Suite<M::Params>
where
    M::Params: FromStored,
{
    let scene = |camera: Camera, gaussians: Vec<_>| Scene {
        params: as_method::<M>(&gaussians),
        camera,
    };
    let (sparse, dense, small) = (
        scenes::camera(48, 32),
        scenes::camera(64, 48),
        scenes::camera(24, 16),
    );
    Suite {
        spread: scene(sparse, scenes::spread(&sparse, 40, 1)),
        dense: scene(dense, scenes::spread(&dense, 1000, 12)),
        covering: scene(small, scenes::covering(&small)),
        faint: scene(sparse, scenes::faint(&sparse, 40, 2)),
        extremes: scene(small, scenes::spread(&small, 10, 3)),
        stack: 1000,
        image: REFERENCE_IMAGE,
        adjoint: REFERENCE_ADJOINT,
        finite_differences: FINITE_DIFFERENCES,
    }
}

/// The extremes' gradients, CPU against the f64 adjoint and GPU against CPU: [`REFERENCE_ADJOINT`]
/// but for 30x its share of the group's largest, which deep stacks need (their front
/// primitives' opacity gradients are the small difference of thousands of pairs' terms on one
/// pixel; `methods/tests/extremes.rs` has what was measured).
pub const EXTREMES: Bound = Bound::new(1e-4, 3e-4).with_sum(1e-6);

/// [`check_method_with`] on [`gaussian_suite`].
pub fn check_method<M: SplatMethod>(label: &str)
where
    M::Params: FromStored,
{
    check_method_with::<M>(label, &gaussian_suite::<M>());
}

/// Every check a method should pass, each panicking with a message that names the pixel,
/// primitive or parameter group that is off, in the order that names a fault's cause first:
///
/// 1. the CPU render against the f64 reference (`spread`, `dense`);
/// 2. the boxes hold every pixel a primitive reaches, the tile cull drops only what the
///    threshold would (`spread`, `faint`);
/// 3. the gradients against finite differences of the reference (`covering`, every parameter
///    group and the camera's pose and intrinsics), against its analytic adjoint (`dense`);
/// 4. renders and gradients finite and correct where training drives parameters
///    ([`extremes`]: collapsed and screen-covering scales, zero quaternions, saturated
///    opacities, `stack` primitives on one pixel; the cases of the fields the method has;
///    within [`EXTREMES`]);
/// 5. on the GPU (where there is one; `SPLAT_REQUIRE_GPU=1` makes its absence an error), the
///    render and the gradients against the CPU's (`spread`, `dense`).
pub fn check_method_with<M: SplatMethod>(label: &str, suite: &Suite<M::Params>) {
    let blend = Blend::default();
    for (name, s) in [("spread", &suite.spread), ("dense", &suite.dense)] {
        let at = format!("{label}, {name}");
        forward_matches_reference_within::<M>(&at, &s.params, &s.camera, blend, suite.image);
    }
    for (name, s) in [("spread", &suite.spread), ("faint", &suite.faint)] {
        let at = format!("{label}, {name}");
        let outside =
            boxes_hold_every_contributing_pixel::<M>(&at, &s.params, &s.camera, ALPHA_THRESHOLD);
        assert!(
            outside > 0,
            "{at}: no pixel lies outside a box; the check saw nothing"
        );
        if M::HAS_TILE_CULL {
            tile_cull_is_conservative::<M>(&at, &s.params, &s.camera);
        }
    }
    let groups = param_groups::<M>();
    let pose_and_intrinsics = &CAMERA_GROUPS[..4];
    let covering = &suite.covering;
    smooth_scene::<M>(label, covering);
    gradients_match_finite_differences::<M>(
        &format!("{label}, covering"),
        &covering.params,
        &covering.camera,
        &groups,
        pose_and_intrinsics,
        suite.finite_differences,
    );
    let dense = &suite.dense;
    gradients_match_reference_adjoint::<M>(
        &format!("{label}, dense"),
        &dense.params,
        &dense.camera,
        &groups,
        pose_and_intrinsics,
        suite.adjoint,
    );
    let e = &suite.extremes;
    let ran = extremes::extremes_stay_finite_and_correct::<M>(
        label,
        &e.params,
        &e.camera,
        suite.stack,
        EXTREMES,
    );
    println!("{label}: extremes {ran:?}");
    #[cfg(feature = "gpu")]
    for (name, s) in [("spread", &suite.spread), ("dense", &suite.dense)] {
        let at = format!("{label}, {name}");
        super::forward::gpu_forward_matches_cpu::<M>(&at, &s.params, &s.camera);
        super::gradients::gpu_gradients_match_cpu::<M>(&at, &s.params, &s.camera);
    }
}

/// Refuses a `covering` scene on which finite differences would test the thresholds instead
/// of the gradients: every primitive must reach every pixel (alpha above twice the threshold)
/// and the transmittance stay far above the T-stop.
fn smooth_scene<M: SplatMethod>(label: &str, s: &Scene<M::Params>) {
    let image = reference_render::<M>(&s.params, &s.camera);
    let most = image.alpha.iter().fold(0.0f64, |m, a| m.max(*a));
    assert!(
        most < 0.99,
        "{label}: the covering scene reaches alpha {most} (at most 0.99: far from the T-stop)"
    );
    for (i, p) in s.params.iter().enumerate() {
        let solo = reference_render::<M>(std::slice::from_ref(p), &s.camera);
        let least = solo.alpha.iter().fold(1.0f64, |m, a| m.min(*a));
        assert!(
            least > 2.0 * ALPHA_THRESHOLD,
            "{label}: primitive {i} of the covering scene reaches alpha {least} somewhere \
             (each must cover every pixel above 2/255 for finite differences); give the suite \
             a covering scene of this method's own"
        );
    }
}
