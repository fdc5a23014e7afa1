// Optimized normal maps (the material's param_normal): the shading normal a map gives, the
// frame under either state, and the derivative of a BRDF evaluation with respect to the map's
// RGB. A pass whose scene optimizes no normal map is composed with shared/normal_map_off
// instead (src/render/gpu_scene.rs, GpuScene::off_modules): the same functions doing nothing,
// which a CPU device compiles in a fraction of the time.
#import shared/params
#import shared/brdf

// The slots a texture may replace (shared/params.wgsl, material_param).
const SLOTS: u32 = 4u;

// Whether normal maps may be optimized (false in shared/normal_map_off).
const NORMAL_MAPS: bool = true;

// The shading normal that sf's optimized normal map gives under the current or (prev) the
// previous iteration's textures, and its derivative with respect to the map's filtered RGB
// (columns: d n / d R, G, B): n = normalize(tbn (2 RGB - 1)), Z floored at NORMAL_Z_FLOOR,
// turned with the face (the back of a double-sided surface), and bent back towards a viewer
// it faces away from (NORMAL_BEND, shared/surface: as a file's normal map is). Where it is
// degenerate it is the geometric normal, derivative zero. The directions are held fixed:
// the derivative of a value that depends on the normal is its gradient in n through this
// matrix.
struct MappedNormal {
    n: vec3f,
    d: mat3x3f,
}

fn optimized_normal(sf: Surface, prev: bool) -> MappedNormal {
    var out = MappedNormal(sf.ng, mat3x3f());
    let p = param_textures[materials[sf.material].param_normal];
    let saved = use_prev_params;
    use_prev_params = prev;
    let rgb = param_value(p, param_footprint(p, sf.uv));
    use_prev_params = saved;
    let z = 2.0 * rgb.z - 1.0;
    let m = sf.tbn * vec3f(2.0 * rgb.xy - 1.0, max(z, NORMAL_Z_FLOOR));
    let len = length(m);
    if !(len > 0.0) {
        return out;
    }
    let s = select(-1.0, 1.0, sf.front);
    var n = m * (s / len);
    let eye = mat3x3f(vec3f(1.0, 0.0, 0.0), vec3f(0.0, 1.0, 0.0), vec3f(0.0, 0.0, 1.0));
    // d(s m / |m|)/dm = s (I - n n^T) / |m|; dm/dRGB = 2 tbn (Z's column 0 below the floor).
    var d = (eye - mat3x3f(n * n.x, n * n.y, n * n.z)) * (s / len);
    d = d * mat3x3f(2.0 * sf.tbn[0], 2.0 * sf.tbn[1], select(0.0, 2.0, z > NORMAL_Z_FLOOR) * sf.tbn[2]);
    let c = dot(n, sf.wo);
    if c < NORMAL_BEND {
        // Bent towards the viewer until n.wo = NORMAL_BEND (before normalizing): continuous
        // where a falling back to the geometric normal would jump, and so differentiable.
        let nb = n + (NORMAL_BEND - c) * sf.wo;
        let lb = length(nb);
        if !(lb > 0.0) {
            return out;
        }
        n = nb / lb;
        let wo = sf.wo;
        d = (eye - mat3x3f(n * n.x, n * n.y, n * n.z)) * (1.0 / lb) * (eye - mat3x3f(wo * wo.x, wo * wo.y, wo * wo.z)) * d;
    }
    out.n = n;
    out.d = d;
    return out;
}

// sf's shading frame under the current or (prev) the previous iteration's textures: they
// differ only where an optimized normal map changed.
fn frame_of(sf: Surface, prev: bool) -> mat3x3f {
    if !prev || materials[sf.material].param_normal == NONE {
        return sf.frame;
    }
    return onb(optimized_normal(sf, true).n);
}

// The derivative of BRDF x cos (directions wo, wi in sf's frame under the state prev
// selects) with respect to the RGB of sf's optimized normal map at the point: column c is
// image channel c's gradient (R, G, B of the map): the BRDF's gradient in the normal
// (brdf_normal_grad), taken to world space by the frame and back through the map's d n/d RGB.
fn normal_rgb_grad(sf: Surface, prev: bool, mat: SurfaceMaterial, wo: vec3f, wi: vec3f) -> mat3x3f {
    let mn = optimized_normal(sf, prev);
    return transpose(mn.d) * onb(mn.n) * brdf_normal_grad(mat, wo, wi);
}
