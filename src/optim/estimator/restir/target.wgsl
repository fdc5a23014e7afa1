#import shared/sampling

// The resampling target of a path's value v for one texel: for RGB textures the
// luminance-weighted sum of the channels' magnitudes, with the sign of the luminance (which
// of the two reservoirs it goes to); the value for scalar ones. The luminance alone is near
// zero where the channels' values cancel (an adjoint of mixed signs), and a sample whose
// target is near zero while a channel's value is not has a huge weight and is almost never
// selected: each channel's estimate then comes out small (measured: about 20% on a texel of
// tests/restir.rs). The magnitudes' sum is zero only where every channel is.
fn target_of(v: vec3f, channels: u32) -> f32 {
    if channels == 3u {
        let magnitude = luminance(abs(v));
        return select(magnitude, -magnitude, luminance(v) < 0.0);
    }
    return v.x;
}
