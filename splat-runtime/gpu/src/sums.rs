//! The backward blend's per-primitive gradient sums held in f16 on the device
//! (`RenderOptions::gradient_precision`, the CPU's `precision::Stored` sums): two to a 32-bit
//! word, each add a compare-exchange loop that rounds the sum to f16 (on the bits, as the CPU
//! does) and saturates it at +-65504. The sums are loss-scaled as on the CPU: a pass over the
//! output gradients finds the largest (`shaders/largest.wgsl`), and every add multiplies by the
//! power of two that brings it to 1 to 2; `project`'s adjoint reads the sums unscaled. This
//! module is the one place their layout is defined, for the shaders and for the host.

use super::device::{Kernel, dispatch};
use super::{Gpu, GpuError};
use half::f16;
use splat_core::precision::{Precision, sum_format, sum_scale};

const LARGEST: &str = include_str!("shaders/largest.wgsl");
const ADD_F16: &str = include_str!("shaders/sums/add_f16.wgsl");
const ADD_F32_ATOMIC: &str = include_str!("shaders/sums/add_f32_atomic.wgsl");
const ADD_F32_EXCHANGE: &str = include_str!("shaders/sums/add_f32_exchange.wgsl");
const READ_F16: &str = include_str!("shaders/sums/read_f16.wgsl");
const READ_F32: &str = include_str!("shaders/sums/read_f32.wgsl");

/// How the sums are held: f32 (one word each, f32 atomics or a compare-exchange loop) or f16.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Sums {
    pub half: bool,
}

impl Sums {
    /// The sums of a backward pass at `precision` (a unorm one is refused before a frame).
    pub fn at(precision: Precision) -> Sums {
        Sums {
            half: sum_format(precision) == Precision::F16,
        }
    }

    /// Words holding `n` sums.
    pub fn words(self, n: usize) -> usize {
        match self.half {
            true => n.div_ceil(2),
            false => n,
        }
    }

    /// `fn add_grad(i: u32, v: f32)` for these sums in `grads` (`shaders/sums/add_*.wgsl`),
    /// and the type of `grads`' elements it needs: f16 sums, or f32 ones as
    /// [`wgsl_add_f32`] adds them.
    pub(crate) fn wgsl_add(self, float_atomics: bool) -> (&'static str, String) {
        match self.half {
            true => ("atomic<u32>", ADD_F16.into()),
            false => wgsl_add_f32("add_grad", "grads", float_atomics),
        }
    }

    /// `fn grad(at: u32) -> f32` (sum `at`, unscaled) and `fn grad_bits(at: u32) -> u32`
    /// (nonzero where the sum is) over the `u32` array `grads` (`shaders/sums/read_*.wgsl`).
    pub(crate) fn wgsl_read(self) -> &'static str {
        match self.half {
            false => READ_F32,
            true => READ_F16,
        }
    }

    /// The `n` sums held in `words`, unscaled by the scale of `largest` (the bits of the
    /// largest output gradient), as `project`'s adjoint reads them.
    pub fn decode(self, words: &[u32], n: usize, largest: u32) -> Vec<f32> {
        match self.half {
            false => words[..n].iter().map(|w| f32::from_bits(*w)).collect(),
            true => {
                let scale = sum_scale(Precision::F16, f32::from_bits(largest));
                (0..n)
                    .map(|at| {
                        let bits = (words[at / 2] >> (16 * (at % 2))) as u16;
                        f16::from_bits(bits).to_f32() / scale
                    })
                    .collect()
            }
        }
    }
}

/// `fn {name}(i: u32, v: f32)` adding `v` to the f32 word `i` of `array`, and the type of the
/// array's elements it needs: by the adapter's f32 atomics where it has them
/// (`float_atomics`), else by compare-exchange.
pub(crate) fn wgsl_add_f32(name: &str, array: &str, float_atomics: bool) -> (&'static str, String) {
    let (atomic, template) = match float_atomics {
        true => ("atomic<f32>", ADD_F32_ATOMIC),
        false => ("atomic<u32>", ADD_F32_EXCHANGE),
    };
    let source = template.replace("{{FN}}", name).replace("{{ARRAY}}", array);
    (atomic, source)
}

/// The pass that finds a frame's largest output gradient, and where it leaves it.
pub(crate) struct Largest {
    kernel: Kernel,
    info: wgpu::Buffer,
    /// The largest magnitude's f32 bits (one word).
    pub bits: wgpu::Buffer,
}

impl Largest {
    /// The pass over output gradients of `words` per pixel.
    pub fn new(gpu: &Gpu, words: usize) -> Result<Largest, GpuError> {
        let source = LARGEST.replace("{{WORDS}}", &words.to_string());
        Ok(Largest {
            kernel: gpu.kernel(&source, "largest_gradient")?,
            info: gpu.uniform_buffer(4),
            bits: gpu.buffer("largest output gradient", 1)?,
        })
    }

    /// Records the pass over the `pixels` gradients of `pixel_grad`, the first `read` words
    /// of each.
    pub fn record(
        &self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        pixel_grad: &wgpu::Buffer,
        (pixels, read): (usize, usize),
    ) -> Result<(), GpuError> {
        gpu.write(&self.info, &[pixels as u32, read as u32, 0, 0]);
        enc.clear_buffer(&self.bits, 0, None);
        let bind = gpu.bind_named(
            &self.kernel,
            &[
                ("pixel_grad", pixel_grad),
                ("grad_largest", &self.bits),
                ("info", &self.info),
            ],
        )?;
        dispatch(
            enc,
            &self.kernel.pipeline,
            &bind,
            (pixels as u32).div_ceil(256),
        );
        Ok(())
    }
}
