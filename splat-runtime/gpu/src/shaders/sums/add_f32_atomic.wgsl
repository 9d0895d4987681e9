// Adds `v` to the f32 word `i` of `{{ARRAY}}` (`array<atomic<f32>>`): the adapter's f32 atomics.
fn {{FN}}(i: u32, v: f32) {
    atomicAdd(&{{ARRAY}}[i], v);
}
