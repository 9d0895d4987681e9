// The first and last pixel (column, row) whose centre lies inside the box (lo, hi) on an image
// of `size` pixels, as (first, last); none when last < first on either axis. Operation for
// operation the CPU's TileGrid::rect (which then takes tiles). Needs `fn finite`.
fn pixel_span(lo: vec2<f32>, hi: vec2<f32>, size: vec2<f32>) -> vec4<f32> {
    if (!(finite(lo.x) && finite(lo.y) && finite(hi.x) && finite(hi.y))) {
        return vec4<f32>(0.0, 0.0, -1.0, -1.0);
    }
    let first = max(ceil(lo - 0.5), vec2<f32>(0.0));
    let last = min(floor(hi - 0.5), size - 1.0);
    return vec4<f32>(first, last);
}

fn spans_a_pixel(span: vec4<f32>) -> bool {
    return span.x <= span.z && span.y <= span.w;
}
