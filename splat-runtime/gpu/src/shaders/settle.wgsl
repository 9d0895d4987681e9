// After the count: how many keys the frame emits and sorts, all of them or as many as the
// buffers hold, and whether that is fewer (the frame's lists are cut, and the host renders it
// again with room for them). Lets a frame be recorded whole before its count is known.

// (intersections low word, high word, primitives with a tile rectangle), from count_tiles.
@group(0) @binding(0) var<storage, read> totals: array<u32>;
@group(0) @binding(1) var<uniform> frame: FrameUniform;
// (keys to sort, 1 if the lists are cut).
@group(0) @binding(2) var<storage, read_write> key_count: array<u32>;

@compute @workgroup_size(1)
fn settle_count() {
    let room = frame.room;
    let cut = totals[1] != 0u || totals[0] > room;
    key_count[0] = select(totals[0], room, cut);
    key_count[1] = u32(cut);
}
