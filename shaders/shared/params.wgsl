// Optimized textures: lookups and the texel footprint that gradients are scattered to.
#import shared/texture
#import shared/brdf

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

// Read the previous iteration's textures instead of the current ones (the ReSTIR merge and
// the control-variate primal evaluate paths under both).
var<private> use_prev_params: bool = false;

fn param_at(i: u32) -> f32 {
    if use_prev_params {
        return params_prev[i];
    }
    return params[i];
}

// The footprint with repeated texels (textures 1 texel wide or high wrap onto themselves)
// merged into their first occurrence, so that a sample touches each texel once.
fn footprint_merged(fp: Footprint) -> Footprint {
    var out = fp;
    for (var k = 1u; k < 4u; k++) {
        for (var j = 0u; j < k; j++) {
            if out.weight[k] != 0.0 && out.weight[j] != 0.0 && out.texel[j] == out.texel[k] {
                out.weight[j] += out.weight[k];
                out.weight[k] = 0.0;
            }
        }
    }
    return out;
}

// The slot of the normal map among those a texture can replace (base color, metallic,
// roughness; SLOTS of them, shared/normal_map.wgsl).
const SLOT_NORMAL: u32 = 3u;

// Index of the optimized texture replacing slot (0 base color, 1 metallic, 2 roughness,
// SLOT_NORMAL) of m.
fn material_param(m: Material, slot: u32) -> u32 {
    switch slot {
        case 0u: {
            return m.param_base_color;
        }
        case 1u: {
            return m.param_metallic;
        }
        case 2u: {
            return m.param_roughness;
        }
        default: {
            return m.param_normal;
        }
    }
}

// Derivative of adjoint . contribution with respect to one input of the slot, where the
// contribution is brdf x weight: per channel for base color (xyz), the map's RGB for the
// normal map (xyz, every image channel depending on each), a scalar (x) otherwise.
fn slot_derivative(slot: u32, bg: BrdfGrad, weight: vec3f, adj: vec3f) -> vec3f {
    if slot == SLOT_NORMAL {
        return bg.d_normal * (weight * adj);
    }
    return with_adjoint(slot_factor(slot, bg, weight), adj, select(1u, 3u, slot == 0u));
}

// The derivative of the contribution brdf x weight with respect to one input of the slot,
// per image channel, before the adjoint: slot_derivative is with_adjoint of it.
fn slot_factor(slot: u32, bg: BrdfGrad, weight: vec3f) -> vec3f {
    switch slot {
        case 0u: {
            return bg.d_base * weight;
        }
        case 1u: {
            return bg.d_metallic * weight;
        }
        default: {
            return bg.d_roughness * weight;
        }
    }
}

// A slot factor (or a sum of them) under adjoint adj, for a texture of `channels` channels:
// per channel for base color (xyz), summed over the image channels into x otherwise.
fn with_adjoint(e: vec3f, adj: vec3f, channels: u32) -> vec3f {
    if channels == 3u {
        return adj * e;
    }
    return vec3f(dot(adj, e), 0.0, 0.0);
}

// What a pixel's adjoint multiplies in a path's derivative with respect to one texel, for an
// estimator that keeps a path's factor apart from the adjoint (ReSTIR): the slot factor per
// image channel (e) for base color and the scalar slots, or for a normal map a matrix (n)
// whose column c is image channel c's derivative in the map's RGB.
struct TexelFactor {
    e: vec3f,
    n: mat3x3f,
}

// The factor of the contribution brdf x weight for one input of the slot.
fn texel_factor(slot: u32, bg: BrdfGrad, weight: vec3f) -> TexelFactor {
    if slot == SLOT_NORMAL {
        let d = bg.d_normal;
        return TexelFactor(vec3f(0.0), mat3x3f(d[0] * weight.x, d[1] * weight.y, d[2] * weight.z));
    }
    return TexelFactor(slot_factor(slot, bg, weight), mat3x3f());
}

fn factor_scaled(f: TexelFactor, s: f32) -> TexelFactor {
    return TexelFactor(s * f.e, s * f.n);
}

fn factor_finite(f: TexelFactor) -> bool {
    let big = vec3f(3.0e38);
    return all(abs(f.e) < big) && all(abs(f.n[0]) < big) && all(abs(f.n[1]) < big) && all(abs(f.n[2]) < big);
}

// The derivative with respect to a texel of texture p that factor f gives under adjoint adj
// (per channel of the texture: slot_derivative for one path and texel).
fn texel_value(f: TexelFactor, adj: vec3f, p: ParamTex) -> vec3f {
    if p.slot == SLOT_NORMAL {
        return f.n * adj;
    }
    return with_adjoint(f.e, adj, p.channels);
}

// Filtered value (up to 3 channels; unused channels are 0).
fn param_value(p: ParamTex, fp: Footprint) -> vec3f {
    var v = vec3f(0.0);
    for (var k = 0u; k < 4u; k++) {
        let base = p.offset + fp.texel[k] * p.channels;
        var texel = vec3f(param_at(base), 0.0, 0.0);
        if p.channels == 3u {
            texel = vec3f(param_at(base), param_at(base + 1u), param_at(base + 2u));
        }
        v += fp.weight[k] * texel;
    }
    return v;
}
