//! Scenes: what the renderer sees after loading a glTF file (world-space triangles, materials,
//! textures, cameras, lights, an optional environment map), and the BVH over the triangles.

pub mod bvh;
pub mod capture;
pub mod env;
mod files;
pub mod images;
mod load;
pub mod tangents;

use glam::{Mat4, Vec2, Vec3, Vec4};
use std::path::PathBuf;

pub use env::EnvMap;
pub use images::Image8;
pub use load::{load, load_source};

/// Largest vertex coordinate (absolute value) psrestir accepts: beyond it, f32 ray tracing
/// loses all precision and bounds overflow.
pub const MAX_COORD: f32 = 1e15;

/// Whether `p` is finite and within ±[`MAX_COORD`].
pub fn in_bounds(p: Vec3) -> bool {
    p.is_finite() && p.abs().max_element() <= MAX_COORD
}

/// One world-space triangle with its shading attributes.
#[derive(Clone, Debug, PartialEq)]
pub struct Triangle {
    /// Vertex positions.
    pub p: [Vec3; 3],
    /// Vertex normals (unit length).
    pub n: [Vec3; 3],
    /// Vertex UV0 (zero when the mesh has none).
    pub uv: [Vec2; 3],
    /// Vertex tangents for normal maps (xyz, and w = ±1: the bitangent is
    /// cross(normal, tangent) x w, glTF's TANGENT): the file's, or MikkTSpace's when loaded
    /// from UVs; zero for a primitive without UVs. A normal-mapped triangle (a glTF or an
    /// optimized normal map) built in code without them gets its face's tangent from its UVs
    /// on upload.
    pub t: [Vec4; 3],
    /// Index into [`Scene::materials`].
    pub material: u32,
}

impl Triangle {
    /// The two triangles of a parallelogram with corner `corner` and edges `u` and `v`, flat
    /// shaded, its front face along `u x v`, UV (0, 0) at `corner` and (1, 1) at the
    /// opposite corner (for building scenes in code).
    pub fn quad(corner: Vec3, u: Vec3, v: Vec3, material: u32) -> [Triangle; 2] {
        let n = u.cross(v).normalize();
        let p = [corner, corner + u, corner + u + v, corner + v];
        let uv = [Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y];
        [[0, 1, 2], [0, 2, 3]].map(|k: [usize; 3]| Triangle {
            p: k.map(|i| p[i]),
            n: [n; 3],
            uv: k.map(|i| uv[i]),
            t: [Vec4::ZERO; 3],
            material,
        })
    }

    /// Twice the area, as the length of the cross product of two edges.
    pub fn area(&self) -> f32 {
        0.5 * (self.p[1] - self.p[0])
            .cross(self.p[2] - self.p[0])
            .length()
    }
}

/// Texture wrap mode (glTF sampler wrapS / wrapT).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Wrap {
    /// REPEAT (glTF default).
    #[default]
    Repeat,
    /// CLAMP_TO_EDGE.
    Clamp,
    /// MIRRORED_REPEAT.
    Mirror,
}

/// A texture as used by one material slot.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureSlot {
    /// Index into [`Scene::images`].
    pub image: usize,
    /// Horizontal wrap.
    pub wrap_s: Wrap,
    /// Vertical wrap.
    pub wrap_t: Wrap,
    /// Nearest lookups (glTF magFilter NEAREST) instead of bilinear.
    pub nearest: bool,
    /// KHR_texture_transform as a 2x3 matrix (rows), identity when absent.
    pub transform: [[f32; 3]; 2],
}

/// A metallic-roughness material (linear values).
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Name from the file, or `material N`.
    pub name: String,
    /// baseColorFactor (linear RGBA).
    pub base_color: Vec4,
    /// baseColorTexture (sRGB).
    pub base_color_texture: Option<TextureSlot>,
    /// metallicFactor.
    pub metallic: f32,
    /// roughnessFactor (perceptual; alpha = roughness^2).
    pub roughness: f32,
    /// metallicRoughnessTexture (linear; G roughness, B metallic).
    pub metallic_roughness_texture: Option<TextureSlot>,
    /// emissiveFactor times KHR_materials_emissive_strength.
    pub emissive: Vec3,
    /// emissiveTexture (sRGB).
    pub emissive_texture: Option<TextureSlot>,
    /// normalTexture (linear, tangent space; its KHR_texture_transform is not read).
    pub normal_texture: Option<TextureSlot>,
    /// normalTexture's scale (of the tangent-space normal's X and Y).
    pub normal_scale: f32,
    /// doubleSided.
    pub double_sided: bool,
}

impl Material {
    /// Whether every factor is finite and the emission is not negative.
    pub fn factors_valid(&self) -> bool {
        self.base_color.is_finite()
            && self.emissive.is_finite()
            && self.metallic.is_finite()
            && self.roughness.is_finite()
            && self.normal_scale.is_finite()
            && self.emissive.min_element() >= 0.0
    }
}

impl Default for Material {
    fn default() -> Self {
        Material {
            name: "default".into(),
            base_color: Vec4::ONE,
            base_color_texture: None,
            metallic: 1.0,
            roughness: 1.0,
            metallic_roughness_texture: None,
            emissive: Vec3::ZERO,
            emissive_texture: None,
            normal_texture: None,
            normal_scale: 1.0,
            double_sided: false,
        }
    }
}

/// A perspective camera.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    /// Name of the camera (or of its node), or `camera N`.
    pub name: String,
    /// Camera-to-world transform (the camera looks down -Z, +Y up).
    pub world: Mat4,
    /// Vertical field of view in radians (derived from `intrinsics` when those are given).
    pub yfov: f32,
    /// Width / height, when the file gives one.
    pub aspect: Option<f32>,
    /// Pinhole intrinsics from a capture (focal lengths and principal point in pixels of an
    /// image of a given size); they replace `yfov` and put the principal point anywhere.
    pub intrinsics: Option<Intrinsics>,
    /// The punctual lights that are on in this camera's capture (indices into
    /// [`Scene::lights`]); None: all of them. Photos of one object under several lights,
    /// one at a time, are captures from cameras at the same pose with different lights.
    /// Emissive surfaces and the environment light every capture.
    pub lights: Option<Vec<usize>>,
}

/// Pinhole intrinsics in pixels of a `width` x `height` image (x right, y down, the origin at
/// the top-left corner of the top-left pixel, as COLMAP and NeRF-style `transforms.json`
/// use). Renders of another size scale them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Intrinsics {
    /// Horizontal focal length.
    pub fx: f32,
    /// Vertical focal length.
    pub fy: f32,
    /// Principal point, x.
    pub cx: f32,
    /// Principal point, y.
    pub cy: f32,
    /// Width of the image these refer to.
    pub width: u32,
    /// Height of the image these refer to.
    pub height: u32,
}

impl Intrinsics {
    /// Whether the numbers make a pinhole camera: positive focal lengths and image size,
    /// finite principal point.
    pub fn valid(&self) -> bool {
        self.fx.is_finite()
            && self.fy.is_finite()
            && self.fx > 0.0
            && self.fy > 0.0
            && self.cx.is_finite()
            && self.cy.is_finite()
            && self.width > 0
            && self.height > 0
    }
}

impl Camera {
    /// Whether a vertical field of view `yfov` (radians) and an `aspect` ratio make a
    /// perspective projection: `yfov` in (0, pi), `aspect` finite and positive when given.
    pub fn projection_valid(yfov: f32, aspect: Option<f32>) -> bool {
        yfov.is_finite()
            && yfov > 0.0
            && yfov < std::f32::consts::PI
            && aspect.is_none_or(|a| a.is_finite() && a > 0.0)
    }

    /// A camera at `eye` looking at `target`, `up` giving the vertical, with a vertical field
    /// of view of `yfov` radians (for building scenes in code).
    pub fn look_at(name: &str, eye: Vec3, target: Vec3, up: Vec3, yfov: f32) -> Camera {
        let f = (target - eye).normalize();
        let r = f.cross(up).normalize();
        let u = r.cross(f);
        Camera {
            name: name.into(),
            world: Mat4::from_cols(
                r.extend(0.0),
                u.extend(0.0),
                (-f).extend(0.0),
                eye.extend(1.0),
            ),
            yfov,
            aspect: None,
            intrinsics: None,
            lights: None,
        }
    }

    /// A camera with camera-to-world transform `world` (glTF convention: it looks down -Z,
    /// +Y up) and pinhole `intrinsics`.
    pub fn with_intrinsics(name: &str, world: Mat4, k: Intrinsics) -> Camera {
        Camera {
            name: name.into(),
            world,
            yfov: 2.0 * (0.5 * k.height as f32 / k.fy).atan(),
            aspect: Some(k.width as f32 / k.height as f32),
            intrinsics: Some(k),
            lights: None,
        }
    }

    /// Focal lengths and principal point [fx, fy, cx, cy] in pixels of a `width` x `height`
    /// render.
    pub fn pixel_intrinsics(&self, width: u32, height: u32) -> [f32; 4] {
        let (w, h) = (width as f32, height as f32);
        match self.intrinsics {
            Some(k) => {
                let (sx, sy) = (w / k.width as f32, h / k.height as f32);
                [k.fx * sx, k.fy * sy, k.cx * sx, k.cy * sy]
            }
            None => {
                let f = 0.5 * h / (0.5 * self.yfov).tan();
                [f, f, 0.5 * w, 0.5 * h]
            }
        }
    }
}

/// Kind of a KHR_lights_punctual light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PunctualKind {
    /// Point light; intensity in candela.
    Point,
    /// Spot light; intensity in candela, cone angles in radians.
    Spot {
        /// Angle where the fall-off starts.
        inner_cone: f32,
        /// Angle where the light ends.
        outer_cone: f32,
    },
    /// Directional light; intensity in lux.
    Directional,
}

/// A KHR_lights_punctual light in world space.
#[derive(Clone, Debug, PartialEq)]
pub struct PunctualLight {
    /// Light name or `light N`.
    pub name: String,
    /// Point, spot or directional.
    pub kind: PunctualKind,
    /// World position (point, spot).
    pub position: Vec3,
    /// World direction the light points to (spot, directional): the node's -Z.
    pub direction: Vec3,
    /// color x intensity.
    pub intensity: Vec3,
    /// Range (0 = infinite).
    pub range: f32,
}

impl PunctualLight {
    /// A point light at `position` with `intensity` (candela, RGB).
    pub fn point(name: &str, position: Vec3, intensity: Vec3) -> PunctualLight {
        PunctualLight {
            name: name.into(),
            kind: PunctualKind::Point,
            position,
            direction: Vec3::NEG_Z,
            intensity,
            range: 0.0,
        }
    }
}

/// How many vertices a camera path has: 1 renders direct light only (emission seen directly,
/// and light arriving from emitters at the first surface a camera ray hits); each more is one
/// more bounce of indirect light (next-event estimation and BSDF sampling by MIS at every
/// vertex, Russian roulette from the fourth). The default is 1.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct MaxDepth(u32);

impl MaxDepth {
    /// Direct light only.
    pub const DIRECT: MaxDepth = MaxDepth(1);
    /// The largest depth accepted (paths that long carry next to nothing on any scene a
    /// camera sees; the bound keeps every path's loop short).
    pub const LIMIT: u32 = 64;

    /// `depth` vertices, 1 to [`MaxDepth::LIMIT`]; the error says what is allowed.
    pub fn new(depth: u32) -> std::result::Result<MaxDepth, String> {
        if (1..=Self::LIMIT).contains(&depth) {
            Ok(MaxDepth(depth))
        } else {
            Err(format!(
                "{depth} is out of range: path depth runs from 1 (direct light only) to {}",
                Self::LIMIT
            ))
        }
    }

    /// The number of vertices.
    pub fn get(self) -> u32 {
        self.0
    }
}

impl Default for MaxDepth {
    fn default() -> Self {
        Self::DIRECT
    }
}

/// Everything the renderer needs, in world space.
#[derive(Clone, Debug, Default)]
pub struct Scene {
    /// The file the scene came from (empty for scenes built in code).
    pub source: PathBuf,
    /// Triangles of every mesh instance.
    pub triangles: Vec<Triangle>,
    /// Materials; index 0.. as in the file, plus a default one at the end when needed.
    pub materials: Vec<Material>,
    /// Decoded images (RGBA8).
    pub images: Vec<Image8>,
    /// Perspective cameras.
    pub cameras: Vec<Camera>,
    /// Punctual lights.
    pub lights: Vec<PunctualLight>,
    /// Optional environment light.
    pub env: Option<EnvMap>,
    /// Whether the environment is looked up with bilinear weights over its four nearest
    /// texel centres (wrapping in azimuth) instead of at its nearest texel.
    pub env_bilinear: bool,
    /// Things skipped while loading, each naming what and why.
    pub warnings: Vec<String>,
    /// Vertices of the camera paths that render it (1, the default: direct light only).
    pub max_depth: MaxDepth,
}

impl Scene {
    /// The indices of the punctual lights named `names` (a capture's lights,
    /// [`Camera::lights`]); on failure, which name no light has and the names there are.
    pub fn light_indices(&self, names: &[String]) -> std::result::Result<Vec<usize>, String> {
        names
            .iter()
            .map(|n| {
                self.lights
                    .iter()
                    .position(|l| &l.name == n)
                    .ok_or_else(|| {
                        let known: Vec<&str> =
                            self.lights.iter().map(|l| l.name.as_str()).collect();
                        let known = if known.is_empty() {
                            "none".to_string()
                        } else {
                            known.join(", ")
                        };
                        format!("no punctual light `{n}` (there are: {known})")
                    })
            })
            .collect()
    }

    /// Find a camera by name or by index.
    pub fn camera(&self, which: Option<&str>) -> crate::Result<usize> {
        if self.cameras.is_empty() {
            return Err(crate::Error::file(
                &self.source,
                "the scene has no perspective camera",
            ));
        }
        let Some(which) = which else { return Ok(0) };
        if let Some(i) = self.cameras.iter().position(|c| c.name == which) {
            return Ok(i);
        }
        if let Ok(i) = which.parse::<usize>() {
            if i < self.cameras.len() {
                return Ok(i);
            }
        }
        let names: Vec<String> = self
            .cameras
            .iter()
            .enumerate()
            .map(|(i, c)| format!("{i}: {}", c.name))
            .collect();
        Err(crate::Error::file(
            &self.source,
            format!("no camera `{which}`; the scene has {}", names.join(", ")),
        ))
    }

    /// Check that the scene is one the renderer can take: finite geometry within
    /// ±[`MAX_COORD`], unit normals, material, image and texture references in range, images
    /// holding width x height pixels, finite non-negative material factors and light
    /// intensities, cameras with a field of view in (0, pi), a finite non-negative
    /// environment. Loaded scenes pass by construction (the loader skips or refuses what
    /// fails); scenes built in code are checked here before they reach the GPU, where such
    /// data would otherwise turn into NaN images or out-of-range reads.
    pub fn validate(&self) -> crate::Result<()> {
        let checks = [
            Scene::check_geometry,
            Scene::check_materials,
            Scene::check_views_and_lights,
        ];
        checks
            .iter()
            .try_for_each(|check| check(self))
            .map_err(|msg| {
                if self.source.as_os_str().is_empty() {
                    crate::Error::Invalid(format!("invalid scene: {msg}"))
                } else {
                    crate::Error::file(&self.source, msg)
                }
            })
    }

    /// [`Scene::validate`]'s triangles and images.
    fn check_geometry(&self) -> Result<(), String> {
        let n_mat = self.materials.len();
        for (i, t) in self.triangles.iter().enumerate() {
            if t.material as usize >= n_mat {
                return Err(format!(
                    "triangle {i} uses material {} of {n_mat}",
                    t.material
                ));
            }
            if !t.p.iter().all(|&p| in_bounds(p)) {
                return Err(format!(
                    "triangle {i} has a non-finite vertex or one beyond ±{MAX_COORD:e}"
                ));
            }
            if t.n
                .iter()
                .any(|n| !n.is_finite() || (n.length() - 1.0).abs() > 1e-3)
            {
                return Err(format!("triangle {i} has a normal that is not unit length"));
            }
            if t.uv.iter().any(|uv| !uv.is_finite()) {
                return Err(format!("triangle {i} has a non-finite UV"));
            }
        }
        for (i, img) in self.images.iter().enumerate() {
            if img.width == 0
                || img.height == 0
                || img.rgba.len() as u64 != img.width as u64 * img.height as u64
            {
                return Err(format!(
                    "image {i} (`{}`) is {}x{} but holds {} pixels",
                    img.name,
                    img.width,
                    img.height,
                    img.rgba.len()
                ));
            }
        }
        Ok(())
    }

    /// [`Scene::validate`]'s materials and their textures.
    fn check_materials(&self) -> Result<(), String> {
        for m in &self.materials {
            if !m.factors_valid() {
                return Err(format!(
                    "material `{}` has non-finite or negative factors",
                    m.name
                ));
            }
            let slots = [
                &m.base_color_texture,
                &m.metallic_roughness_texture,
                &m.emissive_texture,
            ];
            for s in slots.into_iter().flatten() {
                if s.image >= self.images.len() {
                    return Err(format!(
                        "material `{}` uses image {} of {}",
                        m.name,
                        s.image,
                        self.images.len()
                    ));
                }
                if s.transform.iter().flatten().any(|v| !v.is_finite()) {
                    return Err(format!(
                        "material `{}` has a non-finite texture transform",
                        m.name
                    ));
                }
            }
        }
        Ok(())
    }

    /// [`Scene::validate`]'s cameras, lights and environment.
    fn check_views_and_lights(&self) -> Result<(), String> {
        for c in &self.cameras {
            if !c.world.is_finite()
                || !Camera::projection_valid(c.yfov, c.aspect)
                || c.intrinsics.is_some_and(|k| !k.valid())
            {
                return Err(format!(
                    "camera `{}` has a non-finite transform, a field of view outside (0, pi), \
                     a non-positive aspect ratio or invalid intrinsics",
                    c.name
                ));
            }
            if let Some(&i) = c.lights.iter().flatten().find(|&&i| i >= self.lights.len()) {
                return Err(format!(
                    "camera `{}` sees light {i}, the scene has {} punctual lights",
                    c.name,
                    self.lights.len()
                ));
            }
        }
        for l in &self.lights {
            let ok = in_bounds(l.position)
                && l.direction.is_finite()
                && l.intensity.is_finite()
                && l.intensity.min_element() >= 0.0
                && l.range.is_finite()
                && match l.kind {
                    PunctualKind::Spot {
                        inner_cone,
                        outer_cone,
                    } => inner_cone.is_finite() && outer_cone.is_finite(),
                    _ => true,
                };
            if !ok {
                return Err(format!(
                    "light `{}` has non-finite values, a negative intensity or a position \
                     beyond ±{MAX_COORD:e}",
                    l.name
                ));
            }
        }
        if let Some(env) = &self.env {
            if env.width == 0
                || env.height == 0
                || env.rgb.len() as u64 != env.width as u64 * env.height as u64
                || !(env.scale.is_finite() && env.scale >= 0.0)
                || env.rgb.iter().flatten().any(|v| !v.is_finite() || *v < 0.0)
            {
                return Err(
                    "the environment map's size, pixels or scale are invalid (sizes must \
                     match, values be finite and non-negative)"
                        .into(),
                );
            }
        }
        Ok(())
    }

    /// Whether anything emits light: a punctual light, an emissive material used by a
    /// triangle, or an environment.
    pub fn has_light(&self) -> bool {
        !self.lights.is_empty()
            || self.env.is_some()
            || self.triangles.iter().any(|t| {
                self.materials
                    .get(t.material as usize)
                    .is_some_and(|m| m.emissive.max_element() > 0.0)
            })
    }

    /// Make a scene renderable as it comes from a modeling tool: without a camera, add one
    /// named `default` that frames the scene's bounds (from the front, +Z, slightly above);
    /// with `environment`, and neither a punctual light nor an environment, add a uniform
    /// white environment, whatever emissive surfaces it has (an asset's glowing parts light
    /// little of it; a scene lit by its emissive surfaces alone passes `false`). Each
    /// addition is noted in `warnings` and returned.
    pub fn add_defaults(&mut self, environment: bool) -> Vec<String> {
        let mut notes = Vec::new();
        if self.cameras.is_empty() {
            let (c, r) = self.bounding_sphere();
            let yfov = 0.8f32;
            let dir = Vec3::new(0.0, 0.35, 1.0).normalize();
            let eye = c + dir * (1.05 * r / (0.5 * yfov).sin());
            self.cameras
                .push(Camera::look_at("default", eye, c, Vec3::Y, yfov));
            notes.push(format!(
                "the scene has no camera: added `default`, looking at its bounds from +Z                  (eye {:.3?})",
                eye.to_array()
            ));
        }
        if environment && self.lights.is_empty() && self.env.is_none() {
            let emissive = self.has_light();
            self.env = Some(EnvMap::constant([1.0, 1.0, 1.0]));
            notes.push(if emissive {
                "the scene has no punctual light and no environment, only emissive surfaces: \
                 added a uniform white environment (a scene lit by its emissive surfaces alone \
                 says `default_environment = false` in its task, or renders with \
                 --no-default-env)"
                    .into()
            } else {
                "the scene has no light: added a uniform white environment".into()
            });
        }
        self.warnings.extend(notes.iter().cloned());
        notes
    }

    /// Centre and radius of a sphere around every triangle.
    pub fn bounding_sphere(&self) -> (Vec3, f32) {
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for t in &self.triangles {
            for p in t.p {
                lo = lo.min(p);
                hi = hi.max(p);
            }
        }
        if self.triangles.is_empty() {
            return (Vec3::ZERO, 1.0);
        }
        let c = 0.5 * (lo + hi);
        (c, (0.5 * (hi - lo).length()).max(1e-3))
    }
}
