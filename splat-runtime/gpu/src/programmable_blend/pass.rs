//! A render pass in raw Vulkan on wgpu's device whose fragment shader reads and writes its
//! pixel's state: each state image is both an input and a color attachment of the one
//! subpass (layout `GENERAL`). With [`Order::Rasterization`] the subpass and the pipeline carry
//! the flags of `VK_EXT_rasterization_order_attachment_access`, which make each fragment's
//! read see the writes of every fragment before it in rasterization order; without them (the
//! control) a read of what the same subpass writes is undefined.
//!
//! The shaders are WGSL (naga's SPIR-V, its textures rewritten into subpass inputs by
//! [`super::spirv`]); the other resources are wgpu buffers bound by name through their raw
//! handles. wgpu 30 refuses raw commands in an encoder that also holds its own, so each draw
//! records into an encoder of its own, submitted on wgpu's queue after what was submitted
//! before it, with barriers of its own on either side (wgpu's tracking does not see it).

use super::{Order, spirv};
use crate::{Gpu, GpuError};
use ash::vk;
use std::time::{Duration, Instant};
use wgpu::hal::api::Vulkan;

/// What a [`RasterPass`] draws with.
pub struct RasterPassDesc<'a> {
    /// WGSL holding both entry points; its textures are the state images, in binding order.
    pub source: &'a str,
    pub vertex: &'a str,
    pub fragment: &'a str,
    /// The state images' formats, one per texture of `source`.
    pub states: &'a [wgpu::TextureFormat],
    /// The `override` constants of the shaders.
    pub constants: &'a [(&'a str, f64)],
    /// Triangle strips (quads of four vertices) or lists.
    pub strips: bool,
    pub order: Order,
    /// Whether the fragment's `@builtin(front_facing)` reads whether it is a helper
    /// invocation instead ([`spirv::front_facing_as_helper`]).
    pub helper_flag: bool,
    /// Whether the states are copied out after each draw, for [`RasterPass::state_bytes`]
    /// (a host-visible buffer as large as the images).
    pub readback: bool,
}

/// A pass built once: its render pass, pipeline and descriptor set; the state images and
/// their readback are made for the size of the last draw.
pub struct RasterPass {
    device: ash::Device,
    memory_types: vk::PhysicalDeviceMemoryProperties,
    formats: Vec<wgpu::TextureFormat>,
    /// The buffers the shaders bind, by name: (name, binding, descriptor type).
    buffers: Vec<(String, u32, vk::DescriptorType)>,
    /// Where the state images are bound (their input attachments, in order).
    state_bindings: Vec<u32>,
    readback: bool,
    /// What else shapes the render pass: passes alike in these and `formats` may draw on each
    /// other's images ([`RasterPass::draw_on`]).
    order: Order,
    strips: bool,
    fixed: Fixed,
    targets: Option<Targets>,
}

/// The objects that do not depend on the image size.
#[derive(Default)]
struct Fixed {
    render_pass: vk::RenderPass,
    set_layout: vk::DescriptorSetLayout,
    descriptor_pool: vk::DescriptorPool,
    set: vk::DescriptorSet,
    pipeline_layout: vk::PipelineLayout,
    shaders: Vec<vk::ShaderModule>,
    pipeline: vk::Pipeline,
}

/// The state images of one size and the host-visible buffer they are copied into.
#[derive(Default)]
struct Targets {
    size: (u32, u32),
    images: Vec<vk::Image>,
    memories: Vec<vk::DeviceMemory>,
    views: Vec<vk::ImageView>,
    framebuffer: vk::Framebuffer,
    readback: vk::Buffer,
    readback_memory: vk::DeviceMemory,
    /// Where each state's texels lie in the readback buffer (none without one).
    ranges: Vec<(u64, u64)>,
    /// The device memory allocated for the images and the buffer.
    bytes: u64,
}

fn vulkan(what: &'static str) -> impl Fn(vk::Result) -> GpuError {
    move |e| GpuError::Device(format!("programmable blending: {what}: {e}"))
}

/// The Vulkan format of a state image.
fn vk_format(format: wgpu::TextureFormat) -> Result<vk::Format, GpuError> {
    use wgpu::TextureFormat as T;
    Ok(match format {
        T::Rgba32Float => vk::Format::R32G32B32A32_SFLOAT,
        T::Rgba16Float => vk::Format::R16G16B16A16_SFLOAT,
        T::Rgba16Unorm => vk::Format::R16G16B16A16_UNORM,
        T::Rgba8Unorm => vk::Format::R8G8B8A8_UNORM,
        T::R32Uint => vk::Format::R32_UINT,
        T::R8Uint => vk::Format::R8_UINT,
        other => {
            return Err(GpuError::Device(format!(
                "programmable blending: no state images of {other:?}"
            )));
        }
    })
}

impl RasterPass {
    /// The pass `desc` describes on `gpu` (a device from [`super::open`]).
    pub fn new(gpu: &Gpu, desc: &RasterPassDesc) -> Result<RasterPass, GpuError> {
        let (device, memory_types) = {
            // SAFETY: the handles are used only while `gpu` lives, and none is destroyed here.
            let hal = unsafe { gpu.device.as_hal::<Vulkan>() }
                .ok_or_else(|| GpuError::Device("programmable blending needs Vulkan".into()))?;
            if !hal.enabled_device_extensions().contains(&super::EXTENSION) {
                return Err(GpuError::Device(
                    "the device was not opened with rasterization-order attachment access: open it with programmable_blend::open".into(),
                ));
            }
            let instance = hal.shared_instance().raw_instance();
            let physical = hal.raw_physical_device();
            for &format in desc.states {
                // SAFETY: the physical device is the one the device was opened on.
                let features = unsafe {
                    instance.get_physical_device_format_properties(physical, vk_format(format)?)
                };
                if !features
                    .optimal_tiling_features
                    .contains(vk::FormatFeatureFlags::COLOR_ATTACHMENT)
                {
                    return Err(GpuError::Device(format!(
                        "this adapter cannot render into {format:?} state images"
                    )));
                }
            }
            // SAFETY: as above.
            let memory = unsafe { instance.get_physical_device_memory_properties(physical) };
            (hal.raw_device().clone(), memory)
        };
        let module = spirv::Module::parse(desc.source)?;
        let mut pass = RasterPass {
            device,
            memory_types,
            formats: desc.states.to_vec(),
            buffers: module.buffers(),
            state_bindings: module.textures(),
            readback: desc.readback,
            order: desc.order,
            strips: desc.strips,
            fixed: Fixed::default(),
            targets: None,
        };
        if pass.state_bindings.len() != desc.states.len() {
            return Err(GpuError::Shader(format!(
                "programmable blending: {} state images for {} textures",
                desc.states.len(),
                pass.state_bindings.len()
            )));
        }
        let vertex = module.entry_point(desc.vertex, naga::ShaderStage::Vertex, desc.constants)?;
        let mut fragment = spirv::textures_as_input_attachments(&module.entry_point(
            desc.fragment,
            naga::ShaderStage::Fragment,
            desc.constants,
        )?)?;
        if desc.helper_flag {
            fragment = spirv::front_facing_as_helper(&fragment)?;
        }
        pass.build(desc, &vertex, &fragment)?;
        Ok(pass)
    }

    fn build(
        &mut self,
        desc: &RasterPassDesc,
        vertex: &[u32],
        fragment: &[u32],
    ) -> Result<(), GpuError> {
        // SAFETY: every create info is complete and valid for the device; `Drop` destroys
        // each object once.
        unsafe {
            let d = &self.device;
            let f = &mut self.fixed;
            let (subpass_flags, blend_flags) = match desc.order {
                Order::Rasterization => (
                    vk::SubpassDescriptionFlags::RASTERIZATION_ORDER_ATTACHMENT_COLOR_ACCESS_EXT,
                    vk::PipelineColorBlendStateCreateFlags::RASTERIZATION_ORDER_ATTACHMENT_ACCESS_EXT,
                ),
                Order::Unspecified => Default::default(),
            };
            let attachments = self
                .formats
                .iter()
                .map(|&format| {
                    Ok(vk::AttachmentDescription::default()
                        .format(vk_format(format)?)
                        .samples(vk::SampleCountFlags::TYPE_1)
                        .load_op(vk::AttachmentLoadOp::CLEAR)
                        .store_op(vk::AttachmentStoreOp::STORE)
                        .initial_layout(vk::ImageLayout::UNDEFINED)
                        .final_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL))
                })
                .collect::<Result<Vec<_>, GpuError>>()?;
            // Read and written in one subpass: a feedback loop, in the GENERAL layout.
            let states: Vec<vk::AttachmentReference> = (0..attachments.len() as u32)
                .map(|attachment| vk::AttachmentReference {
                    attachment,
                    layout: vk::ImageLayout::GENERAL,
                })
                .collect();
            let subpass = [vk::SubpassDescription::default()
                .flags(subpass_flags)
                .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
                .input_attachments(&states)
                .color_attachments(&states)];
            let to_copy = [vk::SubpassDependency::default()
                .src_subpass(0)
                .dst_subpass(vk::SUBPASS_EXTERNAL)
                .src_stage_mask(vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT)
                .dst_stage_mask(vk::PipelineStageFlags::TRANSFER)
                .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                .dst_access_mask(vk::AccessFlags::TRANSFER_READ)];
            f.render_pass = d
                .create_render_pass(
                    &vk::RenderPassCreateInfo::default()
                        .attachments(&attachments)
                        .subpasses(&subpass)
                        .dependencies(&to_copy),
                    None,
                )
                .map_err(vulkan("the render pass"))?;

            let stages = vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT;
            let mut bindings: Vec<vk::DescriptorSetLayoutBinding> = self
                .buffers
                .iter()
                .map(|(_, binding, ty)| {
                    vk::DescriptorSetLayoutBinding::default()
                        .binding(*binding)
                        .descriptor_type(*ty)
                        .descriptor_count(1)
                        .stage_flags(stages)
                })
                .collect();
            for &binding in &self.state_bindings {
                bindings.push(
                    vk::DescriptorSetLayoutBinding::default()
                        .binding(binding)
                        .descriptor_type(vk::DescriptorType::INPUT_ATTACHMENT)
                        .descriptor_count(1)
                        .stage_flags(vk::ShaderStageFlags::FRAGMENT),
                );
            }
            f.set_layout = d
                .create_descriptor_set_layout(
                    &vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings),
                    None,
                )
                .map_err(vulkan("the descriptor set layout"))?;
            let sizes: Vec<vk::DescriptorPoolSize> = bindings
                .iter()
                .map(|b| vk::DescriptorPoolSize {
                    ty: b.descriptor_type,
                    descriptor_count: 1,
                })
                .collect();
            f.descriptor_pool = d
                .create_descriptor_pool(
                    &vk::DescriptorPoolCreateInfo::default()
                        .max_sets(1)
                        .pool_sizes(&sizes),
                    None,
                )
                .map_err(vulkan("the descriptor pool"))?;
            f.set = d
                .allocate_descriptor_sets(
                    &vk::DescriptorSetAllocateInfo::default()
                        .descriptor_pool(f.descriptor_pool)
                        .set_layouts(&[f.set_layout]),
                )
                .map_err(vulkan("the descriptor set"))?[0];
            f.pipeline_layout = d
                .create_pipeline_layout(
                    &vk::PipelineLayoutCreateInfo::default().set_layouts(&[f.set_layout]),
                    None,
                )
                .map_err(vulkan("the pipeline layout"))?;

            for words in [vertex, fragment] {
                let module = d
                    .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(words), None)
                    .map_err(vulkan("a shader module"))?;
                f.shaders.push(module);
            }
            let vertex_name =
                std::ffi::CString::new(desc.vertex).map_err(|e| GpuError::Shader(e.to_string()))?;
            let fragment_name = std::ffi::CString::new(desc.fragment)
                .map_err(|e| GpuError::Shader(e.to_string()))?;
            let stages = [
                vk::PipelineShaderStageCreateInfo::default()
                    .stage(vk::ShaderStageFlags::VERTEX)
                    .module(f.shaders[0])
                    .name(&vertex_name),
                vk::PipelineShaderStageCreateInfo::default()
                    .stage(vk::ShaderStageFlags::FRAGMENT)
                    .module(f.shaders[1])
                    .name(&fragment_name),
            ];
            let write_all = vec![
                vk::PipelineColorBlendAttachmentState::default()
                    .color_write_mask(vk::ColorComponentFlags::RGBA);
                self.formats.len()
            ];
            let no_vertices = vk::PipelineVertexInputStateCreateInfo::default();
            let topology = match desc.strips {
                true => vk::PrimitiveTopology::TRIANGLE_STRIP,
                false => vk::PrimitiveTopology::TRIANGLE_LIST,
            };
            let assembly = vk::PipelineInputAssemblyStateCreateInfo::default().topology(topology);
            // The viewport and scissor follow the image size of each draw.
            let viewport_state = vk::PipelineViewportStateCreateInfo::default()
                .viewport_count(1)
                .scissor_count(1);
            let dynamic = [vk::DynamicState::VIEWPORT, vk::DynamicState::SCISSOR];
            let dynamic_state =
                vk::PipelineDynamicStateCreateInfo::default().dynamic_states(&dynamic);
            let fill = vk::PipelineRasterizationStateCreateInfo::default()
                .polygon_mode(vk::PolygonMode::FILL)
                .cull_mode(vk::CullModeFlags::NONE)
                .line_width(1.0);
            let one_sample = vk::PipelineMultisampleStateCreateInfo::default()
                .rasterization_samples(vk::SampleCountFlags::TYPE_1);
            let blend = vk::PipelineColorBlendStateCreateInfo::default()
                .flags(blend_flags)
                .attachments(&write_all);
            let pipeline = vk::GraphicsPipelineCreateInfo::default()
                .stages(&stages)
                .vertex_input_state(&no_vertices)
                .input_assembly_state(&assembly)
                .viewport_state(&viewport_state)
                .dynamic_state(&dynamic_state)
                .rasterization_state(&fill)
                .multisample_state(&one_sample)
                .color_blend_state(&blend)
                .layout(f.pipeline_layout)
                .render_pass(f.render_pass)
                .subpass(0);
            f.pipeline = d
                .create_graphics_pipelines(vk::PipelineCache::null(), &[pipeline], None)
                .map_err(|(_, e)| vulkan("the pipeline")(e))?[0];
            Ok(())
        }
    }

    /// Draws `instances` x `vertices` over state images of `size` cleared to zero, the
    /// shaders' buffers bound by name from `buffers`, and copies the states out (where
    /// [`RasterPassDesc::readback`]); returns when the GPU is done, with the time of the
    /// submission.
    pub fn draw(
        &mut self,
        gpu: &Gpu,
        size: (u32, u32),
        vertices: u32,
        instances: u32,
        buffers: &[(&str, &wgpu::Buffer)],
    ) -> Result<Duration, GpuError> {
        if size.0 == 0 || size.1 == 0 {
            return Err(GpuError::Device(
                "programmable blending: an empty image".into(),
            ));
        }
        if self.targets.as_ref().map(|t| t.size) != Some(size) {
            self.drop_targets();
            let mut targets = Targets {
                size,
                ..Default::default()
            };
            let made = self.make_targets(&mut targets);
            self.targets = Some(targets);
            if let Err(e) = made {
                // Half-made targets are destroyed, not drawn on later.
                self.drop_targets();
                return Err(e);
            }
        }
        let targets = self.targets.as_ref().expect("made above");
        self.draw_into(gpu, targets, (vertices, instances), self.readback, buffers)
    }

    /// [`RasterPass::draw`] over the state images of `other`'s last draw (cleared to zero
    /// first, so what `other` drew is gone from them; its copy out stays), which must hold
    /// states of this pass's formats, in the same [`Order`]: a second pass over the same
    /// pixels needs no images of its own. This pass's states are not copied out.
    pub fn draw_on(
        &mut self,
        gpu: &Gpu,
        other: &RasterPass,
        vertices: u32,
        instances: u32,
        buffers: &[(&str, &wgpu::Buffer)],
    ) -> Result<Duration, GpuError> {
        let targets = (other.targets.as_ref()).ok_or_else(|| {
            GpuError::Device("programmable blending: nothing drawn to draw on".into())
        })?;
        let shape = |p: &RasterPass| (p.formats.clone(), p.order, p.strips);
        if shape(other) != shape(self) {
            let why = format!(
                "programmable blending: a pass of {:?} drawn on a pass of {:?} (states, order, strips)",
                shape(self),
                shape(other)
            );
            return Err(GpuError::Device(why));
        }
        self.drop_targets();
        self.draw_into(gpu, targets, (vertices, instances), false, buffers)
    }

    /// The draw over `targets` (this pass's, or another's made for a compatible render
    /// pass: the same formats and order), the states copied into `targets`' readback where
    /// `copy_out`.
    fn draw_into(
        &self,
        gpu: &Gpu,
        targets: &Targets,
        (vertices, instances): (u32, u32),
        copy_out: bool,
        buffers: &[(&str, &wgpu::Buffer)],
    ) -> Result<Duration, GpuError> {
        let raw = |name: &str| -> Result<vk::Buffer, GpuError> {
            let buffer = buffers
                .iter()
                .find(|(n, _)| *n == name)
                .ok_or_else(|| {
                    GpuError::Shader(format!("programmable blending: no buffer for `{name}`"))
                })?
                .1;
            // SAFETY: the buffer outlives the draw, which waits for its submission.
            unsafe { buffer.as_hal::<Vulkan>().map(|b| b.raw_handle()) }
                .ok_or_else(|| GpuError::Device("a wgpu buffer that is not Vulkan's".into()))
        };
        let buffer_infos = self
            .buffers
            .iter()
            .map(|(name, _, _)| {
                Ok([vk::DescriptorBufferInfo {
                    buffer: raw(name)?,
                    offset: 0,
                    range: vk::WHOLE_SIZE,
                }])
            })
            .collect::<Result<Vec<_>, GpuError>>()?;
        let image_infos: Vec<[vk::DescriptorImageInfo; 1]> = targets
            .views
            .iter()
            .map(|&image_view| {
                [vk::DescriptorImageInfo {
                    sampler: vk::Sampler::null(),
                    image_view,
                    image_layout: vk::ImageLayout::GENERAL,
                }]
            })
            .collect();
        let set = self.fixed.set;
        let mut writes: Vec<vk::WriteDescriptorSet> = self
            .buffers
            .iter()
            .zip(&buffer_infos)
            .map(|((_, binding, ty), info)| {
                vk::WriteDescriptorSet::default()
                    .dst_set(set)
                    .dst_binding(*binding)
                    .descriptor_type(*ty)
                    .buffer_info(info)
            })
            .collect();
        for (binding, info) in self.state_bindings.iter().zip(&image_infos) {
            writes.push(
                vk::WriteDescriptorSet::default()
                    .dst_set(set)
                    .dst_binding(*binding)
                    .descriptor_type(vk::DescriptorType::INPUT_ATTACHMENT)
                    .image_info(info),
            );
        }
        let d = &self.device;
        // SAFETY: the set is not in use (the last draw has finished); every handle is live.
        unsafe { d.update_descriptor_sets(&writes, &[]) };

        let mut encoder = gpu.device.create_command_encoder(&Default::default());
        let f = &self.fixed;
        // SAFETY: recorded into the open command buffer of an encoder holding nothing else.
        let recorded = unsafe {
            encoder.as_hal_mut::<Vulkan, _, _>(|encoder| {
                let Some(encoder) = encoder else { return false };
                let counts = (vertices, instances);
                record(d, encoder.raw_handle(), f, targets, counts, copy_out);
                true
            })
        };
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
        Ok(start.elapsed())
    }

    /// Bytes of memory the state images (device-local) and their readback buffer
    /// (host-visible) hold: Vulkan memory of the pass's own, which wgpu's allocator does not
    /// count.
    pub fn memory_bytes(&self) -> u64 {
        self.targets.as_ref().map_or(0, |t| t.bytes)
    }

    /// The last draw's state image `k`, texel by texel, row by row (as its format packs them).
    pub fn state_bytes(&self, k: usize) -> Result<Vec<u8>, GpuError> {
        let targets = self
            .targets
            .as_ref()
            .ok_or_else(|| GpuError::Readback("nothing drawn yet".into()))?;
        let &(start, end) = targets.ranges.get(k).ok_or_else(|| {
            GpuError::Readback(format!("state {k} is not copied out by this pass"))
        })?;
        // SAFETY: host-visible, coherent memory the finished draw's copy wrote, mapped and
        // unmapped here only.
        unsafe {
            let mapped = self
                .device
                .map_memory(
                    targets.readback_memory,
                    start,
                    end - start,
                    vk::MemoryMapFlags::empty(),
                )
                .map_err(vulkan("mapping the readback buffer"))?;
            let bytes =
                std::slice::from_raw_parts(mapped as *const u8, (end - start) as usize).to_vec();
            self.device.unmap_memory(targets.readback_memory);
            Ok(bytes)
        }
    }

    fn make_targets(&self, t: &mut Targets) -> Result<(), GpuError> {
        // SAFETY: as in `build`; `drop_targets` destroys each object once.
        unsafe {
            let d = &self.device;
            let (width, height) = t.size;
            let extent = vk::Extent3D {
                width,
                height,
                depth: 1,
            };
            for &format in &self.formats {
                let image = d
                    .create_image(
                        &vk::ImageCreateInfo::default()
                            .image_type(vk::ImageType::TYPE_2D)
                            .format(vk_format(format)?)
                            .extent(extent)
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
                    .map_err(vulkan("a state image"))?;
                t.images.push(image);
                let needs = d.get_image_memory_requirements(image);
                t.bytes += needs.size;
                let memory = allocate(
                    d,
                    &self.memory_types,
                    needs,
                    vk::MemoryPropertyFlags::DEVICE_LOCAL,
                )?;
                t.memories.push(memory);
                d.bind_image_memory(image, memory, 0)
                    .map_err(vulkan("binding a state image"))?;
                let color = vk::ImageSubresourceRange::default()
                    .aspect_mask(vk::ImageAspectFlags::COLOR)
                    .level_count(1)
                    .layer_count(1);
                let view = d
                    .create_image_view(
                        &vk::ImageViewCreateInfo::default()
                            .image(image)
                            .view_type(vk::ImageViewType::TYPE_2D)
                            .format(vk_format(format)?)
                            .subresource_range(color),
                        None,
                    )
                    .map_err(vulkan("a state view"))?;
                t.views.push(view);
                if !self.readback {
                    continue;
                }
                let texel = format.block_copy_size(None).unwrap_or(16) as u64;
                // Copies start at multiples of the texel size: 16 bytes serves every format.
                let start = t.ranges.last().map_or(0, |r| r.1.next_multiple_of(16));
                t.ranges
                    .push((start, start + texel * width as u64 * height as u64));
            }
            t.framebuffer = d
                .create_framebuffer(
                    &vk::FramebufferCreateInfo::default()
                        .render_pass(self.fixed.render_pass)
                        .attachments(&t.views)
                        .width(width)
                        .height(height)
                        .layers(1),
                    None,
                )
                .map_err(vulkan("the framebuffer"))?;
            if !self.readback {
                return Ok(());
            }
            t.readback = d
                .create_buffer(
                    &vk::BufferCreateInfo::default()
                        .size(t.ranges.last().map_or(16, |r| r.1))
                        .usage(vk::BufferUsageFlags::TRANSFER_DST),
                    None,
                )
                .map_err(vulkan("the readback buffer"))?;
            let needs = d.get_buffer_memory_requirements(t.readback);
            t.bytes += needs.size;
            let host =
                vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT;
            t.readback_memory = allocate(d, &self.memory_types, needs, host)?;
            d.bind_buffer_memory(t.readback, t.readback_memory, 0)
                .map_err(vulkan("binding the readback buffer"))?;
            Ok(())
        }
    }

    fn drop_targets(&mut self) {
        let Some(t) = self.targets.take() else { return };
        let d = &self.device;
        // SAFETY: the targets' last submission has finished (`draw` waits for each); each
        // handle was made by `d` or is null.
        unsafe {
            d.destroy_framebuffer(t.framebuffer, None);
            for &view in &t.views {
                d.destroy_image_view(view, None);
            }
            for &image in &t.images {
                d.destroy_image(image, None);
            }
            for &memory in &t.memories {
                d.free_memory(memory, None);
            }
            d.destroy_buffer(t.readback, None);
            d.free_memory(t.readback_memory, None);
        }
    }
}

impl Drop for RasterPass {
    fn drop(&mut self) {
        self.drop_targets();
        let (d, f) = (&self.device, &self.fixed);
        // SAFETY: as in `drop_targets`.
        unsafe {
            d.destroy_pipeline(f.pipeline, None);
            for &s in &f.shaders {
                d.destroy_shader_module(s, None);
            }
            d.destroy_pipeline_layout(f.pipeline_layout, None);
            d.destroy_descriptor_pool(f.descriptor_pool, None);
            d.destroy_descriptor_set_layout(f.set_layout, None);
            d.destroy_render_pass(f.render_pass, None);
        }
    }
}

/// The draw's commands: wgpu's writes made visible to the shaders, the subpass, the state
/// images copied out, and the shaders' writes made visible to the host and to what follows.
///
/// # Safety
/// `cb` is recording; every handle is live.
unsafe fn record(
    d: &ash::Device,
    cb: vk::CommandBuffer,
    f: &Fixed,
    t: &Targets,
    (vertices, instances): (u32, u32),
    copy_out: bool,
) {
    // SAFETY: the caller's (`cb` recording, every handle live).
    unsafe {
        let (width, height) = t.size;
        let from_wgpu = [vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::MEMORY_WRITE)
            .dst_access_mask(
                vk::AccessFlags::SHADER_READ
                    | vk::AccessFlags::SHADER_WRITE
                    | vk::AccessFlags::UNIFORM_READ,
            )];
        d.cmd_pipeline_barrier(
            cb,
            vk::PipelineStageFlags::ALL_COMMANDS,
            vk::PipelineStageFlags::VERTEX_SHADER | vk::PipelineStageFlags::FRAGMENT_SHADER,
            vk::DependencyFlags::empty(),
            &from_wgpu,
            &[],
            &[],
        );
        let area = vk::Rect2D {
            offset: vk::Offset2D::default(),
            extent: vk::Extent2D { width, height },
        };
        let clear = vec![
            vk::ClearValue {
                color: vk::ClearColorValue { uint32: [0; 4] }
            };
            t.images.len()
        ];
        d.cmd_begin_render_pass(
            cb,
            &vk::RenderPassBeginInfo::default()
                .render_pass(f.render_pass)
                .framebuffer(t.framebuffer)
                .render_area(area)
                .clear_values(&clear),
            vk::SubpassContents::INLINE,
        );
        d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::GRAPHICS, f.pipeline);
        let viewport = vk::Viewport {
            x: 0.0,
            y: 0.0,
            width: width as f32,
            height: height as f32,
            min_depth: 0.0,
            max_depth: 1.0,
        };
        d.cmd_set_viewport(cb, 0, &[viewport]);
        d.cmd_set_scissor(cb, 0, &[area]);
        d.cmd_bind_descriptor_sets(
            cb,
            vk::PipelineBindPoint::GRAPHICS,
            f.pipeline_layout,
            0,
            &[f.set],
            &[],
        );
        if instances > 0 {
            d.cmd_draw(cb, vertices, instances, 0, 0);
        }
        d.cmd_end_render_pass(cb);
        let layer = vk::ImageSubresourceLayers::default()
            .aspect_mask(vk::ImageAspectFlags::COLOR)
            .layer_count(1);
        let ranges = if copy_out { &t.ranges[..] } else { &[] };
        for (image, (start, _)) in t.images.iter().zip(ranges) {
            let copy = vk::BufferImageCopy::default()
                .buffer_offset(*start)
                .image_subresource(layer)
                .image_extent(vk::Extent3D {
                    width,
                    height,
                    depth: 1,
                });
            d.cmd_copy_image_to_buffer(
                cb,
                *image,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                t.readback,
                &[copy],
            );
        }
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
    let index = match (
        (0..count).filter(usable).find(has),
        flags.contains(vk::MemoryPropertyFlags::HOST_VISIBLE),
    ) {
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
