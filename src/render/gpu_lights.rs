//! The scene's lights on the GPU: one entry per punctual light, emissive triangle and the
//! environment, chosen for next-event estimation in proportion to a power estimate, and one
//! copy of them per set of punctual lights that a camera's capture sees
//! ([`crate::scene::Camera::lights`]; shared/lights.wgsl, `light_base`).
use super::layout::*;
use crate::scene::{bvh, PunctualKind, Scene};
use glam::Vec3;

/// Luminance in f64, so that the power of a light with an intensity near f32::MAX stays
/// finite.
fn luminance(c: Vec3) -> f64 {
    0.2126 * c.x as f64 + 0.7152 * c.y as f64 + 0.0722 * c.z as f64
}

/// The lights (punctual, one per emissive triangle, the environment), each chosen with
/// probability proportional to a power estimate; each triangle's light (or none), the
/// environment's sampling table, and the scene's info with the light counts.
pub(super) fn gpu_lights(
    scene: &Scene,
    bvh: &bvh::Bvh,
    gpu_index: &[u32],
) -> (Vec<GpuLight>, Vec<f64>, Vec<u32>, Vec<f32>, GpuSceneInfo) {
    let n_tris = scene.triangles.len();
    let (_, radius) = scene.bounding_sphere();
    use std::f64::consts::PI;
    let mut lights: Vec<GpuLight> = Vec::new();
    let mut power: Vec<f64> = Vec::new();
    for l in &scene.lights {
        let mut g = GpuLight {
            position: l.position.to_array(),
            direction: l.direction.to_array(),
            intensity: l.intensity.to_array(),
            range: l.range,
            ..Default::default()
        };
        let lum = luminance(l.intensity);
        match l.kind {
            PunctualKind::Point => {
                g.kind = LIGHT_POINT;
                power.push(4.0 * PI * lum);
            }
            PunctualKind::Spot {
                inner_cone,
                outer_cone,
            } => {
                g.kind = LIGHT_SPOT;
                let scale = 1.0 / (inner_cone.cos() - outer_cone.cos()).max(1e-3);
                g.spot_scale = scale;
                g.spot_offset = -outer_cone.cos() * scale;
                power.push(2.0 * PI * (1.0 - outer_cone.cos() as f64).max(1e-3) * lum);
            }
            PunctualKind::Directional => {
                g.kind = LIGHT_DIRECTIONAL;
                power.push(PI * (radius as f64).powi(2) * lum);
            }
        }
        lights.push(g);
    }
    let mut tri_light = vec![u32::MAX; n_tris];
    for (i, t) in scene.triangles.iter().enumerate() {
        let m = &scene.materials[t.material as usize];
        let lum = luminance(m.emissive);
        let area = t.area();
        if lum > 0.0 && area > 0.0 {
            tri_light[i] = lights.len() as u32;
            lights.push(GpuLight {
                kind: LIGHT_AREA,
                tri: gpu_index[i],
                ..Default::default()
            });
            let sides = if m.double_sided { 2.0 } else { 1.0 };
            power.push(PI * lum * area as f64 * sides);
        }
    }
    let mut env_table = vec![0f32; 4];
    let mut info = GpuSceneInfo {
        n_nodes: bvh.nodes.len() as u32,
        n_tris: n_tris as u32,
        env_light: u32::MAX,
        scene_radius: radius,
        max_depth: scene.max_depth.get(),
        env_bilinear: scene.env_bilinear as u32,
        ..Default::default()
    };
    if let Some(env) = &scene.env {
        let (table, marginal, conditional) = env.gpu_table();
        env_table = table;
        info.env_width = env.width;
        info.env_height = env.height;
        info.env_marginal = marginal;
        info.env_conditional = conditional;
        info.env_scale = env.scale;
        let p = env.power(radius);
        if p > 0.0 {
            info.env_light = lights.len() as u32;
            lights.push(GpuLight {
                kind: LIGHT_ENV,
                ..Default::default()
            });
            power.push(p);
        }
    }
    if !choose_lights(&mut lights, &power) {
        log::warn!(
            "{}: the scene has no light with positive power (no punctual light, emissive \
             triangle of non-zero area or environment): every render is black",
            scene.source.display()
        );
    }
    info.n_lights = lights.len() as u32;
    (lights, power, tri_light, env_table, info)
}

/// Each light's choice probability in proportion to its power, and the CDF over them; false
/// when no light has positive power.
fn choose_lights(lights: &mut [GpuLight], power: &[f64]) -> bool {
    let total: f64 = power.iter().map(|&p| p.max(0.0)).sum();
    let mut acc = 0f64;
    for (l, p) in lights.iter_mut().zip(power) {
        let pmf = if total > 0.0 { p.max(0.0) / total } else { 0.0 };
        acc += pmf;
        l.pmf = pmf as f32;
        l.cdf = acc as f32;
    }
    // The last light with a positive probability, and any after it, end the CDF at 1: a
    // light that is never chosen keeps an empty interval.
    let last = power.iter().rposition(|&p| p > 0.0).unwrap_or(0);
    for l in lights.iter_mut().skip(last) {
        l.cdf = 1.0;
    }
    total > 0.0
}

/// The sets of punctual lights that the cameras' captures see other than all of them
/// ([`crate::scene::Camera::lights`]), each sorted, in order of first appearance, and how
/// many punctual lights the scene has (the first lights of the buffer).
pub(super) struct CaptureSets {
    sets: Vec<Vec<usize>>,
    n_punctual: usize,
}

impl CaptureSets {
    fn of(scene: &Scene) -> CaptureSets {
        let mut sets: Vec<Vec<usize>> = Vec::new();
        for set in scene.cameras.iter().filter_map(|c| c.lights.as_ref()) {
            let set = sorted(set);
            if !sets.contains(&set) {
                sets.push(set);
            }
        }
        CaptureSets {
            sets,
            n_punctual: scene.lights.len(),
        }
    }

    /// The lights buffer ([`light_tables`]) for `lights` of power `power`.
    pub(super) fn table(&self, lights: &[GpuLight], power: &[f64]) -> (Vec<GpuLight>, Vec<bool>) {
        light_tables(lights, power, &self.sets, self.n_punctual)
    }

    /// The first entry of the copy for a capture that sees `set` in a buffer of `n_lights`
    /// lights per copy; None for a set the buffer has no copy of.
    pub(super) fn base(&self, set: &[usize], n_lights: u32) -> Option<u32> {
        let set = sorted(set);
        let k = self.sets.iter().position(|s| *s == set)?;
        Some((1 + k as u32) * n_lights)
    }
}

fn sorted(set: &[usize]) -> Vec<usize> {
    let mut s = set.to_vec();
    s.sort_unstable();
    s.dedup();
    s
}

/// The lights buffer (shared/lights.wgsl, `light_base`): `lights` once with every light, then
/// once per set of `sets`, in which the first `n_punctual` lights (the scene's punctual ones)
/// not in the set are never chosen; each copy's choice probabilities in proportion to the
/// power of the lights it has. Also returns, per set, whether it has a light with positive
/// power.
fn light_tables(
    lights: &[GpuLight],
    power: &[f64],
    sets: &[Vec<usize>],
    n_punctual: usize,
) -> (Vec<GpuLight>, Vec<bool>) {
    let mut table = Vec::with_capacity(lights.len() * (1 + sets.len()));
    let mut lit = Vec::with_capacity(1 + sets.len());
    for set in std::iter::once(None).chain(sets.iter().map(Some)) {
        let mut copy = lights.to_vec();
        let p: Vec<f64> = power
            .iter()
            .enumerate()
            .map(|(i, &p)| match set {
                Some(s) if i < n_punctual && !s.contains(&i) => 0.0,
                _ => p,
            })
            .collect();
        lit.push(choose_lights(&mut copy, &p));
        table.extend(copy);
    }
    (table, lit)
}

/// The lights buffer for `scene`'s cameras and the sets of their captures, with a warning for
/// a capture that sees no light with power.
pub(super) fn capture_lights(
    scene: &Scene,
    lights: &[GpuLight],
    power: &[f64],
) -> (Vec<GpuLight>, CaptureSets) {
    let sets = CaptureSets::of(scene);
    let (table, lit) = sets.table(lights, power);
    for (set, _) in sets.sets.iter().zip(&lit[1..]).filter(|(_, &lit)| !lit) {
        let names: Vec<&str> = set.iter().map(|&i| scene.lights[i].name.as_str()).collect();
        log::warn!(
            "{}: a capture that sees only the lights [{}] has no light with positive \
             power: its renders are black",
            scene.source.display(),
            names.join(", ")
        );
    }
    (table, sets)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each set's copy chooses among the lights it has, in proportion to their power; a light
    /// that is off, the last one included, has probability 0 and an empty CDF interval.
    #[test]
    fn each_light_set_chooses_among_its_own_lights() {
        let lights = vec![GpuLight::default(); 4];
        // Two punctual lights, an area light and the environment.
        let power = [2.0, 6.0, 1.0, 1.0];
        let sets = [vec![0], vec![1], vec![]];
        let (table, lit) = light_tables(&lights, &power, &sets, 2);
        assert_eq!(table.len(), 16);
        assert_eq!(lit, [true; 4]);
        let pmf =
            |s: usize| -> Vec<f32> { table[4 * s..4 * s + 4].iter().map(|l| l.pmf).collect() };
        let cdf =
            |s: usize| -> Vec<f32> { table[4 * s..4 * s + 4].iter().map(|l| l.cdf).collect() };
        assert_eq!(pmf(0), [0.2, 0.6, 0.1, 0.1]);
        assert_eq!(pmf(1), [0.5, 0.0, 0.25, 0.25]);
        assert_eq!(pmf(2), [0.0, 0.75, 0.125, 0.125]);
        assert_eq!(pmf(3), [0.0, 0.0, 0.5, 0.5]);
        assert_eq!(cdf(1), [0.5, 0.5, 0.75, 1.0]);
        // Only the first light on: the CDF is 1 from it on, so no u picks the others.
        let (table, _) = light_tables(&lights[..2], &power[..2], &[vec![0]], 2);
        assert_eq!([table[2].cdf, table[3].cdf], [1.0, 1.0]);
        assert_eq!([table[2].pmf, table[3].pmf], [1.0, 0.0]);
        // No light with power: black, and said so.
        let (_, lit) = light_tables(&lights[..2], &power[..2], &[vec![]], 2);
        assert_eq!(lit, [true, false]);
    }
}
