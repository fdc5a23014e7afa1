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
// (pixel, its vertices from the camera ray's hit on, the incident direction and radiance at
// the last one; visibility was tested when it was drawn) stays a valid path with the same
// value of everything but the BRDFs and the adjoint. The shift is the identity in path space
// (Jacobian 1): a stored sample, fresh or kept, is evaluated under the current textures from
// its compact form (compact_path.wgsl): every vertex is rebuilt from its triangle and
// barycentrics and the previous vertex's position (the camera's for the first): texture
// coordinates, shading frame, the directions to its neighbours, the glTF material's inputs
// there; its factor e is the derivative of vertex k's BRDF cos times the radiance times every
// other vertex's BRDF cos (a 3x3 matrix for a normal-map texel: shared/params.wgsl,
// TexelFactor), each in the shading frame of the textures it is evaluated under; its value is the pixel's adjoint times e, its target
// target_of(the pixel's target adjoint times e). Its target under the previous state is
// stored with it: the candidate pass computes it for a fresh sample, and the merge stores
// each merged sample's current target, which is its previous-state target at the next merge. With the verify flag the merge
// evaluates every stored path under the previous state as well and compares. Nothing here
// traces a ray: shared/bvh is not part of this pass (a test checks the composed module).
// MIS: balance heuristic with confidences over the inputs' own targets.
// Selection is in place: a texel's four reservoir slots hold its two kept reservoirs and the
// two fresh ones (reservoir.wgsl); the merged reservoir of sign s is whichever input
// it selected, where it already lies, with its W and its target rewritten, and the texel's
// header says which slot that is. The two slots the new header leaves free are emptied
// (W = 0, info word 0) for the next iteration's candidates. One invocation per observed
// texel (observed_list).
#import shared/rng
#import restir/compact_path
#import restir/target
#import restir/reservoir_slots
#import gen/abi
#import gen/restir

// Mirrored by MergeParams in src/optim/estimator/restir/mod.rs. flags: MERGE_FLAG_* (generated).
struct MergeParams {
    // Observed texels (invocations).
    n_observed: u32,
    n_pixels: u32,
    seed: u32,
    flags: u32,
    m_fresh: f32,
    // Confidence of the kept inputs this iteration (0 without reuse).
    m_kept: f32,
    inv_spp: f32,
    n_textures: u32,
    stride: u32,
    // Where this iteration's and the last iteration's target adjoints start in `targets`.
    target_cur: u32,
    target_prev: u32,
    // The moving moments' decay of the fresh estimates and their bias correction (1 -
    // decay^iterations), and the factor that turns a fresh estimate's variance into the
    // merged estimate's (variance_factor in mod.rs; 0: no variance reported).
    moment_decay: f32,
    moment_bias: f32,
    variance_factor: f32,
    _pad0: u32,
    _pad1: u32,
    // The cameras' positions (xyz), by the camera index of a reservoir's info word.
    origins: array<vec4f, MAX_CAMERAS>,
}

@group(1) @binding(0) var<uniform> mp: MergeParams;
@group(1) @binding(1) var<storage, read> adjoint: array<vec4f>;
// The target adjoints of this iteration and the last (reservoir.wgsl).
@group(1) @binding(2) var<storage, read> targets: array<vec4f>;
// Slot k of every observed texel's reservoirs, and their headers (each observed texel's
// invocation owns its four slots and its header).
@group(1) @binding(3) var<storage, read_write> slots0: array<u32>;
@group(1) @binding(4) var<storage, read_write> slots1: array<u32>;
@group(1) @binding(5) var<storage, read_write> slots2: array<u32>;
@group(1) @binding(6) var<storage, read_write> slots3: array<u32>;
@group(1) @binding(7) var<storage, read_write> headers: array<u32>;
@group(1) @binding(8) var<storage, read_write> grad: array<f32>;
// MERGE_STAT_* slots (generated from abi.rs).
@group(1) @binding(9) var<storage, read_write> mstats: array<atomic<u32>, 4>;
// The texel (index into all optimized texels) of each observed texel.
@group(1) @binding(10) var<storage, read> observed_list: array<u32>;
// Per gradient entry: the moving mean and second moment of the fresh candidates' own
// estimate (the fresh reservoirs alone, without what was kept), and the variance of the
// merged estimate the step divides by (Estimator::variance).
@group(1) @binding(11) var<storage, read_write> fresh_moments: array<vec2f>;
@group(1) @binding(12) var<storage, read_write> variance: array<f32>;

var<private> evaluations: u32 = 0u;
var<private> dropped: u32 = 0u;

// Word j of slot k's buffer.
fn slot_word(k: u32, j: u32) -> u32 {
    switch k {
        case 0u: {
            return slots0[j];
        }
        case 1u: {
            return slots1[j];
        }
        case 2u: {
            return slots2[j];
        }
        default: {
            return slots3[j];
        }
    }
}

fn set_slot_word(k: u32, j: u32, x: u32) {
    switch k {
        case 0u: {
            slots0[j] = x;
        }
        case 1u: {
            slots1[j] = x;
        }
        case 2u: {
            slots2[j] = x;
        }
        default: {
            slots3[j] = x;
        }
    }
}

// A stored path rebuilt: its info word, W, the path and its vertices.
struct Stored {
    info: u32,
    w: f32,
    path: PathWords,
    dp: DecodedPath,
}

// The res_stride words from word b of slot k's buffer (the rest 0), read in one switch.
fn slot_words(k: u32, b: u32) -> array<u32, RESERVOIR_WORDS_MAX> {
    var w: array<u32, RESERVOIR_WORDS_MAX>;
    switch k {
        case 0u: {
            for (var j = 0u; j < res_stride; j++) {
                w[j] = slots0[b + j];
            }
        }
        case 1u: {
            for (var j = 0u; j < res_stride; j++) {
                w[j] = slots1[b + j];
            }
        }
        case 2u: {
            for (var j = 0u; j < res_stride; j++) {
                w[j] = slots2[b + j];
            }
        }
        default: {
            for (var j = 0u; j < res_stride; j++) {
                w[j] = slots3[b + j];
            }
        }
    }
    return w;
}

// The position of the camera that a stored path's info word names.
fn origin_of(info: u32) -> vec3f {
    let cam = min((info >> INFO_CAMERA_SHIFT) & INFO_CAMERA_MASK, MAX_CAMERAS - 1u);
    return mp.origins[cam].xyz;
}

// The reservoir in slot k of observed texel i, in the current textures' frames.
fn load(k: u32, i: u32) -> Stored {
    let w = slot_words(k, i * res_stride);
    var pw: array<u32, RES_PATH_WORDS>;
    for (var j = 0u; j < RES_PATH_WORDS; j++) {
        pw[j] = w[RES_TRI + j];
    }
    let path = unpack_path(pw);
    let info = w[RES_INFO];
    return Stored(info, bitcast<f32>(w[RES_W]), path, decode_path(origin_of(info), path, false));
}

fn slot_w(k: u32, i: u32) -> f32 {
    return bitcast<f32>(slot_word(k, i * res_stride + RES_W));
}

fn set_w(k: u32, i: u32, w: f32) {
    set_slot_word(k, i * res_stride + RES_W, bitcast<u32>(w));
}

// The weight sum of the fresh reservoir in slot k of texel i. If the candidate pass's second
// phase wrote no path into it (its info word still holds a race key, reservoir.wgsl: the two
// phases computed a key differently), it is emptied, counted as dropped, and 0.
fn fresh_weight(k: u32, i: u32) -> f32 {
    let w = slot_w(k, i);
    let info = i * res_stride + RES_INFO;
    if w != 0.0 && (slot_word(k, info) & INFO_KEY_BIT) != 0u {
        dropped += 1u;
        set_w(k, i, 0.0);
        set_slot_word(k, info, 0u);
        return 0.0;
    }
    return w;
}

// Store q as the target under the previous state of the reservoir in slot k of texel i (the
// high bytes of its direction words).
fn set_q_prev(k: u32, i: u32, q: f32) {
    let b = i * res_stride;
    let h = bf16_pack(q);
    let low = (1u << PATH_OCT_BITS) - 1u;
    set_slot_word(k, b + RES_WI_X, (slot_word(k, b + RES_WI_X) & low) | ((h & 0xffu) << PATH_OCT_BITS));
    set_slot_word(k, b + RES_WI_Y, (slot_word(k, b + RES_WI_Y) & low) | ((h >> 8u) << PATH_OCT_BITS));
}

// Target of reservoir sign s (0 positive, 1 negative) for signed target q; |q| without
// positivization.
fn tau(q: f32, s: u32) -> f32 {
    if (mp.flags & MERGE_FLAG_POSITIVIZE) == 0u {
        return abs(q);
    }
    return max(select(q, -q, s == 1u), 0.0);
}

// The adjoints of the pixel a stored path (info word) starts at, divided by the spp: the
// iteration's (values) and the target adjoints of this iteration and the last (targets).
struct PixelAdjoints {
    value: vec3f,
    target_cur: vec3f,
    target_prev: vec3f,
}

fn pixel_adjoints(info: u32) -> PixelAdjoints {
    let cam_index = min((info >> INFO_CAMERA_SHIFT) & INFO_CAMERA_MASK, MAX_CAMERAS - 1u);
    let a = cam_index * mp.n_pixels + (info & INFO_PIXEL_MASK);
    return PixelAdjoints(adjoint[a].xyz * mp.inv_spp, targets[mp.target_cur + a].xyz * mp.inv_spp, targets[mp.target_prev + a].xyz * mp.inv_spp);
}

// Factor of the stored path for texel `local` of texture `ti` (shared/surface.wgsl,
// path_factor), under the current (prev = false) or previous textures: st decoded in the
// frames of the same textures.
fn evaluate(st: Stored, ti: u32, local: u32, prev: bool) -> TexelFactor {
    evaluations += 1u;
    let none = TexelFactor(vec3f(0.0), mat3x3f());
    if !st.dp.valid {
        return none;
    }
    use_prev_params = prev;
    let k = st.dp.k;
    let e = path_factor(st.dp.sf[k], st.dp.pv[k], arriving_at(st.dp, k), ti, local);
    use_prev_params = false;
    if !factor_finite(e) {
        dropped += 1u;
        return none;
    }
    return e;
}

// With the verify flag: the largest relative error of a re-evaluation.
fn record_verified(err: f32) {
    atomicAdd(&mstats[MERGE_STAT_VERIFIED], 1u);
    atomicMax(&mstats[MERGE_STAT_VERIFY_MAX_ERROR], bitcast<u32>(min(err, 3.0e38)));
}

// A stored sample: its target under the previous state (stored), and its value and target
// under the current state.
struct Evaluated {
    q_prev: f32,
    v: vec3f,
    q: f32,
}

// The reservoir in slot k of observed texel i, for texel `local` of texture ti with ch
// channels. With `verify`, its evaluation under the previous state is compared with the
// stored target: the error is relative to the larger of its targets under both states, the
// scale at which q_prev enters the MIS weights (a target near zero is a sum that cancels,
// whose own relative rounding error is unbounded).
// evaluate_stored for a path of one vertex (direct light, or the first vertex beyond
// MAX_PATH_VERTICES): the same value and target from the same words, read and rebuilt
// without the whole-path decoding's arrays (which a CPU device keeps in memory; measured on
// lavapipe: the merge of `sphere` in 30 ms instead of 44).
fn evaluate_first(k: u32, i: u32, ti: u32, local: u32, p: ParamTex) -> Evaluated {
    evaluations += 1u;
    let b = i * res_stride;
    let info = slot_word(k, b + RES_INFO);
    let v = unpack_vertex(slot_word(k, b + RES_TRI), slot_word(k, b + RES_BARY));
    let wx = slot_word(k, b + RES_WI_X);
    let wy = slot_word(k, b + RES_WI_Y);
    let radiance = rgbe_unpack(slot_word(k, b + RES_RADIANCE));
    let q_prev = bf16_unpack((wx >> PATH_OCT_BITS) | ((wy >> PATH_OCT_BITS) << 8u));
    let sf = surface_at(origin_of(info), stored_hit(v.x, v.yz));
    if !sf.valid {
        return Evaluated(q_prev, vec3f(0.0), 0.0);
    }
    let oct_mask = (1u << PATH_OCT_BITS) - 1u;
    let wi = stored_direction(sf, sf.frame, vec2u(wx & oct_mask, wy & oct_mask));
    let pv = path_vertex(sf, gltf_inputs(sf.material, sf.uv), wi);
    var e = path_factor(sf, pv, radiance, ti, local);
    if !factor_finite(e) {
        dropped += 1u;
        e = TexelFactor(vec3f(0.0), mat3x3f());
    }
    let pa = pixel_adjoints(info);
    return Evaluated(q_prev, texel_value(e, pa.value, p), target_of(texel_value(e, pa.target_cur, p), p));
}

fn evaluate_stored(k: u32, i: u32, ti: u32, local: u32, p: ParamTex, verify: bool) -> Evaluated {
    if !whole_paths() && !verify {
        return evaluate_first(k, i, ti, local, p);
    }
    var st = load(k, i);
    let pa = pixel_adjoints(st.info);
    let e = evaluate(st, ti, local, false);
    let q = target_of(texel_value(e, pa.target_cur, p), p);
    let v = texel_value(e, pa.value, p);
    if verify {
        // Under the previous textures, in their frames.
        if NORMAL_MAPS {
            st.dp = decode_path(origin_of(st.info), st.path, true);
        }
        let again = target_of(texel_value(evaluate(st, ti, local, true), pa.target_prev, p), p);
        let scale = max(max(abs(again), abs(q)), 1e-30);
        record_verified(abs(again - st.path.q_prev) / scale);
    }
    return Evaluated(st.path.q_prev, v, q);
}

// What the candidate pass added into gradient entry j: the later vertices' derivatives beyond
// MAX_PATH_VERTICES (the buffer was cleared before it; with whole paths nothing, 0); 0 at
// depth 1, where it is not cleared.
fn take_later(j: u32) -> f32 {
    if scene.max_depth <= 1u {
        return 0.0;
    }
    return grad[j];
}

// Gradient entry j of this iteration: the merged estimate g (plus what the candidate pass
// added there), and the variance the step divides by. A fresh estimate f (the fresh
// reservoirs' own RIS estimate, 0 where no candidate reached the texel: an unbiased
// estimate of the gradient from this iteration's samples alone, independent between
// iterations) updates its entry's moving moments; their variance is a fresh estimate's,
// rare hits included, and the merged estimate's is that times variance_factor: the merge
// averages the fresh candidates with the kept ones by confidence, M_c against M_k, as a
// moving average of weight M_c / (M_c + M_k) per iteration would. The spread of the merged
// estimates themselves is no measure of their error: a kept path carries a texel's estimate
// for many iterations.
fn write_entry(j: u32, g: f32, f: f32) {
    grad[j] = g + take_later(j);
    if mp.variance_factor == 0.0 {
        return;
    }
    let m = mp.moment_decay * fresh_moments[j] + (1.0 - mp.moment_decay) * vec2f(f, f * f);
    fresh_moments[j] = m;
    let mean = m.x / mp.moment_bias;
    variance[j] = max(m.y / mp.moment_bias - mean * mean, 0.0) * mp.variance_factor;
}

// A texel's inputs of the merge: the slots and weight sums of its fresh and kept
// reservoirs (signs 0 and 1; the kept ones' weights 0 without reuse) and their samples
// evaluated under the current state. Plain fields, not arrays indexed by a loop counter: on
// a CPU device those live in memory.
struct MergeInputs {
    fresh_k: vec2u,
    kept_k: vec2u,
    fresh_w: vec2f,
    kept_w: vec2f,
    f0: Evaluated,
    f1: Evaluated,
    k0: Evaluated,
    k1: Evaluated,
}

// `inputs` with every one that holds a sample (the fresh ones of signs 0 and 1, then the
// kept ones) evaluated for texel `local` of texture ti (p), in one loop so that
// neighbouring invocations run their evaluations together.
fn evaluate_inputs(inputs: MergeInputs, i: u32, ti: u32, local: u32, p: ParamTex, verify: bool) -> MergeInputs {
    var out = inputs;
    var rest = u32(inputs.fresh_w.x > 0.0) | (u32(inputs.fresh_w.y > 0.0) << 1u) | (u32(inputs.kept_w.x > 0.0) << 2u) | (u32(inputs.kept_w.y > 0.0) << 3u);
    while rest != 0u {
        let j = firstTrailingBit(rest);
        rest &= rest - 1u;
        let k = select(select(inputs.kept_k.y, inputs.kept_k.x, j == 2u), select(inputs.fresh_k.y, inputs.fresh_k.x, j == 0u), j < 2u);
        let e = evaluate_stored(k, i, ti, local, p, verify);
        switch j {
            case 0u: {
                out.f0 = e;
            }
            case 1u: {
                out.f1 = e;
            }
            case 2u: {
                out.k0 = e;
            }
            default: {
                out.k1 = e;
            }
        }
    }
    return out;
}

// What the merge of one sign kept: its term of the gradient (the selected sample's value x
// its W), the fresh reservoir's own estimate (write_entry), and the slot it lies in.
struct SignMerge {
    g: vec3f,
    fresh: vec3f,
    slot: u32,
}

// The merge of sign s of observed texel i (texel t of all optimized texels): the
// confidence-weighted balance heuristic over all inputs, empty ones included, and the
// selection in place (the selected reservoir's W and target rewritten where it lies; an
// empty merge leaves the fresh slot, with W = 0).
fn merge_sign(inputs: MergeInputs, s: u32, i: u32, t: u32, reuse: bool, n_signs: u32) -> SignMerge {
    var out = SignMerge(vec3f(0.0), vec3f(0.0), inputs.fresh_k[s]);
    let k_qprev = vec2f(inputs.k0.q_prev, inputs.k1.q_prev);
    let k_qcur = vec2f(inputs.k0.q, inputs.k1.q);
    let m_c = mp.m_fresh;
    let m_k = select(0.0, mp.m_kept, reuse);
    var c = inputs.f0;
    if s == 1u {
        c = inputs.f1;
    }
    let c_qcur = c.q;
    let c_qprev = select(0.0, c.q_prev, reuse);
    // The candidate pass offered the fresh sample to this sign for the sign of the same
    // target from the same stored path; a rounding difference between the two shaders that
    // flips a target of about zero drops it.
    var c_ok = inputs.fresh_w[s] > 0.0;
    if c_ok && !(tau(c_qcur, s) > 0.0) {
        c_ok = false;
        dropped += 1u;
    }
    // Resampling weights m_r(y_r) * tau_s(q_cur(y_r)) * W_r of the fresh input (w0) and the
    // kept ones (wk).
    var w0 = 0.0;
    if c_ok {
        out.fresh = c.v * (inputs.fresh_w[s] / tau(c_qcur, s));
        let own = m_c * tau(c_qcur, s);
        var den = own;
        for (var r = 0u; r < n_signs; r++) {
            den += m_k * tau(c_qprev, r);
        }
        let big_w = inputs.fresh_w[s] / tau(c_qcur, s);
        w0 = select(0.0, own / den * tau(c_qcur, s) * big_w, den > 0.0);
    }
    var wk = vec2f(0.0);
    for (var r = 0u; r < 2u; r++) {
        let qc = k_qcur[r];
        if inputs.kept_w[r] > 0.0 && tau(qc, s) > 0.0 {
            let qp = k_qprev[r];
            let own = m_k * tau(qp, r);
            var den = m_c * tau(qc, s);
            for (var r2 = 0u; r2 < n_signs; r2++) {
                den += m_k * tau(qp, r2);
            }
            wk[r] = select(0.0, own / den * tau(qc, s) * inputs.kept_w[r], den > 0.0);
        }
    }
    let total = w0 + wk.x + wk.y;
    if !(total > 0.0) || !(total < 3.0e38) {
        // Empty: the fresh slot (W = 0 from here on) stands for it.
        if inputs.fresh_w[s] > 0.0 {
            set_w(inputs.fresh_k[s], i, 0.0);
        }
        return out;
    }
    rng_init(mp.seed, t, 1u + s);
    let u = rand() * total;
    var pick = 0u;
    if u >= w0 {
        pick = select(2u, 1u, u < w0 + wk.x);
    }
    // Guard against rounding picking a zero-weight input.
    if (pick == 0u && w0 <= 0.0) || (pick == 1u && wk.x <= 0.0) || (pick == 2u && wk.y <= 0.0) {
        pick = select(select(2u, 1u, wk.x > 0.0), 0u, w0 > 0.0);
    }
    // A kept sample goes to at most one sign (its weight is zero for the other), so the two
    // merged reservoirs always lie in different slots.
    var v = c.v;
    var q = c_qcur;
    if pick != 0u {
        out.slot = inputs.kept_k[pick - 1u];
        v = select(inputs.k0.v, inputs.k1.v, pick == 2u);
        q = select(inputs.k0.q, inputs.k1.q, pick == 2u);
    }
    let w_out = total / tau(q, s);
    set_w(out.slot, i, w_out);
    // Its target now is its target under the previous state at the next merge.
    set_q_prev(out.slot, i, q);
    out.g = v * w_out;
    return out;
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3u) {
    res_stride = reservoir_stride();
    let i = id.x + id.y * mp.stride;
    if i >= mp.n_observed {
        return;
    }
    let t = observed_list[i];
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
    let verify = (mp.flags & MERGE_FLAG_VERIFY) != 0u && reuse;
    let h = headers[i];
    // Slots of the fresh reservoirs and of the kept ones (signs 0 and 1 of the last merge).
    let none = Evaluated(0.0, vec3f(0.0), 0.0);
    var inputs = MergeInputs(vec2u(fresh_slot(h, 0u), fresh_slot(h, 1u)), vec2u(header_slot(h, 0u), header_slot(h, 1u)), vec2f(0.0), vec2f(0.0), none, none, none, none);
    inputs.fresh_w = vec2f(fresh_weight(inputs.fresh_k.x, i), fresh_weight(inputs.fresh_k.y, i));
    if reuse {
        inputs.kept_w = vec2f(slot_w(inputs.kept_k.x, i), slot_w(inputs.kept_k.y, i));
        // Without positivization the sign-1 reservoir is always empty.
        inputs.kept_w.y = select(0.0, inputs.kept_w.y, n_signs == 2u);
    }
    // Many observed texels hold no sample in an iteration (not hit this iteration and never
    // before): their gradient is 0, found from the header and four words, and their slots
    // and header stay as they are (the fresh slots are empty; kept ones that are not reused
    // keep their slots until a merge selects something else).
    if !any(inputs.fresh_w > vec2f(0.0)) && !any(inputs.kept_w > vec2f(0.0)) {
        for (var c = 0u; c < ch; c++) {
            write_entry(p.offset + local * ch + c, 0.0, 0.0);
        }
        if dropped > 0u {
            atomicAdd(&mstats[MERGE_STAT_DROPPED], dropped);
        }
        return;
    }
    inputs = evaluate_inputs(inputs, i, ti, local, p, verify);
    var g = vec3f(0.0);
    // The fresh reservoirs' own estimate (write_entry).
    var fresh = vec3f(0.0);
    // The slot each sign's merged reservoir ends in.
    var out_slot = inputs.fresh_k;
    for (var s = 0u; s < n_signs; s++) {
        let m = merge_sign(inputs, s, i, t, reuse, n_signs);
        g += m.g;
        fresh += m.fresh;
        out_slot[s] = m.slot;
    }
    let new_h = out_slot.x | (out_slot.y << HEADER_SLOT_BITS);
    headers[i] = new_h;
    // The slots the new header leaves free take the next iteration's candidates: the inputs
    // that were not selected, kept or fresh, are emptied (weight sum and info word 0, the
    // race's start, reservoir.wgsl).
    for (var s = 0u; s < 2u; s++) {
        let k = fresh_slot(new_h, s);
        set_w(k, i, 0.0);
        set_slot_word(k, i * res_stride + RES_INFO, 0u);
    }
    for (var c = 0u; c < ch; c++) {
        write_entry(p.offset + local * ch + c, g[c], fresh[c]);
    }
    atomicAdd(&mstats[MERGE_STAT_EVALUATIONS], evaluations);
    if dropped > 0u {
        atomicAdd(&mstats[MERGE_STAT_DROPPED], dropped);
    }
}
