//! The environment as a parameter: its gradient (dL/d(texel radiance), nearest and bilinear
//! lookups) is unbiased against central finite differences of the loss, with direct light
//! and at depth 3 (escapes after a bounce); the ReSTIR and recursive estimators give the same mean as the
//! baseline; and an optimization that starts from a uniform gray recovers a lit direction.
mod common;

use common::*;
use psrestir::image_io::Image;
use psrestir::optim::environment_fit::EnvFitOptions;
use psrestir::optim::{Method, Optimizer, Settings};
use psrestir::render::params::ParamSet;
use psrestir::scene::{EnvMap, Scene};
use psrestir::task::{Filter, Init, Slot, TextureSpec};

const W: u32 = 16;

/// A 4x2 environment: brighter towards +x in the upper row, tinted per texel.
fn env(scale: f32) -> EnvMap {
    EnvMap {
        width: 4,
        height: 2,
        rgb: (0..8)
            .map(|i| {
                let up = if i < 4 { 1.0 } else { 0.3 };
                let v = scale * up * (0.5 + 0.25 * (i % 4) as f32);
                [v, 0.8 * v + 0.05 * i as f32, 0.6 * v]
            })
            .collect(),
        scale: 1.0,
    }
}

fn with_env(mut s: Scene, e: EnvMap) -> Scene {
    s.env = Some(e);
    s
}

/// A 2x2 base color texture of the plane, gray, held still (learning rate 0), nearest.
fn plane_base_color(scene: &Scene) -> ParamSet {
    ParamSet::from_specs(
        scene,
        &[TextureSpec {
            material: "plane".into(),
            slot: Slot::BaseColor,
            resolution: [2, 2],
            init: Init::Vector(vec![0.5; 3]),
            learning_rate: Some(0.0),
        }],
        Filter::Nearest,
        std::path::Path::new("test"),
    )
    .unwrap()
}

fn optimizer(gpu: &psrestir::gpu::Gpu, scene: &Scene, method: Method, target: &Image) -> Optimizer {
    let set = plane_base_color(scene);
    let settings = Settings {
        primal_spp: 16,
        gradient_spp: 16,
        seed: 7,
        method,
        ..Settings::new(W, W, vec![0])
    };
    Optimizer::new(gpu, scene, set, settings, std::slice::from_ref(target)).unwrap()
}

/// Mean and variance of the mean of k estimates of the environment's gradient.
fn mean_gradient(opt: &mut Optimizer, k: u32) -> (Vec<f64>, Vec<f64>) {
    let mut sum = Vec::new();
    let mut sum2 = Vec::new();
    for it in 0..k {
        opt.estimate_gradient(1000 + it).unwrap();
        let (g, faults) = opt.fit_mut().read_environment_gradient().unwrap();
        assert_eq!(faults, 0, "environment gradient updates lost or dropped");
        sum.resize(g.len(), 0f64);
        sum2.resize(g.len(), 0f64);
        for (i, v) in g.iter().enumerate() {
            sum[i] += *v as f64;
            sum2[i] += (*v as f64).powi(2);
        }
    }
    let kf = k as f64;
    let mean: Vec<f64> = sum.iter().map(|s| s / kf).collect();
    let var = (0..mean.len())
        .map(|i| (sum2[i] / kf - mean[i] * mean[i]).max(0.0) / (kf - 1.0))
        .collect();
    (mean, var)
}

fn check_against_finite_differences(scene: Scene) {
    let Some(gpu) = gpu() else { return };
    let truth = with_env(scene.clone(), env(1.0));
    let blank = Image::new(W, W);
    let target = optimizer(&gpu, &truth, Method::BASELINE, &blank)
        .render(0, 4096, 99)
        .unwrap();
    let start = env(0.6);
    let fitted = with_env(scene, start.clone());
    let mut opt = optimizer(&gpu, &fitted, Method::BASELINE, &target);
    opt.fit_mut()
        .optimize_environment(&start, EnvFitOptions::default())
        .unwrap();
    let (mean, var) = mean_gradient(&mut opt, 48);

    // Central differences of an unbiased loss estimate (the product of two independent
    // renders' residuals), common random numbers on both sides, two repetitions for the
    // difference's own noise (as tests/gradient.rs).
    let h = 0.05f32;
    let spp = 512;
    let mut lossf = |e: &EnvMap, seed: u32| -> f64 {
        opt.fit_mut()
            .optimize_environment(e, EnvFitOptions::default())
            .unwrap();
        let a = opt.render(0, spp, seed).unwrap();
        let b = opt.render(0, spp, seed + 1).unwrap();
        let mut s = 0.0;
        for p in 0..a.rgb.len() {
            for c in 0..3 {
                s += (a.rgb[p][c] - target.rgb[p][c]) as f64
                    * (b.rgb[p][c] - target.rgb[p][c]) as f64;
            }
        }
        s / (a.rgb.len() * 3) as f64
    };
    let n = mean.len();
    let mut fd = vec![0f64; n];
    let mut fd_var = 0.0;
    for i in 0..n {
        let mut reps = [0f64; 2];
        for (r, rep) in reps.iter_mut().enumerate() {
            let seed = 5000 + 10 * r as u32;
            let (mut plus, mut minus) = (start.clone(), start.clone());
            plus.rgb[i / 3][i % 3] += h;
            minus.rgb[i / 3][i % 3] -= h;
            *rep = (lossf(&plus, seed) - lossf(&minus, seed)) / (2.0 * h as f64);
        }
        fd[i] = 0.5 * (reps[0] + reps[1]);
        fd_var += 0.25 * (reps[0] - reps[1]).powi(2) / n as f64;
    }
    let scale = fd.iter().fold(0f64, |m, v| m.max(v.abs()));
    assert!(
        scale > 0.0,
        "all finite differences are zero: the test sees nothing"
    );
    let mut seen = 0;
    for i in 0..n {
        // 4 standard errors (estimator mean and pooled FD noise), 5% for the difference
        // quotient's truncation, 0.1% of the largest derivative for rounding.
        let tol = 4.0 * (var[i] + fd_var).sqrt() + 0.05 * fd[i].abs() + 1e-3 * scale;
        eprintln!(
            "texel {} channel {}: gradient {:.5e} +- {:.1e}, finite difference {:.5e}",
            i / 3,
            i % 3,
            mean[i],
            var[i].sqrt(),
            fd[i]
        );
        if fd[i].abs() > 0.05 * scale {
            seen += 1;
        }
        assert!(
            (mean[i] - fd[i]).abs() <= tol,
            "entry {i}: gradient {} against finite difference {} (tolerance {tol})",
            mean[i],
            fd[i]
        );
    }
    assert!(
        seen >= 6,
        "only {seen} entries with a derivative worth checking"
    );
}

/// The shadow scene seen so that the sky is in view, its environment looked up bilinearly
/// or at the nearest texel.
fn sky_in_view(bilinear: bool) -> Scene {
    let mut s = shadow_scene();
    s.cameras[0] = look_at(
        glam::Vec3::new(0.0, 1.2, 2.2),
        glam::Vec3::new(0.0, 0.3, 0.0),
        glam::Vec3::Y,
        1.1,
    );
    s.env_bilinear = bilinear;
    s
}

/// Direct light: camera rays that miss, light samples and BSDF samples of the environment at
/// the first vertex.
#[test]
fn environment_gradient_matches_finite_differences() {
    check_against_finite_differences(sky_in_view(false));
}

/// The same with bilinear lookups: each escape's derivative spread over four texels.
#[test]
fn bilinear_environment_gradient_matches_finite_differences() {
    check_against_finite_differences(sky_in_view(true));
}

/// Depth 3: the environment reached after bounces off the walls and the floor.
#[test]
fn environment_gradient_at_depth_3_matches_finite_differences() {
    check_against_finite_differences(corner_scene(3));
}

/// ReSTIR and the recursive estimator estimate the environment's gradient by plain Monte
/// Carlo within their own passes: the same mean as the baseline's within 4 standard errors.
#[test]
fn every_estimator_gives_the_environment_gradient_the_baseline_gives() {
    let Some(gpu) = gpu() else { return };
    let scene = corner_scene(3);
    let truth = with_env(scene.clone(), env(1.0));
    let blank = Image::new(W, W);
    let target = optimizer(&gpu, &truth, Method::BASELINE, &blank)
        .render(0, 1024, 99)
        .unwrap();
    let start = env(0.6);
    let fitted = with_env(scene, start.clone());
    let mut results = Vec::new();
    for method in Method::all() {
        let mut opt = optimizer(&gpu, &fitted, method, &target);
        opt.fit_mut()
            .optimize_environment(&start, EnvFitOptions::default())
            .unwrap();
        results.push((method, mean_gradient(&mut opt, 32)));
    }
    let (_, (base, base_var)) = &results[0];
    let scale = base.iter().fold(0f64, |m, v| m.max(v.abs()));
    for (method, (mean, var)) in &results[1..] {
        for i in 0..base.len() {
            let tol = 4.0 * (base_var[i] + var[i]).sqrt() + 1e-3 * scale;
            assert!(
                (mean[i] - base[i]).abs() <= tol,
                "{method}: entry {i}: {} against the baseline's {} (tolerance {tol})",
                mean[i],
                base[i]
            );
        }
    }
}

/// The baseline's gradient pool (optimizer.baseline.cache) refreshed whole every iteration
/// draws the camera samples the gradient pass traces: the environment's gradient from its
/// stored paths (camera rays that miss, the environment's light and BSDF samples, at every
/// vertex) is the traced one's, within float rounding at depth 1 and within what the stored
/// directions between vertices move it at depth 3 (the same bounds as tests/path_cache.rs).
#[test]
fn the_gradient_pool_gives_the_traced_environment_gradient() {
    use psrestir::optim::estimator::baseline::BaselineOptions;
    let Some(gpu) = gpu() else { return };
    for (scene, tol) in [(sky_in_view(true), 1e-4), (corner_scene(3), 1e-2)] {
        let truth = with_env(scene.clone(), env(1.0));
        let blank = Image::new(W, W);
        let target = optimizer(&gpu, &truth, Method::BASELINE, &blank)
            .render(0, 256, 99)
            .unwrap();
        let start = env(0.6);
        let fitted = with_env(scene, start.clone());
        let mut gradients = Vec::new();
        for cache in [None, Some(16)] {
            let set = plane_base_color(&fitted);
            let mut settings = Settings {
                primal_spp: 16,
                gradient_spp: 16,
                seed: 7,
                method: Method::BASELINE,
                ..Settings::new(W, W, vec![0])
            };
            settings.estimator_options.put(&BaselineOptions { cache });
            let targets = std::slice::from_ref(&target);
            let mut opt = Optimizer::new(&gpu, &fitted, set, settings, targets).unwrap();
            opt.fit_mut()
                .optimize_environment(&start, EnvFitOptions::default())
                .unwrap();
            opt.estimate_gradient(1000).unwrap();
            let (g, faults) = opt.fit_mut().read_environment_gradient().unwrap();
            assert_eq!(faults, 0, "environment gradient updates lost or dropped");
            gradients.push(g);
        }
        let diff: f64 = (gradients[0].iter().zip(&gradients[1]))
            .map(|(a, b)| (a - b).abs() as f64)
            .sum();
        let total: f64 = gradients[0].iter().map(|a| a.abs() as f64).sum();
        eprintln!("relative difference {}", diff / total);
        assert!(total > 0.0, "the environment's gradient is zero");
        assert!(diff <= tol * total, "relative difference {}", diff / total);
    }
}

/// A plane with a blocker under a sky whose sun is one bright texel: fitted from a uniform
/// gray with the textures held, the environment's strongest emission ends within 20 degrees
/// of the sun (texels here are 45 degrees wide: the right texel or a neighbour), and the
/// loss falls well below the gray start's.
#[test]
fn an_environment_fitted_from_gray_finds_the_sun() {
    use psrestir::optim::Stop;
    let Some(gpu) = gpu() else { return };
    let mut scene = shadow_scene();
    scene.lights.clear();
    // The lamp's material emits nothing: the sky alone lights the scene.
    scene.materials[2].emissive = glam::Vec3::ZERO;
    let (w, h) = (8u32, 4u32);
    let sun = (2u32, 1u32);
    let sky = EnvMap {
        width: w,
        height: h,
        rgb: (0..w * h)
            .map(|k| {
                if (k % w, k / w) == sun {
                    [12.0, 11.0, 9.0]
                } else if k / w < h / 2 {
                    [0.3, 0.4, 0.6]
                } else {
                    [0.05; 3]
                }
            })
            .collect(),
        scale: 1.0,
    };
    let blank = Image::new(W, W);
    let truth = with_env(scene.clone(), sky.clone());
    let target = optimizer(&gpu, &truth, Method::BASELINE, &blank)
        .render(0, 1024, 99)
        .unwrap();
    let gray = EnvMap {
        rgb: vec![[0.5; 3]; (w * h) as usize],
        ..sky.clone()
    };
    let mut opt = optimizer(
        &gpu,
        &with_env(scene, gray.clone()),
        Method::BASELINE,
        &target,
    );
    let opts = EnvFitOptions {
        learning_rate: 0.1,
        rebuild_every: 2,
        ..Default::default()
    };
    opt.fit_mut().optimize_environment(&gray, opts).unwrap();
    let first = opt.step().unwrap().loss;
    opt.run(Stop::iterations(150), |_| {
        std::ops::ControlFlow::Continue(())
    })
    .unwrap();
    let mut last = 0.0;
    for _ in 0..10 {
        last += opt.step().unwrap().loss / 10.0;
    }
    let env = opt.fit().environment().unwrap();
    let angle = psrestir::job::relight::direction_error_deg(&env, &sky);
    eprintln!("loss {first:.4e} -> {last:.4e}, strongest emission {angle:.1} degrees off");
    assert!(angle <= 20.0, "the recovered sun is {angle:.1} degrees off");
    assert!(last < 0.2 * first, "loss {first} -> {last}");
}

/// One environment texel behind every pixel: a camera that looks up into a 1x1 sky, away
/// from every surface, so that each of its samples adds to the same three words of the
/// environment's gradient (a workgroup's in workgroup memory, then one addition per
/// workgroup), 32k samples in all. Under a given adjoint the gradient is the sum of the
/// pixels' adjoints (each sample adds its pixel's over the spp): every estimator gets it to
/// float rounding, and loses nothing.
#[test]
fn one_environment_texel_seen_by_every_pixel_loses_nothing() {
    let Some(gpu) = gpu() else { return };
    let side = 64u32;
    let sky = EnvMap {
        width: 1,
        height: 1,
        rgb: vec![[0.5, 0.6, 0.7]],
        scale: 1.0,
    };
    let mut scene = with_env(shadow_scene(), sky.clone());
    scene.cameras[0] = look_at(
        glam::Vec3::new(0.0, 1.0, 0.0),
        glam::Vec3::new(0.0, 10.0, 0.5),
        glam::Vec3::Z,
        0.5,
    );
    let set = plane_base_color(&scene);
    // Each pixel's adjoint differs (so that a lost or doubled addition shows).
    let n = (side * side) as usize;
    let adjoint: Vec<f32> = (0..n)
        .flat_map(|p| {
            let a = 1e-3 * (1.0 + (p % 7) as f32);
            [a, 0.5 * a, -0.25 * a, 0.0]
        })
        .collect();
    let mut want = [0f64; 3];
    for p in adjoint.chunks(4) {
        for c in 0..3 {
            want[c] += p[c] as f64;
        }
    }
    for method in Method::all() {
        let settings = Settings {
            gradient_spp: 8,
            method,
            ..Settings::new(side, side, vec![0])
        };
        let target = Image::new(side, side);
        let mut opt = Optimizer::new(&gpu, &scene, set.clone(), settings, &[target]).unwrap();
        opt.fit_mut()
            .optimize_environment(&sky, EnvFitOptions::default())
            .unwrap();
        opt.estimate_gradient_with_adjoint(0, &adjoint).unwrap();
        let (g, faults) = opt.fit_mut().read_environment_gradient().unwrap();
        assert_eq!(faults, 0, "{method}: updates lost or dropped");
        for c in 0..3 {
            let got = g[c] as f64;
            assert!(
                (got - want[c]).abs() <= 1e-4 * want[c].abs(),
                "{method}: channel {c}: {got} where the adjoints sum to {}",
                want[c]
            );
        }
    }
}
