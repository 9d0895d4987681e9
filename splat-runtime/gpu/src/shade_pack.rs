//! The shade data between the preprocess and the blends at `RenderOptions::shade_precision`:
//! the CPU's `precision::PackedShade` on the device. After `project`, one dispatch finds the
//! range each float word spans over the primitives with a tile rectangle (unorm formats only)
//! and one packs every primitive's float words, two (f16, unorm16) or four (unorm8) to a
//! 32-bit word, its other words exact after them. Both blends stage a tile's entries from the
//! packed words, decoding each into the same f32 batch they stage from `project`'s output at
//! f32, so the backward pass differentiates what the forward pass rendered. The layout itself is
//! `packing.rs`'s.
//!
//! Coding, operation for operation the CPU's: f16 rounds to nearest even (on the bits,
//! `shaders/half.wgsl`), saturating finite values at +-65504; unorm codes `(v - lo) / span` in
//! 65535 or 255 steps, rounding half away from zero, and decodes `lo + q * span / steps`. A
//! GPU's division may round differently from the CPU's (Vulkan allows 2.5 ulp), so a code
//! can differ from the CPU's by one step where a value falls that close to a half step.

use super::device::{Grown, Kernel, dispatch};
use super::entries;
use super::front::Front;
pub use super::packing::ShadePacking;
use super::{Gpu, GpuError};
use splat_core::method::SplatMethod;

/// The pack module's source for `M` at `packing` (entries `shade_range`, `shade_pack`).
fn source<M: SplatMethod>(packing: &ShadePacking) -> Result<String, GpuError> {
    entries::shade_pack::<M>(&[
        ("FLOATS", packing.floats().to_string()),
        ("PACKED", packing.words().to_string()),
        ("KEY_WORDS", (2 * packing.floats()).max(1).to_string()),
        ("WIDEN", packing.wgsl_widen()),
        ("WRITE_RANGES", packing.wgsl_write_ranges()),
        ("PACK", packing.wgsl_pack()),
    ])
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
        let source = source::<M>(&packing)?;
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
            ("frame", &front.frame_uniform),
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
    use half::f16;

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
