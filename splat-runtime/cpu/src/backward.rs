//! The backward blend: walk each pixel's list back to front from the last entry its forward
//! walk took, recovering the transmittance before each entry from the final one (T before =
//! T after / (1 - alpha)) and summing the color behind it as the walk goes, as gsplat does.
//! Walking front to back instead, the color behind an entry is the final color minus a
//! prefix, two near-equal f32 values deep in a list, whose difference loses the gradient of
//! entries behind thousands of others; back to front every quantity keeps its relative
//! precision, so an entry's gradient is as precise as its size. Each
//! step calls `evaluate`'s lane adjoint, which sums the gradient over the group's eight lanes
//! (the reduction inside a group); the sum is added to the worker's own dense per-primitive
//! buffer, so no two threads write the same memory and no atomics are needed. The workers'
//! buffers are summed afterwards.

use crate::ForwardState;
use crate::shade::{counts, group_pixels, misses_group};
use splat_core::flat::Flat;
use splat_core::frame::FrameGrad;
use splat_core::lanes::{F32x8, LANES, M32x8};
use splat_core::method::SplatMethod;
use splat_core::precision::{Precision, Stored};
use splat_core::types::{Camera, ContributionLanes};

/// One worker's gradient sums per primitive: `shade[i * Shade::LEN..]` and `depth[i]`, held
/// at the frame's gradient precision, times `scale` ([`sum_scale`](super::precision::sum_scale)); and the
/// camera's through the pixel data of its pixels (methods with `pixel_info`).
pub struct Accum {
    pub shade: Stored,
    pub depth: Stored,
    pub scale: f32,
    pub camera: Camera,
}

impl Accum {
    pub fn new(primitives: usize, words: usize, precision: Precision, scale: f32) -> Self {
        Accum {
            shade: Stored::zero_sums(precision, primitives * words),
            depth: Stored::zero_sums(precision, primitives),
            scale,
            camera: Camera::ZERO,
        }
    }
}

/// One entry of the back-to-front walk, on the lanes that take it.
struct Entry {
    /// The lanes taking their first entry (their last in the list).
    first: M32x8,
    /// T before the entry.
    t: F32x8,
    /// Its weight, alpha T (zero on lanes that skip it).
    w: F32x8,
    one_minus: F32x8,
    t_final: F32x8,
}

impl Entry {
    /// The derivative by the entry's alpha of a blended channel (a color channel or depth sum)
    /// where the entry's value is `v`, and the entry added to what lies `behind`: with B the
    /// sum behind it, T_k v - B / (1 - alpha). In a stack of similar values the two terms
    /// nearly cancel, so the sum is kept relative to a `reference` value (the lane's last
    /// entry's), B = B' + r (T_k (1 - alpha) - T_final), giving
    /// T_k (v - r) + (r T_final - B') / (1 - alpha), whose terms are each as small as the result
    /// when the values are alike: no precision is lost to cancellation.
    #[inline(always)]
    fn blend(&self, behind: &mut F32x8, reference: &mut F32x8, v: F32x8) -> F32x8 {
        *reference = self.first.select_f32(v, *reference);
        let d = v - *reference;
        let g = self.t * d + (*reference * self.t_final - *behind) / self.one_minus;
        *behind = *behind + self.w * d;
        g
    }
}

fn lanes_of(f: impl Fn(usize) -> f32) -> F32x8 {
    F32x8(std::array::from_fn(f))
}

/// The backward blend of one tile, in code compiled for AVX2 + FMA where the CPU has them.
pub fn backward_tile<M: SplatMethod>(
    state: &ForwardState<M>,
    camera: &Camera,
    grad: &FrameGrad,
    tile: u32,
    acc: &mut Accum,
) {
    splat_core::with_pixel_model!(M, camera.model, MODEL => {
        #[cfg(target_arch = "x86_64")]
        if splat_core::lanes::has_avx2() {
            // SAFETY: the CPU supports the features the function is compiled for.
            return unsafe { backward_tile_avx2::<M, MODEL>(state, camera, grad, tile, acc) };
        }
        backward_tile_body::<M, MODEL>(state, camera, grad, tile, acc)
    })
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn backward_tile_avx2<M: SplatMethod, const MODEL: u32>(
    state: &ForwardState<M>,
    camera: &Camera,
    grad: &FrameGrad,
    tile: u32,
    acc: &mut Accum,
) {
    backward_tile_body::<M, MODEL>(state, camera, grad, tile, acc)
}

#[inline(always)]
fn backward_tile_body<M: SplatMethod, const MODEL: u32>(
    state: &ForwardState<M>,
    camera: &Camera,
    grad: &FrameGrad,
    tile: u32,
    acc: &mut Accum,
) {
    let grid = &state.grid;
    let list = state.visited(tile as usize);
    let (s, channels, words) = (grid.size, M::Color::LEN, M::Shade::LEN);
    let (tx, ty) = grid.tile_xy(tile);
    let want_depth = grad.depth.is_some();
    let shade_groups = state.gradients.shade_groups::<M>();
    let alpha_cotangent = state.gradients.alpha_cotangent::<M>();
    // Per-lane gradient sums for every entry of the tile's list, over all its pixel groups;
    // the lanes are summed once per entry at the end of the tile.
    let mut shade_lanes = vec![M::ShadeLanes::default(); list.len()];
    let mut shades = state.pre.tile_shades(list);
    let mut depth_lanes = vec![F32x8::splat(0.0); if want_depth { list.len() } else { 0 }];
    for row in 0..s {
        for gx in (0..s).step_by(LANES) {
            let (x0, y) = (tx * s + gx, ty * s + row);
            let (pixels, inside) = group_pixels::<M, MODEL>(grid, camera, x0, y);
            // Per-lane image index, clamped for lanes past the edge (they are masked out).
            let px = |l: usize| {
                let x = (x0 + l as u32).min(grid.width - 1);
                (y.min(grid.height - 1) * grid.width + x) as usize
            };
            let t_final = lanes_of(|l| state.transmittance.get(px(l)));
            let ends: [u32; LANES] = std::array::from_fn(|l| match inside.lane(l) {
                true => state.ends[px(l)],
                false => 0,
            });
            let mut d_color = M::ColorLanes::default();
            for ch in 0..channels {
                d_color.as_mut()[ch] = lanes_of(|l| grad.color[px(l) * channels + ch]);
            }
            let mut d_alpha_out = match &grad.alpha {
                Some(a) => lanes_of(|l| a[px(l)]),
                None => F32x8::splat(0.0),
            };
            // depth = D / A with D = sum of w z and A = 1 - T: split its gradient into D and A.
            let mut d_d = F32x8::splat(0.0);
            if let Some(g) = &grad.depth {
                let a = 1.0 - t_final;
                let has = a.gt(F32x8::splat(0.0));
                let a_safe = has.select_f32(a, F32x8::splat(1.0));
                let d_final = lanes_of(|l| state.depth_acc.get(px(l)));
                let gd = lanes_of(|l| g[px(l)]);
                d_d = has.select_f32(gd / a_safe, F32x8::splat(0.0));
                d_alpha_out = d_alpha_out
                    - has.select_f32(gd * d_final / (a_safe * a_safe), F32x8::splat(0.0));
            }
            let mut d_pixel = M::PixelLanes::default();
            // Back to front from each lane's last entry: T before an entry is T after it over
            // 1 - alpha, and what lies behind it is summed as the walk goes.
            let mut t = t_final;
            let mut seen = M32x8::splat(false);
            let (mut behind, mut reference) = (M::ColorLanes::default(), M::ColorLanes::default());
            let (mut depth_behind, mut depth_reference) = (F32x8::splat(0.0), F32x8::splat(0.0));
            let walked = ends.iter().max().copied().unwrap_or(0) as usize;
            for k in (0..walked).rev() {
                let p = &state.pre.projected[list[k] as usize];
                if misses_group(p, x0, y) {
                    continue;
                }
                let shade = shades.get(k);
                let c = M::evaluate_lanes(&pixels, shade);
                let before_end = M32x8::from(std::array::from_fn(|l| (k as u32) < ends[l]));
                let take = before_end & counts(c.alpha, c.valid, state.blend);
                if !take.any() {
                    continue;
                }
                let first = take & !seen;
                seen = seen | take;
                let zero = F32x8::splat(0.0);
                let one_minus = 1.0 - c.alpha;
                t = take.select_f32(t / one_minus, t);
                let w = take.select_f32(c.alpha * t, zero);
                let entry = Entry {
                    first,
                    t,
                    w,
                    one_minus,
                    t_final,
                };
                let mut d_col = M::ColorLanes::default();
                for ch in 0..channels {
                    d_col.as_mut()[ch] = w * d_color.as_ref()[ch];
                }
                if want_depth {
                    depth_lanes[k] = depth_lanes[k] + w * d_d;
                }
                let mut d_alpha = zero;
                if alpha_cotangent {
                    for ch in 0..channels {
                        let (b, r) = (&mut behind.as_mut()[ch], &mut reference.as_mut()[ch]);
                        let v = c.color.as_ref()[ch];
                        d_alpha = d_alpha + entry.blend(b, r, v) * d_color.as_ref()[ch];
                    }
                    if want_depth {
                        let z = F32x8::splat(p.depth);
                        d_alpha =
                            d_alpha + entry.blend(&mut depth_behind, &mut depth_reference, z) * d_d;
                    }
                    d_alpha = d_alpha + d_alpha_out * t_final / one_minus;
                }
                let d_out = ContributionLanes {
                    alpha: take.select_f32(d_alpha, zero),
                    color: d_col,
                    valid: M32x8::splat(true),
                };
                M::evaluate_adjoint_lanes_accumulate(
                    &pixels,
                    shade,
                    &d_out,
                    take,
                    &mut shade_lanes[k],
                    &mut d_pixel,
                    shade_groups,
                );
            }
            if M::HAS_PIXEL_INFO && state.gradients.camera() {
                add_ray_gradient::<M, MODEL>(camera, &d_pixel, inside, x0, y, &mut acc.camera);
            }
        }
    }
    let all = M32x8::splat(true);
    let mut sums = vec![0.0f32; M::ShadeLanes::default().as_ref().len()];
    let mut shade_words = vec![0.0f32; words];
    for (k, &prim) in list.iter().enumerate() {
        for (sum, lanes) in sums.iter_mut().zip(shade_lanes[k].as_ref()) {
            *sum = lanes.masked_sum(all);
        }
        M::shade_from_float_slots(&sums).write_words(&mut shade_words);
        if acc.scale != 1.0 {
            shade_words.iter_mut().for_each(|v| *v *= acc.scale);
        }
        let p = prim as usize;
        acc.shade.add_slice(p * words, &shade_words);
        if want_depth {
            acc.depth.add(p, depth_lanes[k].masked_sum(all) * acc.scale);
        }
    }
}

/// Adds the camera's cotangent through each inside lane's pixel data (`pixel_info`'s adjoint
/// at the pixel centre, given the pixel data's summed cotangent).
fn add_ray_gradient<M: SplatMethod, const MODEL: u32>(
    camera: &Camera,
    d_pixel: &M::PixelLanes,
    inside: M32x8,
    x0: u32,
    y: u32,
    out: &mut Camera,
) {
    let mut words = [0.0f32; 64];
    assert!(
        M::Pixel::LEN <= words.len(),
        "pixel data larger than 64 words"
    );
    for l in 0..LANES {
        if !inside.lane(l) {
            continue;
        }
        for (w, lanes) in words.iter_mut().zip(d_pixel.as_ref()) {
            *w = lanes.0[l];
        }
        // A pixel no primitive took has no ray gradient (and a degenerate ray cannot poison
        // the sum through 0 * NaN).
        if words.iter().all(|w| *w == 0.0) {
            continue;
        }
        let centre = glam::Vec2::new((x0 + l as u32) as f32 + 0.5, y as f32 + 0.5);
        let d = M::pixel_info_adjoint_as::<MODEL>(centre, camera, &M::Pixel::read_words(&words));
        *out = out.add_cotangent(&d);
    }
}
