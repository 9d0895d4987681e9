//! Where training drives parameters and single renders rarely go: scales collapsed to 1e-8 or
//! grown over the whole screen, quaternions shrunk to zero, opacities saturated (logit ±30),
//! thousands of primitives stacked on one pixel (transmittance underflow). Each case is a base
//! scene with one field of every other primitive rewritten, found by its name in the method's
//! parameters (`log_scale`, `rotation`, `opacity_logit`, as the Gaussian methods name them; a
//! method without the field skips the case). For each case the CPU render matches the f64
//! reference, its gradients are finite and match the reference's analytic adjoint, and the GPU
//! (where there is one) matches the CPU.

use super::bound::Bound;
use super::{adjoint, channels, frame_grad, options, weights, words};
use splat_core::flat::Flat;
use splat_core::method::{SplatMethod, param_group, param_groups};
use splat_core::types::Camera;
use splat_cpu::{backward, render_for_backward};

/// One way training pushes a parameter field to its limit: every word of `field` set to
/// `value`.
pub struct Extreme {
    pub name: &'static str,
    pub field: &'static str,
    pub value: f32,
}

/// The cases [`extremes_stay_finite_and_correct`] runs.
pub const EXTREMES: [Extreme; 5] = [
    Extreme {
        name: "scales collapsed to 1e-8",
        field: "log_scale",
        value: -18.420681, // ln 1e-8
    },
    Extreme {
        name: "scales covering the screen",
        field: "log_scale",
        value: 3.0, // e^3 = 20 scene units, at a few units from the camera
    },
    Extreme {
        name: "quaternions shrunk to zero",
        field: "rotation",
        value: 0.0,
    },
    Extreme {
        name: "opacities saturated (logit 30)",
        field: "opacity_logit",
        value: 30.0,
    },
    Extreme {
        name: "opacities vanishing (logit -30)",
        field: "opacity_logit",
        value: -30.0,
    },
];

/// `params` with `field` set to `value` in every other primitive (the first, third, ...);
/// `None` if `M` has no such field.
pub fn with_field<M: SplatMethod>(
    params: &[M::Params],
    field: &str,
    value: f32,
) -> Option<Vec<M::Params>> {
    let range = param_group::<M>(field)?;
    let mut w = vec![0.0f32; <M::Params as Flat>::LEN];
    let out = params
        .iter()
        .enumerate()
        .map(|(i, p)| {
            if i % 2 == 1 {
                return *p;
            }
            p.write_words(&mut w);
            w[range.clone()].fill(value);
            M::Params::read_words(&w)
        })
        .collect();
    Some(out)
}

/// `count` copies of `p`, each `step` further from the camera than the one before (along the
/// camera's axis, through the method's `mean` field): a stack on the pixels `p` covers, in a
/// definite depth order. `None` if `M` has no `mean` field of three words.
pub fn stacked<M: SplatMethod>(
    p: &M::Params,
    cam: &Camera,
    count: usize,
    step: f32,
) -> Option<Vec<M::Params>> {
    let range = param_group::<M>("mean").filter(|r| r.len() == 3)?;
    // The camera's axis in the world: the third row of the world-to-camera rotation.
    let axis = cam.rotation.row(2);
    let mut w = vec![0.0f32; <M::Params as Flat>::LEN];
    p.write_words(&mut w);
    let mean = glam::Vec3::from_slice(&w[range.clone()]);
    let out = (0..count)
        .map(|k| {
            let m = mean + axis * (step * k as f32);
            w[range.clone()].copy_from_slice(&m.to_array());
            M::Params::read_words(&w)
        })
        .collect();
    Some(out)
}

/// Every case of [`EXTREMES`] that `M` has the field for, applied to `base` (see
/// [`with_field`]), and a stack of `stack` copies of `base[0]` (see [`stacked`]): names and
/// scenes.
pub fn cases<M: SplatMethod>(
    base: &[M::Params],
    cam: &Camera,
    stack: usize,
) -> Vec<(String, Vec<M::Params>)> {
    let mut cases: Vec<(String, Vec<M::Params>)> = EXTREMES
        .iter()
        .filter_map(|e| Some((e.name.to_string(), with_field::<M>(base, e.field, e.value)?)))
        .collect();
    if let Some(s) = stacked::<M>(&base[0], cam, stack, 1e-4) {
        cases.push((format!("{stack} primitives stacked on one pixel"), s));
    }
    cases
}

/// Every one of [`cases`] checked by [`scene_stays_finite_and_correct`] within `bound`; returns
/// the names of the cases run.
pub fn extremes_stay_finite_and_correct<M: SplatMethod>(
    label: &str,
    base: &[M::Params],
    cam: &Camera,
    stack: usize,
    bound: Bound,
) -> Vec<String> {
    let cases = cases::<M>(base, cam, stack);
    for (name, params) in &cases {
        scene_stays_finite_and_correct::<M>(&format!("{label}, {name}"), params, cam, bound);
    }
    cases.into_iter().map(|(name, _)| name).collect()
}

/// The CPU render as the f64 reference's ([`super::forward::forward_matches_reference`]); every
/// gradient of a random loss on color, alpha and depth (the depth where it is clear, see
/// [`super::reference::Reference::depth_clear`]) finite, and each element of each
/// parameter group within `bound` of the reference's analytic adjoint (tiles 8 and 16), so a
/// primitive whose gradients are tiny (nearly transparent, at the back of a deep stack) is
/// held to its own size; on the GPU, the forward as the CPU's
/// ([`super::forward::gpu_forward_matches_cpu`]) and the gradients within the same `bound` of
/// the CPU's ([`super::gradients::gpu_gradients_match_cpu_within`]).
pub fn scene_stays_finite_and_correct<M: SplatMethod>(
    label: &str,
    params: &[M::Params],
    cam: &Camera,
    bound: Bound,
) {
    super::forward::forward_matches_reference::<M>(label, params, cam);
    let n = (cam.size.x * cam.size.y) as usize;
    let mut w = weights(n, channels::<M>());
    super::reference::render::<M>(params, cam).weigh_depth_where_clear(&mut w);
    let reference = adjoint::backward::<M>(params, cam, &w);
    let groups = param_groups::<M>();
    for tile_size in [8, 16] {
        let (_, state) = render_for_backward::<M>(params, cam, &options(tile_size)).unwrap();
        let g = backward::<M>(&state, params, cam, &frame_grad(&w)).unwrap();
        let got: Vec<Vec<f64>> = g.params.iter().map(words).collect();
        for (i, p) in got.iter().enumerate() {
            assert!(
                p.iter().all(|v| v.is_finite()),
                "{label}, tile {tile_size}: primitive {i}'s gradient is not finite: {p:?}"
            );
        }
        let label = format!("{label}, tile {tile_size}");
        let gross = Some(&reference.gross_params[..]);
        super::gradients::groups_match(&label, &got, &reference.params, gross, &groups, bound);
    }
    #[cfg(feature = "gpu")]
    {
        super::forward::gpu_forward_matches_cpu::<M>(label, params, cam);
        super::gradients::gpu_gradients_match_cpu_within::<M>(
            label,
            params,
            cam,
            Default::default(),
            bound,
        );
    }
}
