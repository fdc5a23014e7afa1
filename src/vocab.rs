//! The vocabulary that task files, the renderer and the optimizer share: which material
//! input a texture replaces ([`Slot`]), how it is filtered ([`Filter`]), the image [`Loss`],
//! and one texture to optimize ([`TextureSpec`]). Task files parse into these
//! (`crate::task` re-exports them); nothing here knows about files.
use serde::Deserialize;

/// Which material input a texture replaces.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Slot {
    /// Linear RGB base color (replaces baseColorFactor x baseColorTexture).
    BaseColor,
    /// Perceptual roughness (replaces roughnessFactor x metallicRoughness.G).
    Roughness,
    /// Metalness (replaces metallicFactor x metallicRoughness.B).
    Metallic,
    /// Tangent-space normal map, RGB in [0, 1] as glTF stores it (replaces normalTexture):
    /// the normal is normalize(2 x RGB - 1) in the frame of the interpolated normal and its
    /// MikkTSpace tangent, its Z floored at [`NORMAL_Z_FLOOR`] (upper hemisphere).
    Normal,
}

impl Slot {
    /// Floats per texel.
    pub fn channels(self) -> u32 {
        match self {
            Slot::BaseColor | Slot::Normal => 3,
            _ => 1,
        }
    }
    /// The valid range that the optimizer clamps to.
    pub fn range(self) -> (f32, f32) {
        match self {
            Slot::Roughness => (ROUGHNESS_FLOOR, 1.0),
            _ => (0.0, 1.0),
        }
    }
    /// Name as in task files.
    pub fn name(self) -> &'static str {
        match self {
            Slot::BaseColor => "base_color",
            Slot::Roughness => "roughness",
            Slot::Metallic => "metallic",
            Slot::Normal => "normal",
        }
    }
}

/// Smallest roughness the optimizer allows (alpha = 4e-4, the renderer's floor).
pub const ROUGHNESS_FLOOR: f32 = 0.02;

/// Smallest Z of an optimized normal map's 2 x RGB - 1 before it is normalized (blue 0.55):
/// the renderer reads any lower Z as this one (no derivative below it), so the normal stays
/// in the upper hemisphere, at most 84 degrees from the surface's. Mirrored in WGSL
/// (shared/surface.wgsl).
pub const NORMAL_Z_FLOOR: f32 = 0.1;

/// The unit normal (tangent space) that an optimized normal map's texel `rgb` stands for, as
/// the renderer reads it: normalize(2 rgb - 1) with Z floored at [`NORMAL_Z_FLOOR`]. The
/// exported map stores (n + 1) / 2 of it, which a glTF viewer reads as the same normal.
pub fn decode_normal(rgb: [f32; 3]) -> [f32; 3] {
    let v = [
        2.0 * rgb[0] - 1.0,
        2.0 * rgb[1] - 1.0,
        (2.0 * rgb[2] - 1.0).max(NORMAL_Z_FLOOR),
    ];
    let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    [v[0] / len, v[1] / len, v[2] / len]
}

/// The angle in degrees between the normals that two normal-map texels stand for.
pub fn normal_angle_deg(a: [f32; 3], b: [f32; 3]) -> f64 {
    let (p, q) = (decode_normal(a), decode_normal(b));
    let d = p[0] as f64 * q[0] as f64 + p[1] as f64 * q[1] as f64 + p[2] as f64 * q[2] as f64;
    d.clamp(-1.0, 1.0).acos().to_degrees()
}

/// Texture filter for optimized textures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Filter {
    /// One texel, weight 1.
    Nearest,
    /// Four texels with bilinear weights.
    #[default]
    Bilinear,
}

/// Image loss.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Loss {
    /// Mean of (I - G)^2.
    #[default]
    L2,
    /// Mean of (I - G)^2 / (G^2 + 0.01).
    Relmse,
    /// Mean of (s(I) - s(G))^2 in the photo's space, s the sRGB curve (continued above 1);
    /// a channel the photo clipped (G at 1) counts only where the render is below it.
    Srgb,
    /// Mean of (ln(1 + I) - ln(1 + G))^2.
    Log,
}

/// Initial value: RGB for base color, one number for scalar textures.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum Init {
    /// One value.
    Scalar(f32),
    /// Several values (RGB).
    Vector(Vec<f32>),
}

/// One texture to optimize.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TextureSpec {
    /// Material name in the scene.
    pub material: String,
    /// Which input.
    pub slot: Slot,
    /// Width and height in texels.
    pub resolution: [u32; 2],
    /// Constant initial value.
    pub init: Init,
    /// Learning rate (None: the step's for the slot, [`crate::optim::StepKind::learning_rate`]).
    #[serde(default)]
    pub learning_rate: Option<f32>,
}

impl TextureSpec {
    /// The initial value as one float per channel.
    pub fn init_values(&self) -> Vec<f32> {
        match &self.init {
            Init::Scalar(v) => vec![*v; self.slot.channels() as usize],
            Init::Vector(v) => v.clone(),
        }
    }
}

/// Check one texture to optimize, listed after `earlier`: on failure, the key at fault
/// (`resolution`, `init`, `learning_rate` or `slot`) and what is wrong.
pub fn check_texture(
    tex: &TextureSpec,
    earlier: &[TextureSpec],
) -> std::result::Result<(), (&'static str, String)> {
    let [w, h] = tex.resolution;
    if !(1..=4096).contains(&w) || !(1..=4096).contains(&h) {
        return Err(("resolution", "each side must be between 1 and 4096".into()));
    }
    if tex.slot == Slot::Normal && matches!(tex.init, Init::Scalar(_)) {
        return Err((
            "init",
            "a normal map starts from one RGB value, e.g. [0.5, 0.5, 1.0] for flat".into(),
        ));
    }
    let init = tex.init_values();
    if init.len() != tex.slot.channels() as usize {
        return Err((
            "init",
            format!(
                "{} takes {} value(s), got {}",
                tex.slot.name(),
                tex.slot.channels(),
                init.len()
            ),
        ));
    }
    let (lo, hi) = tex.slot.range();
    if init
        .iter()
        .any(|v| !(v.is_finite() && *v >= lo && *v <= hi))
    {
        return Err(("init", format!("values must lie in [{lo}, {hi}]")));
    }
    if tex
        .learning_rate
        .is_some_and(|lr| !(lr.is_finite() && lr >= 0.0))
    {
        return Err(("learning_rate", "must be a finite number >= 0".into()));
    }
    if earlier
        .iter()
        .any(|o| o.material == tex.material && o.slot == tex.slot)
    {
        return Err((
            "slot",
            format!("{} of `{}` is listed twice", tex.slot.name(), tex.material),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A texel stands for the normal glTF stores (2 RGB - 1, normalized), its Z floored; the
    /// angle between two is that of their normals; a normal map's init is an RGB triple.
    #[test]
    fn normal_texels_decode_as_gltf_stores_them() {
        let tilt = 30f32.to_radians();
        let texel = [0.5 + 0.5 * tilt.sin(), 0.5, 0.5 + 0.5 * tilt.cos()];
        let n = decode_normal(texel);
        assert!((n[0] - tilt.sin()).abs() < 1e-6 && (n[2] - tilt.cos()).abs() < 1e-6);
        assert!((normal_angle_deg(texel, [0.5, 0.5, 1.0]) - 30.0).abs() < 1e-4);
        // Below the floor: Z reads as NORMAL_Z_FLOOR, the normal stays above the surface.
        let low = decode_normal([1.0, 0.5, 0.2]);
        assert!((low[2] - NORMAL_Z_FLOOR / (1.0 + NORMAL_Z_FLOOR.powi(2)).sqrt()).abs() < 1e-6);
        // The renderer's floor is this one.
        let wgsl = include_str!("../shaders/shared/surface.wgsl");
        assert!(wgsl.contains(&format!("const NORMAL_Z_FLOOR: f32 = {NORMAL_Z_FLOOR};")));
        let spec = |init| TextureSpec {
            material: "m".into(),
            slot: Slot::Normal,
            resolution: [4, 4],
            init,
            learning_rate: None,
        };
        let e = check_texture(&spec(Init::Scalar(0.5)), &[]).unwrap_err();
        assert_eq!(e.0, "init");
        assert!(e.1.contains("[0.5, 0.5, 1.0]"), "{}", e.1);
        assert!(check_texture(&spec(Init::Vector(vec![0.5, 0.5, 1.0])), &[]).is_ok());
    }
}
