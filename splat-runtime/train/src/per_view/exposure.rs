//! A training view's exposure: a gain per color channel.

use splat_core::frame::Image;

/// A view's exposure and white balance: a gain per color channel on the scene's radiance,
/// held as its logarithm (a word per channel, 0 for none: Adam's steps are relative changes,
/// and a gain stays positive). On a premultiplied render it scales each channel, so the
/// background a transparent view is composited on keeps its color.
///
/// Why gains rather than INRIA's 3x4 affine map (which the issue allowed): a change of
/// exposure time, aperture, ISO or white balance multiplies each channel of linear sensor
/// values; the map's other 9 numbers per picture (channel mixing, offsets) follow no change
/// of exposure, and whatever they absorb the scene gives up, which the held-out views,
/// rendered without a correction, show: on the known scene's gained views the 3x4 map trained
/// the views as well as gains do but lost 5.9 dB on the held-out views
/// (`methods/tests/per_view.rs`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Exposure {
    /// Each channel's log-gain.
    pub log_gain: [f32; 3],
}

impl Exposure {
    pub const WORDS: usize = 3;
    pub const IDENTITY: Exposure = Exposure { log_gain: [0.0; 3] };

    /// The exposure in its 3 words.
    pub fn from_words(words: &[f32]) -> Exposure {
        Exposure {
            log_gain: [words[0], words[1], words[2]],
        }
    }

    /// Each channel's gain.
    pub fn gains(&self) -> [f32; 3] {
        self.log_gain.map(f32::exp)
    }

    /// `color` (premultiplied, on black) scaled.
    pub fn apply(&self, color: &mut Image) {
        let gains = self.gains();
        for px in color.data.chunks_exact_mut(3) {
            for (c, g) in px.iter_mut().zip(gains) {
                *c *= g;
            }
        }
    }

    /// The backward pass: given the render before it (`color`) and the gradient `d_out` by
    /// its output, `d_out` becomes the gradient by `color`, and the gradient by the words is
    /// returned (summed over pixels in f64, in order).
    pub fn backward(&self, color: &Image, d_out: &mut [f32]) -> [f32; 3] {
        let gains = self.gains();
        let mut words = [0.0f64; 3];
        for (d, x) in d_out.chunks_exact_mut(3).zip(color.data.chunks_exact(3)) {
            for c in 0..3 {
                // d out / d log-gain = gain * color.
                words[c] += (d[c] * x[c] * gains[c]) as f64;
                d[c] *= gains[c];
            }
        }
        words.map(|w| w as f32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(data: Vec<f32>) -> Image {
        Image {
            width: (data.len() / 3) as u32,
            height: 1,
            channels: 3,
            data,
        }
    }

    /// The backward pass against f64 finite differences of `sum w * out` by every word and
    /// color.
    #[test]
    fn exposure_gradients_match_finite_differences() {
        let words = vec![0.3f32, -0.2, 0.1];
        let color = image(vec![0.2, 0.5, 0.7, 0.9, 0.1, 0.4]);
        let weights = [0.7f32, -1.1, 0.4, 0.2, 0.9, -0.5];
        let loss = |words: &[f32], color: &Image| -> f64 {
            let mut out = color.clone();
            Exposure::from_words(words).apply(&mut out);
            (out.data.iter().zip(&weights))
                .map(|(o, w)| (o * w) as f64)
                .sum()
        };
        let mut d = weights.to_vec();
        let by_words = Exposure::from_words(&words).backward(&color, &mut d);
        let h = 1e-3;
        let fd = |f: &dyn Fn(f32) -> f64| (f(h) - f(-h)) / (2.0 * h as f64);
        for k in 0..3 {
            let want = fd(&|x| {
                let mut w = words.clone();
                w[k] += x;
                loss(&w, &color)
            });
            assert!((by_words[k] as f64 - want).abs() < 1e-3, "word {k}");
        }
        for (i, got) in d.iter().enumerate() {
            let want = fd(&|x| {
                let mut c = color.clone();
                c.data[i] += x;
                loss(&words, &c)
            });
            assert!((*got as f64 - want).abs() < 1e-3, "color {i}");
        }
    }

    #[test]
    fn the_identity_leaves_colors_and_gradients_as_they_are() {
        let mut color = image(vec![0.2, 0.5, 0.7, 0.9, 0.1, 0.4]);
        let before = color.clone();
        Exposure::IDENTITY.apply(&mut color);
        assert_eq!(color, before);
        let mut d = vec![0.5, -0.25, 1.0, 2.0, -3.0, 0.125];
        let want = d.clone();
        Exposure::IDENTITY.backward(&color, &mut d);
        assert_eq!(d, want);
    }
}
