//! The checks a method author runs on a new primitive, written once over [`SplatMethod`]:
//!
//! - [`reference`](mod@reference): an f64 brute-force renderer built from the method's f64 twins (every
//!   primitive at every pixel, in depth order; no tiles, boxes or culling), and
//!   [`adjoint`]: its analytic backward pass;
//! - [`forward`]: the CPU render against the reference, boxes that hold every pixel a primitive
//!   reaches, a conservative `tile_cull`, the GPU render against the CPU's;
//! - [`gradients`]: the backward pass against finite differences of the reference (on smooth
//!   scenes, away from thresholds), against the reference's analytic adjoint (on realistic
//!   scenes, with thresholds crossed and lists stopped at the T-stop), invalid pairs leaving no
//!   trace, and the GPU backward against the CPU's;
//! - [`extremes`]: renders and gradients finite and correct where training drives parameters
//!   (collapsed and screen-covering scales, zero quaternions, saturated opacities, deep stacks);
//! - [`variants`]: the kernels compiled for one camera model against the generic ones, and a
//!   lower SH degree's instance against the full one.
//!
//! Each check holds every element to one rule ([`bound`]) and panics with a message naming the
//! pixel, primitive or parameter group that is off, so it reads as a test:
//!
//! ```ignore
//! use splat_runtime::checks::{forward, gradients};
//! #[test]
//! fn my_primitive_renders_and_differentiates() {
//!     let (scene, camera) = (my_scene(), my_camera());
//!     forward::forward_matches_reference::<my_method::Method>("mine", &scene, &camera);
//!     let groups = [("mean", 0..3), ("scale", 3..6), ("opacity", 6..7)];
//!     gradients::gradients_match_reference_adjoint::<my_method::Method>(
//!         "mine", &scene, &camera, &groups, &[], gradients::REFERENCE_ADJOINT,
//!     );
//!     forward::gpu_forward_matches_cpu::<my_method::Method>("mine", &scene, &camera);
//! }
//! ```
//!
//! The GPU checks skip (with a line on stderr) where there is no adapter, unless
//! `SPLAT_REQUIRE_GPU=1`.

pub mod adjoint;
pub mod bound;
pub mod extremes;
pub mod fixture;
pub mod forward;
pub mod gradients;
pub mod reference;
pub mod scenes;
pub mod suite;

pub use suite::{check_method, check_method_with};
pub mod variants;

use splat_core::blend::Blend;
use splat_core::flat::Flat;
use splat_core::frame::{FrameGrad, RenderOptions};
use splat_core::method::SplatMethod;
use splat_core::types::Camera;

/// The camera's differentiable fields as ranges of its float slots ([`Camera::float_slots`];
/// the image size, slots 16..18, has no gradient): how the gradient checks group them.
pub const CAMERA_GROUPS: [(&str, std::ops::Range<usize>); 7] = [
    ("rotation", 0..9),
    ("translation", 9..12),
    ("focal", 12..14),
    ("principal", 14..16),
    ("distortion", 18..22),
    ("shutter_turn", 22..25),
    ("shutter_shift", 25..28),
];

/// A value's words as f64.
pub fn words<P: Flat>(p: &P) -> Vec<f64> {
    let mut w = vec![0.0f32; P::LEN];
    p.write_words(&mut w);
    w.into_iter().map(f64::from).collect()
}

/// A camera's float slots as f64 (its model is passed separately, as the integer slot).
pub fn camera_words(c: &Camera) -> Vec<f64> {
    c.float_slots().map(f64::from).to_vec()
}

fn channels<M: SplatMethod>() -> usize {
    <M::Color as Flat>::LEN
}

/// Every output, at `tile_size`.
fn options(tile_size: u32) -> RenderOptions {
    options_with(tile_size, Blend::default())
}

/// Every output, at `tile_size`, with the blend's thresholds `blend`.
fn options_with(tile_size: u32, blend: Blend) -> RenderOptions {
    RenderOptions {
        tile_size,
        alpha: true,
        depth: true,
        blend,
        ..Default::default()
    }
}

/// Random loss weights on color, alpha and depth for a frame of `n` pixels.
fn weights(n: usize, channels: usize) -> [Vec<f64>; 3] {
    let mut rng = fastrand::Rng::with_seed(10);
    let mut random = |k: usize| (0..k).map(|_| rng.f64() * 2.0 - 1.0).collect::<Vec<f64>>();
    [random(n * channels), random(n), random(n)]
}

/// [`weights`] zero off the `clear` pixels (one per pixel).
#[cfg(feature = "gpu")]
fn weights_on(clear: &[bool], channels: usize) -> [Vec<f64>; 3] {
    let mut w = weights(clear.len(), channels);
    for (px, _) in clear.iter().enumerate().filter(|(_, c)| !**c) {
        w[0][px * channels..(px + 1) * channels].fill(0.0);
        w[1][px] = 0.0;
        w[2][px] = 0.0;
    }
    w
}

fn frame_grad(w: &[Vec<f64>; 3]) -> FrameGrad {
    let f32s = |v: &[f64]| v.iter().map(|x| *x as f32).collect::<Vec<f32>>();
    FrameGrad {
        color: f32s(&w[0]),
        alpha: Some(f32s(&w[1])),
        depth: Some(f32s(&w[2])),
    }
}
