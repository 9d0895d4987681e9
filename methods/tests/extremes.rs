//! Numerics under optimization (`checks::extremes`): scales collapsed to 1e-8 and grown over
//! the screen, zero quaternions, opacity logits of ±30 and 10 000 Gaussians stacked on one
//! pixel, each against the f64 reference and its adjoint, on the CPU and the GPU; for 3DGS and
//! LinPrim on a pinhole camera, for 3DGUT and 3DGEER also on a fisheye seeing past 90 degrees
//! off axis (Gaussians straddling the image plane's sides), with a Gaussian on the near plane.

use crate::common::{as_method, gaussian_toward, spread_gaussians, wide_camera};
use splat_methods::gs3d::Params;
use splat_methods::{FromStored, geer, gs3d, gut, linprim};
use splat_runtime::checks::bound::Bound;
use splat_runtime::checks::extremes::{EXTREMES, extremes_stay_finite_and_correct};
use splat_runtime::glam::{Vec2, Vec3};
use splat_runtime::{Camera, CameraModel, SplatMethod};

/// Gaussians over a 24 x 16 image, one on the near plane and, on the wide cameras, two at 90
/// degrees off axis, half in front of the camera's plane and half behind it.
fn scene(cam: &Camera) -> Vec<Params> {
    let mut ps = spread_gaussians(cam, 10, 3);
    let mut rng = fastrand::Rng::with_seed(4);
    let mut near = gaussian_toward(&mut rng, cam, Vec2::new(6.0, 5.0), 1.0, -3.0);
    near.mean.z = 0.0100001;
    ps.push(near);
    if cam.model != CameraModel::Pinhole {
        for side in [-1.0, 1.0] {
            let mut g = gaussian_toward(&mut rng, cam, Vec2::new(12.0, 8.0), 2.0, -0.5);
            g.mean = Vec3::new(2.0 * side, 0.0, 0.0);
            ps.push(g);
        }
    }
    ps
}

/// Gradients within 1e-4 of each element plus 1e-3 of its group's largest, on the CPU against
/// the f64 adjoint and on the GPU against the CPU: 100x the other checks' share of the group's
/// largest. What needs it is the GPU against the CPU on Gaussians the cases leave alone: in
/// every case that takes their neighbours out (collapsed, screen-sized, transparent), 3DGUT's
/// primitive 3 has a rotation gradient 1.9e-3 of itself off the CPU's (0.51 of this bound, the
/// worst; 5e-4 of its group's largest) and 3DGS's primitive 5 a log-scale gradient 1.5e-3 off
/// (0.33). Not the Gaussian on the near plane: without it the same elements are the worst. Why
/// the GPU differs there is not yet known; on the CPU, against the f64 adjoint, the worst is
/// 3DGUT's opacity gradient at the back of the 10,000-deep stack (1.8e-3 off a value of 1e-6).
const BOUND: Bound = Bound::new(1e-4, 1e-3);

/// The base scene for `model`, as `M`'s parameters, and its camera.
fn base<M: SplatMethod>(model: CameraModel) -> (Vec<M::Params>, Camera)
where
    M::Params: FromStored,
{
    let cam = wide_camera(24, 16, model);
    (as_method(scene(&cam)), cam)
}

/// Every case, on the CPU and the GPU.
fn check<M: SplatMethod>(label: &str, model: CameraModel)
where
    M::Params: FromStored,
{
    let (base, cam) = base::<M>(model);
    let ran = extremes_stay_finite_and_correct::<M>(label, &base, &cam, 10_000, BOUND);
    assert_eq!(ran.len(), EXTREMES.len() + 1, "{label}: {ran:?}");
}

#[test]
fn gaussians_at_their_limits_stay_finite_and_correct() {
    check::<gs3d::Method>("3dgs, pinhole", CameraModel::Pinhole);
}

#[test]
fn octahedra_at_their_limits_stay_finite_and_correct() {
    check::<linprim::Method>("linprim, pinhole", CameraModel::Pinhole);
}

#[test]
fn unscented_gaussians_at_their_limits_stay_finite_and_correct() {
    check::<gut::Method>("3dgut, pinhole", CameraModel::Pinhole);
    check::<gut::Method>("3dgut, fisheye", CameraModel::KannalaBrandt);
}

#[test]
fn exact_gaussians_at_their_limits_stay_finite_and_correct() {
    check::<geer::Method>("3dgeer, pinhole", CameraModel::Pinhole);
    check::<geer::Method>("3dgeer, fisheye", CameraModel::KannalaBrandt);
}
