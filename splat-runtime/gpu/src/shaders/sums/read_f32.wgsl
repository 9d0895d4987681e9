// Sum `at` of the f32 sums in the `u32` array `grads`, and its bits (nonzero where it is).
fn grad(at: u32) -> f32 {
    return bitcast<f32>(grads[at]);
}

fn grad_bits(at: u32) -> u32 {
    return grads[at];
}
