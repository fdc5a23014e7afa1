//! Indirect light (`max_depth` > 1) against references computed without the renderer: a white
//! furnace (a closed sphere that emits and reflects, seen from its centre, against the
//! integral equation of its radiance solved on the CPU), and light and BSDF sampling agreeing
//! at every vertex of a path.
mod common;

use common::*;
use glam::{Vec2, Vec3};
use psrestir::render::{RenderSettings, Renderer, Techniques};
use psrestir::scene::{Material, MaxDepth, Scene, Triangle};
use std::f32::consts::PI;

/// A sphere of radius `r` at the origin, `rings` x `segments` quads (the poles' as triangles),
/// facing inwards, normals towards the centre; quad (i, j) of material `material(i, j)`.
fn inward_sphere(
    r: f32,
    rings: u32,
    segments: u32,
    material: impl Fn(u32, u32) -> u32,
) -> Vec<Triangle> {
    let point = |i: u32, j: u32| {
        let theta = PI * i as f32 / rings as f32;
        let phi = 2.0 * PI * j as f32 / segments as f32;
        Vec3::new(
            theta.sin() * phi.cos(),
            theta.cos(),
            theta.sin() * phi.sin(),
        )
    };
    let mut out = Vec::new();
    let mut tri = |a: Vec3, b: Vec3, c: Vec3, material: u32| {
        // Wound so that cross(b - a, c - a) points inwards (the front face is inside).
        let (b, c) = if (b - a).cross(c - a).dot(a + b + c) > 0.0 {
            (c, b)
        } else {
            (b, c)
        };
        out.push(Triangle {
            p: [a * r, b * r, c * r],
            n: [-a, -b, -c],
            uv: [Vec2::ZERO; 3],
            t: Default::default(),
            material,
        });
    };
    for i in 0..rings {
        for j in 0..segments {
            let (a, b, c, d) = (
                point(i, j),
                point(i + 1, j),
                point(i + 1, j + 1),
                point(i, j + 1),
            );
            let m = material(i, j);
            if i > 0 {
                tri(a, c, d, m);
            }
            if i + 1 < rings {
                tri(a, b, c, m);
            }
        }
    }
    out
}

/// The radiance leaving the inside of a sphere of uniform emission `le` and the BRDF of
/// (`base`, metallic 0, `roughness`), at angle theta to the normal, for paths of `depth`
/// vertices (None: every depth), tabulated over theta in `n` bins. By the sphere's symmetry
/// (a chord makes the same angle with the normals at both of its ends) the radiance depends on
/// that angle alone: L = le + K L, with K(theta_o, theta_i) the BRDF x cos integrated over
/// the azimuth, by a midpoint rule; depth d sums le + K le + ... + K^d le.
fn furnace_solution(base: f32, roughness: f32, le: f32, depth: Option<u32>, n: usize) -> Vec<f64> {
    let (sub, np) = (4usize, 96usize);
    let dt = 0.5 * PI / (n * sub) as f32;
    let dp = 2.0 * PI / np as f32;
    let mut k = vec![vec![0f64; n]; n];
    for (o, row) in k.iter_mut().enumerate() {
        let to = (o as f32 + 0.5) / n as f32 * 0.5 * PI;
        let wo = Vec3::new(to.sin(), to.cos(), 0.0);
        for (i, kij) in row.iter_mut().enumerate() {
            let mut s = 0f64;
            for a in 0..sub {
                let ti = (i * sub + a) as f32 * dt + 0.5 * dt;
                for b in 0..np {
                    let phi = (b as f32 + 0.5) * dp;
                    let wi = Vec3::new(ti.sin() * phi.cos(), ti.cos(), ti.sin() * phi.sin());
                    let f = brdf_eval_cos(Vec3::splat(base), 0.0, roughness, Vec3::Y, wo, wi);
                    s += (f.x * ti.sin() * dt * dp) as f64;
                }
            }
            *kij = s;
        }
    }
    let steps = depth.unwrap_or(400);
    let mut l = vec![le as f64; n];
    for _ in 0..steps {
        let next: Vec<f64> = (0..n)
            .map(|o| le as f64 + (0..n).map(|i| k[o][i] * l[i]).sum::<f64>())
            .collect();
        l = next;
    }
    l
}

fn render_depth(r: &Renderer, w: u32, spp: u32, seed: u32) -> psrestir::image_io::Image {
    r.render(
        &RenderSettings {
            width: w,
            height: w,
            spp,
            seed,
            camera: 0,
            techniques: Techniques::Mis,
        },
        |_| {},
    )
    .unwrap()
    .image
}

#[test]
fn a_closed_sphere_lit_by_its_own_emission_renders_the_furnace_solution() {
    let Some(gpu) = gpu() else { return };
    let (base, roughness, le) = (0.5f32, 0.8f32, 1.0f32);
    let mut scene = furnace_scene(base, roughness, le, false);
    let (w, n) = (32u32, 32usize);
    let full = furnace_solution(base, roughness, le, None, n);
    // The series at depth 12 is within 0.1% of the converged one.
    let deep = 12u32;
    let truncated = furnace_solution(base, roughness, le, Some(deep), n);
    assert!((truncated[0] / full[0] - 1.0).abs() < 1e-3);
    for depth in [1u32, 2, 3, deep] {
        scene.max_depth = MaxDepth::new(depth).unwrap();
        let r = Renderer::new(&gpu, &scene).unwrap();
        let want = furnace_solution(base, roughness, le, Some(depth), n)[0];
        let (a, b) = (render_depth(&r, w, 64, 1), render_depth(&r, w, 64, 2));
        let (mean, se) = mean_and_error(&a, &b, None);
        eprintln!(
            "depth {depth}: {mean:.5} (standard error {se:.5}), reference {want:.5} \
             (converged {:.5}, le / (1 - albedo at normal incidence) {:.5})",
            full[0],
            le as f64
                / (1.0
                    - lum(
                        directional_albedo(Vec3::splat(base), 0.0, roughness, Vec3::Y).to_array()
                    ))
        );
        // Within 5 standard errors plus 0.2% of the reference (the faceted sphere and the
        // quadrature; the bar is 1%), with the noise well inside 1%.
        assert!(se < 2e-3 * want, "depth {depth}: too noisy to tell ({se})");
        assert!(
            (mean - want).abs() < 5.0 * se + 2e-3 * want,
            "depth {depth}: mean radiance {mean} against {want}"
        );
    }
}

#[test]
fn a_closed_sphere_half_of_whose_cells_emit_reflects_the_furnace_solution_of_half_the_emission() {
    // Every other cell of the sphere emits (half the area of every ring): a path that reaches
    // a cell that does not emit must still bring back what lies beyond it. Light arriving
    // anywhere averages over hundreds of cells, so what a cell reflects is the furnace
    // solution of half the emission. The same seed at depth 1 and at depth d sees the same
    // emission along each camera ray, so their difference is the light of bounces 2 to d.
    let Some(gpu) = gpu() else { return };
    let (base, roughness, le) = (0.5f32, 0.8f32, 1.0f32);
    let mut scene = furnace_scene(base, roughness, le, true);
    let (w, n) = (32u32, 32usize);
    let solution = |d| furnace_solution(base, roughness, 0.5 * le, Some(d), n)[0];
    let render = |scene: &Scene, seed| {
        let r = Renderer::new(&gpu, scene).unwrap();
        render_depth(&r, w, 64, seed)
    };
    scene.max_depth = MaxDepth::DIRECT;
    let direct = [render(&scene, 1), render(&scene, 2)];
    for depth in [2u32, 3, 12] {
        scene.max_depth = MaxDepth::new(depth).unwrap();
        let (a, b) = (render(&scene, 1), render(&scene, 2));
        let (mean, se) = mean_and_error(&a, &b, Some(&direct));
        let want = solution(depth) - solution(1);
        eprintln!("bounces 2 to {depth}: {mean:.5} (standard error {se:.5}), reference {want:.5}");
        assert!(se < 5e-3 * want, "depth {depth}: too noisy to tell ({se})");
        assert!(
            (mean - want).abs() < 5.0 * se + 5e-3 * want,
            "depth {depth}: bounces 2 to {depth} bring {mean}, against {want}"
        );
    }
}

/// A closed sphere of radius 1 of (`base`, metallic 0, `roughness`) that emits `le` from
/// every cell or (`checkered`) from every other, seen from its centre.
fn furnace_scene(base: f32, roughness: f32, le: f32, checkered: bool) -> Scene {
    Scene {
        triangles: inward_sphere(1.0, 48, 96, |i, j| if checkered { (i + j) % 2 } else { 0 }),
        materials: vec![
            Material {
                emissive: Vec3::splat(le),
                ..material([base; 3], 0.0, roughness)
            },
            material([base; 3], 0.0, roughness),
        ],
        // From the centre, every camera ray meets the wall at (nearly) normal incidence.
        cameras: vec![look_at(Vec3::ZERO, Vec3::Z, Vec3::Y, 0.3)],
        ..Default::default()
    }
}

/// The mean luminance of two renders with independent seeds, less that of `minus` (two
/// renders with the same two seeds) when given, and its standard error, from the per-pixel
/// differences between the seeds (the image's own pattern is not noise).
fn mean_and_error(
    a: &psrestir::image_io::Image,
    b: &psrestir::image_io::Image,
    minus: Option<&[psrestir::image_io::Image; 2]>,
) -> (f64, f64) {
    let value = |img: &psrestir::image_io::Image, k: usize, i: usize| {
        lum(img.rgb[i]) - minus.map_or(0.0, |m| lum(m[k].rgb[i]))
    };
    let n = a.rgb.len();
    let (mut sum, mut var) = (0.0, 0.0);
    for i in 0..n {
        let (x, y) = (value(a, 0, i), value(b, 1, i));
        sum += 0.5 * (x + y);
        var += 0.25 * (x - y) * (x - y);
    }
    (sum / n as f64, var.sqrt() / n as f64)
}

#[test]
fn light_and_bsdf_sampling_agree_at_every_vertex_of_a_path() {
    // NEE alone, BSDF sampling alone (delta lights still by NEE) and MIS are three unbiased
    // estimators of the same image at every depth: a wrong MIS weight, density or throughput
    // at a vertex after the first shows as a difference between them.
    let Some(gpu) = gpu() else { return };
    let mut scene = corner_scene(3);
    let r = Renderer::new(&gpu, &scene).unwrap();
    let w = 32usize;
    let render = |t, spp, seed| render_image(&r, w as u32, spp, seed, t).rgb;
    let mis = [
        render(Techniques::Mis, 128, 1),
        render(Techniques::Mis, 128, 2),
    ];
    for (t, spp) in [(Techniques::NeeOnly, 128), (Techniques::BsdfOnly, 512)] {
        let other = [render(t, spp, 3), render(t, spp, 4)];
        let z = block_z_scores([&mis[0], &mis[1]], [&other[0], &other[1]], w, 8);
        let worst = z.iter().fold(0f64, |m, v| m.max(v.abs()));
        eprintln!("MIS against {t:?} at depth 3: worst block z {worst:.2}");
        assert!(worst < 5.0, "{t:?}: block z-scores {z:?}");
    }
    // And the bounces add light: the corner at depth 3 is brighter than at depth 1.
    scene.max_depth = MaxDepth::DIRECT;
    let direct = render_image(
        &Renderer::new(&gpu, &scene).unwrap(),
        w as u32,
        128,
        1,
        Techniques::Mis,
    );
    let sum = |rgb: &[[f32; 3]]| rgb.iter().map(|p| lum(*p)).sum::<f64>();
    let gain = sum(&mis[0]) / sum(&direct.rgb);
    eprintln!("depth 3 / depth 1: {gain:.3}");
    assert!(gain > 1.1, "indirect light adds {gain}");
}

#[test]
fn a_depth_3_model_recovers_a_concave_scenes_base_color_where_direct_light_cannot() {
    // Targets with indirect light (depth 3) of the corner's floor texture; fitted with direct
    // light only, the floor must absorb the light its walls send it (too bright where the
    // walls are near); fitted at depth 3 it is not. Baseline, Adam, the same budget of
    // iterations for both models.
    use psrestir::image_io::Image;
    use psrestir::optim::{Method, Optimizer, Settings};
    use psrestir::render::params::ParamSet;
    use psrestir::task::{Filter, Init, Slot, TextureSpec};
    let Some(gpu) = gpu() else { return };
    let w = 32u32;
    let spec = TextureSpec {
        material: "plane".into(),
        slot: Slot::BaseColor,
        resolution: [4, 4],
        init: Init::Vector(vec![0.5; 3]),
        learning_rate: Some(0.03),
    };
    let mut scene = corner_scene(3);
    // Seeing the whole floor and both walls.
    scene.cameras = vec![look_at(
        Vec3::new(1.4, 2.0, 2.2),
        Vec3::new(-0.3, 0.3, -0.3),
        Vec3::Y,
        1.0,
    )];
    let set = ParamSet::from_specs(
        &scene,
        &[spec],
        Filter::Bilinear,
        std::path::Path::new("test"),
    )
    .unwrap();
    let truth: Vec<f32> = (0..set.values.len())
        .map(|i| 0.2 + 0.6 * ((i * 5 % 7) as f32 / 6.0))
        .collect();
    let settings = Settings {
        method: Method::BASELINE,
        primal_spp: 4,
        gradient_spp: 4,
        seed: 3,
        ..Settings::new(w, w, vec![0])
    };
    let probe = Optimizer::new(
        &gpu,
        &scene,
        set.clone(),
        settings.clone(),
        &[Image::new(w, w)],
    )
    .unwrap();
    probe.write_params(&truth).unwrap();
    let target = probe.render(0, 512, 77).unwrap();
    drop(probe);
    let mut errors = Vec::new();
    for depth in [1u32, 3] {
        scene.max_depth = MaxDepth::new(depth).unwrap();
        let mut opt = Optimizer::new(
            &gpu,
            &scene,
            set.clone(),
            settings.clone(),
            std::slice::from_ref(&target),
        )
        .unwrap();
        for _ in 0..200 {
            opt.step().unwrap();
        }
        let rmse = psrestir::job::run::rmse(&opt.read_params().unwrap(), &truth);
        eprintln!("model depth {depth}: base color RMSE {rmse:.4}");
        errors.push(rmse);
    }
    assert!(
        errors[1] <= 0.5 * errors[0],
        "depth 3 model {:.4} against direct light only {:.4}",
        errors[1],
        errors[0]
    );
}
