//! The family's procedural ground truths: a field over (u, v) drawn from a member's seed,
//! made into base color, roughness, metallic or a normal map.
use super::draw::Draw;
use crate::assets::bench_scenes::hash;
use crate::assets::bundled::srgb8;
use crate::vocab::Slot;
use glam::Vec3;
use std::f32::consts::PI;

/// A procedural field in [0, 1] over (u, v): value noise in octaves, stripes warped by noise,
/// a checker softened by noise, or spots; its frequency and angle drawn from the seed.
struct Pattern {
    kind: u32,
    freq: f32,
    angle: f32,
    key: u32,
}

impl Pattern {
    fn draw(d: &mut Draw) -> Pattern {
        Pattern {
            kind: (d.next() % 4) as u32,
            freq: d.range(3.0, 9.0),
            angle: d.range(0.0, PI),
            key: d.next() as u32,
        }
    }

    /// Smooth value noise at frequency f.
    fn noise(&self, u: f32, v: f32, f: f32, octave: u32) -> f32 {
        let (x, y) = (u * f, v * f);
        let (i, j) = (x.floor(), y.floor());
        let (fx, fy) = (x - i, y - j);
        let s = |t: f32| t * t * (3.0 - 2.0 * t);
        let k = self.key.wrapping_add(octave.wrapping_mul(7919));
        let h = |a: f32, b: f32| hash((a as i32 as u32).wrapping_add(k), (b as i32 as u32) ^ k);
        let top = h(i, j) + (h(i + 1.0, j) - h(i, j)) * s(fx);
        let bottom = h(i, j + 1.0) + (h(i + 1.0, j + 1.0) - h(i, j + 1.0)) * s(fx);
        top + (bottom - top) * s(fy)
    }

    fn fbm(&self, u: f32, v: f32) -> f32 {
        let (mut sum, mut amp, mut f) = (0.0, 0.5, self.freq);
        for o in 0..4 {
            sum += amp * self.noise(u, v, f, o);
            amp *= 0.5;
            f *= 2.0;
        }
        sum / 0.9375
    }

    fn at(&self, u: f32, v: f32) -> f32 {
        let (c, s) = (self.angle.cos(), self.angle.sin());
        let along = u * c + v * s;
        match self.kind {
            0 => self.fbm(u, v),
            1 => 0.5 + 0.5 * (2.0 * PI * self.freq * along + 3.0 * self.fbm(u, v)).sin(),
            2 => {
                let checker = ((u * self.freq).floor() + (v * self.freq).floor()) as i32 & 1;
                0.25 + 0.5 * checker as f32 + 0.25 * (self.fbm(u, v) - 0.5)
            }
            _ => {
                let (x, y) = (u * self.freq, v * self.freq);
                let (cx, cy) = (x.floor(), y.floor());
                let r = 0.15 + 0.3 * hash(cx as u32 ^ self.key, cy as u32);
                let dist = ((x - cx - 0.5).powi(2) + (y - cy - 0.5).powi(2)).sqrt();
                1.0 - smoothstep(r - 0.05, r + 0.05, dist)
            }
        }
        .clamp(0.0, 1.0)
    }
}

fn smoothstep(a: f32, b: f32, x: f32) -> f32 {
    let t = ((x - a) / (b - a)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

fn unit8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// The ground truth of `slot` as RGBA8 texels (`res` x `res`): base color in sRGB, roughness
/// in G and metallic in B (glTF's metallicRoughness), or a tangent-space normal map.
pub(super) fn truth(slot: Slot, res: u32, d: &mut Draw) -> Vec<[u8; 4]> {
    let p = Pattern::draw(d);
    let palette: Vec<[f32; 3]> = (0..3)
        .map(|_| {
            [
                d.range(0.08, 0.85),
                d.range(0.08, 0.85),
                d.range(0.08, 0.85),
            ]
        })
        .collect();
    let strength = d.range(0.02, 0.05);
    let mut out = Vec::with_capacity((res * res) as usize);
    let texel = 1.0 / res as f32;
    for y in 0..res {
        for x in 0..res {
            let (u, v) = ((x as f32 + 0.5) * texel, (y as f32 + 0.5) * texel);
            let t = p.at(u, v);
            out.push(match slot {
                Slot::BaseColor => {
                    let (a, b, w) = if t < 0.5 {
                        (palette[0], palette[1], 2.0 * t)
                    } else {
                        (palette[1], palette[2], 2.0 * t - 1.0)
                    };
                    let c = |k: usize| srgb8(a[k] + (b[k] - a[k]) * w);
                    [c(0), c(1), c(2), 255]
                }
                Slot::Roughness => [0, unit8(0.15 + 0.75 * t), 0, 255],
                Slot::Metallic => [0, unit8(0.45), unit8(smoothstep(0.4, 0.6, t)), 255],
                Slot::Normal => {
                    // The relief's slopes by central differences, in height per unit of uv
                    // over the texture's strength: tangent X along u, Y against v (glTF).
                    let e = texel;
                    let du = (p.at(u + e, v) - p.at(u - e, v)) / (2.0 * e);
                    let dv = (p.at(u, v + e) - p.at(u, v - e)) / (2.0 * e);
                    let n = Vec3::new(-strength * du, strength * dv, 1.0).normalize();
                    [
                        unit8(0.5 + 0.5 * n.x),
                        unit8(0.5 + 0.5 * n.y),
                        unit8(0.5 + 0.5 * n.z),
                        255,
                    ]
                }
            });
        }
    }
    out
}
