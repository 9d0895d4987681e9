// The hardware-rasterized passes' quads (Yuan and He's system): one instance per visible
// primitive, in global front-to-back order, drawn as a quad over its box, for the fragment
// shaders of the forward (`raster.wgsl`) and the backward (`raster_backward.wgsl`).

const STRIDE: u32 = {{STRIDE}}u; // projected words per primitive
const SHADE_AT: u32 = {{SHADE_AT}}u;
// Set when the pipeline is compiled.
override ALPHA_MIN: f32;

@group(0) @binding(0) var<storage, read> projected: array<u32>;
// The visible primitives, front to back.
@group(0) @binding(1) var<storage, read> order: array<u32>;
@group(0) @binding(2) var<uniform> frame: FrameUniform;
{{CAMERA_BINDING}}

struct Quad {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(flat) prim: u32,
}

fn word(i: u32, k: u32) -> f32 {
    return bitcast<f32>(projected[i * STRIDE + k]);
}

// Corner `v` (a triangle strip: (0,0), (1,0), (0,1), (1,1)) of the box of the `k`-th nearest
// primitive, clamped to the image so huge boxes stay in range. Rasterization then covers
// exactly the pixels whose centres lie in the box, as the tile path's box test.
@vertex
fn quad_vertex(@builtin(vertex_index) v: u32, @builtin(instance_index) k: u32) -> Quad {
    let i = order[k];
    let size = vec2<f32>(f32(frame.width), f32(frame.height));
    let lo = clamp(vec2<f32>(word(i, 2u), word(i, 3u)), vec2<f32>(0.0), size);
    let hi = clamp(vec2<f32>(word(i, 4u), word(i, 5u)), vec2<f32>(0.0), size);
    let p = mix(lo, hi, vec2<f32>(f32(v & 1u), f32(v >> 1u)));
    let ndc = vec2<f32>(2.0 * p.x / size.x - 1.0, 1.0 - 2.0 * p.y / size.y);
    return Quad(vec4<f32>(ndc, 0.0, 1.0), i);
}
