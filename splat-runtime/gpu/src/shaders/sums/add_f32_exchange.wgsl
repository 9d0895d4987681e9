// Adds `v` to the f32 word `i` of `{{ARRAY}}` (`array<atomic<u32>>`, f32 bits) by
// compare-exchange: for adapters without f32 atomics.
fn {{FN}}(i: u32, v: f32) {
    var old = atomicLoad(&{{ARRAY}}[i]);
    loop {
        let r = atomicCompareExchangeWeak(&{{ARRAY}}[i], old, bitcast<u32>(bitcast<f32>(old) + v));
        if (r.exchanged) {
            break;
        }
        old = r.old_value;
    }
}
