// Adds `v` to the f16 sum `i` of `grads` (`array<atomic<u32>>`, two sums to a word) by
// compare-exchange, scaled by the largest output gradient's bits in `grad_largest[0]`
// (`gpu::sums`; needs `half.wgsl` and `finite`).
fn add_grad(i: u32, v: f32) {
    let word = i / 2u;
    let shift = (i % 2u) * 16u;
    let scaled = v * sum_scale(grad_largest[0]);
    var old = atomicLoad(&grads[word]);
    loop {
        let sum = saturate_half(from_half((old >> shift) & 0xffffu) + scaled);
        let held = (old & ~(0xffffu << shift)) | (to_half(sum) << shift);
        let r = atomicCompareExchangeWeak(&grads[word], old, held);
        if (r.exchanged) {
            break;
        }
        old = r.old_value;
    }
}
