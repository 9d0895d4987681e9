//! SPIR-V for a pass that reads its own color attachment: naga writes the shader from WGSL, and
//! the one texture load of a fragment entry point becomes a subpass-input read at the
//! fragment's own pixel. WGSL has no input attachments (naga issue gfx-rs/wgpu#5233), so
//! this is a rewrite of the words naga writes, checked to find exactly what it rewrites.

use crate::GpuError;
use naga::back::spv;
use spirv::{Capability, Decoration, Dim, Op, StorageClass};

/// The SPIR-V of `entry` (a `stage` entry point of WGSL `source`) as naga writes it for Vulkan.
pub fn entry_point(
    source: &str,
    entry: &str,
    stage: naga::ShaderStage,
) -> Result<Vec<u32>, GpuError> {
    let shader = |e: String| GpuError::Shader(format!("{entry}: {e}"));
    let module =
        naga::front::wgsl::parse_str(source).map_err(|e| shader(e.emit_to_string(source)))?;
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::empty(),
    )
    .validate(&module)
    .map_err(|e| shader(format!("{e:?}")))?;
    let options = spv::Options {
        // The load is rewritten as it is: no bounds check around it.
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

/// `words` (a fragment shader with one 2D texture and one `textureLoad` of it) with that texture
/// an input attachment of index 0 and the load a read of it at offset (0, 0): the value the
/// attachment holds at the fragment's own pixel.
pub fn texture_as_input_attachment(words: &[u32]) -> Result<Vec<u32>, GpuError> {
    let wrong = |what: &str| GpuError::Shader(format!("input attachment rewrite: {what}"));
    let (header, body) = words
        .split_at_checked(5)
        .ok_or_else(|| wrong("no SPIR-V header"))?;
    let instructions = split(body).ok_or_else(|| wrong("a truncated instruction"))?;
    let only = |op: Op, what: &str| {
        let found: Vec<_> = instructions
            .iter()
            .filter(|i| i[0] & 0xffff == op as u32)
            .collect();
        match found[..] {
            [one] => Ok(one.to_vec()),
            _ => Err(wrong(&format!("{} {what} (want one)", found.len()))),
        }
    };
    let image_type = only(Op::TypeImage, "image types")?;
    let image_id = image_type[1];
    let pointer = instructions
        .iter()
        .find(|i| {
            i[0] & 0xffff == Op::TypePointer as u32
                && i[2] == StorageClass::UniformConstant as u32
                && i[3] == image_id
        })
        .ok_or_else(|| wrong("no pointer to the image"))?[1];
    let variable = instructions
        .iter()
        .find(|i| i[0] & 0xffff == Op::Variable as u32 && i[1] == pointer)
        .ok_or_else(|| wrong("no image variable"))?[2];
    only(Op::ImageFetch, "image loads")?;

    let mut out = header.to_vec();
    let mut capability_added = false;
    let mut decoration_added = false;
    for i in instructions {
        let op = i[0] & 0xffff;
        if op == Op::Decorate as u32 && !decoration_added {
            out.extend(instruction(
                Op::Decorate,
                &[variable, Decoration::InputAttachmentIndex as u32, 0],
            ));
            decoration_added = true;
        }
        match op {
            o if o == Op::TypeImage as u32 => {
                // [id, sampled type, dim, depth, arrayed, ms, sampled, format]
                let mut ty = i[1..].to_vec();
                ty[2] = Dim::DimSubpassData as u32;
                ty[6] = 2; // read without a sampler
                out.extend(instruction(Op::TypeImage, &ty));
            }
            // [result type, id, image, coordinate, Lod, level]: the read takes no level.
            o if o == Op::ImageFetch as u32 => out.extend(instruction(Op::ImageRead, &i[1..5])),
            _ => out.extend_from_slice(i),
        }
        if op == Op::Capability as u32 && !capability_added {
            out.extend(instruction(
                Op::Capability,
                &[Capability::InputAttachment as u32],
            ));
            capability_added = true;
        }
    }
    match (capability_added, decoration_added) {
        (true, true) => Ok(out),
        _ => Err(wrong("no capability or decoration section")),
    }
}

/// The instructions of a SPIR-V body, each with its opcode word; `None` if one runs past the end.
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
