//! Storage formats for the per-pixel values a frame's forward pass writes (its render targets,
//! in the sense of Yuan and He's mixed-precision rendering): the color, which the image is
//! read from, and the final transmittance and depth sums, which the outputs are read from and
//! the backward pass walks back from. Arithmetic stays f32; only what is stored is rounded,
//! and it really is stored in the format (2 or 1 bytes per value).

use half::f16;

/// How the per-pixel state is stored.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Precision {
    #[default]
    F32,
    /// IEEE half: 11 significant bits (relative error at most 2^-11), range to 65504.
    F16,
    /// Colors in [0, 1] in steps of 1/65535 (values outside saturate); transmittance and depth
    /// sums as f16 ([`Range::Relative`]).
    Unorm16,
    /// Colors in [0, 1] in steps of 1/255; transmittance and depth sums as f16.
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
    /// Colors: in [0, 1] (they may exceed 1, and saturate in unorm).
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

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        match self {
            Stored::F32(v) => v.capacity() * 4,
            Stored::F16(v) | Stored::Unorm16(v) => v.capacity() * 2,
            Stored::Unorm8(v) => v.capacity(),
        }
    }
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
    fn each_format_holds_its_width_in_bytes() {
        let values = vec![0.5f32; 1000];
        let bytes = Precision::ALL.map(|p| Stored::new(p, Range::Unit, values.clone()).bytes());
        assert_eq!(bytes, [4000, 2000, 2000, 1000]);
    }
}
