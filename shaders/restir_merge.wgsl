// ReSTIR merge pass, one invocation per texel: temporal reuse by generalized RIS in path
// space. Inputs of the merge for sign s (the positive or the negative part of the target):
//   - the fresh reservoir of this iteration for s (its W = Wsum / q_cur(y), confidence M_c);
//   - both reservoirs kept from the previous iteration, whatever their sign was: each is
//     offered here and its weight is zero unless its sample's current target has sign s
//     (sign routing), confidence M_k = min(M_c x merges so far, M_cap).
// Every kept reservoir is an input of the MIS weights even when it holds no sample: its
// unbiased contribution weight already accounts for the chance of being empty, so leaving its
// target out of the others' weights when it happens to be empty would count that part of the
// domain twice (a bias that grows with M_cap when the adjoint is noisy). For the same reason
// the confidences are the same for every reservoir (a function of the iteration count), never
// a count carried by the reservoir itself, which would correlate with its weight.
// Geometry, cameras and lights do not change during a texture optimization, so a stored path
// (pixel, camera-ray hit, incident direction, incident radiance; visibility was tested when it
// was drawn) stays a valid path with the same value of everything but the BRDF and the
// adjoint. The shift is the identity in path space (Jacobian 1): a kept sample is evaluated
// under the current textures and adjoint by one BRDF-with-derivative evaluation from what the
// reservoir stores of the hit (material, texture coordinates, shading-frame directions): no
// geometry is read. A fresh sample's target under the previous textures and adjoint (both
// double-buffered) comes with it from the candidate pass (RES_Q_PREV), which evaluated the
// same path there; with the verify flag the merge evaluates it again and compares. Nothing here traces a ray: shared/bvh is not part of this pass (a test checks the
// composed module).
// MIS: balance heuristic with confidences over the inputs' own targets.
#import shared/rng
#import shared/surface
#import gen/restir_layout

// Mirrored by MergeParams in src/optim/estimator/restir.rs. flags: MERGE_FLAG_* (generated).
struct MergeParams {
    n_texels: u32,
    n_pixels: u32,
    seed: u32,
    flags: u32,
    m_fresh: f32,
    // Confidence of the kept inputs this iteration (0 without reuse).
    m_kept: f32,
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
// MERGE_STAT_* slots (generated from src/optim/estimator/restir.rs).
@group(1) @binding(6) var<storage, read_write> mstats: array<atomic<u32>, 4>;

var<private> evaluations: u32 = 0u;
var<private> dropped: u32 = 0u;

struct Stored {
    info: u32,
    w: f32,
    v: vec3f,
    vertex: PathVertex,
    radiance: vec3f,
    // Fresh reservoirs: the target under the previous state (see RES_Q_PREV).
    q_prev: f32,
}

fn unpack(words: array<u32, RESERVOIR_WORDS>) -> Stored {
    var s: Stored;
    s.info = words[RES_INFO];
    s.w = bitcast<f32>(words[RES_W]);
    s.v = vec3f(bitcast<f32>(words[RES_VALUE]), bitcast<f32>(words[RES_VALUE + 1u]), bitcast<f32>(words[RES_VALUE + 2u]));
    s.vertex = PathVertex(
        words[RES_MATERIAL],
        vec2f(bitcast<f32>(words[RES_UV]), bitcast<f32>(words[RES_UV + 1u])),
        vec2f(bitcast<f32>(words[RES_WO]), bitcast<f32>(words[RES_WO + 1u])),
        vec2f(bitcast<f32>(words[RES_WI]), bitcast<f32>(words[RES_WI + 1u])),
    );
    s.radiance = vec3f(bitcast<f32>(words[RES_RADIANCE]), bitcast<f32>(words[RES_RADIANCE + 1u]), bitcast<f32>(words[RES_RADIANCE + 2u]));
    s.q_prev = bitcast<f32>(words[RES_Q_PREV]);
    return s;
}

fn load_kept(r: u32) -> Stored {
    var words: array<u32, RESERVOIR_WORDS>;
    for (var k = 0u; k < RESERVOIR_WORDS; k++) {
        words[k] = kept[r * RESERVOIR_WORDS + k];
    }
    return unpack(words);
}

fn load_fresh(r: u32) -> Stored {
    var words: array<u32, RESERVOIR_WORDS>;
    for (var k = 0u; k < RESERVOIR_WORDS; k++) {
        words[k] = merged[r * RESERVOIR_WORDS + k];
    }
    return unpack(words);
}

fn store_merged(r: u32, s: Stored) {
    let b = r * RESERVOIR_WORDS;
    merged[b + RES_INFO] = s.info;
    merged[b + RES_W] = bitcast<u32>(s.w);
    merged[b + RES_VALUE] = bitcast<u32>(s.v.x);
    merged[b + RES_VALUE + 1u] = bitcast<u32>(s.v.y);
    merged[b + RES_VALUE + 2u] = bitcast<u32>(s.v.z);
    merged[b + RES_MATERIAL] = s.vertex.material;
    merged[b + RES_UV] = bitcast<u32>(s.vertex.uv.x);
    merged[b + RES_UV + 1u] = bitcast<u32>(s.vertex.uv.y);
    merged[b + RES_WO] = bitcast<u32>(s.vertex.wo.x);
    merged[b + RES_WO + 1u] = bitcast<u32>(s.vertex.wo.y);
    merged[b + RES_WI] = bitcast<u32>(s.vertex.wi.x);
    merged[b + RES_WI + 1u] = bitcast<u32>(s.vertex.wi.y);
    merged[b + RES_RADIANCE] = bitcast<u32>(s.radiance.x);
    merged[b + RES_RADIANCE + 1u] = bitcast<u32>(s.radiance.y);
    merged[b + RES_RADIANCE + 2u] = bitcast<u32>(s.radiance.z);
    merged[b + RES_Q_PREV] = bitcast<u32>(s.q_prev);
}

// Target of reservoir sign s (0 positive, 1 negative) for signed target q; |q| without
// positivization.
fn tau(q: f32, s: u32) -> f32 {
    if (mp.flags & MERGE_FLAG_POSITIVIZE) == 0u {
        return abs(q);
    }
    return max(select(q, -q, s == 1u), 0.0);
}

// Value of the stored path for texel `local` of texture `ti`, under the current (prev =
// false) or previous textures and adjoint.
fn evaluate(st: Stored, ti: u32, local: u32, prev: bool) -> vec3f {
    evaluations += 1u;
    let cam_index = min((st.info >> INFO_CAMERA_SHIFT) & INFO_CAMERA_MASK, MAX_CAMERAS - 1u);
    let pixel = st.info & INFO_PIXEL_MASK;
    let a = cam_index * mp.n_pixels + pixel;
    var adj = adjoint[a].xyz;
    if prev {
        adj = adjoint_prev[a].xyz;
    }
    use_prev_params = prev;
    let v = path_value(st.vertex, st.radiance, adj * mp.inv_spp, ti, local);
    use_prev_params = false;
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
    let n_signs = select(1u, 2u, (mp.flags & MERGE_FLAG_POSITIVIZE) != 0u);
    let reuse = (mp.flags & MERGE_FLAG_TEMPORAL) != 0u && (mp.flags & MERGE_FLAG_HAVE_PREV) != 0u;
    // Most texels of a typical task hold no sample at all (unobserved, or not hit this
    // iteration and never before): their merged reservoirs stay empty (the fresh ones' W is
    // 0 already) and their gradient is 0, found from four words.
    var any_sample = false;
    for (var r = 0u; r < n_signs; r++) {
        any_sample = any_sample || bitcast<f32>(merged[(2u * t + r) * RESERVOIR_WORDS + RES_W]) > 0.0;
        if reuse {
            any_sample = any_sample || bitcast<f32>(kept[(2u * t + r) * RESERVOIR_WORDS + RES_W]) > 0.0;
        }
    }
    if !any_sample {
        for (var c = 0u; c < ch; c++) {
            grad[p.offset + local * ch + c] = 0.0;
        }
        return;
    }

    // Kept samples (their values under the previous state are stored) and fresh samples
    // (their values under the current state and their targets under the previous one are
    // stored). Evaluated: each kept sample under the current state.
    var k_st: array<Stored, 2>;
    var k_ok: array<bool, 2>;
    var k_cur: array<vec3f, 2>;
    var k_qprev: array<f32, 2>;
    var k_qcur: array<f32, 2>;
    var f_st: array<Stored, 2>;
    var f_ok: array<bool, 2>;
    var c_qprev: array<f32, 2>;
    for (var r = 0u; r < 2u; r++) {
        k_ok[r] = false;
        k_qcur[r] = 0.0;
        if reuse && r < n_signs {
            let st = load_kept(2u * t + r);
            if st.w > 0.0 {
                k_st[r] = st;
                k_ok[r] = true;
                k_qprev[r] = target_of(st.v, ch);
                k_cur[r] = evaluate(st, ti, local, false);
                k_qcur[r] = target_of(k_cur[r], ch);
                if (mp.flags & MERGE_FLAG_VERIFY) != 0u {
                    // The stored value was computed under the previous state: evaluating the
                    // stored path there must give it back. Record the largest relative error.
                    let again = evaluate(st, ti, local, true);
                    let err = length(again - st.v) / max(length(st.v), 1e-30);
                    atomicAdd(&mstats[MERGE_STAT_VERIFIED], 1u);
                    atomicMax(&mstats[MERGE_STAT_VERIFY_MAX_ERROR], bitcast<u32>(min(err, 3.0e38)));
                }
            }
        }
    }
    for (var s = 0u; s < 2u; s++) {
        f_ok[s] = false;
        c_qprev[s] = 0.0;
        if s < n_signs {
            f_st[s] = load_fresh(2u * t + s);
            f_ok[s] = f_st[s].w > 0.0;
            if f_ok[s] && reuse {
                c_qprev[s] = f_st[s].q_prev;
                if (mp.flags & MERGE_FLAG_VERIFY) != 0u {
                    // The candidate pass evaluated the same path under the same state, in
                    // another shader (so the rounding may differ). The error is relative to
                    // the larger of the sample's targets under both states, the scale at
                    // which q_prev enters the MIS weights (a target near zero is a sum that
                    // cancels, whose own relative rounding error is unbounded).
                    let again = target_of(evaluate(f_st[s], ti, local, true), ch);
                    let scale = max(max(abs(again), abs(target_of(f_st[s].v, ch))), 1e-30);
                    let err = abs(again - c_qprev[s]) / scale;
                    atomicAdd(&mstats[MERGE_STAT_VERIFIED], 1u);
                    atomicMax(&mstats[MERGE_STAT_VERIFY_MAX_ERROR], bitcast<u32>(min(err, 3.0e38)));
                }
            }
        }
    }
    // Confidence-weighted balance heuristic over all inputs, empty ones included.
    let m_c = mp.m_fresh;
    let m_k = select(0.0, mp.m_kept, reuse);
    var g = vec3f(0.0);
    for (var s = 0u; s < 2u; s++) {
        var empty: Stored;
        empty.info = 0u;
        empty.w = 0.0;
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
            let own = m_c * tau(c_qcur, s);
            var den = own;
            for (var r = 0u; r < n_signs; r++) {
                den += m_k * tau(c_qprev[s], r);
            }
            let big_w = fresh.w / tau(c_qcur, s);
            w[0] = select(0.0, own / den * tau(c_qcur, s) * big_w, den > 0.0);
        }
        for (var r = 0u; r < 2u; r++) {
            w[r + 1u] = 0.0;
            if k_ok[r] && tau(k_qcur[r], s) > 0.0 {
                let own = m_k * tau(k_qprev[r], r);
                var den = m_c * tau(k_qcur[r], s);
                for (var r2 = 0u; r2 < n_signs; r2++) {
                    den += m_k * tau(k_qprev[r], r2);
                }
                w[r + 1u] = select(0.0, own / den * tau(k_qcur[r], s) * k_st[r].w, den > 0.0);
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
        store_merged(2u * t + s, out);
        g += out.v * out.w;
    }
    for (var c = 0u; c < ch; c++) {
        grad[p.offset + local * ch + c] = g[c];
    }
    atomicAdd(&mstats[MERGE_STAT_EVALUATIONS], evaluations);
    if dropped > 0u {
        atomicAdd(&mstats[MERGE_STAT_DROPPED], dropped);
    }
}
