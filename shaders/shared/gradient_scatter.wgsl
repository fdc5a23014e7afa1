// Adding a sample's derivative into the gradient, for passes that declare
// `grad: array<atomic<u32>>` (f32 bits, laid out like params[]): the baseline's gradient pass,
// and ReSTIR's candidate pass for the later vertices of paths. Float additions use a bounded
// compare-and-swap loop on 32-bit atomics; an update that exhausts the bound is counted
// (scatter_lost), never silently lost, and a value that is not finite is dropped and counted
// (scatter_dropped); the pass adds both to its statistics.

const CAS_BOUND: u32 = 256u;

var<private> scatter_lost: u32 = 0u;
var<private> scatter_dropped: u32 = 0u;

fn atomic_add_f32(i: u32, v: f32) {
    if v == 0.0 {
        return;
    }
    if !(abs(v) < 3.0e38) {
        scatter_dropped += 1u;
        return;
    }
    var old = atomicLoad(&grad[i]);
    for (var k = 0u; k < CAS_BOUND; k++) {
        let r = atomicCompareExchangeWeak(&grad[i], old, bitcast<u32>(bitcast<f32>(old) + v));
        if r.exchanged {
            return;
        }
        old = r.old_value;
    }
    scatter_lost += 1u;
}

// Scatter the derivative of one contribution c = f cos x weight into the optimized textures
// of material m at uv, weighted by the pixel's adjoint adj.
fn scatter(m: Material, uv: vec2f, bg: BrdfGrad, weight: vec3f, adj: vec3f) {
    if all(weight == vec3f(0.0)) {
        return;
    }
    for (var slot = 0u; slot < SLOTS; slot++) {
        let pi = material_param(m, slot);
        if pi == NONE {
            continue;
        }
        let p = param_textures[pi];
        let fp = param_footprint(p, uv);
        let g = slot_derivative(slot, bg, weight, adj);
        for (var k = 0u; k < 4u; k++) {
            if fp.weight[k] != 0.0 {
                let base = p.offset + fp.texel[k] * p.channels;
                for (var c = 0u; c < p.channels; c++) {
                    atomic_add_f32(base + c, fp.weight[k] * g[c]);
                }
            }
        }
    }
}
