// The hardware-rasterized forward pass (after `quads.wgsl`): the fragment shader evaluates the
// primitive at the pixel, and blending composites front to back into the render targets
// ("under": dst += (1 - dst.a) * (alpha * value, alpha), so dst.a ends as 1 - T): the blend
// unit's, which cannot stop a pixel, or the fragment's own (then it reads the targets).

struct Targets {
{{TARGETS}}
}

// The fragment's position is the pixel centre (x + 0.5, y + 0.5), as the tile path's.
@fragment
fn splat_fragment(q: Quad) -> Targets {
    let px = q.position.x;
    let py = q.position.y;
    {{PIXEL}}
    let s = q.prim * STRIDE + SHADE_AT;
    let r = {{EVALUATE}};
    if (r.{{VALID}} == 0u || r.{{ALPHA}} < ALPHA_MIN) {
        discard;
    }
    let a = r.{{ALPHA}};
    let depth = word(q.prim, 1u);
    var out: Targets;
{{WRITE}}
    return out;
}
