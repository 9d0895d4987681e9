//! The f64 brute-force reference renderer: every visible primitive evaluated at every pixel in
//! depth order with the f64 twins of the method's functions; no tiles, no bounding boxes, no
//! tile culling; only the method's own thresholds and the blend's rule ([`Blend`]). It shares
//! no code with the pipeline, so agreeing with it means something.

use super::{camera_words, words};
use splat_core::blend::Blend;
use splat_core::flat::Flat;
use splat_core::method::SplatMethod;
use splat_core::types::{Camera, CameraModel};

/// The alpha threshold every built-in method and example compares with (`alpha >= 1/255`): the
/// decision the clear-pixel rule watches beside the blend's own `alpha_min`.
pub const ALPHA_THRESHOLD: f64 = 1.0 / 255.0;

/// How near an alpha may come to a threshold (relative to the threshold) before its pixel is
/// not clear: an f32 renderer's alpha is off the f64 one by ~1e-6 relative (the exponent's
/// rounding), and two f32 renderers (CPU, GPU) may decide such a pair either way.
pub const ALPHA_MARGIN: f64 = 1e-4;

/// How near T after a pair may come to the T-stop (relative) before its pixel is not clear: T
/// is a product over the pixel's list, so its rounding grows with the list.
pub const T_MARGIN: f64 = 1e-3;

/// How many roundings of its own size a pixel's depth may carry and still be weighed in a
/// gradient check's loss. The renderers output depth D / (1 - T), and the f32 1 - T keeps T's
/// absolute rounding (up to 2^-24 T): T / (1 - T) roundings of its own size, 254 on a pixel of
/// alpha 1/255. The two depth terms of a pair's alpha cotangent (w z / (1 - T) and
/// -w D / (1 - T)^2) are then each ~z / (1 - T) times the loss weight, cancel (exactly, for a
/// pixel of one pair), and leave their rounding behind: measured on one 3DGS Gaussian alone,
/// 8e-5 on a single pixel of alpha 4.6e-3 where the f64 term is 1e-14, 1.5e-3 of the
/// gradient (GPU and CPU alike, with opposite signs). The checks' sum bound allows a term
/// 1e-6 of its size, ~16 roundings.
pub const DEPTH_ROUNDINGS: f64 = 16.0;

/// An f64 render: color (H x W x channels), alpha and depth (H x W), row-major.
pub struct Reference {
    pub width: usize,
    pub height: usize,
    pub color: Vec<f64>,
    pub alpha: Vec<f64>,
    pub depth: Vec<f64>,
    /// Per pixel, whether no decision its walk takes lies within the margins of its threshold
    /// ([`ALPHA_MARGIN`] of [`ALPHA_THRESHOLD`] or of the blend's `alpha_min`, [`T_MARGIN`] of
    /// the T-stop): where f32 renderers must agree with each other and with the reference.
    /// The checks compare images only on clear pixels and weight losses only there.
    pub clear: Vec<bool>,
}

impl Reference {
    /// How many pixels are not clear.
    pub fn unclear(&self) -> usize {
        self.clear.iter().filter(|c| !**c).count()
    }

    /// Per pixel, whether its depth carries at most [`DEPTH_ROUNDINGS`] roundings of its own
    /// size (alpha 1/17 or more), or has no gradient (alpha zero): where a gradient check
    /// weighs the depth.
    pub fn depth_clear(&self) -> Vec<bool> {
        let well_conditioned = |a: f64| a == 0.0 || (1.0 - a) <= DEPTH_ROUNDINGS * a;
        self.alpha.iter().map(|a| well_conditioned(*a)).collect()
    }

    /// `w`, a loss's weights on color, alpha and depth (per pixel), with the
    /// depth's zero where it is not [clear](Self::depth_clear).
    pub fn weigh_depth_where_clear(&self, w: &mut [Vec<f64>; 3]) {
        for (d, clear) in w[2].iter_mut().zip(self.depth_clear()) {
            if !clear {
                *d = 0.0;
            }
        }
    }
}

/// Whether `value` lies within `margin` (relative) of `threshold`.
fn near(value: f64, threshold: f64, margin: f64) -> bool {
    threshold > 0.0 && (value / threshold - 1.0).abs() <= margin
}

/// Renders `params` with method `M` through `camera`, with the default blend.
pub fn render<M: SplatMethod>(params: &[M::Params], camera: &Camera) -> Reference {
    render_with::<M>(params, camera, Blend::default())
}

/// Renders `params` with method `M` through `camera`, with the blend's thresholds `blend`.
pub fn render_with<M: SplatMethod>(
    params: &[M::Params],
    camera: &Camera,
    blend: Blend,
) -> Reference {
    let words: Vec<Vec<f64>> = params.iter().map(words).collect();
    render_words_with::<M>(
        &words,
        &camera_words(camera),
        camera.model,
        blend,
        |_, _| {},
    )
}

/// Renders parameters given as f64 words (`M::Params`' words per primitive) through a camera
/// given as its float slots (`Camera::float_slots`) and its model: the form finite
/// differences perturb.
pub fn render_words<M: SplatMethod>(
    params: &[Vec<f64>],
    camera: &[f64],
    model: CameraModel,
) -> Reference {
    render_words_with::<M>(params, camera, model, Blend::default(), |_, _| {})
}

/// [`render_words`] with `edit(i, shade)` applied to primitive `i`'s shade words after
/// `project`: the form finite differences of the shade data's gradient perturb.
pub fn render_words_edited<M: SplatMethod>(
    params: &[Vec<f64>],
    camera: &[f64],
    model: CameraModel,
    edit: impl Fn(usize, &mut [f64]),
) -> Reference {
    render_words_with::<M>(params, camera, model, Blend::default(), edit)
}

fn render_words_with<M: SplatMethod>(
    params: &[Vec<f64>],
    camera: &[f64],
    model: CameraModel,
    blend: Blend,
    edit: impl Fn(usize, &mut [f64]),
) -> Reference {
    // The thresholds are f32 in the renderer: compare with the same values.
    let (t_min, alpha_min) = (blend.t_min as f64, blend.alpha_min as f64);
    let twin = &M::TWIN;
    let (cull_words, channels) = (<M::Cull as Flat>::LEN, <M::Color as Flat>::LEN);
    let (width, height) = (camera[16] as usize, camera[17] as usize);
    let ints = [model as u32];
    let mut prims: Vec<(f64, usize, Vec<f64>)> = vec![];
    for (i, p) in params.iter().enumerate() {
        let input: Vec<f64> = p.iter().chain(camera).copied().collect();
        let (f, b) = (twin.project)(&input, &ints);
        if b[0] == 0 || !f[0].is_finite() {
            continue;
        }
        let mut shade = f[5 + cull_words..].to_vec();
        edit(i, &mut shade);
        prims.push((f[0], i, shade));
    }
    prims.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let mut out = Reference {
        width,
        height,
        color: vec![],
        alpha: vec![0.0; width * height],
        depth: vec![0.0; width * height],
        clear: vec![true; width * height],
    };
    for y in 0..height {
        for x in 0..width {
            let mut pixel = vec![x as f64 + 0.5, y as f64 + 0.5];
            if let Some(info) = twin.pixel_info {
                pixel.extend(camera);
                pixel = info(&pixel, &ints).0;
            }
            let (mut t, mut c, mut d) = (1.0f64, vec![0.0; channels], 0.0f64);
            let mut clear = true;
            for (depth, _, shade) in &prims {
                let input: Vec<f64> = pixel.iter().chain(shade).copied().collect();
                let (o, valid) = (twin.evaluate)(&input, &[]);
                clear &= !near(o[0], ALPHA_THRESHOLD, ALPHA_MARGIN)
                    && !near(o[0], alpha_min, ALPHA_MARGIN);
                if valid[0] == 0 || o[0] < alpha_min {
                    continue;
                }
                let next = t * (1.0 - o[0]);
                clear &= !near(next, t_min, T_MARGIN);
                if next <= t_min {
                    break;
                }
                for (ch, v) in c.iter_mut().zip(&o[1..]) {
                    *ch += o[0] * t * v;
                }
                d += o[0] * t * depth;
                t = next;
            }
            out.color.extend(&c);
            let px = y * width + x;
            out.clear[px] = clear;
            out.alpha[px] = 1.0 - t;
            out.depth[px] = if t < 1.0 { d / (1.0 - t) } else { 0.0 };
        }
    }
    out
}
