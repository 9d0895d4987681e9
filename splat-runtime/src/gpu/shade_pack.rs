//! The shade data between the preprocess and the blends at `RenderOptions::shade_precision`:
//! the CPU's `precision::PackedShade` on the device. After `project`, one dispatch finds the
//! range each float word spans over the primitives with a tile rectangle (unorm formats only)
//! and one packs every primitive's float words, two (f16, unorm16) or four (unorm8) to a
//! 32-bit word, its other words exact after them. Both blends stage a tile's entries from the
//! packed words, decoding each into the same f32 batch they stage from `project`'s output at
//! f32, so the backward pass differentiates what the forward pass rendered. This module is the
//! one place the packed layout is defined, for the shaders and for the host.
//!
//! Coding, operation for operation the CPU's: f16 rounds to nearest even (on the bits,
//! `shaders/half.wgsl`), saturating finite values at +-65504; unorm codes `(v - lo) / span` in
//! 65535 or 255 steps, rounding half away from zero, and decodes `lo + q * span / steps`. A
//! GPU's division may round differently from the CPU's (Vulkan allows 2.5 ulp), so a code
//! can differ from the CPU's by one step where a value falls that close to a half step.

use super::device::{Grown, Kernel, dispatch};
use super::entries;
use super::front::Front;
use super::{Gpu, GpuError};
use crate::method::SplatMethod;
use crate::pipeline::precision::{Precision, float_words};
use half::f16;

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
    fn wgsl_widen(&self) -> String {
        let (floats, _) = self.split();
        floats
            .iter()
            .map(|(w, k)| format!("            widen({k}u, word(i, SHADE_AT + {w}u));\n"))
            .collect()
    }

    /// WGSL of `shade_pack`'s first statement: invocation 0 stores each float word's coding
    /// range after the keys.
    fn wgsl_write_ranges(&self) -> String {
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
    fn wgsl_pack(&self) -> String {
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

    /// The pack module's source for `M` (entries `shade_range`, `shade_pack`).
    pub(crate) fn source<M: SplatMethod>(&self) -> Result<String, GpuError> {
        entries::shade_pack::<M>(&[
            ("FLOATS", self.floats().to_string()),
            ("PACKED", self.words().to_string()),
            ("KEY_WORDS", (2 * self.floats()).max(1).to_string()),
            ("WIDEN", self.wgsl_widen()),
            ("WRITE_RANGES", self.wgsl_write_ranges()),
            ("PACK", self.wgsl_pack()),
        ])
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

/// The two dispatches that pack a frame's shade data, and what they write.
pub(crate) struct ShadePacker {
    packing: ShadePacking,
    range: Option<Kernel>,
    pack: Kernel,
    /// [`ShadePacking::words`] per primitive.
    pub packed: Grown,
    /// [`ShadePacking::range_words`] (one word where there are no ranges).
    pub ranges: wgpu::Buffer,
}

impl ShadePacker {
    pub fn new<M: SplatMethod>(gpu: &Gpu, packing: ShadePacking) -> Result<Self, GpuError> {
        let source = packing.source::<M>()?;
        Ok(ShadePacker {
            range: match packing.has_ranges() {
                true => Some(gpu.kernel(&source, "shade_range")?),
                false => None,
            },
            pack: gpu.kernel(&source, "shade_pack")?,
            packed: Grown::new(gpu, "packed shade data", 1)?,
            ranges: gpu.buffer("shade data ranges", packing.range_words().max(1))?,
            packing,
        })
    }

    pub fn packing(&self) -> &ShadePacking {
        &self.packing
    }

    /// Records the packing of the `n` primitives `front` projected last.
    pub fn record(
        &mut self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        front: &Front,
        n: usize,
    ) -> Result<(), GpuError> {
        self.packed.ensure(gpu, n * self.packing.words())?;
        let groups = (n as u32).div_ceil(256);
        let mut inputs: Vec<(&str, &wgpu::Buffer)> = vec![
            ("projected", &front.projected),
            ("frame", &front.frame_info),
        ];
        if let Some(range) = &self.range {
            inputs.push(("shade_ranges", &self.ranges));
            enc.clear_buffer(&self.ranges, 0, None);
            dispatch(
                enc,
                &range.pipeline,
                &gpu.bind_named(range, &inputs)?,
                groups,
            );
        }
        inputs.push(("packed_shade", &self.packed));
        dispatch(
            enc,
            &self.pack.pipeline,
            &gpu.bind_named(&self.pack, &inputs)?,
            groups,
        );
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `half.wgsl` against the `half` crate: every f16 pattern back to f32, and to f16 every
    /// f16 value, the midpoints between neighbours (ties, to even) and the floats either side
    /// of them, f32 subnormals, values past f16's range, infinities and NaN.
    #[test]
    fn wgsl_half_conversions_round_as_the_half_crate_does() {
        let Some(gpu) = super::super::adapter_or_skip() else {
            return;
        };
        let source = format!(
            "{}
@group(0) @binding(0) var<storage, read> input: array<u32>;
@group(0) @binding(1) var<storage, read_write> output: array<u32>;
@group(0) @binding(2) var<uniform> count: vec4<u32>;

@compute @workgroup_size(64)
fn convert(@builtin(global_invocation_id) gid: vec3<u32>) {{
    let i = gid.y * 65535u * 64u + gid.x;
    if (i < count.x) {{
        output[2u * i] = to_half(bitcast<f32>(input[i]));
        output[2u * i + 1u] = bitcast<u32>(from_half(input[i] & 0xffffu));
    }}
}}",
            entries::HALF
        );
        let mut floats: Vec<u32> = (0..=u16::MAX as u32).collect();
        for h in 0..0x7bffu16 {
            let (a, b) = (f16::from_bits(h).to_f32(), f16::from_bits(h + 1).to_f32());
            let mid = (a + b) / 2.0;
            floats.extend([
                mid.to_bits(),
                mid.to_bits() - 1,
                mid.to_bits() + 1,
                a.to_bits(),
            ]);
            floats.extend([(-mid).to_bits(), (-a).to_bits()]);
        }
        let mut rng = fastrand::Rng::with_seed(5);
        floats.extend((0..20_000).map(|_| rng.u32(..)));
        let special = [
            1e-40f32,
            -3e-39,
            65504.0,
            65519.0,
            65520.0,
            1e6,
            f32::INFINITY,
        ];
        floats.extend(special.iter().map(|x| x.to_bits()));
        floats.extend([f32::NEG_INFINITY.to_bits(), f32::NAN.to_bits(), 0x7f80_0001]);
        let n = floats.len();
        let out = super::super::dispatch::run(
            &gpu,
            &source,
            "convert",
            &[("input", &floats)],
            ("output", 2 * n),
            ("count", &[n as u32]),
            (n as u32).div_ceil(64),
        )
        .unwrap();
        for (x, got) in floats.iter().zip(out.chunks_exact(2)) {
            let value = f32::from_bits(*x);
            let half = f16::from_f32(value);
            match value.is_nan() {
                true => assert!(f16::from_bits(got[0] as u16).is_nan(), "{x:#x}"),
                false => assert_eq!(got[0], half.to_bits() as u32, "to_half({value:e})"),
            }
            let back = f16::from_bits(*x as u16);
            match back.is_nan() {
                true => assert!(f32::from_bits(got[1]).is_nan(), "{x:#x}"),
                false => assert_eq!(got[1], back.to_f32().to_bits(), "from_half({x:#x})"),
            }
        }
    }
}
