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
// under the current textures by one BRDF-with-derivative evaluation from what the reservoir
// stores of the hit (material, texture coordinates, shading-frame directions): no geometry
// is read. That gives its factor e (shared/reservoir.wgsl); its value is the pixel's adjoint
// times e, its target the luminance of the pixel's target adjoint times e, and its target
// under the previous state comes from the stored factor and the previous target adjoint.
// A fresh sample's target under the previous textures and target adjoint (both
// double-buffered) comes with it from the candidate pass (RES_Q_PREV), which evaluated the
// same path there; with the verify flag the merge evaluates it again and compares. Nothing
// here traces a ray: shared/bvh is not part of this pass (a test checks the composed module).
// MIS: balance heuristic with confidences over the inputs' own targets.
// Selection is in place: a texel's four reservoir slots hold its two kept reservoirs and the
// two fresh ones (shared/reservoir.wgsl); the merged reservoir of sign s is whichever input
// it selected, where it already lies, with its W (and, for a kept sample, its factor under
// the current textures) rewritten, and the texel's header says which slot that is. The two slots
// the new header leaves free get W = 0 for the next iteration's candidates.
#import shared/rng
#import shared/surface
#import shared/reservoir_slots
#import gen/abi

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
    // Where this iteration's and the last iteration's target adjoints start in `targets`.
    target_cur: u32,
    target_prev: u32,
    _pad0: u32,
}

@group(1) @binding(0) var<uniform> mp: MergeParams;
@group(1) @binding(1) var<storage, read> adjoint: array<vec4f>;
// The target adjoints of this iteration and the last (shared/reservoir.wgsl).
@group(1) @binding(2) var<storage, read> targets: array<vec4f>;
// Reservoir slots (RESERVOIR_WORDS / 4 vec4s each) and headers (each texel's invocation owns
// its four slots and its header).
@group(1) @binding(3) var<storage, read_write> slots: array<vec4u>;
@group(1) @binding(4) var<storage, read_write> headers: array<u32>;
@group(1) @binding(5) var<storage, read_write> grad: array<f32>;
// MERGE_STAT_* slots (generated from src/optim/estimator/restir.rs).
@group(1) @binding(6) var<storage, read_write> mstats: array<atomic<u32>, 4>;

var<private> evaluations: u32 = 0u;
var<private> dropped: u32 = 0u;

// A stored path with its W and its factor (RES_VALUE) under the textures it was formed at.
struct Stored {
    info: u32,
    w: f32,
    v: vec3f,
    vertex: PathVertex,
    radiance: vec3f,
}

// The slots are read here as vec4s: a CPU device (lavapipe) loads a storage word at a
// per-invocation address lane by lane, so one 16-byte load costs what one 4-byte load does
// (RESERVOIR_WORDS / 4 loads instead of RESERVOIR_WORDS per stored path: merge 4-11%
// faster on lavapipe).
const SLOT_VEC4S: u32 = RESERVOIR_WORDS / 4u;

// Word i of a reservoir read as SLOT_VEC4S vec4s (i is a constant: this is a register pick).
fn word_of(q: array<vec4u, SLOT_VEC4S>, i: u32) -> u32 {
    return q[i / 4u][i % 4u];
}

fn word(r: u32, i: u32) -> u32 {
    return slots[r * SLOT_VEC4S + i / 4u][i % 4u];
}

fn set_word(r: u32, i: u32, x: u32) {
    slots[r * SLOT_VEC4S + i / 4u][i % 4u] = x;
}

fn slot_w(r: u32) -> f32 {
    return bitcast<f32>(word(r, RES_W));
}

fn slot_value(r: u32) -> vec3f {
    return vec3f(bitcast<f32>(word(r, RES_VALUE)), bitcast<f32>(word(r, RES_VALUE + 1u)), bitcast<f32>(word(r, RES_VALUE + 2u)));
}

fn load(r: u32) -> Stored {
    let b = r * SLOT_VEC4S;
    var q: array<vec4u, SLOT_VEC4S>;
    for (var i = 0u; i < SLOT_VEC4S; i++) {
        q[i] = slots[b + i];
    }
    var s: Stored;
    s.info = word_of(q, RES_INFO);
    s.w = bitcast<f32>(word_of(q, RES_W));
    s.v = bitcast<vec3f>(vec3u(word_of(q, RES_VALUE), word_of(q, RES_VALUE + 1u), word_of(q, RES_VALUE + 2u)));
    s.vertex = PathVertex(
        word_of(q, RES_MATERIAL),
        bitcast<vec2f>(vec2u(word_of(q, RES_UV), word_of(q, RES_UV + 1u))),
        bitcast<vec2f>(vec2u(word_of(q, RES_WO), word_of(q, RES_WO + 1u))),
        bitcast<vec2f>(vec2u(word_of(q, RES_WI), word_of(q, RES_WI + 1u))),
        bitcast<vec4f>(vec4u(word_of(q, RES_FIXED), word_of(q, RES_FIXED + 1u), word_of(q, RES_FIXED + 2u), word_of(q, RES_FIXED + 3u))),
    );
    s.radiance = bitcast<vec3f>(vec3u(word_of(q, RES_RADIANCE), word_of(q, RES_RADIANCE + 1u), word_of(q, RES_RADIANCE + 2u)));
    return s;
}

fn set_w(r: u32, w: f32) {
    set_word(r, RES_W, bitcast<u32>(w));
}

fn set_value(r: u32, v: vec3f) {
    set_word(r, RES_VALUE, bitcast<u32>(v.x));
    set_word(r, RES_VALUE + 1u, bitcast<u32>(v.y));
    set_word(r, RES_VALUE + 2u, bitcast<u32>(v.z));
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
// path_factor), under the current (prev = false) or previous textures.
fn evaluate(st: Stored, ti: u32, local: u32, prev: bool) -> vec3f {
    evaluations += 1u;
    use_prev_params = prev;
    let e = path_factor(st.vertex, st.radiance, ti, local);
    use_prev_params = false;
    if !all(abs(e) < vec3f(3.0e38)) {
        dropped += 1u;
        return vec3f(0.0);
    }
    return e;
}

// With the verify flag: the largest relative error of a re-evaluation.
fn record_verified(err: f32) {
    atomicAdd(&mstats[MERGE_STAT_VERIFIED], 1u);
    atomicMax(&mstats[MERGE_STAT_VERIFY_MAX_ERROR], bitcast<u32>(min(err, 3.0e38)));
}

// A kept sample: its target under the previous state (from its stored factor), and its
// factor, value and target under the current state.
struct Evaluated {
    q_prev: f32,
    v: vec3f,
    q: f32,
    e: vec3f,
}

fn evaluate_kept(r: u32, ti: u32, local: u32, ch: u32, verify: bool) -> Evaluated {
    let st = load(r);
    if verify {
        // The stored factor was computed under the previous textures: evaluating the stored
        // path there must give it back.
        let again = evaluate(st, ti, local, true);
        record_verified(length(again - st.v) / max(length(st.v), 1e-30));
    }
    let pa = pixel_adjoints(st.info);
    let e = evaluate(st, ti, local, false);
    return Evaluated(target_of(with_adjoint(st.v, pa.target_prev, ch), ch), with_adjoint(e, pa.value, ch), target_of(with_adjoint(e, pa.target_cur, ch), ch), e);
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
    let verify = (mp.flags & MERGE_FLAG_VERIFY) != 0u;
    let h = headers[t];
    let base = RESERVOIR_SLOTS * t;
    // Slots of the kept reservoirs (signs 0 and 1 of the last merge) and of the fresh ones.
    let kept_r = base + vec2u(header_slot(h, 0u), header_slot(h, 1u));
    let fresh_r = base + vec2u(fresh_slot(h, 0u), fresh_slot(h, 1u));
    let fresh_w = vec2f(slot_w(fresh_r.x), slot_w(fresh_r.y));
    var kept_w = vec2f(0.0);
    if reuse {
        kept_w = vec2f(slot_w(kept_r.x), slot_w(kept_r.y));
        // Without positivization the sign-1 reservoir is always empty.
        kept_w.y = select(0.0, kept_w.y, n_signs == 2u);
    }
    // Most texels of a typical task hold no sample at all (unobserved, or not hit this
    // iteration and never before): their gradient is 0, found from the header and four
    // words, and their slots and header stay as they are (the fresh slots are empty; kept
    // ones that are not reused keep their slots until a merge selects something else).
    if !any(fresh_w > vec2f(0.0)) && !any(kept_w > vec2f(0.0)) {
        for (var c = 0u; c < ch; c++) {
            grad[p.offset + local * ch + c] = 0.0;
        }
        return;
    }

    // Kept samples (their values under the previous state are stored), each evaluated under
    // the current state. Plain variables, not arrays indexed by a loop counter: on a CPU
    // device those live in memory.
    var k0 = Evaluated(0.0, vec3f(0.0), 0.0, vec3f(0.0));
    var k1 = Evaluated(0.0, vec3f(0.0), 0.0, vec3f(0.0));
    // One loop over the kept inputs that hold a sample, so that neighbouring invocations
    // that need one evaluation run it together whichever sign it is for.
    let n_kept = u32(kept_w.x > 0.0) + u32(kept_w.y > 0.0);
    for (var i = 0u; i < n_kept; i++) {
        let second = i == 1u || !(kept_w.x > 0.0);
        let e = evaluate_kept(select(kept_r.x, kept_r.y, second), ti, local, ch, verify);
        if second {
            k1 = e;
        } else {
            k0 = e;
        }
    }
    let k_qprev = vec2f(k0.q_prev, k1.q_prev);
    let k_qcur = vec2f(k0.q, k1.q);
    // Confidence-weighted balance heuristic over all inputs, empty ones included.
    let m_c = mp.m_fresh;
    let m_k = select(0.0, mp.m_kept, reuse);
    var g = vec3f(0.0);
    // The slot each sign's merged reservoir ends in.
    var out_slot = vec2u(fresh_r.x - base, fresh_r.y - base);
    for (var s = 0u; s < n_signs; s++) {
        let r_fresh = fresh_r[s];
        let c_ok = fresh_w[s] > 0.0;
        // A fresh sample's factor under the current textures and its target under the
        // previous state are stored.
        var c_e = vec3f(0.0);
        var c_v = vec3f(0.0);
        var c_qcur = 0.0;
        var c_qprev = 0.0;
        if c_ok {
            c_e = slot_value(r_fresh);
            let pa = pixel_adjoints(word(r_fresh, RES_INFO));
            c_v = with_adjoint(c_e, pa.value, ch);
            c_qcur = target_of(with_adjoint(c_e, pa.target_cur, ch), ch);
            if reuse {
                c_qprev = bitcast<f32>(word(r_fresh, RES_Q_PREV));
                if verify {
                    // The candidate pass evaluated the same path under the same state, in
                    // another shader (so the rounding may differ). The error is relative to
                    // the larger of the sample's targets under both states, the scale at
                    // which q_prev enters the MIS weights (a target near zero is a sum that
                    // cancels, whose own relative rounding error is unbounded).
                    let again = target_of(with_adjoint(evaluate(load(r_fresh), ti, local, true), pa.target_prev, ch), ch);
                    let scale = max(max(abs(again), abs(c_qcur)), 1e-30);
                    record_verified(abs(again - c_qprev) / scale);
                }
            }
        }
        // Resampling weights m_r(y_r) * tau_s(q_cur(y_r)) * W_r of the fresh input (w0) and
        // the kept ones (wk).
        var w0 = 0.0;
        if c_ok {
            let own = m_c * tau(c_qcur, s);
            var den = own;
            for (var r = 0u; r < n_signs; r++) {
                den += m_k * tau(c_qprev, r);
            }
            let big_w = fresh_w[s] / tau(c_qcur, s);
            w0 = select(0.0, own / den * tau(c_qcur, s) * big_w, den > 0.0);
        }
        var wk = vec2f(0.0);
        for (var r = 0u; r < 2u; r++) {
            let qc = k_qcur[r];
            if kept_w[r] > 0.0 && tau(qc, s) > 0.0 {
                let qp = k_qprev[r];
                let own = m_k * tau(qp, r);
                var den = m_c * tau(qc, s);
                for (var r2 = 0u; r2 < n_signs; r2++) {
                    den += m_k * tau(qp, r2);
                }
                wk[r] = select(0.0, own / den * tau(qc, s) * kept_w[r], den > 0.0);
            }
        }
        let total = w0 + wk.x + wk.y;
        if !(total > 0.0) || !(total < 3.0e38) {
            // Empty: the fresh slot (W = 0 from here on) stands for it.
            if c_ok {
                set_w(r_fresh, 0.0);
            }
            continue;
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
        // A kept sample goes to at most one sign (its weight is zero for the other), so the
        // two merged reservoirs always lie in different slots.
        var r_out = r_fresh;
        var v = c_v;
        var q = c_qcur;
        if pick != 0u {
            r_out = kept_r[pick - 1u];
            v = select(k0.v, k1.v, pick == 2u);
            q = select(k0.q, k1.q, pick == 2u);
            set_value(r_out, select(k0.e, k1.e, pick == 2u));
        }
        let w_out = total / tau(q, s);
        set_w(r_out, w_out);
        out_slot[s] = r_out - base;
        g += v * w_out;
    }
    let new_h = out_slot.x | (out_slot.y << HEADER_SLOT_BITS);
    headers[t] = new_h;
    // The slots the new header leaves free take the next iteration's candidates: the inputs
    // that were not selected, kept or fresh, are emptied.
    for (var s = 0u; s < 2u; s++) {
        let r = base + fresh_slot(new_h, s);
        if slot_w(r) != 0.0 {
            set_w(r, 0.0);
        }
    }
    for (var c = 0u; c < ch; c++) {
        grad[p.offset + local * ch + c] = g[c];
    }
    atomicAdd(&mstats[MERGE_STAT_EVALUATIONS], evaluations);
    if dropped > 0u {
        atomicAdd(&mstats[MERGE_STAT_DROPPED], dropped);
    }
}
