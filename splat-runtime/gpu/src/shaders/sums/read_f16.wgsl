// Sum `at` of the f16 sums in the `u32` array `grads` (two to a word), unscaled, and its bits
// (nonzero where it is).
fn grad(at: u32) -> f32 {
    return from_half(grad_bits(at)) / sum_scale(grad_largest[0]);
}

fn grad_bits(at: u32) -> u32 {
    return (grads[at / 2u] >> ((at % 2u) * 16u)) & 0xffffu;
}
