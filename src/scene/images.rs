//! The scene's textures on the CPU: decoded glTF images ([`Image8`], decoded by
//! [`crate::image_io::decode`]) and the lookup the shaders do.
pub use crate::image_io::decode::Image8;
use crate::image_io::srgb_to_linear;

/// Texel coordinate `i` of a texture `n` texels wide wrapped into [0, n) with mode `w`, as
/// shaders/shared/wrap.wgsl does.
pub fn wrap_texel(i: i64, n: i64, w: super::Wrap) -> i64 {
    match w {
        super::Wrap::Clamp => i.clamp(0, n - 1),
        super::Wrap::Repeat => i.rem_euclid(n),
        super::Wrap::Mirror => {
            let m = i.rem_euclid(2 * n);
            if m >= n {
                2 * n - 1 - m
            } else {
                m
            }
        }
    }
}

/// Bilinear lookup as in shaders/shared/texture.wgsl (wrap modes, transform, sRGB decoding),
/// on the CPU. Returns linear RGBA.
pub fn sample_bilinear(
    img: &Image8,
    slot: &super::TextureSlot,
    uv: [f32; 2],
    srgb: bool,
) -> [f32; 4] {
    let t = slot.transform;
    let u = t[0][0] * uv[0] + t[0][1] * uv[1] + t[0][2];
    let v = t[1][0] * uv[0] + t[1][1] * uv[1] + t[1][2];
    let wrap = |i: i64, n: i64, w: super::Wrap| wrap_texel(i, n, w) as usize;
    let (w, h) = (img.width as i64, img.height as i64);
    let fetch = |x: i64, y: i64| -> [f32; 4] {
        let p = img.rgba[wrap(y, h, slot.wrap_t) * img.width as usize + wrap(x, w, slot.wrap_s)];
        let f = |c: u8| {
            let v = c as f32 / 255.0;
            if srgb {
                srgb_to_linear(v)
            } else {
                v
            }
        };
        [f(p[0]), f(p[1]), f(p[2]), p[3] as f32 / 255.0]
    };
    if slot.nearest {
        return fetch((u * w as f32).floor() as i64, (v * h as f32).floor() as i64);
    }
    let qx = u * w as f32 - 0.5;
    let qy = v * h as f32 - 0.5;
    let (fx, fy) = (qx.floor(), qy.floor());
    let (tx, ty) = (qx - fx, qy - fy);
    let (x, y) = (fx as i64, fy as i64);
    let (a, b, c, d) = (
        fetch(x, y),
        fetch(x + 1, y),
        fetch(x, y + 1),
        fetch(x + 1, y + 1),
    );
    let mut out = [0.0; 4];
    for k in 0..4 {
        out[k] =
            (a[k] * (1.0 - tx) + b[k] * tx) * (1.0 - ty) + (c[k] * (1.0 - tx) + d[k] * tx) * ty;
    }
    out
}
