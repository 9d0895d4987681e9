// Adds `v` to the f32 sum `i` of `grads` (`array<atomic<u32>>`, f32 bits) by compare-exchange:
// for adapters without f32 atomics.
fn add_grad(i: u32, v: f32) {
    var old = atomicLoad(&grads[i]);
    loop {
        let r = atomicCompareExchangeWeak(&grads[i], old, bitcast<u32>(bitcast<f32>(old) + v));
        if (r.exchanged) {
            break;
        }
        old = r.old_value;
    }
}
