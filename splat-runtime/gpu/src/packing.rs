//! The packed layout of a method's shade data at a reduced precision: the one place it is
//! defined, for the shaders (the WGSL that packs and the WGSL that stages from the packed
//! words) and for the host (decoding). Coding, operation for operation the CPU's
//! `precision::PackedShade`: f16 rounds to nearest even, saturating finite values at +-65504;
//! unorm codes `(v - lo) / span` in 65535 or 255 steps, rounding half away from zero, and
//! decodes `lo + q * span / steps`.

use half::f16;
use splat_core::method::SplatMethod;
use splat_core::precision::{Precision, float_words};

/// How a method's shade data is packed at a reduced precision.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ShadePacking {
    pub precision: Precision,
    /// Per word of the shade type, whether it is a float.
    float_words: Vec<bool>,
}

impl ShadePacking {
    /// The packing of `M`'s shade data at `precision`; `None` at f32 (the blends then read
    /// `project`'s output itself).
    pub fn of<M: SplatMethod>(precision: Precision) -> Option<ShadePacking> {
        (precision != Precision::F32).then(|| ShadePacking {
            precision,
            float_words: float_words::<M>(),
        })
    }

    /// Float words per primitive.
    pub fn floats(&self) -> usize {
        self.float_words.iter().filter(|f| **f).count()
    }

    fn per_word(&self) -> usize {
        match self.precision {
            Precision::Unorm8 => 4,
            _ => 2,
        }
    }

    /// Bits per code.
    fn bits(&self) -> usize {
        32 / self.per_word()
    }

    /// Unorm steps, or `None` for f16.
    fn steps(&self) -> Option<f32> {
        match self.precision {
            Precision::Unorm16 => Some(65535.0),
            Precision::Unorm8 => Some(255.0),
            _ => None,
        }
    }

    /// Whether the floats are coded in ranges (the unorm formats).
    pub fn has_ranges(&self) -> bool {
        self.steps().is_some()
    }

    /// Words holding the codes.
    fn coded(&self) -> usize {
        self.floats().div_ceil(self.per_word())
    }

    /// 32-bit words per primitive: the codes, then the words that are not floats.
    pub fn words(&self) -> usize {
        self.coded() + self.float_words.len() - self.floats()
    }

    /// Words of the ranges buffer: per float word two keys, then (lo, span).
    pub fn range_words(&self) -> usize {
        4 * self.floats()
    }

    /// (shade word, float index) of each float word, and the other words in order.
    fn split(&self) -> (Vec<(usize, usize)>, Vec<usize>) {
        let mut floats = vec![];
        let mut exact = vec![];
        for (w, &float) in self.float_words.iter().enumerate() {
            match float {
                true => floats.push((w, floats.len())),
                false => exact.push(w),
            }
        }
        (floats, exact)
    }

    /// WGSL of `shade_range`'s body: widen each float word's range by primitive `i`'s value.
    pub(crate) fn wgsl_widen(&self) -> String {
        let (floats, _) = self.split();
        floats
            .iter()
            .map(|(w, k)| format!("            widen({k}u, word(i, SHADE_AT + {w}u));\n"))
            .collect()
    }

    /// WGSL of `shade_pack`'s first statement: invocation 0 stores each float word's coding
    /// range after the keys.
    pub(crate) fn wgsl_write_ranges(&self) -> String {
        if !self.has_ranges() {
            return String::new();
        }
        "    if (i == 0u) {
        for (var k = 0u; k < FLOATS; k++) {
            let r = coding_range(k);
            atomicStore(&shade_ranges[2u * FLOATS + 2u * k], bitcast<u32>(r.x));
            atomicStore(&shade_ranges[2u * FLOATS + 2u * k + 1u], bitcast<u32>(r.y));
        }
    }"
        .into()
    }

    /// WGSL of `shade_pack`'s body: code primitive `i`'s words into `packed_shade[at..]`.
    pub(crate) fn wgsl_pack(&self) -> String {
        let (floats, exact) = self.split();
        let mut out = String::new();
        if self.has_ranges() {
            for (_, k) in &floats {
                out += &format!("    let r{k} = coding_range({k}u);\n");
            }
        }
        let code = |w: usize, k: usize| match self.steps() {
            None => format!("to_half(saturate_half(word(i, SHADE_AT + {w}u)))"),
            Some(steps) => {
                format!("unit_code((word(i, SHADE_AT + {w}u) - r{k}.x) / r{k}.y, {steps:?})")
            }
        };
        for (c, group) in floats.chunks(self.per_word()).enumerate() {
            let parts: Vec<String> = group
                .iter()
                .enumerate()
                .map(|(lane, (w, k))| match lane {
                    0 => code(*w, *k),
                    _ => format!("({} << {}u)", code(*w, *k), lane * self.bits()),
                })
                .collect();
            out += &format!("    packed_shade[at + {c}u] = {};\n", parts.join(" | "));
        }
        for (e, w) in exact.iter().enumerate() {
            out += &format!(
                "    packed_shade[at + {}u] = projected[i * STRIDE + SHADE_AT + {w}u];\n",
                self.coded() + e
            );
        }
        out
    }

    /// WGSL staging primitive `p`'s shade words into `batch_words[lid * NS..]` as f32 bits,
    /// decoded from `packed_shade` (and `shade_ranges`' coding ranges).
    pub(crate) fn wgsl_stage(&self) -> String {
        let (floats, exact) = self.split();
        let mut out = format!("        let at = p * {}u;\n", self.words());
        for c in 0..self.coded() {
            out += &format!("        let c{c} = packed_shade[at + {c}u];\n");
        }
        let mask = (1u64 << self.bits()) - 1;
        for (w, k) in &floats {
            let (c, lane) = (k / self.per_word(), k % self.per_word());
            let q = format!("((c{c} >> {}u) & {mask}u)", lane * self.bits());
            let value = match self.steps() {
                None => format!("from_half({q})"),
                Some(steps) => format!(
                    "bitcast<f32>(shade_ranges[{lo}u]) + f32({q}) * bitcast<f32>(shade_ranges[{lo}u + 1u]) / {steps:?}",
                    lo = 2 * self.floats() + 2 * k
                ),
            };
            out += &format!("        batch_words[lid * NS + {w}u] = bitcast<u32>({value});\n");
        }
        for (e, w) in exact.iter().enumerate() {
            out += &format!(
                "        batch_words[lid * NS + {w}u] = packed_shade[at + {}u];\n",
                self.coded() + e
            );
        }
        out
    }

    /// The shade words of each primitive (as f32, `M::Shade::LEN` per primitive) decoded from
    /// `packed` (this packing's words) with the coding ranges in `ranges` (the ranges
    /// buffer's words), as the blends decode them.
    pub fn decode(&self, packed: &[u32], ranges: &[u32]) -> Vec<f32> {
        let (floats, exact) = self.split();
        let mut out = Vec::with_capacity(packed.len() / self.words() * self.float_words.len());
        for words in packed.chunks_exact(self.words()) {
            let mut shade = vec![0.0f32; self.float_words.len()];
            for (w, k) in &floats {
                let (c, lane) = (k / self.per_word(), k % self.per_word());
                let q = (words[c] >> (lane * self.bits())) & ((1u64 << self.bits()) - 1) as u32;
                shade[*w] = match self.steps() {
                    None => f16::from_bits(q as u16).to_f32(),
                    Some(steps) => {
                        let at = 2 * self.floats() + 2 * k;
                        let (lo, span) =
                            (f32::from_bits(ranges[at]), f32::from_bits(ranges[at + 1]));
                        lo + q as f32 * span / steps
                    }
                };
            }
            for (e, w) in exact.iter().enumerate() {
                shade[*w] = f32::from_bits(words[self.coded() + e]);
            }
            out.extend(shade);
        }
        out
    }
}
