// What the forward and backward blends share: one workgroup per tile, one invocation per
// pixel; the tile's list is walked in batches staged in workgroup memory, and the walk ends
// early once every pixel of the tile is done.

const TILE: u32 = {{TILE}}u;
const WG: u32 = {{WG}}u;
const BATCH: u32 = {{BATCH}}u;
const NS: u32 = {{NS}}u; // shade words per primitive
const STRIDE: u32 = {{STRIDE}}u; // projected words per primitive
const SHADE_AT: u32 = {{SHADE_AT}}u;
const CHANNELS: u32 = {{CHANNELS}}u;
// The blend's thresholds (`splat_core::blend::Blend`): stop once transmittance would fall to
// T_MIN; skip pairs whose alpha is below ALPHA_MIN.
// Set when the pipeline is compiled (`entries::blend_constants`).
override T_MIN: f32;
override ALPHA_MIN: f32;

@group(0) @binding(0) var<storage, read> projected: array<u32>;
@group(0) @binding(1) var<storage, read> tile_prims: array<u32>;
@group(0) @binding(2) var<storage, read> tile_ranges: array<u32>;
@group(0) @binding(3) var<storage, read> tile_order: array<u32>;
@group(0) @binding(4) var<uniform> frame: FrameUniform;
{{SHADE_BINDINGS}}

var<workgroup> batch_words: array<u32, {{BATCH_WORDS}}>;
var<workgroup> batch_depth: array<f32, BATCH>;
var<workgroup> batch_prim: array<u32, BATCH>;
var<workgroup> done_count: atomic<u32>;
var<workgroup> all_done: u32;

// The pixel of invocation `lid` in the workgroup's tile, and the tile's list range (capped at
// P_max). Tiles are taken in the binned order.
struct TilePixel {
    x: u32,
    y: u32,
    inside: bool,
    start: u32,
    end: u32,
}

fn tile_pixel(wid: vec3<u32>, lid: u32) -> TilePixel {
    let slot = wid.y * 65535u + wid.x;
    // A dispatch past 65,535 workgroups is rounded up to whole rows: a spare one takes no
    // tile (its pixels are outside, its list empty).
    if (slot >= frame.tiles) {
        return TilePixel(0u, 0u, false, 0u, 0u);
    }
    let tile = tile_order[slot];
    let x = (tile % frame.tiles_x) * TILE + lid % TILE;
    let y = (tile / frame.tiles_x) * TILE + lid / TILE;
    let start = tile_ranges[2u * tile];
    let end = start + min(tile_ranges[2u * tile + 1u] - start, frame.p_max);
    return TilePixel(x, y, x < frame.width && y < frame.height, start, end);
}

// Starts the walk of the list: no pixel is done yet but those for which `done` holds already
// (past the image edge).
fn start_walk(lid: u32, done: bool) {
    if (lid == 0u) {
        atomicStore(&done_count, 0u);
    }
    workgroupBarrier();
    if (done) {
        atomicAdd(&done_count, 1u);
    }
}

// Entries [b, b + BATCH) of the tile's list, one per invocation (their shade words decoded
// where they are packed: `gpu::shade_pack`).
fn stage_batch(lid: u32, b: u32, end: u32) {
    let k = b + lid;
    if (lid < BATCH && k < end) {
        let p = tile_prims[k];
        batch_prim[lid] = p;
{{STAGE_SHADE}}
        batch_depth[lid] = bitcast<f32>(projected[p * STRIDE + 1u]);
    }
}

// True once every invocation of the workgroup is done (read uniformly after a barrier).
fn all_pixels_done(lid: u32) -> bool {
    workgroupBarrier();
    if (lid == 0u) {
        all_done = atomicLoad(&done_count);
    }
    return workgroupUniformLoad(&all_done) == WG;
}
