//! The analytic adjoint of the f64 reference renderer: a brute-force blend (every visible
//! primitive at every pixel, in depth order), reversed with the textbook recurrence over each
//! pixel's stored list of taken entries, and chained through the f64 twins of `evaluate`'s,
//! `pixel_info`'s and `project`'s adjoints. It shares no code with the runtime's backward blend
//! (which carries a prefix instead of storing lists), so it checks that blend on scenes where
//! finite differences cannot: thresholds crossed everywhere, lists that end at the T-stop.
//!
//! An image with thresholds is piecewise smooth, and its gradient is the derivative of the
//! piece the renderer is on. So the discrete choices (the depth order, which pairs are valid,
//! where each pixel stops) are made as the f32 renderer makes them, from the method's own f32
//! `project`, `pixel_info` and `evaluate`; every value and derivative is f64. Decided in f64, a
//! pair whose alpha sits within rounding of 1/255 flips, and the gradients differ by that
//! pair's whole term, which says nothing about the blend.

use super::{camera_words, words};
use glam::Vec2;
use splat_core::blend::T_MIN;
use splat_core::flat::Flat;
use splat_core::frame::FrameGrad;
use splat_core::method::SplatMethod;
use splat_core::types::Camera;

/// Cotangents of a linear loss `<w_color, color> + <w_alpha, alpha> + <w_depth, depth>`.
pub struct ReferenceGrad {
    /// Per primitive, the cotangent of its parameter words.
    pub params: Vec<Vec<f64>>,
    /// The camera's float slots.
    pub camera: Vec<f64>,
    /// Per primitive and word, a bound on the sum of the magnitudes of the terms its gradient
    /// adds up over pixels (each pixel's cotangent of the shade data, in magnitude, through
    /// the magnitude of `project`'s Jacobian): the scale an f32 sum's rounding is relative to,
    /// however much the terms cancel.
    pub gross_params: Vec<Vec<f64>>,
    /// The same for the camera's float slots.
    pub gross_camera: Vec<f64>,
    /// Pairs skipped as invalid on a pixel that took a later entry of its list (the case a
    /// blend must skip without a trace).
    pub skipped_before_a_take: usize,
    /// Pixels whose walk ended at the T-stop.
    pub stopped_pixels: usize,
}

/// One entry a pixel took: which visible primitive, its alpha, color, and T before it.
struct Taken {
    prim: usize,
    alpha: f64,
    color: Vec<f64>,
    t: f64,
    input: Vec<f64>,
}

/// [`backward`] for the loss whose output gradients are `grad` (an output it leaves out
/// weighs zero).
pub fn backward_for<M: SplatMethod>(
    params: &[M::Params],
    cam: &Camera,
    grad: &FrameGrad,
) -> ReferenceGrad {
    let f64s = |v: &[f32]| v.iter().map(|x| f64::from(*x)).collect::<Vec<f64>>();
    let pixels = (cam.size.x * cam.size.y) as usize;
    let or_zero = |g: &Option<Vec<f32>>| g.as_deref().map_or(vec![0.0; pixels], f64s);
    let w = [
        f64s(&grad.color),
        or_zero(&grad.alpha),
        or_zero(&grad.depth),
    ];
    backward::<M>(params, cam, &w)
}

/// The gradient of the loss with weights `w = [color, alpha, depth]` (H x W x channels, H x W,
/// H x W) for the method `M` (its f64 twins) rendering `params` through `cam`.
pub fn backward<M: SplatMethod>(
    params: &[M::Params],
    cam: &Camera,
    w: &[Vec<f64>; 3],
) -> ReferenceGrad {
    let twin = &M::TWIN;
    let camera = &camera_words(cam)[..];
    let (width, height) = (cam.size.x as usize, cam.size.y as usize);
    let ints = [cam.model as u32];
    let shade_at = 5 + <M::Cull as Flat>::LEN;
    // Every primitive visible in f32: its f32 projection, index, project's f64 inputs and
    // outputs.
    let mut prims = vec![];
    for (i, p) in params.iter().enumerate() {
        let projected = M::project(p, cam);
        if !projected.visible {
            continue;
        }
        let input: Vec<f64> = words(p).iter().chain(camera).copied().collect();
        let (f, _) = (twin.project)(&input, &ints);
        prims.push((projected, i, input, f));
    }
    prims.sort_by(|a, b| a.0.depth.total_cmp(&b.0.depth).then(a.1.cmp(&b.1)));
    // Cotangents of project's float outputs per visible primitive.
    let mut d_projected: Vec<Vec<f64>> = prims.iter().map(|p| vec![0.0; p.3.len()]).collect();
    let mut gross_projected = d_projected.clone();
    let mut d_camera = vec![0.0; camera.len()];
    let mut gross_camera = vec![0.0; camera.len()];
    let (mut skipped_before_a_take, mut stopped_pixels) = (0, 0);
    let channels = <M::Color as Flat>::LEN;
    let depth = |k: usize| prims[k].3[0];
    for y in 0..height {
        for x in 0..width {
            let centre = [x as f64 + 0.5, y as f64 + 0.5];
            let pixel_input: Vec<f64> = centre.iter().chain(camera).copied().collect();
            let pixel = match twin.pixel_info {
                Some(info) => info(&pixel_input, &ints).0,
                None => centre.to_vec(),
            };
            let pixel32 = M::pixel_info(Vec2::new(x as f32 + 0.5, y as f32 + 0.5), cam);
            let (mut t, mut t32, mut taken, mut skipped) = (1.0f64, 1.0f32, vec![], 0);
            for (k, (projected, _, _, f)) in prims.iter().enumerate() {
                let c32 = M::evaluate(&pixel32, &projected.shade);
                if !c32.valid {
                    skipped += 1;
                    continue;
                }
                let next32 = t32 * (1.0 - c32.alpha);
                if next32 <= T_MIN {
                    stopped_pixels += 1;
                    break;
                }
                t32 = next32;
                let input: Vec<f64> = pixel.iter().chain(&f[shade_at..]).copied().collect();
                let o = (twin.evaluate)(&input, &[]).0;
                let next = t * (1.0 - o[0]);
                skipped_before_a_take += skipped;
                skipped = 0;
                taken.push(Taken {
                    prim: k,
                    alpha: o[0],
                    color: o[1..].to_vec(),
                    t,
                    input,
                });
                t = next;
            }
            let px = y * width + x;
            // alpha = 1 - T; depth = D / (1 - T) with D = sum of alpha T z.
            let d_color = &w[0][px * channels..(px + 1) * channels];
            let depth_sum: f64 = taken.iter().map(|e| e.alpha * e.t * depth(e.prim)).sum();
            let mut d_alpha_out = w[1][px];
            let mut d_depth_sum = 0.0;
            if t < 1.0 {
                d_depth_sum = w[2][px] / (1.0 - t);
                d_alpha_out -= w[2][px] * depth_sum / ((1.0 - t) * (1.0 - t));
            }
            // Reverse sweep: d_t is the cotangent of the T after the current entry.
            let mut d_t = -d_alpha_out;
            let mut d_pixel = vec![0.0; pixel.len()];
            for e in taken.iter().rev() {
                let z = depth(e.prim);
                let lit: f64 = e.color.iter().zip(d_color).map(|(c, d)| c * d).sum();
                let d_a = e.t * (lit + z * d_depth_sum) - d_t * e.t;
                d_t = d_t * (1.0 - e.alpha) + e.alpha * (lit + z * d_depth_sum);
                let d_out: Vec<f64> = std::iter::once(d_a)
                    .chain(d_color.iter().map(|d| e.alpha * e.t * d))
                    .collect();
                let d_in = (twin.evaluate_adjoint)(&e.input, &[], &d_out);
                let d_proj = &mut d_projected[e.prim];
                d_proj[0] += e.alpha * e.t * d_depth_sum;
                for (acc, v) in d_proj[shade_at..].iter_mut().zip(&d_in[pixel.len()..]) {
                    *acc += v;
                }
                let gross = &mut gross_projected[e.prim];
                gross[0] += (e.alpha * e.t * d_depth_sum).abs();
                for (acc, v) in gross[shade_at..].iter_mut().zip(&d_in[pixel.len()..]) {
                    *acc += v.abs();
                }
                for (acc, v) in d_pixel.iter_mut().zip(&d_in) {
                    *acc += v;
                }
            }
            if let (Some(adjoint), false) = (twin.pixel_info_adjoint, taken.is_empty()) {
                let d_in = adjoint(&pixel_input, &ints, &d_pixel);
                for (acc, v) in d_camera.iter_mut().zip(&d_in[2..]) {
                    *acc += v;
                }
                for (acc, v) in gross_camera.iter_mut().zip(&d_in[2..]) {
                    *acc += v.abs();
                }
            }
        }
    }
    let n = <M::Params as Flat>::LEN;
    let mut out = ReferenceGrad {
        params: vec![vec![0.0; n]; params.len()],
        camera: d_camera,
        gross_params: vec![vec![0.0; n]; params.len()],
        gross_camera,
        skipped_before_a_take,
        stopped_pixels,
    };
    for (((_, i, input, _), d), gross) in prims.iter().zip(&d_projected).zip(&gross_projected) {
        let d_in = (twin.project_adjoint)(input, &ints, d);
        out.params[*i].copy_from_slice(&d_in[..n]);
        for (acc, v) in out.camera.iter_mut().zip(&d_in[n..]) {
            *acc += v;
        }
        // |J^T| g, one column of the Jacobian (a unit cotangent) per output that has terms.
        for (j, g) in gross.iter().enumerate().filter(|(_, g)| **g > 0.0) {
            let mut unit = vec![0.0; gross.len()];
            unit[j] = 1.0;
            let column = (twin.project_adjoint)(input, &ints, &unit);
            for (acc, v) in out.gross_params[*i].iter_mut().zip(&column[..n]) {
                *acc += v.abs() * g;
            }
            for (acc, v) in out.gross_camera.iter_mut().zip(&column[n..]) {
                *acc += v.abs() * g;
            }
        }
    }
    out
}
