//! The photometric loss of 3DGS and gsplat's trainer, with its gradient: `(1 - λ) L1 + λ (1 -
//! SSIM)`, SSIM with an 11 x 11 Gaussian window (σ = 1.5), C1 = 0.01², C2 = 0.03², over the
//! window positions that lie inside the image ("valid" padding, as gsplat's trainer calls
//! `fused_ssim`), averaged over positions and channels. Evaluated in f64 on the CPU; the
//! Gaussian filter is separable, and the gradient runs the transposed filter ("full").
//!
//! Also PSNR and SSIM for evaluation.

use crate::pipeline::Image;
use rayon::prelude::*;

/// Side of the SSIM window.
pub const WINDOW: usize = 11;
const SIGMA: f64 = 1.5;
const C1: f64 = 0.01 * 0.01;
const C2: f64 = 0.03 * 0.03;

/// The value of the loss and its parts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LossValue {
    pub loss: f64,
    pub l1: f64,
    pub ssim: f64,
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum LossError {
    #[error("the render is {got:?} (width, height, channels), the target {want:?}")]
    Shape {
        got: (u32, u32, usize),
        want: (u32, u32, usize),
    },
    #[error("SSIM needs images of at least {WINDOW} x {WINDOW} pixels, not {0} x {1}")]
    TooSmall(u32, u32),
}

/// The normalized Gaussian taps of the SSIM window.
pub(crate) fn window() -> [f64; WINDOW] {
    let g: [f64; WINDOW] = std::array::from_fn(|i| {
        let d = i as f64 - (WINDOW / 2) as f64;
        (-d * d / (2.0 * SIGMA * SIGMA)).exp()
    });
    let sum: f64 = g.iter().sum();
    g.map(|v| v / sum)
}

/// One channel of an image as f64 rows.
struct Plane {
    w: usize,
    h: usize,
    v: Vec<f64>,
}

impl Plane {
    fn of(img: &Image, channel: usize) -> Plane {
        let c = img.channels;
        Plane {
            w: img.width as usize,
            h: img.height as usize,
            v: img
                .data
                .iter()
                .skip(channel)
                .step_by(c)
                .map(|x| *x as f64)
                .collect(),
        }
    }

    fn map2(&self, other: &Plane, f: impl Fn(f64, f64) -> f64) -> Plane {
        Plane {
            w: self.w,
            h: self.h,
            v: self
                .v
                .iter()
                .zip(&other.v)
                .map(|(a, b)| f(*a, *b))
                .collect(),
        }
    }

    /// The Gaussian-weighted mean over every window inside the plane ("valid"): a plane of
    /// (w - 10) x (h - 10).
    fn filter_valid(&self, g: &[f64; WINDOW]) -> Plane {
        let (ow, oh) = (self.w + 1 - WINDOW, self.h + 1 - WINDOW);
        let mut rows = vec![0.0; ow * self.h];
        for y in 0..self.h {
            for x in 0..ow {
                let src = &self.v[y * self.w + x..y * self.w + x + WINDOW];
                rows[y * ow + x] = src.iter().zip(g).map(|(a, b)| a * b).sum();
            }
        }
        let mut out = vec![0.0; ow * oh];
        for y in 0..oh {
            for x in 0..ow {
                out[y * ow + x] = (0..WINDOW).map(|k| rows[(y + k) * ow + x] * g[k]).sum();
            }
        }
        Plane {
            w: ow,
            h: oh,
            v: out,
        }
    }

    /// The transpose of [`Plane::filter_valid`]: spreads each window's value back over its
    /// pixels, giving a (w + 10) x (h + 10) plane.
    fn filter_transposed(&self, g: &[f64; WINDOW]) -> Plane {
        let (ow, oh) = (self.w + WINDOW - 1, self.h + WINDOW - 1);
        let mut cols = vec![0.0; self.w * oh];
        for y in 0..self.h {
            for x in 0..self.w {
                let v = self.v[y * self.w + x];
                for (k, gk) in g.iter().enumerate() {
                    cols[(y + k) * self.w + x] += v * gk;
                }
            }
        }
        let mut out = vec![0.0; ow * oh];
        for y in 0..oh {
            for x in 0..self.w {
                let v = cols[y * self.w + x];
                for (k, gk) in g.iter().enumerate() {
                    out[y * ow + x + k] += v * gk;
                }
            }
        }
        Plane {
            w: ow,
            h: oh,
            v: out,
        }
    }
}

fn check(render: &Image, target: &Image) -> Result<(), LossError> {
    let shape = |i: &Image| (i.width, i.height, i.channels);
    if shape(render) != shape(target) {
        return Err(LossError::Shape {
            got: shape(render),
            want: shape(target),
        });
    }
    if (render.width as usize) < WINDOW || (render.height as usize) < WINDOW {
        return Err(LossError::TooSmall(render.width, render.height));
    }
    Ok(())
}

/// Mean SSIM of one channel, and (when `scale` is given) its gradient with respect to `x`
/// times `scale`, per pixel of the channel.
fn ssim_channel(x: &Plane, y: &Plane, scale: Option<f64>) -> (f64, Option<Vec<f64>>) {
    let g = window();
    let (mx, my) = (x.filter_valid(&g), y.filter_valid(&g));
    let exx = x.map2(x, |a, _| a * a).filter_valid(&g);
    let eyy = y.map2(y, |a, _| a * a).filter_valid(&g);
    let exy = x.map2(y, |a, b| a * b).filter_valid(&g);
    let n = mx.v.len();
    let mut sum = 0.0;
    // Cotangents of the filtered quantities mx, exx, exy, per window position.
    let (mut d_mx, mut d_exx, mut d_exy) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    for i in 0..n {
        let (m1, m2) = (mx.v[i], my.v[i]);
        let (vx, vy, cxy) = (exx.v[i] - m1 * m1, eyy.v[i] - m2 * m2, exy.v[i] - m1 * m2);
        let (a, b) = (2.0 * m1 * m2 + C1, 2.0 * cxy + C2);
        let (c, d) = (m1 * m1 + m2 * m2 + C1, vx + vy + C2);
        let s = a * b / (c * d);
        sum += s;
        // ds/dm1 through A, B (cxy), C and D (vx); ds/dexx through D; ds/dexy through B.
        d_mx[i] = (2.0 * m2 * b - 2.0 * m2 * a) / (c * d) - s * (2.0 * m1 / c - 2.0 * m1 / d);
        d_exx[i] = -s / d;
        d_exy[i] = 2.0 * a / (c * d);
    }
    let grad = scale.map(|scale| {
        let k = scale / n as f64;
        let spread = |v: Vec<f64>| {
            Plane {
                w: mx.w,
                h: mx.h,
                v: v.into_iter().map(|d| d * k).collect(),
            }
            .filter_transposed(&g)
        };
        let (gm, gxx, gxy) = (spread(d_mx), spread(d_exx), spread(d_exy));
        (0..x.v.len())
            .map(|p| gm.v[p] + 2.0 * x.v[p] * gxx.v[p] + y.v[p] * gxy.v[p])
            .collect()
    });
    (sum / n as f64, grad)
}

/// Mean SSIM of `a` against `b` over positions and channels.
pub fn ssim(a: &Image, b: &Image) -> Result<f64, LossError> {
    check(a, b)?;
    let c = a.channels;
    // Channels in parallel, summed in order.
    let total: f64 = (0..c)
        .into_par_iter()
        .map(|ch| ssim_channel(&Plane::of(a, ch), &Plane::of(b, ch), None).0)
        .collect::<Vec<_>>()
        .iter()
        .sum();
    Ok(total / c as f64)
}

/// Peak signal-to-noise ratio of `a` against `b` for values in [0, 1] (`a` clamped, as an
/// image saved to 8 bits would be).
pub fn psnr(a: &Image, b: &Image) -> Result<f64, LossError> {
    check(a, b)?;
    let mse = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (x.clamp(0.0, 1.0) as f64 - *y as f64).powi(2))
        .sum::<f64>()
        / a.data.len() as f64;
    Ok(-10.0 * mse.max(1e-20).log10())
}

/// `(1 - ssim_weight) L1 + ssim_weight (1 - SSIM)` of `render` against `target`, and its
/// gradient with respect to `render` (laid out like `render.data`).
pub fn loss_and_gradient(
    render: &Image,
    target: &Image,
    ssim_weight: f64,
) -> Result<(LossValue, Vec<f32>), LossError> {
    check(render, target)?;
    let n = render.data.len() as f64;
    let mut grad: Vec<f32> = render
        .data
        .iter()
        .zip(&target.data)
        .map(|(x, y)| {
            let s = if x > y {
                1.0
            } else if x < y {
                -1.0
            } else {
                0.0
            };
            ((1.0 - ssim_weight) * s / n) as f32
        })
        .collect();
    let l1 = render
        .data
        .iter()
        .zip(&target.data)
        .map(|(x, y)| (*x as f64 - *y as f64).abs())
        .sum::<f64>()
        / n;
    let c = render.channels;
    // d(1 - mean SSIM) = -d(sum over channels of the channel means) / c.
    let scale = -ssim_weight / c as f64;
    // Channels in parallel; their sums and gradients added in order.
    let channels: Vec<(f64, Option<Vec<f64>>)> = (0..c)
        .into_par_iter()
        .map(|ch| ssim_channel(&Plane::of(render, ch), &Plane::of(target, ch), Some(scale)))
        .collect();
    let mut total = 0.0;
    for (ch, (s, d)) in channels.into_iter().enumerate() {
        total += s;
        for (p, d) in d.into_iter().flatten().enumerate() {
            grad[p * c + ch] += d as f32;
        }
    }
    let ssim = total / c as f64;
    let value = LossValue {
        loss: (1.0 - ssim_weight) * l1 + ssim_weight * (1.0 - ssim),
        l1,
        ssim,
    };
    Ok((value, grad))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(w: u32, h: u32, c: usize, seed: u64) -> Image {
        let mut rng = fastrand::Rng::with_seed(seed);
        Image {
            width: w,
            height: h,
            channels: c,
            data: (0..w as usize * h as usize * c)
                .map(|_| rng.f32())
                .collect(),
        }
    }

    #[test]
    fn ssim_of_an_image_with_itself_is_one_and_psnr_is_high() {
        let a = image(20, 16, 3, 1);
        assert!((ssim(&a, &a).unwrap() - 1.0).abs() < 1e-12);
        assert!(psnr(&a, &a).unwrap() > 150.0);
        let b = image(20, 16, 3, 2);
        let s = ssim(&a, &b).unwrap();
        assert!(s < 0.2, "unrelated noise images: {s}");
    }

    /// The separable filter against a direct evaluation of every window with the 2D weights.
    #[test]
    fn ssim_matches_a_direct_evaluation_of_every_window() {
        let (a, b) = (image(15, 12, 2, 6), image(15, 12, 2, 7));
        let g = window();
        let (w, h) = (15usize, 12usize);
        let mut total = 0.0;
        let mut count = 0;
        for ch in 0..2 {
            let at = |img: &Image, x: usize, y: usize| img.data[(y * w + x) * 2 + ch] as f64;
            for y0 in 0..=h - WINDOW {
                for x0 in 0..=w - WINDOW {
                    let (mut mx, mut my, mut xx, mut yy, mut xy) = (0.0, 0.0, 0.0, 0.0, 0.0);
                    for j in 0..WINDOW {
                        for i in 0..WINDOW {
                            let k = g[i] * g[j];
                            let (p, q) = (at(&a, x0 + i, y0 + j), at(&b, x0 + i, y0 + j));
                            (mx, my) = (mx + k * p, my + k * q);
                            (xx, yy, xy) = (xx + k * p * p, yy + k * q * q, xy + k * p * q);
                        }
                    }
                    let (vx, vy, cxy) = (xx - mx * mx, yy - my * my, xy - mx * my);
                    total += (2.0 * mx * my + C1) * (2.0 * cxy + C2)
                        / ((mx * mx + my * my + C1) * (vx + vy + C2));
                    count += 1;
                }
            }
        }
        let want = total / count as f64;
        let got = ssim(&a, &b).unwrap();
        assert!((got - want).abs() < 1e-12, "{got} vs {want}");
    }

    /// The gradient against central differences of the loss, on random pixels and every
    /// channel (pixels where render and target are equal would sit on L1's kink).
    #[test]
    fn the_gradient_matches_finite_differences() {
        let (render, target) = (image(17, 13, 3, 3), image(17, 13, 3, 4));
        let (_, grad) = loss_and_gradient(&render, &target, 0.2).unwrap();
        let mut rng = fastrand::Rng::with_seed(5);
        let mut worst = 0.0f64;
        let scale = grad.iter().fold(0.0f32, |m, g| m.max(g.abs())) as f64;
        for _ in 0..60 {
            let i = rng.usize(..render.data.len());
            let (x, h) = (render.data[i], 1e-3);
            if (x - target.data[i]).abs() < 2.0 * h {
                continue;
            }
            let at = |v: f32| {
                let mut r = render.clone();
                r.data[i] = v;
                loss_and_gradient(&r, &target, 0.2).unwrap().0.loss
            };
            let (hi, lo) = (x + h, x - h);
            let fd = (at(hi) - at(lo)) / (hi - lo) as f64;
            worst = worst.max((fd - grad[i] as f64).abs() / scale);
        }
        println!("worst gradient error {worst:.2e} of the largest");
        assert!(worst < 1e-5, "{worst}");
    }

    #[test]
    fn mismatched_or_tiny_images_are_refused() {
        let a = image(20, 16, 3, 1);
        assert!(matches!(
            loss_and_gradient(&a, &image(20, 15, 3, 1), 0.2),
            Err(LossError::Shape { .. })
        ));
        assert_eq!(
            ssim(&image(10, 30, 1, 1), &image(10, 30, 1, 2)),
            Err(LossError::TooSmall(10, 30))
        );
    }
}
