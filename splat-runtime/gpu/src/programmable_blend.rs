//! Programmable blending: fragment shaders that read and write their pixel's state in
//! rasterization order, what the seed's hardware backward (paper 001) is built on: a device
//! opened for it ([`open`]), a render pass that does it ([`RasterPass`], which the hardware
//! forward's `Blending::Programmable` draws with), and the order test that tells an ordered
//! read-modify-write from an unordered one ([`fold`]).
//!
//! WebGPU has no such access (gpuweb issues 395 and 442), and wgpu 30 stops short of it in
//! three places: WGSL and naga have no input attachments (gfx-rs/wgpu#5233), wgpu's render
//! pipelines and passes have none either (gfx-rs/wgpu#10148), and neither carries the
//! rasterization-order flags. What wgpu does lend is enough for the rest: its Vulkan layer opens
//! the device with `VK_EXT_rasterization_order_attachment_access` and its feature, hands out
//! the raw device and the open command buffer of an encoder of our own, and submits that
//! buffer on its queue in order with its own work, so the one pass is raw Vulkan (`ash`), its
//! shaders the SPIR-V naga writes from WGSL with the texture loads rewritten into
//! subpass-input reads ([`spirv`]).
//!
//! Which devices have it: Mesa's lavapipe (CI's adapter), RADV, Turnip and ARM's drivers
//! expose the extension; NVIDIA's drivers expose `VK_EXT_fragment_shader_interlock` instead
//! (a critical section around a fragment's access to storage memory, which wgpu's
//! passthrough SPIR-V could take without raw passes), and Mesa's lavapipe gained the
//! interlock only after the 25.0 that Debian bookworm's backports carry.

mod pass;
pub mod spirv;

pub use pass::{RasterPass, RasterPassDesc};

use crate::device::first_adapter;
use crate::{Gpu, GpuError};
use ash::vk;
use std::ffi::CStr;
use std::time::Duration;
use wgpu::hal::api::Vulkan;

/// The Vulkan extension that orders attachment reads in a subpass by rasterization order.
pub const EXTENSION: &CStr = ash::ext::rasterization_order_attachment_access::NAME;

/// Whether a pass asks for rasterization order: [`Order::Unspecified`] is the control, whose
/// reads of what the subpass writes Vulkan leaves undefined.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Order {
    Rasterization,
    Unspecified,
}

/// The first adapter's device opened with rasterization-order attachment access, or `None`
/// when the adapter is not Vulkan or lacks the extension or its color-attachment feature.
pub fn open() -> Result<Option<Gpu>, GpuError> {
    let adapter = first_adapter()?;
    if !color_access(&adapter) {
        return Ok(None);
    }
    Gpu::open_with(&adapter, open_ordered).map(Some)
}

/// [`open`] for tests and tools that can do without it: `None` (with a line on stderr) where
/// the adapter lacks the extension, unless `SPLAT_REQUIRE_RASTER_ORDER=1` (set by CI, whose
/// lavapipe has it), which makes that a panic.
pub fn open_or_skip() -> Option<Gpu> {
    let required = std::env::var("SPLAT_REQUIRE_RASTER_ORDER").is_ok_and(|v| v == "1");
    let why = match open() {
        Ok(Some(gpu)) => return Some(gpu),
        Ok(None) => "the adapter lacks rasterization-order attachment access".to_string(),
        Err(e) => e.to_string(),
    };
    if required {
        panic!("{why}");
    }
    eprintln!("skipping programmable blending: {why}");
    None
}

/// What the first adapter offers for programmable blending.
#[derive(Clone, Debug)]
pub struct Support {
    pub adapter: String,
    /// `VK_EXT_rasterization_order_attachment_access` with its color-attachment feature: what
    /// [`open`] and [`fold`] use.
    pub rasterization_order: bool,
    /// `VK_EXT_fragment_shader_interlock`: the other route (NVIDIA's), not built yet.
    pub interlock: bool,
}

/// What the first adapter offers ([`Support`]).
pub fn support() -> Result<Support, GpuError> {
    let adapter = first_adapter()?;
    let info = adapter.get_info();
    // SAFETY: the handle is only read, while `adapter` lives.
    let interlock = unsafe { adapter.as_hal::<Vulkan>() }.is_some_and(|hal| {
        let extension = ash::ext::fragment_shader_interlock::NAME;
        hal.physical_device_capabilities()
            .supports_extension(extension)
    });
    Ok(Support {
        adapter: format!(
            "{} ({:?}, driver {})",
            info.name, info.backend, info.driver_info
        ),
        rasterization_order: color_access(&adapter),
        interlock,
    })
}

/// Whether `adapter` is a Vulkan one with the extension and its color-attachment feature.
fn color_access(adapter: &wgpu::Adapter) -> bool {
    // SAFETY: the handles are only read, while `adapter` lives.
    let Some(hal) = (unsafe { adapter.as_hal::<Vulkan>() }) else {
        return false;
    };
    if !hal
        .physical_device_capabilities()
        .supports_extension(EXTENSION)
    {
        return false;
    }
    let mut order = vk::PhysicalDeviceRasterizationOrderAttachmentAccessFeaturesEXT::default();
    let mut features = vk::PhysicalDeviceFeatures2::default().push_next(&mut order);
    let instance = hal.shared_instance().raw_instance();
    // SAFETY: the physical device is the adapter's; the chain's one struct is the extension's.
    unsafe { instance.get_physical_device_features2(hal.raw_physical_device(), &mut features) };
    order.rasterization_order_color_attachment_access == vk::TRUE
}

/// `desc`'s device on `adapter` through wgpu's Vulkan layer, with the extension and its
/// color-attachment feature enabled besides what wgpu enables.
fn open_ordered(
    adapter: &wgpu::Adapter,
    desc: &wgpu::DeviceDescriptor,
) -> Result<(wgpu::Device, wgpu::Queue), GpuError> {
    let failed = |e: String| GpuError::Device(format!("with rasterization-order access: {e}"));
    let mut order = vk::PhysicalDeviceRasterizationOrderAttachmentAccessFeaturesEXT::default()
        .rasterization_order_color_attachment_access(true);
    let opened = {
        // SAFETY: the adapter's own handle; `color_access` checked the extension and feature.
        let hal =
            unsafe { adapter.as_hal::<Vulkan>() }.ok_or_else(|| failed("not Vulkan".into()))?;
        let order = &mut order;
        let add_order: Box<wgpu::hal::vulkan::CreateDeviceCallback> = Box::new(move |args| {
            args.extensions.push(EXTENSION);
            *args.create_info = args.create_info.push_next(order);
        });
        // SAFETY: the callback adds a supported extension and feature and removes nothing.
        unsafe {
            hal.open_with_callback(
                desc.required_features,
                &desc.required_limits,
                &desc.memory_hints,
                Some(add_order),
            )
        }
        .map_err(|e| failed(e.to_string()))?
    };
    // SAFETY: the device was opened on this adapter with `desc`'s features and limits.
    unsafe { adapter.create_device_from_hal(opened, desc) }.map_err(|e| failed(e.to_string()))
}

/// What the order test's pass left.
#[derive(Clone, Debug)]
pub struct Fold {
    /// The fold's final value per pixel, row by row.
    pub values: Vec<u32>,
    /// Fragments per draw, added up in a wgpu storage buffer by the fragments.
    pub reached: Vec<u32>,
    /// The GPU time of the pass and its readback copy (one submission).
    pub time: Duration,
}

/// The order test on `gpu` (from [`open`]): `draws` triangles over a `width` x `height` target,
/// each fragment folding one step into its pixel ([`fold_step`]) and counting itself into its
/// draw's word of a wgpu buffer.
pub fn fold(
    gpu: &Gpu,
    width: u32,
    height: u32,
    draws: u32,
    order: Order,
) -> Result<Fold, GpuError> {
    if draws == 0 {
        return Err(GpuError::Device("the order test needs a draw".into()));
    }
    let mut pass = fold_pass(gpu, order, true)?;
    let reached = gpu.buffer_from("fragments per draw", &vec![0; draws as usize])?;
    let time = pass.draw(gpu, (width, height), 3, draws, &[("reached", &reached)])?;
    Ok(Fold {
        values: words(&pass.state_bytes(0)?),
        reached: gpu.read(&reached, draws as usize)?,
        time,
    })
}

/// The order test's pass, its state copied out where `readback`.
fn fold_pass(gpu: &Gpu, order: Order, readback: bool) -> Result<RasterPass, GpuError> {
    RasterPass::new(
        gpu,
        &RasterPassDesc {
            source: include_str!("shaders/pixel_fold.wgsl"),
            vertex: "cover",
            fragment: "fold",
            states: &[wgpu::TextureFormat::R32Uint],
            constants: &[],
            strips: false,
            order,
            helper_flag: false,
            readback,
        },
    )
}

fn words(bytes: &[u8]) -> Vec<u32> {
    let word = |b: &[u8]| u32::from_le_bytes(b.try_into().expect("four bytes"));
    bytes.chunks_exact(4).map(word).collect()
}

/// Pixels each draw reaches: what [`Fold::reached`] must hold.
pub fn reached_by_draw(width: u32, height: u32, draws: u32) -> Vec<u32> {
    let reached = |d: u32| {
        (0..width * height)
            .filter(|i| covers(i % width, i / width, d))
            .count()
    };
    (0..draws).map(|d| reached(d) as u32).collect()
}

/// What [`fold`] must leave in each pixel: the fold over the draws that reach the pixel, in
/// draw order, from zero.
pub fn fold_in_order(width: u32, height: u32, draws: u32) -> Vec<u32> {
    let pixel = |i: u32| {
        let (x, y) = (i % width, i / width);
        (0..draws).filter(|&d| covers(x, y, d)).fold(0, fold_step)
    };
    (0..width * height).map(pixel).collect()
}

/// One fragment's step: not commutative (two draws swapped or one lost change the value), as in
/// `shaders/pixel_fold.wgsl`.
pub fn fold_step(previous: u32, draw: u32) -> u32 {
    previous.wrapping_mul(0x0100_0193).wrapping_add(draw + 1)
}

/// Whether `draw` reaches pixel (x, y), as `covers` in `shaders/pixel_fold.wgsl`.
pub fn covers(x: u32, y: u32, draw: u32) -> bool {
    let mut h =
        x.wrapping_mul(0x9e37_79b1) ^ y.wrapping_mul(0x85eb_ca77) ^ draw.wrapping_mul(0xc2b2_ae3d);
    h = (h ^ (h >> 15)).wrapping_mul(0x2c1b_3c6d);
    h ^= h >> 12;
    (h >> 7) & 1 == 1
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every pixel holds the fold of its fragments in draw order: each fragment read what the
    /// one before it wrote. Any two fragments of a pixel run out of order, or a write lost to a
    /// read that came before it, change the pixel's value. And the fragments' adds into a wgpu
    /// buffer reach wgpu's own readback.
    #[test]
    fn each_fragment_reads_what_the_one_before_it_wrote() {
        let Some(gpu) = open_or_skip() else { return };
        for (width, height, draws) in [(1, 1, 1), (64, 48, 96), (100, 37, 300)] {
            let got = fold(&gpu, width, height, draws, Order::Rasterization).unwrap();
            let want = fold_in_order(width, height, draws);
            let wrong = got.values.iter().zip(&want).filter(|(g, w)| g != w).count();
            let pixels = want.len();
            assert_eq!(
                wrong, 0,
                "{wrong} of {pixels} pixels ({width}x{height}, {draws} draws)"
            );
            // Every fragment added to its draw's word of the wgpu buffer, once.
            assert_eq!(got.reached, reached_by_draw(width, height, draws));
        }
    }

    /// A pass drawn on another's images (as the hardware backward draws on the forward's)
    /// runs its fragments there and leaves the other's copy of its states as it was; it holds
    /// no images and copies nothing out.
    #[test]
    fn a_pass_drawn_on_anothers_images_leaves_its_copy() {
        let Some(gpu) = open_or_skip() else { return };
        let (width, height, draws) = (40, 24, 60);
        let mut first = fold_pass(&gpu, Order::Rasterization, true).unwrap();
        let mut second = fold_pass(&gpu, Order::Rasterization, false).unwrap();
        let reached = gpu
            .buffer_from("fragments", &vec![0; draws as usize])
            .unwrap();
        let bound = [("reached", &reached)];
        first.draw(&gpu, (width, height), 3, draws, &bound).unwrap();
        let copy = first.state_bytes(0).unwrap();
        assert_eq!(words(&copy), fold_in_order(width, height, draws));
        second.draw_on(&gpu, &first, 3, draws / 2, &bound).unwrap();
        assert_eq!(first.state_bytes(0).unwrap(), copy);
        // The second pass's fragments ran: its draws counted twice.
        let mut want = reached_by_draw(width, height, draws);
        want.iter_mut()
            .take(draws as usize / 2)
            .for_each(|r| *r *= 2);
        assert_eq!(gpu.read(&reached, draws as usize).unwrap(), want);
        assert_eq!(second.memory_bytes(), 0);
        assert!(second.state_bytes(0).is_err());
    }

    /// The fold tells orders apart: the same fragments in reverse order, or with one lost, end
    /// differently at every pixel where it could.
    #[test]
    fn the_fold_depends_on_the_order_of_every_two_fragments() {
        let (width, height, draws) = (32, 32, 40);
        let in_order = fold_in_order(width, height, draws);
        for i in 0..width * height {
            let (x, y) = (i % width, i / width);
            let reached: Vec<u32> = (0..draws).filter(|&d| covers(x, y, d)).collect();
            let reversed = reached.iter().rev().fold(0, |v, &d| fold_step(v, d));
            let one_lost = reached.iter().skip(1).fold(0, |v, &d| fold_step(v, d));
            let palindrome = reached.iter().eq(reached.iter().rev());
            assert!(palindrome || reversed != in_order[i as usize], "pixel {i}");
            assert!(
                reached.is_empty() || one_lost != in_order[i as usize],
                "pixel {i}"
            );
        }
        // About half of the draws reach each pixel.
        let fragments = (0..width * height)
            .map(|i| {
                (0..draws)
                    .filter(|&d| covers(i % width, i / width, d))
                    .count()
            })
            .sum::<usize>();
        let share = fragments as f64 / (width * height * draws) as f64;
        assert!((0.4..0.6).contains(&share), "{share}");
    }

    /// The rewritten fragment shader reads a subpass input: the texture type, the load, the
    /// capability and the decoration are what Vulkan needs, and nothing else changed.
    #[test]
    fn the_texture_load_becomes_a_subpass_input_read() {
        let module = spirv::Module::parse(include_str!("shaders/pixel_fold.wgsl")).unwrap();
        let fragment = module
            .entry_point("fold", naga::ShaderStage::Fragment, &[])
            .unwrap();
        let patched = spirv::textures_as_input_attachments(&fragment).unwrap();
        let ops = |words: &[u32]| spirv::split(&words[5..]).unwrap().len();
        let find = |op: ::spirv::Op| -> Vec<Vec<u32>> {
            let body = spirv::split(&patched[5..]).unwrap();
            body.into_iter()
                .filter(|i| i[0] & 0xffff == op as u32)
                .map(<[u32]>::to_vec)
                .collect()
        };
        assert_eq!(find(::spirv::Op::ImageFetch).len(), 0);
        assert_eq!(find(::spirv::Op::ImageRead).len(), 1);
        let image = &find(::spirv::Op::TypeImage)[0];
        assert_eq!(image[3], ::spirv::Dim::DimSubpassData as u32);
        assert_eq!(image[7], 2);
        assert!(
            find(::spirv::Op::Capability)
                .iter()
                .any(|c| c[1] == ::spirv::Capability::InputAttachment as u32)
        );
        assert!(
            find(::spirv::Op::Decorate)
                .iter()
                .any(|d| d[2] == ::spirv::Decoration::InputAttachmentIndex as u32)
        );
        // Two instructions more (capability, decoration), one word less (the load's level).
        assert_eq!(ops(&patched), ops(&fragment) + 2);
        assert_eq!(patched.len(), fragment.len() + 2 + 4 - 2);
    }

    /// A shader the rewrite does not fit (no texture, or a texture used otherwise than by a
    /// load) is refused with the reason.
    #[test]
    fn front_facing_becomes_helper_invocation_and_nothing_else_changes() {
        let source =
            "@fragment fn f(@builtin(front_facing) helper: bool) -> @location(0) vec4<f32> {
            return select(vec4<f32>(1.0), vec4<f32>(0.0), helper);
        }";
        let module = spirv::Module::parse(source).unwrap();
        let fragment = module
            .entry_point("f", naga::ShaderStage::Fragment, &[])
            .unwrap();
        let patched = spirv::front_facing_as_helper(&fragment).unwrap();
        let builtins = |words: &[u32]| -> Vec<u32> {
            (spirv::split(&words[5..]).unwrap().into_iter())
                .filter(|i| i[0] & 0xffff == ::spirv::Op::Decorate as u32)
                .filter(|i| i[2] == ::spirv::Decoration::BuiltIn as u32)
                .map(|i| i[3])
                .collect()
        };
        let (front, helper) = (
            ::spirv::BuiltIn::FrontFacing as u32,
            ::spirv::BuiltIn::HelperInvocation as u32,
        );
        assert!(builtins(&fragment).contains(&front));
        assert!(!builtins(&patched).contains(&front));
        assert!(builtins(&patched).contains(&helper));
        // One word differs: the decoration's built-in.
        assert_eq!(patched.len(), fragment.len());
        let differ = patched
            .iter()
            .zip(&fragment)
            .filter(|(a, b)| a != b)
            .count();
        assert_eq!(differ, 1);
        let no_input = "@fragment fn f() -> @location(0) vec4<f32> { return vec4<f32>(1.0); }";
        let module = spirv::Module::parse(no_input).unwrap();
        let words = module
            .entry_point("f", naga::ShaderStage::Fragment, &[])
            .unwrap();
        assert!(spirv::front_facing_as_helper(&words).is_err());
    }

    #[test]
    fn a_shader_the_rewrite_does_not_fit_is_refused() {
        let no_texture = "@fragment fn f() -> @location(0) vec4<f32> { return vec4<f32>(1.0); }";
        let sized = "@group(0) @binding(0) var t: texture_2d<u32>;
            @fragment fn f() -> @location(0) vec4<u32> {
                return textureLoad(t, vec2<i32>(0, 0), 0) + textureDimensions(t).x;
            }";
        for (source, why) in [(no_texture, "no image types"), (sized, "other than a load")] {
            let module = spirv::Module::parse(source).unwrap();
            let words = module
                .entry_point("f", naga::ShaderStage::Fragment, &[])
                .unwrap();
            let e = spirv::textures_as_input_attachments(&words)
                .unwrap_err()
                .to_string();
            assert!(e.contains(why), "{e}");
        }
        let e =
            spirv::textures_as_input_attachments(&[0x0723_0203, 0x10000, 0, 10, 0, 0x0005_0011])
                .unwrap_err()
                .to_string();
        assert!(e.contains("truncated"), "{e}");
    }
}
