// Optimized textures: lookups and the texel footprint that gradients are scattered to.
#import shared/texture

// Up to four texels (indices within the texture) and their filter weights.
struct Footprint {
    texel: vec4u,
    weight: vec4f,
}

fn param_footprint(p: ParamTex, uv: vec2f) -> Footprint {
    let w = i32(p.width);
    let h = i32(p.height);
    let size = vec2f(f32(p.width), f32(p.height));
    if p.filtering == 0u {
        let f = floor(uv * size);
        let x = wrap_coord(i32(f.x), w, 0u);
        let y = wrap_coord(i32(f.y), h, 0u);
        return Footprint(vec4u(u32(y * w + x), 0u, 0u, 0u), vec4f(1.0, 0.0, 0.0, 0.0));
    }
    let q = uv * size - 0.5;
    let f = floor(q);
    let t = q - f;
    let x0 = wrap_coord(i32(f.x), w, 0u);
    let x1 = wrap_coord(i32(f.x) + 1, w, 0u);
    let y0 = wrap_coord(i32(f.y), h, 0u);
    let y1 = wrap_coord(i32(f.y) + 1, h, 0u);
    return Footprint(
        vec4u(u32(y0 * w + x0), u32(y0 * w + x1), u32(y1 * w + x0), u32(y1 * w + x1)),
        vec4f((1.0 - t.x) * (1.0 - t.y), t.x * (1.0 - t.y), (1.0 - t.x) * t.y, t.x * t.y),
    );
}

// Filtered value (up to 3 channels; unused channels are 0).
fn param_value(p: ParamTex, fp: Footprint) -> vec3f {
    var v = vec3f(0.0);
    for (var k = 0u; k < 4u; k++) {
        let base = p.offset + fp.texel[k] * p.channels;
        var texel = vec3f(params[base], 0.0, 0.0);
        if p.channels == 3u {
            texel = vec3f(params[base], params[base + 1u], params[base + 2u]);
        }
        v += fp.weight[k] * texel;
    }
    return v;
}
