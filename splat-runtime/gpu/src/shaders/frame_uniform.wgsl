// The frame's uniform: what the passes of one frame share. Its Rust twin is `FrameUniform`
// (frame_uniform.rs), whose fields and byte offsets a test compares with this struct's through
// naga's reflection of this file.
struct FrameUniform {
    // The scene's primitives.
    primitives: u32,
    // The image's size, pixels.
    width: u32,
    height: u32,
    tile_size: u32,
    // Tiles per row, P_max (u32::MAX for whole lists), and tiles in all.
    tiles_x: u32,
    p_max: u32,
    tiles: u32,
    // The tile keys the buffers hold (written when they grow, before the frame runs).
    room: u32,
}
