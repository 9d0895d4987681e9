//! The per-pixel state of the GPU's tile path, stored at `RenderOptions::precision` (the
//! CPU's `precision::Stored` on the device): per pixel the color channels, the final
//! transmittance, the sum of weight x depth and where the pixel's walk of its tile's list
//! ended, packed into 32-bit words with WGSL's pack builtins. The forward blend writes it, the
//! backward blend walks back from it, and the host reads the frame from it; this module is the
//! one place its layout is defined, for the shaders (generated WGSL) and for the host
//! (decoding).
//!
//! Layout per pixel, values v = (colors, T, depth sum), the depth sum only where the frame
//! keeps one (an output not asked for has no word), then the walk's end as a `u32` word:
//! - f32: one word per value;
//! - f16: two values per word (`pack2x16float`);
//! - unorm16 / unorm8: the colors two or four per word (`pack2x16unorm` / `pack4x8unorm`,
//!   saturating to [0, 1]), then T and the depth sum as f16 in a word of their own (see
//!   `precision::Range::Relative`: a unorm format cannot hold them).

use half::f16;
use splat_core::precision::Precision;

/// How one frame's pixels are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelState {
    pub precision: Precision,
    pub channels: usize,
    /// Whether the depth sum is kept.
    pub depth: bool,
}

impl PixelState {
    /// Values stored per pixel: the colors, T, the depth sum if kept.
    fn values(&self) -> usize {
        self.channels + 1 + self.depth as usize
    }

    /// Values packed per word in the format's packing.
    fn per_word(&self) -> usize {
        match self.precision {
            Precision::F32 => 1,
            Precision::F16 | Precision::Unorm16 => 2,
            Precision::Unorm8 => 4,
        }
    }

    /// Whether T and the depth sum have an f16 word of their own (the unorm formats).
    fn relative_word(&self) -> bool {
        matches!(self.precision, Precision::Unorm16 | Precision::Unorm8)
    }

    /// The values in the format's packing: the colors, and T and the depth sum unless they
    /// have a word of their own.
    fn packed(&self) -> usize {
        match self.relative_word() {
            true => self.channels,
            false => self.values(),
        }
    }

    /// 32-bit words per pixel.
    pub fn words(&self) -> usize {
        self.packed().div_ceil(self.per_word()) + self.relative_word() as usize + 1
    }

    /// WGSL: `const STATE_WORDS`, `fn state_value(pix: u32, k: u32) -> f32` reading value `k`
    /// of pixel `pix` from the `u32` array `buffer` (k = channels + 1, the depth sum, only
    /// where it is kept), and `fn state_end(pix: u32) -> u32`, where its walk ended.
    pub fn wgsl_load(&self, buffer: &str) -> String {
        let packed = match self.precision {
            Precision::F32 => format!("bitcast<f32>({buffer}[at + k])"),
            Precision::F16 => format!("unpack2x16float({buffer}[at + k / 2u])[k % 2u]"),
            Precision::Unorm16 => format!("unpack2x16unorm({buffer}[at + k / 2u])[k % 2u]"),
            Precision::Unorm8 => format!("unpack4x8unorm({buffer}[at + k / 4u])[k % 4u]"),
        };
        let relative = match self.relative_word() {
            true => format!(
                "    if (k >= CHANNELS) {{
        return unpack2x16float({buffer}[at + STATE_WORDS - 2u])[k - CHANNELS];
    }}
"
            ),
            false => String::new(),
        };
        format!(
            "const STATE_WORDS: u32 = {words}u;

// Value k (colors, T, depth sum) of pixel `pix`'s stored state.
fn state_value(pix: u32, k: u32) -> f32 {{
    let at = pix * STATE_WORDS;
{relative}    return {packed};
}}

// How many entries of its tile's list pixel `pix` walked (its last taken one, plus one).
fn state_end(pix: u32) -> u32 {{
    return {buffer}[pix * STATE_WORDS + STATE_WORDS - 1u];
}}
",
            words = self.words()
        )
    }

    /// WGSL statements storing the pixel `pix`'s values `v` (an `array<f32, N>` of the colors,
    /// T and the depth sum) and its walk's end `end` (a `u32`) into the `u32` array `buffer`.
    pub fn wgsl_store(&self, buffer: &str, end: &str) -> String {
        let n = self.packed();
        let value = |k: usize| match k < n {
            true => format!("v[{k}]"),
            false => "0.0".into(),
        };
        let words = self.words();
        let mut out = format!("let at = pix * {words}u;\n");
        for w in 0..n.div_ceil(self.per_word()) {
            let k = w * self.per_word();
            let word = match self.precision {
                Precision::F32 => format!("bitcast<u32>(v[{k}])"),
                Precision::F16 => {
                    format!("pack2x16float(vec2<f32>({}, {}))", value(k), value(k + 1))
                }
                Precision::Unorm16 => {
                    format!("pack2x16unorm(vec2<f32>({}, {}))", value(k), value(k + 1))
                }
                Precision::Unorm8 => format!(
                    "pack4x8unorm(vec4<f32>({}, {}, {}, {}))",
                    value(k),
                    value(k + 1),
                    value(k + 2),
                    value(k + 3)
                ),
            };
            out += &format!("        {buffer}[at + {w}u] = {word};\n");
        }
        if self.relative_word() {
            let depth = match self.depth {
                true => format!("v[{}]", n + 1),
                false => "0.0".into(),
            };
            out += &format!(
                "        {buffer}[at + {}u] = pack2x16float(vec2<f32>(v[{n}], {depth}));\n",
                words - 2
            );
        }
        out += &format!("        {buffer}[at + {}u] = {end};\n", words - 1);
        out
    }

    /// The stored words of a frame, decoded: per pixel the colors, T and the depth sum (zero
    /// where it is not kept).
    pub fn decode(&self, words: &[u32]) -> Vec<f32> {
        let (n, per) = (self.packed(), self.per_word());
        let half = |bits: u32| f16::from_bits(bits as u16).to_f32();
        let mut out = Vec::with_capacity(words.len() / self.words().max(1) * self.values());
        for px in words.chunks_exact(self.words()) {
            for k in 0..n {
                let w = px[k / per];
                let lane = (k % per) as u32;
                out.push(match self.precision {
                    Precision::F32 => f32::from_bits(w),
                    Precision::F16 => half(w >> (16 * lane)),
                    Precision::Unorm16 => ((w >> (16 * lane)) & 0xffff) as f32 / 65535.0,
                    Precision::Unorm8 => ((w >> (8 * lane)) & 0xff) as f32 / 255.0,
                });
            }
            if self.relative_word() {
                let w = px[self.words() - 2];
                out.push(half(w));
                if self.depth {
                    out.push(half(w >> 16));
                }
            }
            if !self.depth {
                out.push(0.0);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_format_packs_into_fewer_words_and_decodes_what_it_stored() {
        let state = |precision| PixelState {
            precision,
            channels: 3,
            depth: true,
        };
        let words: Vec<usize> = Precision::ALL.map(|p| state(p).words()).into();
        // (3 colors, T, depth) and the end: 6 words; 3 halves + 1; 2 + 1 + 1; 1 + 1 + 1.
        assert_eq!(words, [6, 4, 4, 3]);
        // Without the depth sum: 5 words; 2 halves + 1; 2 + 1 + 1; 1 + 1 + 1.
        let shallow = |precision| PixelState {
            depth: false,
            ..state(precision)
        };
        let words: Vec<usize> = Precision::ALL.map(|p| shallow(p).words()).into();
        assert_eq!(words, [5, 3, 4, 3]);
        let half = |a: f32, b: f32| {
            f16::from_f32(a).to_bits() as u32 | (f16::from_f32(b).to_bits() as u32) << 16
        };
        let unorm8 = 64 | 128 << 8 | 255 << 16;
        let end = 17;
        assert_eq!(
            shallow(Precision::Unorm8).decode(&[unorm8, half(0.75, 0.0), end]),
            [64.0 / 255.0, 128.0 / 255.0, 1.0, 0.75, 0.0]
        );
        let v = [0.25f32, 0.5, 1.0, 0.75, 3.5];
        let halves = [half(v[0], v[1]), half(v[2], v[3]), half(v[4], 0.0), end];
        assert_eq!(state(Precision::F16).decode(&halves), v);
        let got = state(Precision::Unorm8).decode(&[unorm8, half(0.75, 3.5), end]);
        let want = [64.0 / 255.0, 128.0 / 255.0, 1.0, 0.75, 3.5];
        assert_eq!(got, want);
        let unorm16 = [16384 | 32768 << 16, 65535, half(0.75, 3.5), end];
        let got = state(Precision::Unorm16).decode(&unorm16);
        assert!(
            got.iter().zip(v).all(|(a, b)| (a - b).abs() < 1e-4),
            "{got:?}"
        );
        // T keeps its relative precision where the colors are unorm: 1e-4 is not 0.
        let t = state(Precision::Unorm8).decode(&[0, half(1e-4, 0.0), end])[3];
        assert!((t - 1e-4).abs() < 1e-7, "{t}");
    }
}
