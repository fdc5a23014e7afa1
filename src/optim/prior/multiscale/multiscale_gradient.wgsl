// Multiscale gradient: replaces each observed texel's gradient by a weighted mean, over the
// levels 0..levels, of the gradient averaged over the texel's 2^l x 2^l block (level 0: the
// texel itself, weight FINE_WEIGHT; every block level, weight 1). For plain gradient descent this is descent on a pyramid of textures whose levels
// are added up (x = sum_l U_l p_l gives dx = -lr sum_l U_l U_l^T g): the coarse levels carry
// many samples each, so broad errors fall fast, and fine detail keeps its own level. The
// preconditioner is positive definite, so the textures it converges to are those of the plain
// gradient. Blocks are the aligned blocks of a 16x16 tile grid shifted by `shift` (a new shift
// each iteration, so that no block edge stays put). Only observed texels take part: the others
// keep a zero gradient and their initial values.

// Mirrored by MultiscaleParams in src/optim/prior/multiscale.rs.
struct MultiscaleParams {
    // First float of the texture in the gradient.
    offset: u32,
    width: u32,
    height: u32,
    channels: u32,
    // Coarsest level (1..=4; block 2^levels).
    levels: u32,
    // Shift of the tile grid, in texels (0..16).
    shift_x: u32,
    shift_y: u32,
    // First word of the texture in `observed` (one word per texel).
    texel_offset: u32,
}

@group(0) @binding(0) var<uniform> mp: MultiscaleParams;
@group(0) @binding(1) var<storage, read_write> grad: array<f32>;
@group(0) @binding(2) var<storage, read> observed: array<u32>;

const TILE: u32 = 16u;
// Weight of the texel's own gradient; each block level has weight 1.
const FINE_WEIGHT: f32 = 0.25;

// Per level, the sums of the gradient (xyz: channels, w: observed texels) over its blocks.
var<workgroup> level0: array<vec4f, 256>;
var<workgroup> level1: array<vec4f, 64>;
var<workgroup> level2: array<vec4f, 16>;
var<workgroup> level3: array<vec4f, 4>;
var<workgroup> level4: array<vec4f, 1>;

fn mean(s: vec4f) -> vec3f {
    return s.xyz / max(s.w, 1.0);
}

@compute @workgroup_size(16, 16)
fn main(@builtin(workgroup_id) wg: vec3u, @builtin(local_invocation_id) lid: vec3u) {
    // Tile (wg.x, wg.y) covers texels [wg * 16 - shift, wg * 16 - shift + 16).
    let px = i32(wg.x * TILE + lid.x) - i32(mp.shift_x);
    let py = i32(wg.y * TILE + lid.y) - i32(mp.shift_y);
    let inside = px >= 0 && py >= 0 && px < i32(mp.width) && py < i32(mp.height);
    var texel = 0u;
    var observed_here = false;
    var g = vec3f(0.0);
    if inside {
        texel = u32(py) * mp.width + u32(px);
        observed_here = observed[mp.texel_offset + texel] != 0u;
        if observed_here {
            let base = mp.offset + texel * mp.channels;
            for (var c = 0u; c < mp.channels; c++) {
                g[c] = grad[base + c];
            }
        }
    }
    let l = lid.y * TILE + lid.x;
    level0[l] = select(vec4f(0.0), vec4f(g, 1.0), observed_here);
    workgroupBarrier();
    if lid.x < 8u && lid.y < 8u {
        let b = 2u * lid.y * TILE + 2u * lid.x;
        level1[lid.y * 8u + lid.x] = level0[b] + level0[b + 1u] + level0[b + TILE] + level0[b + TILE + 1u];
    }
    workgroupBarrier();
    if lid.x < 4u && lid.y < 4u {
        let b = 2u * lid.y * 8u + 2u * lid.x;
        level2[lid.y * 4u + lid.x] = level1[b] + level1[b + 1u] + level1[b + 8u] + level1[b + 9u];
    }
    workgroupBarrier();
    if lid.x < 2u && lid.y < 2u {
        let b = 2u * lid.y * 4u + 2u * lid.x;
        level3[lid.y * 2u + lid.x] = level2[b] + level2[b + 1u] + level2[b + 4u] + level2[b + 5u];
    }
    workgroupBarrier();
    if l == 0u {
        level4[0] = level3[0] + level3[1] + level3[2] + level3[3];
    }
    workgroupBarrier();
    if !observed_here {
        return;
    }
    var sum = FINE_WEIGHT * g;
    sum += mean(level1[(lid.y / 2u) * 8u + lid.x / 2u]);
    if mp.levels >= 2u {
        sum += mean(level2[(lid.y / 4u) * 4u + lid.x / 4u]);
    }
    if mp.levels >= 3u {
        sum += mean(level3[(lid.y / 8u) * 2u + lid.x / 8u]);
    }
    if mp.levels >= 4u {
        sum += mean(level4[0]);
    }
    let out = sum / (f32(mp.levels) + FINE_WEIGHT);
    let base = mp.offset + texel * mp.channels;
    for (var c = 0u; c < mp.channels; c++) {
        grad[base + c] = out[c];
    }
}
