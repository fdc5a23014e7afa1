// ReSTIR merge pass, one invocation per texel: temporal reuse by generalized RIS.
// Inputs of the merge for sign s (the positive or the negative part of the target):
//   - the fresh reservoir of this iteration for s (its W = Wsum / q_cur(y), confidence M_c);
//   - both reservoirs kept from the previous iteration, whatever their sign was: each is
//     offered here and its weight is zero unless its sample's current target has sign s
//     (sign routing), confidence min(M, M_cap).
// Kept samples are replayed from their random numbers (camera-sample index, seed, technique:
// the shift is the identity in primary sample space, Jacobian 1) under the current textures
// and adjoint; the fresh sample is replayed under the previous ones, both double-buffered.
// Geometry and cameras are fixed, so a replay starts from the stored camera-ray hit and, for
// a light sample (unoccluded when drawn, or it would have no weight), skips the shadow ray:
// only BSDF samples trace a ray, since their direction depends on the textures.
// MIS: balance heuristic with confidences over the inputs' own targets.
#import shared/rng
#import shared/camera
#import shared/integrator

const MAX_CAMERAS: u32 = 8u;
const FLAG_TEMPORAL: u32 = 1u;
const FLAG_POSITIVIZE: u32 = 2u;
const FLAG_HAVE_PREV: u32 = 4u;

// Keep in sync with GpuMergeParams in src/render/layout.rs.
struct MergeParams {
    cameras: array<CameraInfo, MAX_CAMERAS>,
    n_texels: u32,
    n_pixels: u32,
    seed: u32,
    flags: u32,
    m_fresh: f32,
    m_cap: f32,
    inv_spp: f32,
    n_textures: u32,
    stride: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(1) @binding(0) var<uniform> mp: MergeParams;
@group(1) @binding(1) var<storage, read> adjoint: array<vec4f>;
@group(1) @binding(2) var<storage, read> adjoint_prev: array<vec4f>;
@group(1) @binding(3) var<storage, read> kept: array<u32>;
// Fresh reservoirs in, merged reservoirs out (each texel's invocation owns its two).
@group(1) @binding(4) var<storage, read_write> merged: array<u32>;
@group(1) @binding(5) var<storage, read_write> grad: array<f32>;
// [0] replays, [1] non-finite replays dropped.
@group(1) @binding(6) var<storage, read_write> mstats: array<atomic<u32>, 4>;

var<private> replays: u32 = 0u;
var<private> dropped: u32 = 0u;

struct Stored {
    sample: u32,
    seed: u32,
    info: u32,
    w: f32,
    m: f32,
    v: vec3f,
    hit: Hit,
}

fn load_kept(r: u32) -> Stored {
    let b = r * RESERVOIR_WORDS;
    return Stored(kept[b], kept[b + 1u], kept[b + 2u], bitcast<f32>(kept[b + 3u]), bitcast<f32>(kept[b + 4u]), vec3f(bitcast<f32>(kept[b + 5u]), bitcast<f32>(kept[b + 6u]), bitcast<f32>(kept[b + 7u])), Hit(bitcast<f32>(kept[b + 8u]), kept[b + 9u], bitcast<f32>(kept[b + 10u]), bitcast<f32>(kept[b + 11u])));
}

fn load_fresh(r: u32) -> Stored {
    let b = r * RESERVOIR_WORDS;
    return Stored(merged[b], merged[b + 1u], merged[b + 2u], bitcast<f32>(merged[b + 3u]), bitcast<f32>(merged[b + 4u]), vec3f(bitcast<f32>(merged[b + 5u]), bitcast<f32>(merged[b + 6u]), bitcast<f32>(merged[b + 7u])), Hit(bitcast<f32>(merged[b + 8u]), merged[b + 9u], bitcast<f32>(merged[b + 10u]), bitcast<f32>(merged[b + 11u])));
}

fn store_merged(r: u32, s: Stored) {
    let b = r * RESERVOIR_WORDS;
    merged[b] = s.sample;
    merged[b + 1u] = s.seed;
    merged[b + 2u] = s.info;
    merged[b + 3u] = bitcast<u32>(s.w);
    merged[b + 4u] = bitcast<u32>(s.m);
    merged[b + 5u] = bitcast<u32>(s.v.x);
    merged[b + 6u] = bitcast<u32>(s.v.y);
    merged[b + 7u] = bitcast<u32>(s.v.z);
    merged[b + 8u] = bitcast<u32>(s.hit.t);
    merged[b + 9u] = s.hit.tri;
    merged[b + 10u] = bitcast<u32>(s.hit.b1);
    merged[b + 11u] = bitcast<u32>(s.hit.b2);
}

// The target of a value: luminance for RGB textures, the value for scalar ones.
fn target_of(v: vec3f, channels: u32) -> f32 {
    if channels == 3u {
        return luminance(v);
    }
    return v.x;
}

// Target of reservoir sign s (0 positive, 1 negative) for signed target q; |q| without
// positivization.
fn tau(q: f32, s: u32) -> f32 {
    if (mp.flags & FLAG_POSITIVIZE) == 0u {
        return abs(q);
    }
    return max(select(q, -q, s == 1u), 0.0);
}

// Value v of the stored sample for texel `local` of texture `ti`, under the current (prev =
// false) or previous textures and adjoint.
fn replay(st: Stored, ti: u32, local: u32, prev: bool) -> vec3f {
    replays += 1u;
    let cam_index = min((st.info >> 1u) & 127u, MAX_CAMERAS - 1u);
    let cam = mp.cameras[cam_index];
    let pixel = st.sample % mp.n_pixels;
    let a = cam_index * mp.n_pixels + pixel;
    var adj = adjoint[a].xyz;
    if prev {
        adj = adjoint_prev[a].xyz;
    }
    adj *= mp.inv_spp;
    if all(adj == vec3f(0.0)) {
        return vec3f(0.0);
    }
    use_prev_params = prev;
    rng_init(st.seed, st.sample, 0u);
    let xy = vec2f(f32(pixel % cam.width), f32(pixel / cam.width));
    // The jittered direction (for the outgoing direction, and to keep the random numbers in
    // step); the hit is the stored one.
    let d = camera_direction(cam, xy + rand2());
    if st.hit.tri >= arrayLength(&tri_shading) {
        return vec3f(0.0);
    }
    let sf = surface_at(cam.origin, d, st.hit);
    if !sf.valid {
        return vec3f(0.0);
    }
    let m = materials[sf.material];
    var slot = NONE;
    for (var s = 0u; s < 3u; s++) {
        if material_param(m, s) == ti {
            slot = s;
        }
    }
    if slot == NONE {
        return vec3f(0.0);
    }
    let fp = footprint_merged(param_footprint(param_textures[ti], sf.uv));
    var wf = 0.0;
    for (var k = 0u; k < 4u; k++) {
        if fp.texel[k] == local {
            wf += fp.weight[k];
        }
    }
    if wf == 0.0 {
        return vec3f(0.0);
    }
    let mat = surface_material(sf);
    let wo = to_local(sf.frame, sf.wo);
    // The random numbers in the order of sample_direct: 3 for light sampling, then 3 for
    // BSDF sampling.
    var ds: DirectSample;
    if (st.info & 1u) == 0u {
        let u_pick = rand();
        let u_light = rand2();
        assume_visible = true;
        ds = nee_sample(sf, mat, u_pick, u_light);
        assume_visible = false;
    } else {
        _ = rand();
        _ = rand2();
        let u_bsdf = vec3f(rand(), rand2());
        ds = bsdf_direct_sample(sf, mat, u_bsdf);
    }
    let v = wf * slot_derivative(slot, brdf_eval_cos_grad(mat, wo, to_local(sf.frame, ds.wi)), ds.weight, adj);
    if !all(abs(v) < vec3f(3.0e38)) {
        dropped += 1u;
        return vec3f(0.0);
    }
    return v;
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3u) {
    let t = id.x + id.y * mp.stride;
    if t >= mp.n_texels {
        return;
    }
    // The texture holding texel t.
    var ti = 0u;
    for (var k = 0u; k < mp.n_textures; k++) {
        let p = param_textures[k];
        if t >= p.texel_offset && t < p.texel_offset + p.width * p.height {
            ti = k;
        }
    }
    let p = param_textures[ti];
    let local = t - p.texel_offset;
    let ch = p.channels;
    let n_signs = select(1u, 2u, (mp.flags & FLAG_POSITIVIZE) != 0u);
    let reuse = (mp.flags & FLAG_TEMPORAL) != 0u && (mp.flags & FLAG_HAVE_PREV) != 0u;

    // Kept samples (their previous values are stored) and fresh samples. Replays: each kept
    // sample under the current textures and adjoint, each fresh sample under the previous
    // ones (only needed when there is a kept sample to weigh it against). The replays are
    // gathered into one list and run from one loop, so that the invocations of a SIMD group
    // replay together whatever their mix of inputs.
    var k_st: array<Stored, 2>;
    var k_ok: array<bool, 2>;
    var k_cur: array<vec3f, 2>;
    var k_qprev: array<f32, 2>;
    var k_qcur: array<f32, 2>;
    var k_m: array<f32, 2>;
    var f_st: array<Stored, 2>;
    var f_ok: array<bool, 2>;
    var c_qprev: array<f32, 2>;
    var any_kept = false;
    var jobs: array<u32, 4>;
    var n_jobs = 0u;
    for (var r = 0u; r < 2u; r++) {
        k_ok[r] = false;
        if reuse && r < n_signs {
            let st = load_kept(2u * t + r);
            if st.info != NONE && st.w > 0.0 {
                k_st[r] = st;
                k_ok[r] = true;
                any_kept = true;
                k_qprev[r] = target_of(st.v, ch);
                k_m[r] = min(st.m, mp.m_cap);
                jobs[n_jobs] = r;
                n_jobs += 1u;
            }
        }
    }
    for (var s = 0u; s < 2u; s++) {
        f_ok[s] = false;
        c_qprev[s] = 0.0;
        if s < n_signs {
            f_st[s] = load_fresh(2u * t + s);
            f_ok[s] = f_st[s].info != NONE && f_st[s].w > 0.0;
            if f_ok[s] && any_kept {
                jobs[n_jobs] = 2u + s;
                n_jobs += 1u;
            }
        }
    }
    for (var j = 0u; j < n_jobs; j++) {
        let job = jobs[j];
        if job < 2u {
            k_cur[job] = replay(k_st[job], ti, local, false);
            k_qcur[job] = target_of(k_cur[job], ch);
        } else {
            c_qprev[job - 2u] = target_of(replay(f_st[job - 2u], ti, local, true), ch);
        }
    }

    var g = vec3f(0.0);
    for (var s = 0u; s < 2u; s++) {
        let empty = Stored(0u, 0u, NONE, 0.0, 0.0, vec3f(0.0), Hit(0.0, NONE, 0.0, 0.0));
        if s >= n_signs {
            store_merged(2u * t + s, empty);
            continue;
        }
        let fresh = f_st[s];
        let c_ok = f_ok[s];
        let c_qcur = target_of(fresh.v, ch);
        // Resampling weights m_r(y_r) * tau_s(q_cur(y_r)) * W_r.
        var w: array<f32, 3>;
        w[0] = 0.0;
        if c_ok {
            let own = mp.m_fresh * tau(c_qcur, s);
            var den = own;
            for (var r = 0u; r < 2u; r++) {
                if k_ok[r] {
                    den += k_m[r] * tau(c_qprev[s], r);
                }
            }
            let big_w = fresh.w / tau(c_qcur, s);
            w[0] = select(0.0, own / den * tau(c_qcur, s) * big_w, den > 0.0);
        }
        var m_new = mp.m_fresh;
        for (var r = 0u; r < 2u; r++) {
            w[r + 1u] = 0.0;
            if k_ok[r] && tau(k_qcur[r], s) > 0.0 {
                let own = k_m[r] * tau(k_qprev[r], r);
                var den = mp.m_fresh * tau(k_qcur[r], s);
                for (var r2 = 0u; r2 < 2u; r2++) {
                    if k_ok[r2] {
                        den += k_m[r2] * tau(k_qprev[r], r2);
                    }
                }
                w[r + 1u] = select(0.0, own / den * tau(k_qcur[r], s) * k_st[r].w, den > 0.0);
                m_new += k_m[r];
            }
        }
        let total = w[0] + w[1] + w[2];
        if !(total > 0.0) || !(total < 3.0e38) {
            store_merged(2u * t + s, empty);
            continue;
        }
        rng_init(mp.seed, t, 1u + s);
        let u = rand() * total;
        var pick = 0u;
        if u >= w[0] {
            pick = select(2u, 1u, u < w[0] + w[1]);
        }
        // Guard against rounding picking a zero-weight input.
        if w[pick] <= 0.0 {
            pick = select(select(2u, 1u, w[1] > 0.0), 0u, w[0] > 0.0);
        }
        var out: Stored;
        var q = 0.0;
        if pick == 0u {
            out = fresh;
            q = tau(c_qcur, s);
        } else {
            out = k_st[pick - 1u];
            out.v = k_cur[pick - 1u];
            q = tau(k_qcur[pick - 1u], s);
        }
        out.w = total / q;
        out.m = m_new;
        store_merged(2u * t + s, out);
        g += out.v * out.w;
    }
    for (var c = 0u; c < ch; c++) {
        grad[p.offset + local * ch + c] = g[c];
    }
    atomicAdd(&mstats[0], replays);
    if dropped > 0u {
        atomicAdd(&mstats[1], dropped);
    }
}
