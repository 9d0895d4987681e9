// The order test of programmable blending (programmable_blend.rs): every draw covers the
// viewport, and each of its fragments folds one step into its pixel's state, read from the
// pixel's own attachment. The fold is not commutative, so a pixel's final value says whether
// its fragments ran in draw order, each after the one before had written. Each fragment also
// counts itself into its draw's word of a wgpu storage buffer, as the backward adds a
// fragment's gradient into its primitive's words.

// The pixel's state. WGSL has no input attachments: the SPIR-V naga writes for this texture and
// its one load is patched into a subpass input and a read at the fragment's own pixel.
@group(0) @binding(0) var state: texture_2d<u32>;
// Fragments per draw.
@group(0) @binding(1) var<storage, read_write> reached: array<atomic<u32>>;

struct Fragment {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(flat) draw: u32,
}

// One triangle over the whole viewport per instance; the instance is the draw.
@vertex
fn cover(@builtin(vertex_index) vertex: u32, @builtin(instance_index) draw: u32) -> Fragment {
    let corner = vec2<f32>(f32((vertex << 1u) & 2u), f32(vertex & 2u));
    return Fragment(vec4<f32>(corner * 2.0 - 1.0, 0.0, 1.0), draw);
}

// Whether `draw` reaches pixel (x, y): about half the draws reach each pixel, a different half
// at every pixel. `covers` in programmable_blend.rs is the same function.
fn covers(x: u32, y: u32, draw: u32) -> bool {
    var h = x * 0x9e3779b1u ^ y * 0x85ebca77u ^ draw * 0xc2b2ae3du;
    h = (h ^ (h >> 15u)) * 0x2c1b3c6du;
    h = h ^ (h >> 12u);
    return ((h >> 7u) & 1u) == 1u;
}

@fragment
fn fold(fragment: Fragment) -> @location(0) vec4<u32> {
    let pixel = vec2<u32>(fragment.position.xy);
    if !covers(pixel.x, pixel.y, fragment.draw) {
        discard;
    }
    atomicAdd(&reached[fragment.draw], 1u);
    // The offset (0, 0) from this fragment once patched.
    let previous = textureLoad(state, vec2<i32>(0, 0), 0).x;
    return vec4<u32>(previous * 0x01000193u + fragment.draw + 1u, 0u, 0u, 0u);
}
