//! A task file's tables as they are read: the scene, cameras, lights, targets, textures and
//! the optimizer's table, with the checks of their numbers.
use super::environment::EnvironmentSpec;
use super::optimizer::{self, OptimizerSpec};
use super::TextureSpec;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Where the target images come from.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetSpec {
    /// A ground-truth version of the scene (same geometry, other textures).
    pub scene: Option<PathBuf>,
    /// Samples per pixel for rendering the ground-truth scene.
    #[serde(default = "default_target_spp")]
    pub spp: u32,
    /// Target image per camera name (with a `cameras_file`, each frame's image is its
    /// camera's target unless listed here).
    pub images: Option<BTreeMap<String, PathBuf>>,
    /// Mask image per camera name: its alpha (or, without alpha, its gray value) weighs
    /// each pixel's loss and gradient; 0 leaves the pixel out. Targets with an alpha channel
    /// are masked by it without this.
    pub masks: Option<BTreeMap<String, PathBuf>>,
    /// Fixed exposure per camera name: the render is multiplied by it before it is compared
    /// with the target (default 1; see `optimizer.optimize_exposure`).
    pub exposure: Option<BTreeMap<String, f32>>,
    /// The punctual lights (the scene's and the task's `[[light]]`s, by name) that are on in
    /// a camera's capture, per camera name: photos of one object under several lights, one
    /// set at a time, are cameras at the same pose (`[[camera]]` tables) with different
    /// sets. A camera not listed sees every light; emissive surfaces and the environment
    /// light every capture.
    pub lights: Option<BTreeMap<String, Vec<String>>>,
}

/// A camera defined in a task file: look-at, or a camera-to-world matrix with pinhole
/// intrinsics.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraDef {
    /// Name (targets, masks and `cameras` refer to it).
    pub name: String,
    /// Look-at: the eye position.
    pub eye: Option<[f32; 3]>,
    /// Look-at: the point looked at.
    pub target: Option<[f32; 3]>,
    /// Look-at: the up direction (default +Y).
    pub up: Option<[f32; 3]>,
    /// Look-at: vertical field of view in degrees.
    pub yfov_deg: Option<f32>,
    /// Matrix form: camera-to-world, 4 rows of 4 (glTF axes: the camera looks down -Z, +Y
    /// up).
    pub matrix: Option<[[f32; 4]; 4]>,
    /// Matrix form: focal lengths and principal point in pixels of a `width` x `height`
    /// image (default: the task's size).
    pub fx: Option<f32>,
    /// See `fx`.
    pub fy: Option<f32>,
    /// See `fx` (default: the image center).
    pub cx: Option<f32>,
    /// See `fx` (default: the image center).
    pub cy: Option<f32>,
    /// The image size the intrinsics refer to.
    pub width: Option<u32>,
    /// See `width`.
    pub height: Option<u32>,
}

/// A light added by a task file, in glTF's KHR_lights_punctual units (candela for point and
/// spot lights, lux for directional ones).
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightDef {
    /// Name (default `task light N`).
    pub name: Option<String>,
    /// "point", "spot" or "directional".
    #[serde(rename = "type")]
    pub kind: LightKind,
    /// Position (point and spot lights).
    pub position: Option<[f32; 3]>,
    /// Direction the light points in (spot and directional lights).
    pub direction: Option<[f32; 3]>,
    /// Linear RGB color (default white).
    pub color: Option<[f32; 3]>,
    /// Intensity.
    pub intensity: f32,
    /// Range (0 or absent: unlimited).
    pub range: Option<f32>,
    /// Spot lights: angle where the fall-off starts, radians (default 0).
    pub inner_cone_angle: Option<f32>,
    /// Spot lights: angle where the light ends, radians (default pi/4).
    pub outer_cone_angle: Option<f32>,
}

/// The kind of a [`LightDef`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LightKind {
    /// Point light.
    Point,
    /// Spot light.
    Spot,
    /// Directional light.
    Directional,
}

fn default_target_spp() -> u32 {
    256
}

/// A whole task file.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Task {
    /// The scene, relative to the task file.
    pub scene: PathBuf,
    /// Optional environment map (relative to the task file) and its scale.
    pub env: Option<PathBuf>,
    /// Multiplier of the environment map.
    #[serde(default = "unit")]
    pub env_scale: f32,
    /// Whether a scene without punctual lights and environment gets the default uniform white
    /// environment (true; false for a scene lit by its emissive surfaces alone).
    #[serde(default = "optimizer::yes")]
    pub default_environment: bool,
    /// Cameras rendered every iteration (names or indices). When absent: the cameras that
    /// the task defines or loads from `cameras_file`, or else all of the scene's.
    pub cameras: Option<Vec<String>>,
    /// Cameras defined here (`[[camera]]` tables), added to the scene's.
    #[serde(default, rename = "camera")]
    pub camera_defs: Vec<CameraDef>,
    /// A camera file from a capture tool: NeRF-style `transforms.json`, or a COLMAP text
    /// model (its folder, or its `cameras.txt`/`images.txt`), relative to the task file.
    pub cameras_file: Option<PathBuf>,
    /// Lights added to the scene (`[[light]]` tables).
    #[serde(default, rename = "light")]
    pub lights: Vec<LightDef>,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Random seed.
    #[serde(default = "optimizer::one")]
    pub seed: u32,
    /// Vertices of a camera path, for the target renders and the model that is fitted: 1 (the
    /// default) is direct light only; photos of real objects carry indirect light, which a
    /// depth of 3 or more models (docs/guide.md, "Indirect light").
    #[serde(default = "optimizer::one")]
    pub max_depth: u32,
    /// Output folder (relative to the working directory).
    pub output: Option<PathBuf>,
    /// Where the targets come from.
    pub target: TargetSpec,
    /// Optimizer settings.
    pub optimizer: OptimizerSpec,
    /// Textures to optimize.
    pub textures: Vec<TextureSpec>,
    /// The environment recovered with the textures (`[environment]`; absent: it is known).
    pub environment: Option<EnvironmentSpec>,
    /// Environment maps (relative to the task) under which the recovered model and the
    /// ground truth are rendered at the end of the run and compared (`relight.csv`).
    #[serde(default)]
    pub relight: Vec<PathBuf>,
    /// Folder of the task file; paths in the task are relative to it.
    #[serde(skip)]
    pub base: PathBuf,
    /// The task file itself.
    #[serde(skip)]
    pub path: PathBuf,
}

fn unit() -> f32 {
    1.0
}

fn finite3(v: &Option<[f32; 3]>) -> bool {
    v.is_none_or(|v| v.iter().all(|x| x.is_finite()))
}

impl CameraDef {
    /// Check the numbers; on failure the key at fault and what is wrong.
    pub fn check(&self) -> std::result::Result<(), (&'static str, String)> {
        let look_at = self.eye.is_some() || self.target.is_some() || self.yfov_deg.is_some();
        match (look_at, self.matrix.is_some()) {
            (true, true) => {
                return Err((
                    "matrix",
                    "give either eye/target/yfov_deg or matrix with intrinsics, not both".into(),
                ))
            }
            (false, false) => {
                return Err((
                    "eye",
                    "give eye, target and yfov_deg, or matrix and fx".into(),
                ))
            }
            _ => {}
        }
        if look_at {
            let (Some(e), Some(t)) = (self.eye, self.target) else {
                return Err(("target", "a look-at camera needs eye and target".into()));
            };
            if !finite3(&self.eye) || !finite3(&self.target) || !finite3(&self.up) {
                return Err(("eye", "eye, target and up must be finite".into()));
            }
            let d = glam::Vec3::from(t) - glam::Vec3::from(e);
            let up = glam::Vec3::from(self.up.unwrap_or([0.0, 1.0, 0.0]));
            if d.length() <= 0.0 || d.cross(up).length() <= 1e-6 * d.length() * up.length() {
                return Err((
                    "up",
                    "eye and target coincide, or up is parallel to the view direction".into(),
                ));
            }
            match self.yfov_deg {
                Some(f) if f > 0.0 && f < 180.0 => {}
                _ => return Err(("yfov_deg", "must be in (0, 180) degrees".into())),
            }
            if self.fx.is_some() || self.fy.is_some() || self.cx.is_some() || self.cy.is_some() {
                return Err((
                    "fx",
                    "intrinsics go with matrix, not with a look-at camera".into(),
                ));
            }
        } else {
            let m = self.matrix.unwrap_or_default();
            if m.iter().flatten().any(|x| !x.is_finite()) {
                return Err(("matrix", "must be finite".into()));
            }
            match self.fx {
                Some(f) if f.is_finite() && f > 0.0 => {}
                _ => {
                    return Err((
                        "fx",
                        "a matrix camera needs a positive focal length fx".into(),
                    ))
                }
            }
            for (k, v) in [("fy", self.fy), ("cx", self.cx), ("cy", self.cy)] {
                if v.is_some_and(|v| !v.is_finite() || (k == "fy" && v <= 0.0)) {
                    return Err((k, "must be a finite number (fy > 0)".into()));
                }
            }
            if self.width == Some(0) || self.height == Some(0) {
                return Err(("width", "must be at least 1".into()));
            }
        }
        Ok(())
    }
}

impl CameraDef {
    /// The camera this definition makes (checked with [`CameraDef::check`] first), for a
    /// task rendering `width` x `height` images.
    pub fn camera(&self, width: u32, height: u32) -> crate::scene::Camera {
        use glam::Vec3;
        if let (Some(eye), Some(target)) = (self.eye, self.target) {
            let up = self.up.unwrap_or([0.0, 1.0, 0.0]);
            let yfov = self.yfov_deg.unwrap_or(45.0).to_radians();
            return crate::scene::Camera::look_at(
                &self.name,
                Vec3::from(eye),
                Vec3::from(target),
                Vec3::from(up),
                yfov,
            );
        }
        let m = self.matrix.unwrap_or([
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ]);
        let (w, h) = (self.width.unwrap_or(width), self.height.unwrap_or(height));
        let fx = self.fx.unwrap_or(1.0);
        let k = crate::scene::Intrinsics {
            fx,
            fy: self.fy.unwrap_or(fx),
            cx: self.cx.unwrap_or(0.5 * w as f32),
            cy: self.cy.unwrap_or(0.5 * h as f32),
            width: w,
            height: h,
        };
        crate::scene::Camera::with_intrinsics(
            &self.name,
            glam::Mat4::from_cols_array_2d(&m).transpose(),
            k,
        )
    }
}

impl LightDef {
    /// The punctual light this definition makes; `index` numbers unnamed ones.
    pub fn light(&self, index: usize) -> crate::scene::PunctualLight {
        use crate::scene::PunctualKind;
        use glam::Vec3;
        let color = Vec3::from(self.color.unwrap_or([1.0; 3]));
        crate::scene::PunctualLight {
            name: self
                .name
                .clone()
                .unwrap_or_else(|| format!("task light {index}")),
            kind: match self.kind {
                LightKind::Point => PunctualKind::Point,
                LightKind::Directional => PunctualKind::Directional,
                LightKind::Spot => PunctualKind::Spot {
                    inner_cone: self.inner_cone_angle.unwrap_or(0.0),
                    outer_cone: self.outer_cone_angle.unwrap_or(std::f32::consts::FRAC_PI_4),
                },
            },
            position: Vec3::from(self.position.unwrap_or([0.0; 3])),
            direction: Vec3::from(self.direction.unwrap_or([0.0, -1.0, 0.0]))
                .normalize_or(Vec3::NEG_Y),
            intensity: color * self.intensity,
            range: self.range.unwrap_or(0.0),
        }
    }

    /// Check the numbers; on failure the key at fault and what is wrong.
    pub fn check(&self) -> std::result::Result<(), (&'static str, String)> {
        if !(self.intensity.is_finite() && self.intensity >= 0.0) {
            return Err(("intensity", "must be a finite number >= 0".into()));
        }
        if !finite3(&self.position) || !finite3(&self.direction) || !finite3(&self.color) {
            return Err((
                "position",
                "position, direction and color must be finite".into(),
            ));
        }
        if self.color.is_some_and(|c| c.iter().any(|x| *x < 0.0)) {
            return Err(("color", "must not be negative".into()));
        }
        let needs_position = self.kind != LightKind::Directional;
        let needs_direction = self.kind != LightKind::Point;
        if needs_position && self.position.is_none() {
            return Err(("position", "point and spot lights need a position".into()));
        }
        if needs_direction
            && self
                .direction
                .is_none_or(|d| glam::Vec3::from(d).length() <= 0.0)
        {
            return Err((
                "direction",
                "spot and directional lights need a direction".into(),
            ));
        }
        if self.range.is_some_and(|r| !(r.is_finite() && r >= 0.0)) {
            return Err(("range", "must be a finite number >= 0".into()));
        }
        let inner = self.inner_cone_angle.unwrap_or(0.0);
        let outer = self.outer_cone_angle.unwrap_or(std::f32::consts::FRAC_PI_4);
        if !(inner >= 0.0 && inner < outer && outer <= std::f32::consts::FRAC_PI_2) {
            return Err((
                "outer_cone_angle",
                "cone angles must satisfy 0 <= inner < outer <= pi/2".into(),
            ));
        }
        Ok(())
    }
}
