// The primitives' tiles: the depth sort's keys (`depth.wgsl`), then, over the primitives front
// to back, the count and emission of (primitive, tile) intersections. Count and emit visit a
// primitive's tiles through `kept_tiles` (whose emit step is empty when counting), so they
// cannot disagree. `projected` holds `project`'s result per primitive: visible, depth, bbox
// (4), cull, shade.

const STRIDE: u32 = {{STRIDE}}u;
const CULL_AT: u32 = 6u;

@group(0) @binding(0) var<storage, read> projected: array<u32>;
// Per primitive front to back: its kept tiles, then (scanned) its first key.
@group(0) @binding(1) var<storage, read_write> counts: array<u32>;
@group(0) @binding(2) var<uniform> frame: FrameUniform;

fn word(i: u32, k: u32) -> f32 {
    return bitcast<f32>(projected[i * STRIDE + k]);
}

// The tiles holding a pixel centre inside primitive i's box, as (x0, y0, x1, y1) half-open;
// x1 == x0 if none (the CPU's TileGrid::rect, operation for operation).
fn tile_rect(i: u32) -> vec4<u32> {
    let lo = vec2<f32>(word(i, 2u), word(i, 3u));
    let hi = vec2<f32>(word(i, 4u), word(i, 5u));
    let size = vec2<f32>(f32(frame.width), f32(frame.height));
    let span = pixel_span(projected[i * STRIDE], word(i, 1u), lo, hi, size);
    if (!spans_a_pixel(span)) {
        return vec4<u32>(0u);
    }
    let tile = frame.tile_size;
    return vec4<u32>(vec2<u32>(span.xy) / tile, vec2<u32>(span.zw) / tile + 1u);
}

// Visits the tiles of `rect` that tile_cull keeps; returns how many (emitting from `first`).
fn kept_tiles(i: u32, rect: vec4<u32>, first: u32) -> u32 {
    let size = frame.tile_size;
    var n = 0u;
    for (var ty = rect.y; ty < rect.w; ty++) {
        for (var tx = rect.x; tx < rect.z; tx++) {
            let x0 = tx * size;
            let y0 = ty * size;
            let x1 = min(x0 + size, frame.width);
            let y1 = min(y0 + size, frame.height);
            let lo = vec2<f32>(f32(x0) + 0.5, f32(y0) + 0.5);
            let hi = vec2<f32>(f32(x1) - 0.5, f32(y1) - 0.5);
            if ({{KEEP}}) {
                {{EMIT}}
                n++;
            }
        }
    }
    return n;
}

{{ENTRY}}
