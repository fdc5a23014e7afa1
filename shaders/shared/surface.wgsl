// A surface point as the shading code sees it, rebuilt from a triangle and barycentrics
// alone, and the value of a stored path. Tracing (shared/bvh) is not imported here: ReSTIR's
// merge evaluates stored paths with these functions and must not be able to trace a ray.
#import shared/lights
#import shared/brdf
#import shared/params
#import shared/normal_map

struct Surface {
    p: vec3f,
    ng: vec3f,
    frame: mat3x3f,
    wo: vec3f,
    uv: vec2f,
    material: u32,
    front: bool,
    valid: bool,
    // With an optimized normal map (the material's param_normal): the frame it is read in,
    // columns tangent, bitangent and the interpolated normal of the front face (tangent and
    // bitangent zero where the triangle has no tangents). Zero otherwise.
    tbn: mat3x3f,
}

// Smallest Z of an optimized normal map's 2 x RGB - 1 before it is normalized (mirrors
// NORMAL_Z_FLOOR in src/vocab.rs): a lower Z reads as this one.
const NORMAL_Z_FLOOR: f32 = 0.1;

// A mapped normal (the file's normal map or an optimized one) that the viewer sees at a
// smaller cosine than this is bent towards the viewer to it (bent_to_viewer). Both kinds of
// map read their texels the same way, so that an optimized map equal to a file's renders
// as the file's does: targets rendered from a scene's own normal map are then matched
// exactly by the true map, not by a map that makes up for a difference between two readings.
const NORMAL_BEND: f32 = 0.01;

// n (unit) bent towards the viewer wo until n.wo = NORMAL_BEND (before normalizing) where it
// is less: continuous where a falling back to the geometric normal would jump, and so
// differentiable (shared/normal_map, optimized_normal, takes its derivative). Zero where
// the bent vector is degenerate.
fn bent_to_viewer(n: vec3f, wo: vec3f) -> vec3f {
    let c = dot(n, wo);
    if c >= NORMAL_BEND {
        return n;
    }
    let nb = n + (NORMAL_BEND - c) * wo;
    let lb = length(nb);
    return select(vec3f(0.0), nb / lb, lb > 0.0);
}

// Geometry at the point (hit.b1, hit.b2) of triangle hit.tri seen from o, normals turned
// towards the viewer for double-sided materials. The point is interpolated from the
// triangle's vertices (not o + t d), so that the same (o, triangle, barycentrics) always give
// the same surface: a path stored by ReSTIR is evaluated exactly as it was drawn.
// valid is false for the back of a single-sided surface (it shades black).
fn surface_at(o: vec3f, hit: Hit) -> Surface {
    let tri = hit.tri;
    let s = tri_shading[tri];
    let b0 = 1.0 - hit.b1 - hit.b2;
    let p0 = tri_vertex(tri, 0u);
    let p1 = tri_vertex(tri, 1u);
    let p2 = tri_vertex(tri, 2u);
    let p = b0 * p0 + hit.b1 * p1 + hit.b2 * p2;
    let to = p - o;
    let len_to = length(to);
    let d = select(vec3f(0.0, 0.0, -1.0), to / len_to, len_to > 0.0);
    var ng = normalize(cross(p1 - p0, p2 - p0));
    var ns = b0 * s.n0 + hit.b1 * s.n1 + hit.b2 * s.n2;
    let front = dot(ng, d) < 0.0;
    let m = materials[s.material];
    var out: Surface;
    out.p = p;
    out.uv = b0 * s.uv01.xy + hit.b1 * s.uv01.zw + hit.b2 * s.uv2;
    out.material = s.material;
    let tangents = s.t0 != 0u && s.t1 != 0u && s.t2 != 0u;
    var mapped = false;
    out.tbn = mat3x3f();
    if m.param_normal != NONE {
        out.tbn = tangent_frame(ns, vec3f(b0, hit.b1, hit.b2), s, tangents);
    } else if m.normal_tex.offset != NONE && tangents {
        ns = normal_mapped(m, out.uv, ns, vec3f(b0, hit.b1, hit.b2), s);
        mapped = true;
    }
    out.front = front;
    out.wo = -d;
    out.valid = front || m.double_sided != 0u;
    if !front {
        ng = -ng;
        ns = -ns;
    }
    out.ng = ng;
    if m.param_normal != NONE {
        out.frame = onb(optimized_normal(out, false).n);
        return out;
    }
    if mapped {
        // The file's normal map, read as an optimized one is (bent, not dropped).
        let len = length(ns);
        let nb = select(vec3f(0.0), bent_to_viewer(ns / len, out.wo), len > 0.0);
        out.frame = onb(select(ng, nb, length(nb) > 0.0));
        return out;
    }
    let len = length(ns);
    if len <= 0.0 || dot(ns / len, out.wo) <= 1e-6 {
        ns = ng;
    } else {
        ns = ns / len;
    }
    out.frame = onb(ns);
    return out;
}

// The tangent frame of triangle s at barycentrics b around the interpolated normal n (of the
// front face): the tangent made orthogonal to the normal, the bitangent cross(n, t) x w, the
// unit normal; tangent and bitangent zero without tangents.
fn tangent_frame(n: vec3f, b: vec3f, s: TriShading, tangents: bool) -> mat3x3f {
    let nn = normalize(n);
    if !tangents || !all(nn == nn) {
        return mat3x3f(vec3f(0.0), vec3f(0.0), nn);
    }
    let t0 = tangent_at(s.t0);
    var t = b.x * t0.xyz + b.y * tangent_at(s.t1).xyz + b.z * tangent_at(s.t2).xyz;
    t -= nn * dot(nn, t);
    if !(length(t) > 0.0) {
        return mat3x3f(vec3f(0.0), vec3f(0.0), nn);
    }
    t = normalize(t);
    return mat3x3f(t, cross(nn, t) * t0.w, nn);
}

// BRDF x cos of sf towards wi (world space) with inputs mat and its derivatives, in sf's
// frame under the current or (prev) the previous textures; with an optimized normal map,
// d_normal too (the derivative with respect to the map's RGB at the point).
fn surface_brdf_grad(sf: Surface, mat: SurfaceMaterial, wi: vec3f, prev: bool) -> BrdfGrad {
    let frame = frame_of(sf, prev);
    let wo_l = to_local(frame, sf.wo);
    let wi_l = to_local(frame, wi);
    var bg = brdf_eval_cos_grad(mat, wo_l, wi_l);
    if materials[sf.material].param_normal != NONE {
        bg.d_normal = normal_rgb_grad(sf, prev, mat, wo_l, wi_l);
    }
    return bg;
}

// A vertex tangent packed by pack_tangent (src/render/layout.rs): direction and handedness w.
fn tangent_at(w: u32) -> vec4f {
    let e = vec2f(f32(w & 0x7fffu), f32((w >> 15u) & 0x7fffu)) * (2.0 / 32767.0) - 1.0;
    return vec4f(oct_decode(e), select(1.0, -1.0, (w & 0x40000000u) != 0u));
}

// The normal n (interpolated, of the front face) perturbed by material m's tangent-space
// normal map at uv: the interpolated tangent of triangle s at barycentrics b, made
// orthogonal to n, the bitangent cross(n, t) x w, and the map's normal (2 x texel - 1, X and
// Y times normal_scale, Z floored at NORMAL_Z_FLOOR as an optimized map's) in that frame. The
// back face of a double-sided surface flips the result with the rest of its shading frame,
// and surface_at bends it towards the viewer (bent_to_viewer).
fn normal_mapped(m: Material, uv: vec2f, n: vec3f, b: vec3f, s: TriShading) -> vec3f {
    let t0 = tangent_at(s.t0);
    var t = b.x * t0.xyz + b.y * tangent_at(s.t1).xyz + b.z * tangent_at(s.t2).xyz;
    let nn = normalize(n);
    t -= nn * dot(nn, t);
    let tn = sample_texture(m.normal_tex, transform_uv(m, 3u, uv)).xyz * 2.0 - 1.0;
    let v = vec3f(tn.xy * m.normal_scale, max(tn.z, NORMAL_Z_FLOOR));
    if !(length(t) > 0.0) || !(length(v) > 0.0) || !all(nn == nn) {
        return n;
    }
    t = normalize(t);
    let bt = cross(nn, t) * t0.w;
    return normalize(t * v.x + bt * v.y + nn * v.z);
}

// The BRDF inputs of material `mi` at texture coordinates uv are
// with_optimized(mi, uv, gltf_inputs(mi, uv)); a ReSTIR path keeps what gltf_inputs gave
// (fixed_pack) and is re-evaluated with with_optimized(mi, uv, fixed_unpack(...)).

// The inputs of material `mi` at uv that the glTF material gives (factors and textures);
// those of slots that an optimized texture replaces are left at 1 (with_optimized replaces
// them), and a glTF texture whose every channel in use is replaced is not sampled. Fields
// are read one by one, and the whole material only where a glTF texture is sampled: a CPU
// device loads every word of a struct read at a per-invocation index.
fn gltf_inputs(mi: u32, uv: vec2f) -> SurfaceMaterial {
    var bc = vec4f(1.0);
    if materials[mi].param_base_color == NONE {
        let m = materials[mi];
        bc = sample_texture(m.base_color_tex, transform_uv(m, 0u, uv));
    }
    var mr = vec4f(1.0);
    if materials[mi].param_metallic == NONE || materials[mi].param_roughness == NONE {
        let m = materials[mi];
        mr = sample_texture(m.mr_tex, transform_uv(m, 1u, uv));
    }
    return SurfaceMaterial(materials[mi].base_color.rgb * bc.rgb, clamp(materials[mi].metallic * mr.b, 0.0, 1.0), clamp(materials[mi].roughness * mr.g, 0.0, 1.0));
}

// The BRDF inputs at sf under the current or (prev) the previous iteration's textures.
fn material_at(sf: Surface, prev: bool) -> SurfaceMaterial {
    let gltf = gltf_inputs(sf.material, sf.uv);
    let saved = use_prev_params;
    use_prev_params = prev;
    let m = with_optimized(sf.material, sf.uv, gltf);
    use_prev_params = saved;
    return m;
}

// m with the inputs of the slots that optimized textures replace read from them (UV0, repeat
// wrap; the textures that use_prev_params selects).
fn with_optimized(mi: u32, uv: vec2f, m: SurfaceMaterial) -> SurfaceMaterial {
    let pb = materials[mi].param_base_color;
    let pm = materials[mi].param_metallic;
    let pr = materials[mi].param_roughness;
    var out = m;
    if pb != NONE {
        let p = param_textures[pb];
        out.base_color = param_value(p, param_footprint(p, uv));
    }
    if pm != NONE {
        let p = param_textures[pm];
        out.metallic = param_value(p, param_footprint(p, uv)).x;
    }
    if pr != NONE {
        let p = param_textures[pr];
        out.roughness = param_value(p, param_footprint(p, uv)).x;
    }
    return out;
}

// The inputs of m that no optimized texture of material `mi` replaces (they never change
// during an optimization), packed in four floats: base color (RGB), then metallic, then
// roughness, skipping the optimized ones. A path vertex keeps them (PathVertex.fixed), so
// that re-evaluating it samples no glTF texture. For a material with an optimized base
// color, metallic or roughness at most four inputs are left; with none of them optimized
// (a normal map alone) the roughness is kept beside them (PathVertex.fixed_roughness).
// fixed_unpack gives them back exactly.
fn fixed_pack(mi: u32, m: SurfaceMaterial) -> vec4f {
    if materials[mi].param_base_color == NONE {
        return vec4f(m.base_color, select(m.metallic, m.roughness, materials[mi].param_metallic != NONE));
    }
    return vec4f(m.metallic, m.roughness, 0.0, 0.0);
}

fn fixed_unpack(mi: u32, fixed: vec4f, roughness: f32) -> SurfaceMaterial {
    if materials[mi].param_base_color == NONE {
        let all_gltf = NORMAL_MAPS && materials[mi].param_metallic == NONE && materials[mi].param_roughness == NONE;
        return SurfaceMaterial(fixed.xyz, fixed.w, select(fixed.w, roughness, all_gltf));
    }
    return SurfaceMaterial(vec3f(1.0), fixed.x, fixed.y);
}

// Origin pushed off the surface along the geometric normal, on the side of direction d.
fn offset_origin(sf: Surface, d: vec3f) -> vec3f {
    let scale = 1e-4 * (1.0 + max(max(abs(sf.p.x), abs(sf.p.y)), abs(sf.p.z)));
    return sf.p + sf.ng * select(-scale, scale, dot(sf.ng, d) >= 0.0);
}

// Unit direction <-> two floats (octahedral map). ReSTIR stores directions this way;
// decode(encode(d)) differs from d by about 1e-7, and the gradient passes evaluate every
// sample at the decoded directions, so a stored path is re-evaluated exactly.
fn oct_encode(d: vec3f) -> vec2f {
    let n = d / (abs(d.x) + abs(d.y) + abs(d.z));
    if n.z >= 0.0 {
        return n.xy;
    }
    let s = select(vec2f(-1.0), vec2f(1.0), n.xy >= vec2f(0.0));
    return (vec2f(1.0) - abs(n.yx)) * s;
}

fn oct_decode(e: vec2f) -> vec3f {
    var v = vec3f(e, 1.0 - abs(e.x) - abs(e.y));
    if v.z < 0.0 {
        let s = select(vec2f(-1.0), vec2f(1.0), v.xy >= vec2f(0.0));
        v = vec3f((vec2f(1.0) - abs(v.yx)) * s, v.z);
    }
    return normalize(v);
}

// The factor of a path's contribution to texel `local` of optimized texture `ti` that the
// adjoint multiplies (shared/params.wgsl, TexelFactor), d(f)/d(texel) with f = BRDF x cos x
// L_i at path vertex pv of surface sf (its directions in sf.frame): texel_value(factor,
// adjoint, texture) is the path-space integrand of the gradient, before any sampling density.
// Zero when the path's material does not use the texture or its filter does not reach the
// texel. Uses the textures that use_prev_params selects (and sf.frame the frame under them).
// No geometry and no glTF texture is looked at.
fn path_factor(sf: Surface, pv: PathVertex, li: vec3f, ti: u32, local: u32) -> TexelFactor {
    let none = TexelFactor(vec3f(0.0), mat3x3f());
    if pv.material >= arrayLength(&materials) {
        return none;
    }
    var slot = NONE;
    if materials[pv.material].param_roughness == ti {
        slot = 2u;
    } else if materials[pv.material].param_metallic == ti {
        slot = 1u;
    } else if materials[pv.material].param_base_color == ti {
        slot = 0u;
    } else if NORMAL_MAPS && materials[pv.material].param_normal == ti {
        slot = SLOT_NORMAL;
    }
    if slot == NONE {
        return none;
    }
    let fp = footprint_merged(param_footprint(param_textures[ti], pv.uv));
    var wf = 0.0;
    for (var k = 0u; k < 4u; k++) {
        if fp.texel[k] == local {
            wf += fp.weight[k];
        }
    }
    if wf == 0.0 {
        return none;
    }
    return factor_scaled(texel_factor(slot, vertex_grad(sf, pv, slot == SLOT_NORMAL), li), wf);
}

// The BRDF derivatives of path vertex pv of surface sf, with the glTF inputs it kept and the
// textures that use_prev_params selects; with `normal`, the derivative with respect to the
// optimized normal map's RGB too (sf.frame is then the map's frame under those textures).
fn vertex_grad(sf: Surface, pv: PathVertex, normal: bool) -> BrdfGrad {
    let mat = with_optimized(pv.material, pv.uv, fixed_unpack(pv.material, pv.fixed, pv.fixed_roughness));
    let wo = oct_decode(pv.wo);
    let wi = oct_decode(pv.wi);
    var bg = brdf_eval_cos_grad(mat, wo, wi);
    if NORMAL_MAPS && normal && materials[pv.material].param_normal != NONE {
        bg.d_normal = normal_rgb_grad(sf, use_prev_params, mat, wo, wi);
    }
    return bg;
}
