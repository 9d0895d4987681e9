// Adds `v` to the f32 sum `i` of `grads` (`array<atomic<f32>>`): the adapter's f32 atomics.
fn add_grad(i: u32, v: f32) {
    atomicAdd(&grads[i], v);
}
