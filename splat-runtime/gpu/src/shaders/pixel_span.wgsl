// The first and last pixel (column, row) whose centre lies inside a primitive's box (lo, hi)
// on an image of `size` pixels, as (first, last); none (last < first) when `project` did not
// mark it `visible`, its depth or box is not finite, or the box covers no pixel centre.
// Operation for operation the CPU's `pipeline::filter` with TileGrid::rect. Needs `fn finite`.
fn pixel_span(visible: u32, depth: f32, lo: vec2<f32>, hi: vec2<f32>, size: vec2<f32>) -> vec4<f32> {
    let finite_box = finite(lo.x) && finite(lo.y) && finite(hi.x) && finite(hi.y);
    if (visible == 0u || !finite(depth) || !finite_box) {
        return vec4<f32>(0.0, 0.0, -1.0, -1.0);
    }
    let first = max(ceil(lo - 0.5), vec2<f32>(0.0));
    let last = min(floor(hi - 0.5), size - 1.0);
    return vec4<f32>(first, last);
}

fn spans_a_pixel(span: vec4<f32>) -> bool {
    return span.x <= span.z && span.y <= span.w;
}
