//! The order test's pass in raw Vulkan, on wgpu's device and inside a wgpu command encoder:
//! a render pass whose one subpass reads and writes the same `R32Uint` attachment (as input
//! and color attachment, layout `GENERAL`), and a pipeline drawing `draws` instances of a
//! triangle over it. With [`Order::Rasterization`] both carry the flags of
//! `VK_EXT_rasterization_order_attachment_access`, which make each fragment's read see the
//! writes of every fragment before it in rasterization order; without them (the control) a
//! read of what the same subpass writes is undefined. Each fragment also adds to a wgpu
//! storage buffer, bound by its raw handle, with barriers of our own on either side of the
//! pass (wgpu's tracking does not see it).

use super::{Fold, Order, spirv};
use crate::{Gpu, GpuError};
use ash::vk;
use std::time::Instant;
use wgpu::hal::api::Vulkan;

const SOURCE: &str = include_str!("../shaders/pixel_fold.wgsl");
const FORMAT: vk::Format = vk::Format::R32_UINT;

/// Every Vulkan object of the pass, destroyed on drop (null handles are skipped by Vulkan).
#[derive(Default)]
struct Objects {
    device: Option<ash::Device>,
    image: vk::Image,
    image_memory: vk::DeviceMemory,
    view: vk::ImageView,
    render_pass: vk::RenderPass,
    framebuffer: vk::Framebuffer,
    set_layout: vk::DescriptorSetLayout,
    descriptor_pool: vk::DescriptorPool,
    pipeline_layout: vk::PipelineLayout,
    shaders: Vec<vk::ShaderModule>,
    pipeline: vk::Pipeline,
    readback: vk::Buffer,
    readback_memory: vk::DeviceMemory,
}

impl Drop for Objects {
    fn drop(&mut self) {
        let Some(d) = &self.device else { return };
        // SAFETY: the pass's one submission has finished (`run` waits for it or fails before
        // submitting), and each handle was made by `d` or is null.
        unsafe {
            d.destroy_pipeline(self.pipeline, None);
            for &s in &self.shaders {
                d.destroy_shader_module(s, None);
            }
            d.destroy_pipeline_layout(self.pipeline_layout, None);
            d.destroy_descriptor_pool(self.descriptor_pool, None);
            d.destroy_descriptor_set_layout(self.set_layout, None);
            d.destroy_framebuffer(self.framebuffer, None);
            d.destroy_render_pass(self.render_pass, None);
            d.destroy_image_view(self.view, None);
            d.destroy_image(self.image, None);
            d.free_memory(self.image_memory, None);
            d.destroy_buffer(self.readback, None);
            d.free_memory(self.readback_memory, None);
        }
    }
}

fn vulkan(what: &'static str) -> impl Fn(vk::Result) -> GpuError {
    move |e| GpuError::Device(format!("{what}: {e}"))
}

/// The order test's pass (see [`super::fold`]).
pub(super) fn run(
    gpu: &Gpu,
    width: u32,
    height: u32,
    draws: u32,
    order: Order,
) -> Result<Fold, GpuError> {
    let reached = gpu.buffer_from("fragments per draw", &vec![0; draws as usize])?;
    let (device, memory_types, reached_raw) = {
        // SAFETY: the handles are used only while `gpu` lives, and none is destroyed here.
        let hal = unsafe { gpu.device.as_hal::<Vulkan>() }
            .ok_or_else(|| GpuError::Device("programmable blending needs Vulkan".into()))?;
        if !hal.enabled_device_extensions().contains(&super::EXTENSION) {
            return Err(GpuError::Device(
                "the device was not opened with rasterization-order attachment access: open it with programmable_blend::open".into(),
            ));
        }
        let instance = hal.shared_instance().raw_instance();
        // SAFETY: the physical device is the one the device was opened on.
        let memory =
            unsafe { instance.get_physical_device_memory_properties(hal.raw_physical_device()) };
        // SAFETY: `reached` outlives the pass, which waits for its submission, and is not
        // destroyed through its handle.
        let reached_raw = unsafe { reached.as_hal::<Vulkan>().map(|b| b.raw_handle()) }
            .ok_or_else(|| GpuError::Device("a wgpu buffer that is not Vulkan's".into()))?;
        (hal.raw_device().clone(), memory, reached_raw)
    };
    let mut o = Objects::default();
    o.device = Some(device.clone());
    let d = &device;
    let extent = vk::Extent2D { width, height };
    let (subpass_flags, blend_flags) = match order {
        Order::Rasterization => (
            vk::SubpassDescriptionFlags::RASTERIZATION_ORDER_ATTACHMENT_COLOR_ACCESS_EXT,
            vk::PipelineColorBlendStateCreateFlags::RASTERIZATION_ORDER_ATTACHMENT_ACCESS_EXT,
        ),
        Order::Unspecified => Default::default(),
    };

    // SAFETY (the whole block): every create info is complete and valid for the device, each
    // object is destroyed once by `o` after the submission that uses it has finished.
    unsafe {
        o.image = d
            .create_image(
                &vk::ImageCreateInfo::default()
                    .image_type(vk::ImageType::TYPE_2D)
                    .format(FORMAT)
                    .extent(extent.into())
                    .mip_levels(1)
                    .array_layers(1)
                    .samples(vk::SampleCountFlags::TYPE_1)
                    .tiling(vk::ImageTiling::OPTIMAL)
                    .usage(
                        vk::ImageUsageFlags::COLOR_ATTACHMENT
                            | vk::ImageUsageFlags::INPUT_ATTACHMENT
                            | vk::ImageUsageFlags::TRANSFER_SRC,
                    ),
                None,
            )
            .map_err(vulkan("the state image"))?;
        let needs = d.get_image_memory_requirements(o.image);
        o.image_memory = allocate(
            d,
            &memory_types,
            needs,
            vk::MemoryPropertyFlags::DEVICE_LOCAL,
        )?;
        d.bind_image_memory(o.image, o.image_memory, 0)
            .map_err(vulkan("binding the state image"))?;
        let color = vk::ImageSubresourceRange::default()
            .aspect_mask(vk::ImageAspectFlags::COLOR)
            .level_count(1)
            .layer_count(1);
        o.view = d
            .create_image_view(
                &vk::ImageViewCreateInfo::default()
                    .image(o.image)
                    .view_type(vk::ImageViewType::TYPE_2D)
                    .format(FORMAT)
                    .subresource_range(color),
                None,
            )
            .map_err(vulkan("the state view"))?;

        let attachment = [vk::AttachmentDescription::default()
            .format(FORMAT)
            .samples(vk::SampleCountFlags::TYPE_1)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(vk::AttachmentStoreOp::STORE)
            .initial_layout(vk::ImageLayout::UNDEFINED)
            .final_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL)];
        // Read and written in one subpass: a feedback loop, in the GENERAL layout.
        let state = [vk::AttachmentReference {
            attachment: 0,
            layout: vk::ImageLayout::GENERAL,
        }];
        let subpass = [vk::SubpassDescription::default()
            .flags(subpass_flags)
            .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
            .input_attachments(&state)
            .color_attachments(&state)];
        let to_copy = [vk::SubpassDependency::default()
            .src_subpass(0)
            .dst_subpass(vk::SUBPASS_EXTERNAL)
            .src_stage_mask(vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT)
            .dst_stage_mask(vk::PipelineStageFlags::TRANSFER)
            .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
            .dst_access_mask(vk::AccessFlags::TRANSFER_READ)];
        o.render_pass = d
            .create_render_pass(
                &vk::RenderPassCreateInfo::default()
                    .attachments(&attachment)
                    .subpasses(&subpass)
                    .dependencies(&to_copy),
                None,
            )
            .map_err(vulkan("the render pass"))?;
        o.framebuffer = d
            .create_framebuffer(
                &vk::FramebufferCreateInfo::default()
                    .render_pass(o.render_pass)
                    .attachments(&[o.view])
                    .width(width)
                    .height(height)
                    .layers(1),
                None,
            )
            .map_err(vulkan("the framebuffer"))?;

        let binding = [
            vk::DescriptorSetLayoutBinding::default()
                .binding(0)
                .descriptor_type(vk::DescriptorType::INPUT_ATTACHMENT)
                .descriptor_count(1)
                .stage_flags(vk::ShaderStageFlags::FRAGMENT),
            vk::DescriptorSetLayoutBinding::default()
                .binding(1)
                .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                .descriptor_count(1)
                .stage_flags(vk::ShaderStageFlags::FRAGMENT),
        ];
        o.set_layout = d
            .create_descriptor_set_layout(
                &vk::DescriptorSetLayoutCreateInfo::default().bindings(&binding),
                None,
            )
            .map_err(vulkan("the descriptor set layout"))?;
        let sizes = [
            vk::DescriptorPoolSize {
                ty: vk::DescriptorType::INPUT_ATTACHMENT,
                descriptor_count: 1,
            },
            vk::DescriptorPoolSize {
                ty: vk::DescriptorType::STORAGE_BUFFER,
                descriptor_count: 1,
            },
        ];
        o.descriptor_pool = d
            .create_descriptor_pool(
                &vk::DescriptorPoolCreateInfo::default()
                    .max_sets(1)
                    .pool_sizes(&sizes),
                None,
            )
            .map_err(vulkan("the descriptor pool"))?;
        let set = d
            .allocate_descriptor_sets(
                &vk::DescriptorSetAllocateInfo::default()
                    .descriptor_pool(o.descriptor_pool)
                    .set_layouts(&[o.set_layout]),
            )
            .map_err(vulkan("the descriptor set"))?[0];
        let image_info = [vk::DescriptorImageInfo {
            sampler: vk::Sampler::null(),
            image_view: o.view,
            image_layout: vk::ImageLayout::GENERAL,
        }];
        let buffer_info = [vk::DescriptorBufferInfo {
            buffer: reached_raw,
            offset: 0,
            range: vk::WHOLE_SIZE,
        }];
        d.update_descriptor_sets(
            &[
                vk::WriteDescriptorSet::default()
                    .dst_set(set)
                    .dst_binding(0)
                    .descriptor_type(vk::DescriptorType::INPUT_ATTACHMENT)
                    .image_info(&image_info),
                vk::WriteDescriptorSet::default()
                    .dst_set(set)
                    .dst_binding(1)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .buffer_info(&buffer_info),
            ],
            &[],
        );
        o.pipeline_layout = d
            .create_pipeline_layout(
                &vk::PipelineLayoutCreateInfo::default().set_layouts(&[o.set_layout]),
                None,
            )
            .map_err(vulkan("the pipeline layout"))?;

        let vertex = spirv::entry_point(SOURCE, "cover", naga::ShaderStage::Vertex)?;
        let fragment = spirv::texture_as_input_attachment(&spirv::entry_point(
            SOURCE,
            "fold",
            naga::ShaderStage::Fragment,
        )?)?;
        for words in [&vertex, &fragment] {
            let module = d
                .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(words), None)
                .map_err(vulkan("a shader module"))?;
            o.shaders.push(module);
        }
        let stages = [
            vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::VERTEX)
                .module(o.shaders[0])
                .name(c"cover"),
            vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::FRAGMENT)
                .module(o.shaders[1])
                .name(c"fold"),
        ];
        let viewport = [vk::Viewport {
            x: 0.0,
            y: 0.0,
            width: width as f32,
            height: height as f32,
            min_depth: 0.0,
            max_depth: 1.0,
        }];
        let scissor = [vk::Rect2D {
            offset: vk::Offset2D::default(),
            extent,
        }];
        let write_red = [vk::PipelineColorBlendAttachmentState::default()
            .color_write_mask(vk::ColorComponentFlags::R)];
        let no_vertices = vk::PipelineVertexInputStateCreateInfo::default();
        let triangles = vk::PipelineInputAssemblyStateCreateInfo::default()
            .topology(vk::PrimitiveTopology::TRIANGLE_LIST);
        let viewport_state = vk::PipelineViewportStateCreateInfo::default()
            .viewports(&viewport)
            .scissors(&scissor);
        let fill = vk::PipelineRasterizationStateCreateInfo::default()
            .polygon_mode(vk::PolygonMode::FILL)
            .cull_mode(vk::CullModeFlags::NONE)
            .line_width(1.0);
        let one_sample = vk::PipelineMultisampleStateCreateInfo::default()
            .rasterization_samples(vk::SampleCountFlags::TYPE_1);
        let blend = vk::PipelineColorBlendStateCreateInfo::default()
            .flags(blend_flags)
            .attachments(&write_red);
        let pipeline = vk::GraphicsPipelineCreateInfo::default()
            .stages(&stages)
            .vertex_input_state(&no_vertices)
            .input_assembly_state(&triangles)
            .viewport_state(&viewport_state)
            .rasterization_state(&fill)
            .multisample_state(&one_sample)
            .color_blend_state(&blend)
            .layout(o.pipeline_layout)
            .render_pass(o.render_pass)
            .subpass(0);
        o.pipeline = d
            .create_graphics_pipelines(vk::PipelineCache::null(), &[pipeline], None)
            .map_err(|(_, e)| vulkan("the pipeline")(e))?[0];

        let bytes = 4 * width as u64 * height as u64;
        o.readback = d
            .create_buffer(
                &vk::BufferCreateInfo::default()
                    .size(bytes)
                    .usage(vk::BufferUsageFlags::TRANSFER_DST),
                None,
            )
            .map_err(vulkan("the readback buffer"))?;
        let needs = d.get_buffer_memory_requirements(o.readback);
        let host = vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT;
        o.readback_memory = allocate(d, &memory_types, needs, host)?;
        d.bind_buffer_memory(o.readback, o.readback_memory, 0)
            .map_err(vulkan("binding the readback buffer"))?;

        // Recorded into wgpu's own command buffer and submitted on its queue, where wgpu's
        // passes before and after it would be ordered with it.
        let mut encoder = gpu.device.create_command_encoder(&Default::default());
        let recorded = encoder.as_hal_mut::<Vulkan, _, _>(|encoder| {
            let Some(encoder) = encoder else { return false };
            let cb = encoder.raw_handle();
            // wgpu's writes of the buffer (its zeros) before the fragments' adds.
            let from_wgpu = [vk::MemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::MEMORY_WRITE)
                .dst_access_mask(vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE)];
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::PipelineStageFlags::FRAGMENT_SHADER,
                vk::DependencyFlags::empty(),
                &from_wgpu,
                &[],
                &[],
            );
            let clear = [vk::ClearValue {
                color: vk::ClearColorValue { uint32: [0; 4] },
            }];
            d.cmd_begin_render_pass(
                cb,
                &vk::RenderPassBeginInfo::default()
                    .render_pass(o.render_pass)
                    .framebuffer(o.framebuffer)
                    .render_area(scissor[0])
                    .clear_values(&clear),
                vk::SubpassContents::INLINE,
            );
            d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::GRAPHICS, o.pipeline);
            d.cmd_bind_descriptor_sets(
                cb,
                vk::PipelineBindPoint::GRAPHICS,
                o.pipeline_layout,
                0,
                &[set],
                &[],
            );
            d.cmd_draw(cb, 3, draws, 0, 0);
            d.cmd_end_render_pass(cb);
            let layer = vk::ImageSubresourceLayers::default()
                .aspect_mask(vk::ImageAspectFlags::COLOR)
                .layer_count(1);
            d.cmd_copy_image_to_buffer(
                cb,
                o.image,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                o.readback,
                &[vk::BufferImageCopy::default()
                    .image_subresource(layer)
                    .image_extent(extent.into())],
            );
            // The copy's writes to the host; the fragments' adds to whatever wgpu does next.
            let after = [vk::MemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::TRANSFER_WRITE | vk::AccessFlags::SHADER_WRITE)
                .dst_access_mask(
                    vk::AccessFlags::HOST_READ
                        | vk::AccessFlags::MEMORY_READ
                        | vk::AccessFlags::MEMORY_WRITE,
                )];
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::TRANSFER | vk::PipelineStageFlags::FRAGMENT_SHADER,
                vk::PipelineStageFlags::HOST | vk::PipelineStageFlags::ALL_COMMANDS,
                vk::DependencyFlags::empty(),
                &after,
                &[],
                &[],
            );
            true
        });
        if !recorded {
            return Err(GpuError::Device(
                "wgpu lent no Vulkan command buffer".into(),
            ));
        }
        let start = Instant::now();
        gpu.queue.submit([encoder.finish()]);
        gpu.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        let time = start.elapsed();

        let mapped = d
            .map_memory(o.readback_memory, 0, bytes, vk::MemoryMapFlags::empty())
            .map_err(vulkan("mapping the readback buffer"))?;
        let values =
            std::slice::from_raw_parts(mapped as *const u32, (width * height) as usize).to_vec();
        d.unmap_memory(o.readback_memory);
        let reached = gpu.read(&reached, draws as usize)?;
        Ok(Fold {
            values,
            reached,
            time,
        })
    }
}

/// Memory for `needs` of a type with `flags` (any type it may use if none has them).
fn allocate(
    d: &ash::Device,
    types: &vk::PhysicalDeviceMemoryProperties,
    needs: vk::MemoryRequirements,
    flags: vk::MemoryPropertyFlags,
) -> Result<vk::DeviceMemory, GpuError> {
    let usable = |i: &u32| needs.memory_type_bits & (1 << i) != 0;
    let has = |i: &u32| {
        types.memory_types[*i as usize]
            .property_flags
            .contains(flags)
    };
    let count = types.memory_type_count;
    let index = (0..count).filter(usable).find(has);
    let index = match (index, flags.contains(vk::MemoryPropertyFlags::HOST_VISIBLE)) {
        (Some(i), _) => i,
        // Host-visible memory cannot be done without; device-local can.
        (None, true) => {
            return Err(GpuError::Device(
                "no host-visible memory for readback".into(),
            ));
        }
        (None, false) => (0..count)
            .find(usable)
            .ok_or_else(|| GpuError::Device("no memory type".into()))?,
    };
    // SAFETY: a valid allocation of a type the resource may use.
    unsafe {
        d.allocate_memory(
            &vk::MemoryAllocateInfo::default()
                .allocation_size(needs.size)
                .memory_type_index(index),
            None,
        )
    }
    .map_err(vulkan("allocating memory"))
}
