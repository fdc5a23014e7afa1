// Texture lookups from the packed RGBA8 texel buffer: wrap modes, nearest and bilinear.
#import shared/scene
#import shared/wrap

fn srgb_to_linear(c: vec3f) -> vec3f {
    let lo = c / 12.92;
    let hi = pow((c + 0.055) / 1.055, vec3f(2.4));
    return select(hi, lo, c <= vec3f(0.04045));
}

fn fetch_texel(t: TexRef, x: i32, y: i32) -> vec4f {
    let xi = wrap_coord(x, i32(t.width), t.flags & 3u);
    let yi = wrap_coord(y, i32(t.height), (t.flags >> 2u) & 3u);
    let v = unpack4x8unorm(texels[t.offset + u32(yi) * t.width + u32(xi)]);
    if (t.flags & 16u) != 0u {
        return vec4f(srgb_to_linear(v.rgb), v.a);
    }
    return v;
}

// Texture value at uv (glTF convention: v points down the image); white when absent.
fn sample_texture(t: TexRef, uv: vec2f) -> vec4f {
    if t.offset == NONE {
        return vec4f(1.0);
    }
    let size = vec2f(f32(t.width), f32(t.height));
    if (t.flags & 32u) != 0u {
        let f = floor(uv * size);
        return fetch_texel(t, i32(f.x), i32(f.y));
    }
    let q = uv * size - 0.5;
    let f = floor(q);
    let w = q - f;
    let x = i32(f.x);
    let y = i32(f.y);
    let top = mix(fetch_texel(t, x, y), fetch_texel(t, x + 1, y), w.x);
    let bottom = mix(fetch_texel(t, x, y + 1), fetch_texel(t, x + 1, y + 1), w.x);
    return mix(top, bottom, w.y);
}

// KHR_texture_transform: slot 0 base color, 1 metallic-roughness, 2 emissive.
fn transform_uv(m: Material, slot: u32, uv: vec2f) -> vec2f {
    let h = vec3f(uv, 1.0);
    return vec2f(dot(m.uv_xf[2u * slot].xyz, h), dot(m.uv_xf[2u * slot + 1u].xyz, h));
}
