#import shared/sampling

// The resampling target of a path's value v for one texel of texture p: for base color the
// luminance-weighted sum of the channels' magnitudes, with the sign of the luminance (which
// of the two reservoirs it goes to); for a normal map the plain sum of the magnitudes with
// the sign of the sum (its channels are directions, not colors); the value for scalar
// textures. The luminance alone is near zero where the channels' values cancel (an adjoint
// of mixed signs), and a sample whose target is near zero while a channel's value is not has
// a huge weight and is almost never selected: each channel's estimate then comes out small
// (measured: about 20% on a texel of tests/restir.rs). The magnitudes' sum is zero only
// where every channel is.
fn target_of(v: vec3f, p: ParamTex) -> f32 {
    if p.slot == SLOT_NORMAL {
        let magnitude = abs(v.x) + abs(v.y) + abs(v.z);
        return select(magnitude, -magnitude, v.x + v.y + v.z < 0.0);
    }
    if p.channels == 3u {
        let magnitude = luminance(abs(v));
        return select(magnitude, -magnitude, luminance(v) < 0.0);
    }
    return v.x;
}
