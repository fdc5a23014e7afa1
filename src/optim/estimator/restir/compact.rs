//! ReSTIR's compact path encodings (shaders/shared/path_encoding.wgsl and compact_path.wgsl
//! here), mirrored on the CPU with the precision of each one. A reservoir keeps its path in [`reservoir::WORDS`] words:
//!
//! | field | encoding | precision |
//! |---|---|---|
//! | pixel, camera, technique | 26 + 3 + 1 bits | exact |
//! | weight W | f32 | exact |
//! | hit triangle | 24 bits | exact (scenes of up to 2^24 triangles) |
//! | barycentrics | 20-bit fixed point each | within [`BARY_ERROR`] |
//! | incident direction | octahedral, 24-bit fixed point per coordinate | within [`DIRECTION_ERROR`] radians |
//! | incident radiance | RGBE (8-bit mantissas, shared 8-bit exponent) | each channel within [`RADIANCE_ERROR`] of the largest |
//! | target under the previous state | bfloat16 | within [`TARGET_ERROR`] (relative) |
//!
//! The candidate pass takes ReSTIR's gradient samples at the rounded hit, direction and
//! radiance, so a stored path re-evaluates exactly to what its candidate was worth; the
//! rounding only moves the point, direction and radiance a sample is evaluated at by these
//! amounts. The previous-state target only enters the MIS weights.
use super::abi::reservoir;
pub use crate::render::layout::oct_encode;

/// Largest error of a rounded barycentric: a step of 2^-20 (half a step, but a whole one for
/// b = 1, which rounds to the largest step below it).
pub const BARY_ERROR: f32 = 1.0 / (1 << reservoir::BARY_BITS) as f32;
/// Largest angle between a unit direction and its rounded octahedral form, in radians
/// (7.4e-7 measured over 10^6 directions by the test below, f32 rounding of the encoding
/// included; the bound leaves a margin of 2).
pub const DIRECTION_ERROR: f32 = 1.5e-6;
/// Largest error of a rounded radiance channel, relative to the largest channel: half a
/// mantissa step of the largest channel, whose mantissa is at least 128 (2^-8, and a hair
/// more where the largest channel rounds up into the next exponent).
pub const RADIANCE_ERROR: f32 = 1.0 / 255.0;
/// Largest relative error of a rounded target: half a step of bfloat16's 8-bit significand.
pub const TARGET_ERROR: f32 = 1.0 / 256.0;

const BARY_SCALE: f32 = (1u32 << reservoir::BARY_BITS) as f32;
const OCT_HALF_SCALE: f32 = (1u32 << (reservoir::OCT_BITS - 1)) as f32;

/// Barycentric `b` as fixed point (WGSL `bary_round`).
pub fn bary_round(b: f32) -> u32 {
    ((b.max(0.0) * BARY_SCALE + 0.5) as u32).min((1 << reservoir::BARY_BITS) - 1)
}

/// The barycentric of fixed-point `k` (WGSL `bary_value`).
pub fn bary_value(k: u32) -> f32 {
    k as f32 * (1.0 / BARY_SCALE)
}

/// Octahedral coordinate `x` in [-1, 1] as fixed point (WGSL `oct_round`).
pub fn oct_round(x: f32) -> u32 {
    (((x + 1.0).max(0.0) * OCT_HALF_SCALE + 0.5) as u32).min((1 << reservoir::OCT_BITS) - 1)
}

/// The octahedral coordinate of fixed-point `k` (WGSL `oct_value`).
pub fn oct_value(k: u32) -> f32 {
    k as f32 * (1.0 / OCT_HALF_SCALE) - 1.0
}

/// Octahedral coordinates to a unit direction (WGSL `oct_decode`).
pub fn oct_decode(e: [f32; 2]) -> [f32; 3] {
    let mut v = [e[0], e[1], 1.0 - e[0].abs() - e[1].abs()];
    if v[2] < 0.0 {
        let sign = |v: f32| if v >= 0.0 { 1.0 } else { -1.0 };
        let (x, y) = (v[0], v[1]);
        v[0] = (1.0 - y.abs()) * sign(x);
        v[1] = (1.0 - x.abs()) * sign(y);
    }
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    [v[0] / l, v[1] / l, v[2] / l]
}

/// Non-negative RGB as RGBE (WGSL `rgbe_pack`): 0 for a largest channel below 2^-100.
pub fn rgbe_pack(c: [f32; 3]) -> u32 {
    let m = c[0].max(c[1]).max(c[2]);
    if !(m >= 7.9e-31) || !(m < 3.0e38) {
        return 0;
    }
    let mut e = ((m.to_bits() >> 23) & 0xff) as i32 - 126;
    let mut s = pow2(8 - e);
    if (m * s + 0.5).floor() >= 256.0 {
        e += 1;
        s *= 0.5;
    }
    let k = |v: f32| ((v.max(0.0) * s + 0.5).floor()).min(255.0) as u32;
    k(c[0]) | (k(c[1]) << 8) | (k(c[2]) << 16) | (((e + 128) as u32) << 24)
}

/// The RGB of an RGBE word (WGSL `rgbe_unpack`).
pub fn rgbe_unpack(w: u32) -> [f32; 3] {
    if w == 0 {
        return [0.0; 3];
    }
    let e = (w >> 24) as i32 - 128;
    let s = pow2(e - 8);
    [0, 8, 16].map(|sh| ((w >> sh) & 0xff) as f32 * s)
}

fn pow2(e: i32) -> f32 {
    f32::from_bits(((e + 127) as u32) << 23)
}

/// A finite f32 as bfloat16, rounded to nearest even (WGSL `bf16_pack`).
pub fn bf16_pack(x: f32) -> u32 {
    let b = x.to_bits();
    (b.wrapping_add(0x7fff + ((b >> 16) & 1))) >> 16
}

/// The f32 of a bfloat16 (WGSL `bf16_unpack`).
pub fn bf16_unpack(h: u32) -> f32 {
    f32::from_bits(h << 16)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic stream of numbers in [0, 1).
    fn uniforms(seed: u64) -> impl Iterator<Item = f32> {
        let mut x = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
        std::iter::from_fn(move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            Some((x >> 40) as f32 / (1u64 << 24) as f32)
        })
    }

    #[test]
    fn barycentrics_round_trip_within_half_a_step() {
        for (i, b) in uniforms(1).take(100_000).enumerate() {
            let b = if i == 0 { 1.0 } else { b };
            let k = bary_round(b);
            assert!(k < 1 << reservoir::BARY_BITS);
            assert!(
                (bary_value(k) - b).abs() <= BARY_ERROR + f32::EPSILON,
                "{b}"
            );
            // Rounding a rounded value changes nothing (the candidate pass and the merge
            // see the same barycentrics).
            assert_eq!(bary_round(bary_value(k)), k);
        }
    }

    #[test]
    fn directions_round_trip_within_the_stated_angle() {
        let mut u = uniforms(2);
        let mut worst = 0.0f64;
        for _ in 0..1_000_000 {
            let z = 2.0 * u.next().unwrap() - 1.0;
            let phi = std::f32::consts::TAU * u.next().unwrap();
            let r = (1.0 - z * z).max(0.0).sqrt();
            let d = [r * phi.cos(), r * phi.sin(), z];
            let e = oct_encode(d);
            let k = [oct_round(e[0]), oct_round(e[1])];
            let back = oct_decode([oct_value(k[0]), oct_value(k[1])]);
            assert_eq!([oct_round(oct_value(k[0])), oct_round(oct_value(k[1]))], k);
            // The angle from the cross product, in f64 (1 - dot^2 would drown in the f32
            // rounding of the inputs' lengths).
            let a = d.map(f64::from);
            let b = back.map(f64::from);
            let c = [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ];
            let norm = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            worst = worst.max(norm(c) / (norm(a) * norm(b)));
        }
        eprintln!("largest direction error {worst:.3e} rad");
        assert!(worst <= f64::from(DIRECTION_ERROR), "{worst}");
    }

    #[test]
    fn radiance_round_trips_within_the_stated_fraction_of_its_largest_channel() {
        let mut u = uniforms(3);
        for i in 0..100_000 {
            // Magnitudes from 2^-90 to 2^90, channels of very different sizes, and zeros.
            let scale = 2f32.powi((u.next().unwrap() * 180.0) as i32 - 90);
            let mut c = [0.0f32; 3].map(|_| u.next().unwrap() * scale);
            if i % 7 == 0 {
                c[i % 3] = 0.0;
            }
            if i % 11 == 0 {
                c[(i + 1) % 3] *= 1e-6;
            }
            let back = rgbe_unpack(rgbe_pack(c));
            let m = c[0].max(c[1]).max(c[2]);
            for ch in 0..3 {
                assert!(
                    (back[ch] - c[ch]).abs() <= RADIANCE_ERROR * m,
                    "{c:?} -> {back:?}"
                );
            }
        }
        assert_eq!(rgbe_unpack(rgbe_pack([0.0; 3])), [0.0; 3]);
        // The largest channel just below a power of two rounds up into the next exponent.
        let back = rgbe_unpack(rgbe_pack([0.9999, 0.5, 0.0]));
        assert!((back[0] - 1.0).abs() < 1e-6 && (back[1] - 0.5).abs() < 1e-6);
    }

    #[test]
    fn targets_round_trip_within_the_stated_relative_error() {
        let mut u = uniforms(4);
        for _ in 0..100_000 {
            let sign = if u.next().unwrap() < 0.5 { -1.0 } else { 1.0 };
            let x = sign
                * 2f32.powi((u.next().unwrap() * 200.0) as i32 - 100)
                * (1.0 + u.next().unwrap());
            let back = bf16_unpack(bf16_pack(x));
            assert!((back - x).abs() <= TARGET_ERROR * x.abs(), "{x} -> {back}");
            assert_eq!(back.signum(), x.signum());
        }
        assert_eq!(bf16_unpack(bf16_pack(0.0)), 0.0);
    }
}
