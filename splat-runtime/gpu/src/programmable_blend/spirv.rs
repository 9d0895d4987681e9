//! SPIR-V for a pass that reads its own color attachments: naga writes the shaders from WGSL,
//! and every texture load of a fragment entry point becomes a subpass-input read at the
//! fragment's own pixel. WGSL has no input attachments (gfx-rs/wgpu#5233), so this is a
//! rewrite of the words naga writes, checked to find what it rewrites.

use crate::GpuError;
use ash::vk;
use naga::back::spv;
use spirv::{Capability, Decoration, Dim, Op, StorageClass};

/// A WGSL module parsed and validated once, for its bindings and its entry points' SPIR-V.
pub struct Module {
    module: naga::Module,
    info: naga::valid::ModuleInfo,
}

impl Module {
    pub fn parse(source: &str) -> Result<Module, GpuError> {
        let shader = |e: String| GpuError::Shader(format!("programmable blending: {e}"));
        let module =
            naga::front::wgsl::parse_str(source).map_err(|e| shader(e.emit_to_string(source)))?;
        let info = naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::all(),
        )
        .validate(&module)
        .map_err(|e| shader(format!("{e:?}")))?;
        Ok(Module { module, info })
    }

    /// The buffers of group 0: (name, binding, descriptor type).
    pub fn buffers(&self) -> Vec<(String, u32, vk::DescriptorType)> {
        let mut out = Vec::new();
        for (_, var) in self.module.global_variables.iter() {
            let (Some(binding), Some(name)) = (&var.binding, &var.name) else {
                continue;
            };
            let ty = match var.space {
                naga::AddressSpace::Storage { .. } => vk::DescriptorType::STORAGE_BUFFER,
                naga::AddressSpace::Uniform => vk::DescriptorType::UNIFORM_BUFFER,
                _ => continue,
            };
            out.push((name.clone(), binding.binding, ty));
        }
        out
    }

    /// The bindings of group 0's textures, in order: the state images, input attachments
    /// 0, 1, ... once rewritten.
    pub fn textures(&self) -> Vec<u32> {
        let mut out: Vec<u32> = (self.module.global_variables.iter())
            .filter(|(_, v)| matches!(self.module.types[v.ty].inner, naga::TypeInner::Image { .. }))
            .filter_map(|(_, v)| v.binding.as_ref().map(|b| b.binding))
            .collect();
        out.sort_unstable();
        out
    }

    /// The SPIR-V of `entry` (a `stage` entry point) with its `override`s set to `constants`,
    /// as naga writes it for Vulkan.
    pub fn entry_point(
        &self,
        entry: &str,
        stage: naga::ShaderStage,
        constants: &[(&str, f64)],
    ) -> Result<Vec<u32>, GpuError> {
        let shader = |e: String| GpuError::Shader(format!("{entry}: {e}"));
        let mut values = naga::back::PipelineConstants::default();
        for (name, value) in constants {
            values.insert(name.to_string(), *value);
        }
        let (module, info) = naga::back::pipeline_constants::process_overrides(
            &self.module,
            &self.info,
            Some((stage, entry)),
            &values,
        )
        .map_err(|e| shader(e.to_string()))?;
        let options = spv::Options {
            // Quad operations (the hardware backward's reductions) take SPIR-V 1.3.
            lang_version: (1, 3),
            // The loads are rewritten as they are: no bounds checks around them.
            bounds_check_policies: naga::proc::BoundsCheckPolicies {
                image_load: naga::proc::BoundsCheckPolicy::Unchecked,
                ..Default::default()
            },
            ..Default::default()
        };
        let pipeline = spv::PipelineOptions {
            shader_stage: stage,
            entry_point: entry.into(),
        };
        spv::write_vec(&module, &info, &options, Some(&pipeline)).map_err(|e| shader(e.to_string()))
    }
}

/// `words` (a fragment shader whose textures are 2D and each read by `textureLoad`) with its
/// textures input attachments, numbered in the order of their bindings, and every load a read
/// of its attachment at offset (0, 0): the value at the fragment's own pixel.
pub fn textures_as_input_attachments(words: &[u32]) -> Result<Vec<u32>, GpuError> {
    let wrong = |what: &str| GpuError::Shader(format!("input attachment rewrite: {what}"));
    let (header, instructions) = parse(words).map_err(wrong)?;
    let is = |i: &[u32], op: Op| i[0] & 0xffff == op as u32;
    let images: Vec<u32> = instructions
        .iter()
        .filter(|i| is(i, Op::TypeImage))
        .map(|i| i[1])
        .collect();
    if images.is_empty() {
        return Err(wrong("no image types"));
    }
    if let Some(other) = instructions.iter().find(|i| {
        is(i, Op::ImageSampleImplicitLod)
            || is(i, Op::ImageSampleExplicitLod)
            || is(i, Op::ImageQuerySizeLod)
    }) {
        return Err(wrong(&format!(
            "an image use other than a load (opcode {})",
            other[0] & 0xffff
        )));
    }
    if !instructions.iter().any(|i| is(i, Op::ImageFetch)) {
        return Err(wrong("no image loads"));
    }
    let pointers: Vec<u32> = instructions
        .iter()
        .filter(|i| {
            is(i, Op::TypePointer)
                && i[2] == StorageClass::UniformConstant as u32
                && images.contains(&i[3])
        })
        .map(|i| i[1])
        .collect();
    let variables: Vec<u32> = instructions
        .iter()
        .filter(|i| is(i, Op::Variable) && pointers.contains(&i[1]))
        .map(|i| i[2])
        .collect();
    // Each variable's binding, for its attachment index.
    let binding_of = |v: u32| {
        instructions
            .iter()
            .find(|i| is(i, Op::Decorate) && i[1] == v && i[2] == Decoration::Binding as u32)
            .map(|i| i[3])
    };
    let mut bound: Vec<(u32, u32)> = variables
        .iter()
        .map(|&v| {
            binding_of(v)
                .map(|b| (b, v))
                .ok_or_else(|| wrong("an image without a binding"))
        })
        .collect::<Result<_, _>>()?;
    bound.sort_unstable();

    let mut out = header.to_vec();
    let mut capability_added = false;
    let mut decorations_added = false;
    for i in instructions {
        if is(i, Op::Decorate) && !decorations_added {
            for (index, &(_, v)) in bound.iter().enumerate() {
                let operands = [v, Decoration::InputAttachmentIndex as u32, index as u32];
                out.extend(instruction(Op::Decorate, &operands));
            }
            decorations_added = true;
        }
        if is(i, Op::TypeImage) {
            // [id, sampled type, dim, depth, arrayed, ms, sampled, format]
            let mut ty = i[1..].to_vec();
            ty[2] = Dim::DimSubpassData as u32;
            ty[6] = 2; // read without a sampler
            out.extend(instruction(Op::TypeImage, &ty));
        } else if is(i, Op::ImageFetch) {
            // [result type, id, image, coordinate, Lod, level]: the read takes no level.
            out.extend(instruction(Op::ImageRead, &i[1..5]));
        } else {
            out.extend_from_slice(i);
        }
        if is(i, Op::Capability) && !capability_added {
            out.extend(instruction(
                Op::Capability,
                &[Capability::InputAttachment as u32],
            ));
            capability_added = true;
        }
    }
    match (capability_added, decorations_added) {
        (true, true) => Ok(out),
        _ => Err(wrong("no capability or decoration section")),
    }
}

/// `words` with the `FrontFacing` built-in input made `HelperInvocation`: WGSL has no way to
/// ask whether a fragment is a helper invocation (one that runs only so its quad has four
/// lanes, and whose writes do nothing), and both are input booleans, so a shader that takes
/// `@builtin(front_facing)` (quads drawn without culling have no use for it) reads that
/// instead.
pub fn front_facing_as_helper(words: &[u32]) -> Result<Vec<u32>, GpuError> {
    let wrong = |what: &str| GpuError::Shader(format!("helper invocation rewrite: {what}"));
    let (header, instructions) = parse(words).map_err(wrong)?;
    let mut out = header.to_vec();
    let mut found = false;
    for i in instructions {
        let front_facing = i[0] & 0xffff == Op::Decorate as u32
            && i.get(2) == Some(&(Decoration::BuiltIn as u32))
            && i.get(3) == Some(&(spirv::BuiltIn::FrontFacing as u32));
        if front_facing {
            out.extend(instruction(
                Op::Decorate,
                &[
                    i[1],
                    Decoration::BuiltIn as u32,
                    spirv::BuiltIn::HelperInvocation as u32,
                ],
            ));
            found = true;
        } else {
            out.extend_from_slice(i);
        }
    }
    match found {
        true => Ok(out),
        false => Err(wrong("no front_facing input")),
    }
}

/// The instructions of a SPIR-V body, each with its opcode word; `None` if one runs past the end.
/// A SPIR-V module's header (five words) and its instructions, or what is malformed.
fn parse(words: &[u32]) -> Result<(&[u32], Vec<&[u32]>), &'static str> {
    let (header, body) = words.split_at_checked(5).ok_or("no SPIR-V header")?;
    Ok((header, split(body).ok_or("a truncated instruction")?))
}

pub(crate) fn split(mut body: &[u32]) -> Option<Vec<&[u32]>> {
    let mut out = Vec::new();
    while let Some(&first) = body.first() {
        let count = (first >> 16) as usize;
        if count == 0 || count > body.len() {
            return None;
        }
        let (one, rest) = body.split_at(count);
        out.push(one);
        body = rest;
    }
    Some(out)
}

fn instruction(op: Op, operands: &[u32]) -> Vec<u32> {
    let mut words = vec![((operands.len() as u32 + 1) << 16) | op as u32];
    words.extend_from_slice(operands);
    words
}
