//! Renders of scenes with a closed-form answer: a plane under a point light (radiance
//! f cos I / d^2 at every point) and a plane under a constant environment (radiance =
//! environment x directional albedo of the BRDF, integrated on the CPU); and the texel
//! coordinates the shaders' texture lookups wrap to.
mod common;

use common::*;
use glam::{Vec2, Vec3};
use psrestir::render::{RenderSettings, Renderer, Techniques};
use psrestir::scene::{EnvMap, PunctualKind, PunctualLight, Wrap};

const W: u32 = 64;

#[test]
fn plane_under_a_point_light_matches_the_closed_form() {
    let Some(gpu) = gpu() else { return };
    let (base, metallic, roughness) = (Vec3::new(0.6, 0.5, 0.4), 0.0, 0.5);
    let mut scene = plane_scene(material(base.to_array(), metallic, roughness), 5.0);
    let light_pos = Vec3::new(0.3, 1.5, -0.2);
    let intensity = Vec3::splat(4.0);
    scene.lights.push(PunctualLight {
        name: "p".into(),
        kind: PunctualKind::Point,
        position: light_pos,
        direction: Vec3::NEG_Y,
        intensity,
        range: 0.0,
    });
    let spp = 64;
    let r = Renderer::new(&gpu, &scene).unwrap();
    let out = r
        .render(
            &RenderSettings {
                width: W,
                height: W,
                spp,
                seed: 3,
                camera: 0,
                techniques: Techniques::Mis,
            },
            |_| {},
        )
        .unwrap();
    // Reference: the closed form averaged over an 8x8 grid inside each pixel; its spread
    // within the pixel bounds the error of the GPU's random jitter (sd / sqrt(spp)).
    let cam = &scene.cameras[0];
    let radiance = |px: Vec2| -> Vec3 {
        let (o, d) = camera_dir(cam, W, W, px);
        let t = -o.y / d.y;
        let x = o + t * d;
        let to = light_pos - x;
        brdf_eval_cos(base, metallic, roughness, Vec3::Y, -d, to.normalize()) * intensity
            / to.length_squared()
    };
    let mut worst = 0.0f64;
    for y in 0..W {
        for x in 0..W {
            let mut subs = Vec::new();
            for j in 0..8 {
                for i in 0..8 {
                    let p = Vec2::new(
                        x as f32 + (i as f32 + 0.5) / 8.0,
                        y as f32 + (j as f32 + 0.5) / 8.0,
                    );
                    subs.push(lum(radiance(p).to_array()));
                }
            }
            let (m, sd) = mean_sd(&subs);
            let got = lum(out.image.at(x, y));
            let tol = 5.0 * sd / (spp as f64).sqrt() + 2e-3 * m + 1e-6;
            worst = worst.max((got - m).abs() / tol);
            assert!(
                (got - m).abs() <= tol,
                "pixel ({x},{y}): {got} vs closed form {m} (tolerance {tol})"
            );
        }
    }
    eprintln!("worst error / tolerance: {worst:.3}");
}

#[test]
fn plane_under_a_constant_environment_matches_the_albedo_integral() {
    let Some(gpu) = gpu() else { return };
    let (base, metallic, roughness) = (Vec3::new(0.5, 0.5, 0.5), 0.0, 0.6);
    let env = 0.8f32;
    let mut scene = plane_scene(material(base.to_array(), metallic, roughness), 5.0);
    scene.env = Some(EnvMap::constant([env; 3]));
    let spp = 64;
    let r = Renderer::new(&gpu, &scene).unwrap();
    let out = r
        .render(
            &RenderSettings {
                width: W,
                height: W,
                spp,
                seed: 5,
                camera: 0,
                techniques: Techniques::Mis,
            },
            |_| {},
        )
        .unwrap();
    // The albedo depends on the view elevation only: tabulate it over cos(theta_o).
    let table: Vec<f64> = (0..=32)
        .map(|k| {
            let c = (k as f32 / 32.0).max(0.02);
            let wo = Vec3::new((1.0 - c * c).sqrt(), c, 0.0);
            lum(directional_albedo(base, metallic, roughness, wo).to_array())
        })
        .collect();
    let albedo = |c: f32| {
        let x = (c.clamp(0.02, 1.0) * 32.0).min(31.999);
        let k = x as usize;
        let f = (x - k as f32) as f64;
        table[k] * (1.0 - f) + table[k + 1] * f
    };
    let cam = &scene.cameras[0];
    let mut residual = Vec::new();
    let mut reference = Vec::new();
    for y in 0..W {
        for x in 0..W {
            let (_, d) = camera_dir(cam, W, W, Vec2::new(x as f32 + 0.5, y as f32 + 0.5));
            let want = env as f64 * albedo(-d.y);
            residual.push(lum(out.image.at(x, y)) - want);
            reference.push(want);
        }
    }
    let (mean_r, sd_r) = mean_sd(&residual);
    let (mean_ref, _) = mean_sd(&reference);
    let n = residual.len() as f64;
    // Unbiased: the mean residual is within 5 standard errors of zero, plus 0.2% for the
    // quadrature, the table interpolation and evaluating the albedo at pixel centres.
    let tol = 5.0 * sd_r / n.sqrt() + 2e-3 * mean_ref;
    eprintln!("mean residual {mean_r:.5}, per-pixel sd {sd_r:.4}, reference mean {mean_ref:.4}");
    assert!(
        mean_r.abs() <= tol,
        "mean radiance off by {mean_r} (tolerance {tol})"
    );
    // And not merely unbiased on average: per-pixel noise at 64 spp stays small.
    assert!(sd_r < 0.1 * mean_ref, "per-pixel error sd {sd_r} too large");
    // White furnace sanity: a plane never reflects more than it receives.
    assert!(out
        .image
        .rgb
        .iter()
        .all(|p| p.iter().all(|&v| v.is_finite() && v >= 0.0)));
}

#[test]
fn texel_coordinates_wrap_as_the_integer_modulo() {
    let Some(gpu) = gpu() else { return };
    // The shaders wrap without an integer division (shared/wrap.wgsl): exact for |i| <= 2^23,
    // the range of texel coordinates that come from f32 texture coordinates with a sub-texel
    // step; beyond it, at least inside the texture.
    let exact = 1i64 << 23;
    let mut rng = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        rng
    };
    for n in [1i32, 2, 3, 7, 64, 255, 256, 1000, 4096, 65536, 1 << 22] {
        let mut coords: Vec<i32> = (-3 * n.min(5000)..=3 * n.min(5000)).collect();
        for _ in 0..20000 {
            coords.push((next() % (2 * exact as u64 + 1)) as i64 as i32 - exact as i32);
        }
        coords.extend([
            i32::MIN,
            i32::MAX,
            -(1 << 24) - 1,
            1 << 24,
            1 << 30,
            -(1 << 30),
        ]);
        for wrap in [Wrap::Repeat, Wrap::Clamp, Wrap::Mirror] {
            let got = psrestir::render::wrap_trial(&gpu, &coords, n, wrap).unwrap();
            for (&i, &g) in coords.iter().zip(&got) {
                let want = psrestir::scene::images::wrap_texel(i as i64, n as i64, wrap);
                assert!(
                    (0..n).contains(&g),
                    "{wrap:?}: {i} in width {n} wrapped to {g}"
                );
                if (i as i64).abs() <= exact {
                    assert_eq!(g as i64, want, "{wrap:?}: {i} in width {n}");
                }
            }
        }
    }
}
