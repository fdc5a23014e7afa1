// Texel coordinate wrapping (glTF sampler wrap modes), shared by the scene's textures
// (shared/texture) and the optimized ones (shared/params).

// i modulo n in [0, n), for n > 0, without an integer division: a CPU device has no vector
// instruction for one, so lavapipe divides lane by lane, and every bilinear lookup wraps four
// coordinates. floor(i / n) from a float multiply is off by at most one while |i / n| < 2^23
// (f32(i) is exact: i comes from the floor of a float), which the two corrections fix; beyond
// that the clamp keeps the texel in range.
fn wrap_repeat(i: i32, n: i32) -> i32 {
    var m = i - n * i32(floor(f32(i) * (1.0 / f32(n))));
    m = select(m, m + n, m < 0);
    m = select(m, m - n, m >= n);
    return clamp(m, 0, n - 1);
}

// Wrap an integer texel coordinate: 0 repeat, 1 clamp to edge, 2 mirrored repeat.
fn wrap_coord(i: i32, n: i32, mode: u32) -> i32 {
    switch mode {
        case 1u: {
            return clamp(i, 0, n - 1);
        }
        case 2u: {
            let period = 2 * n;
            let m = wrap_repeat(i, period);
            return select(m, period - 1 - m, m >= n);
        }
        default: {
            return wrap_repeat(i, n);
        }
    }
}
