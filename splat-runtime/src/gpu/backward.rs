//! The backward pass on the GPU: the backward blend per tile (gradients of each primitive's
//! shade words and depth, summed with global atomics, after a workgroup reduction by
//! default), then `project`'s adjoint per primitive with the camera's gradient summed per
//! workgroup. Gradient buffers are cleared explicitly (no reliance on zeroed memory).

use super::device::dispatch;
use super::entries::{self, Accumulation, Layout, Reduction};
use super::render::{GpuForwardState, GpuRenderError, frame_uniform};
use super::{Gpu, GpuError};
use crate::flat::Flat;
use crate::method::SplatMethod;
use crate::pipeline::{BackwardStats, FrameGrad, Gradients, RenderError};
use crate::types::Camera;
use std::time::Instant;

/// Gradients, plus the number of global atomic adds the backward blend issued.
pub struct GpuGradients<M: SplatMethod> {
    pub gradients: Gradients<M>,
    pub atomics: u64,
}

/// Gradients of the parameters and the camera, given the gradient of each output of the
/// frame `state` was kept from. `acc` chooses the reduction and the kind of atomics
/// (default: [`Accumulation::default_for`]).
pub fn backward<M: SplatMethod>(
    gpu: &Gpu,
    state: &GpuForwardState<M>,
    grad: &FrameGrad,
    acc: Accumulation,
) -> Result<GpuGradients<M>, GpuRenderError> {
    let grid = &state.grid;
    let layout = Layout::of::<M>();
    let (channels, pixels) = (layout.channels, (grid.width * grid.height) as usize);
    let sizes = [
        ("color", Some(grad.color.len()), pixels * channels),
        ("alpha", grad.alpha.as_ref().map(Vec::len), pixels),
        ("depth", grad.depth.as_ref().map(Vec::len), pixels),
    ];
    for (what, got, want) in sizes {
        if let Some(got) = got.filter(|g| *g != want) {
            return Err(RenderError::GradientSize { what, got, want }.into());
        }
    }
    if acc.float_atomics && !gpu.float_atomics {
        return Err(GpuError::Shader("this adapter has no f32 atomics".into()).into());
    }
    if acc.reduce == Reduction::Subgroup && !gpu.subgroups {
        return Err(GpuError::Shader("this adapter has no subgroup operations".into()).into());
    }
    let n = state.primitives;
    let n32 = n as u32;
    let tiles = grid.tile_count() as u32;
    let want_depth = grad.depth.is_some();

    // The backward blend.
    let t0 = Instant::now();
    let mut pixel_grad = vec![0u32; pixels * (channels + 2)];
    for (p, out) in pixel_grad.chunks_exact_mut(channels + 2).enumerate() {
        let color = &grad.color[p * channels..(p + 1) * channels];
        for (o, c) in out.iter_mut().zip(color) {
            *o = c.to_bits();
        }
        out[channels] = grad.alpha.as_ref().map_or(0.0, |a| a[p]).to_bits();
        out[channels + 1] = grad.depth.as_ref().map_or(0.0, |d| d[p]).to_bits();
    }
    let pixel_grad = gpu.buffer_from("pixel gradients", &pixel_grad)?;
    let grads = gpu.buffer("primitive gradients", n * layout.grad_words)?;
    let issued = gpu.buffer("atomic count", 2)?;
    let frame = frame_uniform(gpu, n32, grid, state.p_max);
    let source = entries::backward::<M>(gpu, grid.size, want_depth, acc)?;
    let blend = gpu.pipeline(&source, "backward_tiles")?;
    let mut inputs = vec![
        &state.projected,
        &state.prims,
        &state.ranges,
        &state.order,
        &frame,
        &state.pixels,
        &pixel_grad,
        &grads,
        &issued,
    ];
    // With `pixel_info`: the cotangent of each pixel's data, for the camera's ray gradient.
    let npx = M::PixelLanes::default().as_ref().len();
    let pixel_cotangent = if M::HAS_PIXEL_INFO {
        Some(gpu.buffer("pixel data cotangents", pixels * npx)?)
    } else {
        None
    };
    if let Some(pc) = &pixel_cotangent {
        inputs.push(&state.camera);
        inputs.push(pc);
    }
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    enc.clear_buffer(&grads, 0, None);
    enc.clear_buffer(&issued, 0, None);
    dispatch(&mut enc, &blend, &gpu.bind(&blend, &inputs), tiles);
    gpu.finish(enc)?;
    let count = gpu.read(&issued, 2)?;
    let atomics = count[0] as u64 | (count[1] as u64) << 32;
    let blend_time = t0.elapsed();

    // project's adjoint.
    let t1 = Instant::now();
    let (source, npf) = entries::project_backward::<M>()?;
    let project = gpu.pipeline(&source, "project_backward")?;
    let groups = n32.div_ceil(64).max(1);
    let param_grads = gpu.buffer("parameter gradients", n * npf)?;
    let partials = gpu.buffer(
        "camera gradient partials",
        groups as usize * Camera::FLOAT_SLOTS,
    )?;
    let info = gpu.uniform(&[n32]);
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    let bind = gpu.bind(
        &project,
        &[
            &state.params,
            &state.camera,
            &state.projected,
            &grads,
            &param_grads,
            &partials,
            &info,
        ],
    );
    dispatch(&mut enc, &project, &bind, groups);
    gpu.finish(enc)?;
    let words = gpu.read(&param_grads, n * npf)?;
    let floats: Vec<f32> = words.into_iter().map(f32::from_bits).collect();
    let params = floats
        .chunks_exact(npf.max(1))
        .take(n)
        .map(M::params_from_float_slots)
        .collect();
    let mut partials = gpu.read(&partials, groups as usize * Camera::FLOAT_SLOTS)?;
    if let Some(pc) = &pixel_cotangent {
        partials.extend(pixel_backward::<M>(gpu, state, pc)?);
    }
    // The model word (last) stays zero: a cotangent has no model.
    let mut cam = vec![0.0f64; Camera::LEN];
    for group in partials.chunks_exact(Camera::FLOAT_SLOTS) {
        for (c, w) in cam.iter_mut().zip(group) {
            *c += f32::from_bits(*w) as f64;
        }
    }
    let cam: Vec<f32> = cam.into_iter().map(|c| c as f32).collect();
    let stats = BackwardStats {
        blend: blend_time,
        reduce: Default::default(),
        project: t1.elapsed(),
    };
    Ok(GpuGradients {
        gradients: Gradients {
            params,
            camera: Camera::read_words(&cam),
            stats,
        },
        atomics,
    })
}

impl Accumulation {
    /// Subgroup reduction where the adapter has subgroups (else workgroup reduction), with
    /// f32 atomics where it has them (else compare-exchange).
    pub fn default_for(gpu: &Gpu) -> Accumulation {
        Accumulation {
            reduce: if gpu.subgroups {
                Reduction::Subgroup
            } else {
                Reduction::Workgroup
            },
            float_atomics: gpu.float_atomics,
        }
    }
}

/// `pixel_info`'s adjoint over every pixel: the camera gradient's partial sums through the
/// rays (one per workgroup of 64 pixels).
fn pixel_backward<M: SplatMethod>(
    gpu: &Gpu,
    state: &GpuForwardState<M>,
    pixel_cotangent: &wgpu::Buffer,
) -> Result<Vec<u32>, GpuRenderError> {
    let grid = &state.grid;
    let pixels = grid.width * grid.height;
    let pipeline = gpu.pipeline(&entries::pixel_backward::<M>()?, "pixel_backward")?;
    let groups = pixels.div_ceil(64).max(1);
    let partials = gpu.buffer(
        "camera ray gradient partials",
        groups as usize * Camera::FLOAT_SLOTS,
    )?;
    let info = gpu.uniform(&[grid.width, grid.height]);
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    let bind = gpu.bind(
        &pipeline,
        &[&state.camera, pixel_cotangent, &partials, &info],
    );
    dispatch(&mut enc, &pipeline, &bind, groups);
    gpu.finish(enc)?;
    Ok(gpu.read(&partials, groups as usize * Camera::FLOAT_SLOTS)?)
}
