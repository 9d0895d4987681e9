//! Storage formats for what a frame keeps between its stages: the per-pixel values the forward
//! pass writes (its render targets, in the sense of Yuan and He's mixed-precision rendering:
//! the color, which the image is read from, and the final transmittance and depth sums, which
//! the outputs are read from and the backward pass walks back from), the shade data `project`
//! hands the blend ([`PackedShade`]), and the backward pass's per-primitive gradient sums.
//! Arithmetic stays f32; only what is stored is rounded, and it really is stored in the
//! format (2 or 1 bytes per value).

use crate::flat::Flat;
use crate::grid::TileRect;
use crate::method::SplatMethod;
use crate::types::Projected;
use half::f16;
use half::slice::{HalfBitsSliceExt, HalfFloatSliceExt};
use rayon::prelude::*;

/// A storage format: for the per-pixel state, the shade data between the stages
/// ([`PackedShade`]) and the gradient sums ([`sum_format`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Precision {
    #[default]
    F32,
    /// IEEE half: 11 significant bits (relative error at most 2^-11), range to 65504.
    F16,
    /// Colors in [0, 1] in steps of 1/65535 (values outside saturate); transmittance and depth
    /// sums as f16 ([`Range::Relative`]); shade data in 65535 steps of each word's range.
    Unorm16,
    /// Colors in [0, 1] in steps of 1/255; transmittance and depth sums as f16; shade data in
    /// 255 steps of each word's range.
    Unorm8,
}

impl Precision {
    pub const ALL: [Precision; 4] = [
        Precision::F32,
        Precision::F16,
        Precision::Unorm16,
        Precision::Unorm8,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::F16 => "f16",
            Precision::Unorm16 => "unorm16",
            Precision::Unorm8 => "unorm8",
        }
    }

    /// The largest difference between a value in [0, 1] and what is stored for it.
    pub fn unit_error(self) -> f32 {
        match self {
            Precision::F32 => 0.0,
            Precision::F16 => 2f32.powi(-12),
            Precision::Unorm16 => 0.5 / 65535.0,
            Precision::Unorm8 => 0.5 / 255.0,
        }
    }
}

/// What a value means, which decides how a unorm format holds it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Range {
    /// Colors in [0, 1] (they may exceed 1, and saturate in unorm), and shade data mapped to
    /// [0, 1] by its range.
    Unit,
    /// Values whose relative precision matters, stored as f16 where the format is unorm: the
    /// final transmittance (the backward pass recovers every entry's T by dividing it back up,
    /// so all of a pixel's gradients scale with it, and a unorm step near 0 would lose them)
    /// and sums of weight x depth (of any size).
    Relative,
}

/// Values stored in one format.
#[derive(Clone, Debug, PartialEq)]
pub enum Stored {
    F32(Vec<f32>),
    F16(Vec<u16>),
    Unorm16(Vec<u16>),
    Unorm8(Vec<u8>),
}

impl Stored {
    /// `values` stored as `precision` says for values of `range`.
    pub fn new(precision: Precision, range: Range, values: Vec<f32>) -> Stored {
        let half =
            |v: Vec<f32>| Stored::F16(v.iter().map(|x| f16::from_f32(*x).to_bits()).collect());
        let unit = |x: f32, steps: f32| (x.clamp(0.0, 1.0) * steps).round();
        match (precision, range) {
            (Precision::F32, _) => Stored::F32(values),
            (Precision::F16, _) | (_, Range::Relative) => half(values),
            (Precision::Unorm16, Range::Unit) => {
                Stored::Unorm16(values.iter().map(|x| unit(*x, 65535.0) as u16).collect())
            }
            (Precision::Unorm8, Range::Unit) => {
                Stored::Unorm8(values.iter().map(|x| unit(*x, 255.0) as u8).collect())
            }
        }
    }

    /// Value `i`, as f32.
    #[inline(always)]
    pub fn get(&self, i: usize) -> f32 {
        match self {
            Stored::F32(v) => v[i],
            Stored::F16(v) => f16::from_bits(v[i]).to_f32(),
            Stored::Unorm16(v) => v[i] as f32 / 65535.0,
            Stored::Unorm8(v) => v[i] as f32 / 255.0,
        }
    }

    pub fn len(&self) -> usize {
        match self {
            Stored::F32(v) => v.len(),
            Stored::F16(v) | Stored::Unorm16(v) => v.len(),
            Stored::Unorm8(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Every value, as f32.
    pub fn to_f32(&self) -> Vec<f32> {
        self.as_f32().into_owned()
    }

    /// Every value, as f32 (borrowed where they are stored so).
    pub fn as_f32(&self) -> std::borrow::Cow<'_, [f32]> {
        match self {
            Stored::F32(v) => std::borrow::Cow::Borrowed(v),
            _ => (0..self.len()).map(|i| self.get(i)).collect(),
        }
    }

    /// Every value, as f32 (moved where they are stored so).
    pub fn into_f32(self) -> Vec<f32> {
        match self {
            Stored::F32(v) => v,
            other => other.to_f32(),
        }
    }

    /// `n` sums of zero, held as `precision` holds sums ([`sum_format`]).
    pub fn zero_sums(precision: Precision, n: usize) -> Stored {
        // Zeros written now, not pages the kernel maps and zeroes at their first write: the
        // backward blend's first writes land in random order, and with its workers faulting
        // pages in together the 2-thread blend took 15% longer at 1M Gaussians.
        fn written<T: Copy>(zero: T, n: usize) -> Vec<T> {
            let mut v = Vec::with_capacity(n);
            v.resize(n, zero);
            v
        }
        match sum_format(precision) {
            Precision::F32 => Stored::F32(written(0.0, n)),
            _ => Stored::F16(written(0, n)),
        }
    }

    /// Adds `v` to value `i`, the sum rounded to the format (f32 or f16: sums of any size are
    /// [`Range::Relative`]); a finite f16 sum saturates at +-65504 rather than becoming
    /// infinite (an infinite or NaN one stays so).
    #[inline(always)]
    pub fn add(&mut self, i: usize, v: f32) {
        match self {
            Stored::F32(s) => s[i] += v,
            Stored::F16(s) => {
                let sum = f16::from_bits(s[i]).to_f32() + v;
                s[i] = f16::from_f32(saturate(sum)).to_bits();
            }
            Stored::Unorm16(_) | Stored::Unorm8(_) => unreachable!("sums are stored as f32 or f16"),
        }
    }

    /// Adds `values` to the values from `at` on, as [`Stored::add`] does one by one (f16:
    /// converted a slice at a time, with the CPU's conversion instructions where it has them).
    #[inline]
    pub fn add_slice(&mut self, at: usize, values: &[f32]) {
        let n = values.len();
        match self {
            Stored::F32(s) => {
                for (sum, v) in s[at..at + n].iter_mut().zip(values) {
                    *sum += v;
                }
            }
            Stored::F16(s) => {
                let held = s[at..at + n].reinterpret_cast_mut::<f16>();
                let mut sums = [0.0f32; MAX_SHADE_WORDS];
                for chunk in (0..n).step_by(MAX_SHADE_WORDS) {
                    let m = (n - chunk).min(MAX_SHADE_WORDS);
                    let held = &mut held[chunk..chunk + m];
                    held.convert_to_f32_slice(&mut sums[..m]);
                    for (sum, v) in sums.iter_mut().zip(&values[chunk..chunk + m]) {
                        *sum = saturate(*sum + v);
                    }
                    held.convert_from_f32_slice(&sums[..m]);
                }
            }
            Stored::Unorm16(_) | Stored::Unorm8(_) => unreachable!("sums are stored as f32 or f16"),
        }
    }

    /// Adds the values from `from` on to `out`, one per element (f16: converted a slice at a
    /// time).
    pub fn add_to(&self, from: usize, out: &mut [f32]) {
        match self {
            Stored::F32(s) => {
                for (o, v) in out.iter_mut().zip(&s[from..]) {
                    *o += v;
                }
            }
            Stored::F16(s) => {
                let held = s[from..from + out.len()].reinterpret_cast::<f16>();
                let mut values = [0.0f32; MAX_SHADE_WORDS];
                for (out, held) in out
                    .chunks_mut(MAX_SHADE_WORDS)
                    .zip(held.chunks(MAX_SHADE_WORDS))
                {
                    held.convert_to_f32_slice(&mut values[..out.len()]);
                    for (o, v) in out.iter_mut().zip(&values) {
                        *o += v;
                    }
                }
            }
            Stored::Unorm16(_) | Stored::Unorm8(_) => unreachable!("sums are stored as f32 or f16"),
        }
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        match self {
            Stored::F32(v) => v.capacity() * 4,
            Stored::F16(v) | Stored::Unorm16(v) => v.capacity() * 2,
            Stored::Unorm8(v) => v.capacity(),
        }
    }
}

/// The largest finite f16.
const F16_MAX: f32 = 65504.0;

/// `x` clamped to f16's finite range if finite (an infinity or NaN is a fault to pass on).
#[inline(always)]
fn saturate(x: f32) -> f32 {
    match x.is_finite() {
        true => x.clamp(-F16_MAX, F16_MAX),
        false => x,
    }
}

/// The format sums are held in at `precision` (they have no fixed range: f16 for the unorm
/// formats, as [`Range::Relative`] values are).
pub fn sum_format(precision: Precision) -> Precision {
    match precision {
        Precision::F32 => Precision::F32,
        _ => Precision::F16,
    }
}

/// Rounds `sums` to the format `precision` holds sums in, saturating as [`Stored::add`] does.
pub fn hold_sums(precision: Precision, sums: &mut [f32]) {
    if sum_format(precision) == Precision::F32 {
        return;
    }
    let mut held = [f16::ZERO; MAX_SHADE_WORDS];
    for chunk in sums.chunks_mut(MAX_SHADE_WORDS) {
        for v in chunk.iter_mut() {
            *v = saturate(*v);
        }
        let held = &mut held[..chunk.len()];
        held.convert_from_f32_slice(chunk);
        held.convert_to_f32_slice(chunk);
    }
}

/// The power of two the backward pass scales its f16 gradient sums by (the loss scaling of
/// mixed-precision training): the largest output gradient `largest` becomes 1 to 2, so sums
/// keep f16's relative precision at a training loss's scale (per-pixel gradients near 1e-7,
/// which unscaled would fall among f16's subnormals or to zero) and at any other. Scaling by
/// a power of two adds no rounding; f32 sums are not scaled.
pub fn sum_scale(precision: Precision, largest: f32) -> f32 {
    if sum_format(precision) == Precision::F32 || !(largest.is_finite() && largest > 0.0) {
        return 1.0;
    }
    // The floor of log2, read from the exponent bits (f32's `log2` may round up to the next
    // integer just below a power of two; subnormals count as 2^-127), as the GPU reads it.
    let exponent = (largest.to_bits() >> 23) as i32 - 127;
    2f32.powi(-exponent.clamp(-100, 100))
}

/// The shade data of a frame's primitives (what `project` hands `evaluate`), stored between
/// the preprocess and the blend in a reduced format: the blend loads a tile's entries from
/// here as it reaches them and decodes each once per tile. f16 holds every float as is; the
/// unorm formats code each float word in the range it spans over the frame's visible
/// primitives (pixel centres spread over 1,000 pixels get steps of 1000/65535 or 1000/255
/// pixels; one large primitive reaching in from far outside the image widens them all). Words
/// that are not floats (flags, integers) are kept exact.
pub struct PackedShade {
    /// Words of the shade type, and which of them are floats.
    float_words: Vec<bool>,
    /// Per float word: the value coded as 0 and the span coded as 1 (unorm), or (0, 1) (f16).
    ranges: Vec<(f32, f32)>,
    /// The float words of each primitive, `ranges.len()` per primitive.
    codes: Stored,
    /// The other words of each primitive, as bits.
    exact: Vec<u32>,
}

impl PackedShade {
    /// Packs `projected`'s shade data at `precision` (not f32: that is the shade data itself);
    /// the unorm ranges span the finite values of the `visible` primitives, the ones the blend
    /// can read. f16 saturates finite values past its range at +-65504.
    pub fn new<M: SplatMethod>(
        precision: Precision,
        projected: &[Projected<M::Cull, M::Shade>],
        visible: &[(u32, TileRect)],
    ) -> PackedShade {
        debug_assert!(precision != Precision::F32);
        let len = M::Shade::LEN;
        assert!(
            len <= MAX_SHADE_WORDS,
            "shade data larger than {MAX_SHADE_WORDS} words"
        );
        let float_words = float_words::<M>();
        let words = |p: &Projected<M::Cull, M::Shade>| {
            let mut w = [0.0; MAX_SHADE_WORDS];
            p.shade.write_words(&mut w);
            w
        };
        let float_at: Vec<usize> = (0..len).filter(|w| float_words[*w]).collect();
        let ranges: Vec<(f32, f32)> = match precision {
            Precision::Unorm16 | Precision::Unorm8 => {
                let none = || vec![(f32::INFINITY, f32::NEG_INFINITY); float_at.len()];
                let bounds = visible
                    .par_iter()
                    .fold(none, |mut b, (i, _)| {
                        let w = words(&projected[*i as usize]);
                        for (r, &at) in b.iter_mut().zip(&float_at) {
                            if w[at].is_finite() {
                                *r = (r.0.min(w[at]), r.1.max(w[at]));
                            }
                        }
                        b
                    })
                    .reduce(none, |a, b| {
                        a.iter()
                            .zip(&b)
                            .map(|(a, b)| (a.0.min(b.0), a.1.max(b.1)))
                            .collect()
                    });
                let span = |(lo, hi): (f32, f32)| match lo <= hi && (hi - lo).is_finite() {
                    true => (lo, (hi - lo).max(f32::MIN_POSITIVE)),
                    false => (0.0, 1.0),
                };
                bounds.into_iter().map(span).collect()
            }
            _ => vec![(0.0, 1.0); float_at.len()],
        };
        let half = precision == Precision::F16;
        let normalized: Vec<f32> = projected
            .par_iter()
            .flat_map_iter(|p| {
                let w = words(p);
                let ranges = &ranges;
                float_at
                    .iter()
                    .zip(ranges)
                    .map(move |(&at, (lo, span))| match half {
                        true => saturate(w[at]),
                        false => (w[at] - lo) / span,
                    })
            })
            .collect();
        let exact = match float_at.len() == len {
            true => vec![],
            false => projected
                .iter()
                .flat_map(|p| {
                    let w = words(p);
                    let float_words = &float_words;
                    (0..len)
                        .filter(move |i| !float_words[*i])
                        .map(move |i| w[i].to_bits())
                })
                .collect(),
        };
        PackedShade {
            float_words,
            ranges,
            codes: Stored::new(precision, Range::Unit, normalized),
            exact,
        }
    }

    /// The shade data of primitive `i`, decoded.
    #[inline]
    pub fn get<S: Flat>(&self, i: usize) -> S {
        let floats = self.ranges.len();
        let mut values = [0.0f32; MAX_SHADE_WORDS];
        let at = i * floats..(i + 1) * floats;
        let coded = values.iter_mut().zip(&self.ranges);
        match &self.codes {
            Stored::F16(c) => c[at]
                .reinterpret_cast::<f16>()
                .convert_to_f32_slice(&mut values[..floats]),
            Stored::Unorm16(c) => {
                for ((v, (lo, span)), q) in coded.zip(&c[at]) {
                    *v = lo + *q as f32 * span / 65535.0;
                }
            }
            Stored::Unorm8(c) => {
                for ((v, (lo, span)), q) in coded.zip(&c[at]) {
                    *v = lo + *q as f32 * span / 255.0;
                }
            }
            Stored::F32(_) => unreachable!("f32 shade data is not packed"),
        }
        if self.exact.is_empty() {
            return S::read_words(&values);
        }
        let mut words = [0.0f32; MAX_SHADE_WORDS];
        let others = self.float_words.len() - floats;
        let (mut f, mut e) = (0, 0);
        for (word, &float) in words.iter_mut().zip(&self.float_words) {
            if float {
                *word = values[f];
                f += 1;
            } else {
                *word = f32::from_bits(self.exact[i * others + e]);
                e += 1;
            }
        }
        S::read_words(&words)
    }

    /// The largest difference between two neighbouring stored values of float word `w` (the
    /// word's range over 65535 or 255 steps in the unorm formats; 0 for f16, whose step is
    /// relative to the value).
    pub fn step(&self, w: usize) -> f32 {
        debug_assert!(self.float_words[w], "word {w} is not a float");
        let f = self.float_words[..w].iter().filter(|f| **f).count();
        let steps = match self.codes {
            Stored::Unorm16(_) => 65535.0,
            Stored::Unorm8(_) => 255.0,
            _ => return 0.0,
        };
        self.ranges[f].1 / steps
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.codes.bytes() + self.exact.capacity() * 4 + self.ranges.capacity() * 8
    }
}

/// The most words a shade type may have (3DGEER's has 16).
const MAX_SHADE_WORDS: usize = 64;

/// Which words of `M::Shade` are floats (the others, flags and integers, are stored exact).
pub fn float_words<M: SplatMethod>() -> Vec<bool> {
    // A float word reads back the slot value it was given; the others stay zero.
    let floats = M::ShadeLanes::default().as_ref().len();
    let mut probe = [0.0; MAX_SHADE_WORDS];
    M::shade_from_float_slots(&vec![1.0; floats]).write_words(&mut probe);
    probe[..M::Shade::LEN].iter().map(|w| *w == 1.0).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_format_rounds_within_its_step_and_saturates_instead_of_wrapping() {
        let values: Vec<f32> = (0..=1000).map(|i| i as f32 / 1000.0).collect();
        for p in Precision::ALL {
            let stored = Stored::new(p, Range::Unit, values.clone());
            for (i, v) in values.iter().enumerate() {
                let err = (stored.get(i) - v).abs();
                assert!(err <= p.unit_error() + 1e-7, "{p:?} {v}: {err}");
            }
        }
        let outside = vec![-0.2, 1.5, 300.0];
        for p in [Precision::Unorm16, Precision::Unorm8] {
            let stored = Stored::new(p, Range::Unit, outside.clone());
            assert_eq!(stored.to_f32(), [0.0, 1.0, 1.0], "{p:?}");
            // Relative values keep their size (as f16).
            let sums = Stored::new(p, Range::Relative, outside.clone());
            assert_eq!(
                sums.to_f32(),
                [-0.2f32, 1.5, 300.0].map(|x| f16::from_f32(x).to_f32())
            );
        }
    }

    #[test]
    fn sums_add_a_slice_at_a_time_as_one_by_one_and_saturate_in_f16() {
        for p in [Precision::F32, Precision::F16] {
            let mut by_slice = Stored::new(p, Range::Relative, vec![0.0; 150]);
            let mut one_by_one = by_slice.clone();
            for round in 0..5 {
                let values: Vec<f32> = (0..150)
                    .map(|i| ((i * 7 + round * 13) % 17) as f32 * 0.37 - 3.0)
                    .collect();
                by_slice.add_slice(0, &values);
                for (i, v) in values.iter().enumerate() {
                    one_by_one.add(i, *v);
                }
            }
            assert_eq!(by_slice, one_by_one, "{p:?}");
        }
        let mut big = Stored::new(Precision::F16, Range::Relative, vec![60000.0, -60000.0]);
        big.add_slice(0, &[60000.0, -60000.0]);
        assert_eq!(big.to_f32(), [65504.0, -65504.0]);
    }

    #[test]
    fn each_format_holds_its_width_in_bytes() {
        let values = vec![0.5f32; 1000];
        let bytes = Precision::ALL.map(|p| Stored::new(p, Range::Unit, values.clone()).bytes());
        assert_eq!(bytes, [4000, 2000, 2000, 1000]);
    }
}
