// Whether `x` is neither infinite nor NaN (its exponent bits not all set): WGSL has no isFinite,
// and compilers may assume finite math where a comparison with itself would test for NaN.
fn finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}
