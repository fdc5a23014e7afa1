//! The recursive estimator (a recursive control variate on the gradient) and the
//! variance-scaled step:
//! - its fresh term is the baseline's gradient, sample for sample (same seeds), so with the
//!   weight a = 1 it is the baseline, with direct light and at depth 3;
//! - run along one fixed sequence of states (textures and adjoints) with independent seeds,
//!   the mean of its running estimate matches the baseline's mean at every state within the
//!   standard error, for base color (bilinear), a normal map (bilinear) and roughness
//!   (nearest), and its spread at the
//!   last state is well below the baseline's;
//! - the variance-scaled step on the GPU equals its CPU reference;
//! - an optimization with it, with either step, recovers a texture.
mod common;

use common::*;
use psrestir::image_io::Image;
use psrestir::optim::estimator::recursive::RecursiveOptions;
use psrestir::optim::{Method, Optimizer, Settings, StepKind};
use psrestir::render::params::ParamSet;
use psrestir::task::{Filter, Init, Slot, TextureSpec};

const W: u32 = 16;

fn spec(slot: Slot, resolution: [u32; 2]) -> TextureSpec {
    TextureSpec {
        material: "plane".into(),
        slot,
        resolution,
        init: Init::Vector(vec![0.5; slot.channels() as usize]),
        learning_rate: Some(0.0),
    }
}

fn settings(method: Method, spp: u32, seed: u32) -> Settings {
    Settings {
        method,
        gradient_spp: spp,
        primal_spp: 16,
        seed,
        ..Settings::new(W, W, vec![0])
    }
}

/// The textures of state k of the fixed sequence: the start moved a little further each step
/// (a normal map's Z channel around 0.9, above its floor).
fn state(slot: Slot, n: usize, k: usize, lo: f32) -> Vec<f32> {
    (0..n)
        .map(|i| {
            let start = if slot == Slot::Normal && i % 3 == 2 {
                0.9
            } else {
                0.5
            };
            (start + 0.04 * k as f32 * ((i * 7 % 5) as f32 - 2.0) / 2.0).max(lo)
        })
        .collect()
}

#[test]
fn recursive_fresh_term_is_the_baseline_gradient() {
    let Some(gpu) = gpu() else { return };
    // Direct light, and paths of 3 vertices where the texture is also seen at later vertices
    // (each pass replays the path to differentiate them).
    for scene in [shadow_scene(), corner_scene(3)] {
        fresh_term_is_the_baseline_gradient(&gpu, &scene);
    }
}

fn fresh_term_is_the_baseline_gradient(gpu: &psrestir::gpu::Gpu, scene: &psrestir::scene::Scene) {
    let scene = scene.clone();
    let set = ParamSet::from_specs(
        &scene,
        &[spec(Slot::BaseColor, [4, 4])],
        Filter::Bilinear,
        std::path::Path::new("test"),
    )
    .unwrap();
    let target = vec![Image::new(W, W)];
    let mut base = Optimizer::new(
        gpu,
        &scene,
        set.clone(),
        settings(Method::BASELINE, 2, 3),
        &target,
    )
    .unwrap();
    let mut rec_settings = settings(Method::RECURSIVE, 2, 3);
    rec_settings.estimator_options.put(&RecursiveOptions {
        weight: Some(1.0),
        ..Default::default()
    });
    let mut rec = Optimizer::new(gpu, &scene, set, rec_settings, &target).unwrap();
    let (adjoint, _) = base.converged_adjoint(64, 5).unwrap();
    for it in 0..3 {
        let values = state(Slot::BaseColor, 48, it as usize, 0.0);
        base.write_params(&values).unwrap();
        rec.write_params(&values).unwrap();
        let b = base.estimate_gradient_with_adjoint(it, &adjoint).unwrap();
        let r = rec.estimate_gradient_with_adjoint(it, &adjoint).unwrap();
        let scale = b.iter().fold(0f32, |m, v| m.max(v.abs()));
        assert!(
            scale > 0.0,
            "the baseline's gradient is zero: the test sees nothing"
        );
        for (i, (x, y)) in b.iter().zip(&r).enumerate() {
            // The same samples added in another order (float atomics).
            assert!(
                (x - y).abs() <= 1e-4 * scale,
                "iteration {it}, scalar {i}: baseline {x}, recursive with a = 1 {y}"
            );
        }
    }
}

/// Mean and variance of the columns of `rows`.
fn column_stats(rows: &[Vec<f32>]) -> (Vec<f64>, Vec<f64>) {
    let n = rows[0].len();
    let k = rows.len() as f64;
    let mean: Vec<f64> = (0..n)
        .map(|i| rows.iter().map(|r| r[i] as f64).sum::<f64>() / k)
        .collect();
    let var: Vec<f64> = (0..n)
        .map(|i| {
            rows.iter()
                .map(|r| (r[i] as f64 - mean[i]).powi(2))
                .sum::<f64>()
                / (k - 1.0)
        })
        .collect();
    (mean, var)
}

fn check_unbiased_along_states(slot: Slot, filter: Filter, options: RecursiveOptions) {
    let Some(gpu) = gpu() else { return };
    let scene = shadow_scene();
    let resolution = [3, 3];
    let set = ParamSet::from_specs(
        &scene,
        &[spec(slot, resolution)],
        filter,
        std::path::Path::new("test"),
    )
    .unwrap();
    let n = set.values.len();
    let lo = slot.range().0;
    // The target: other texel values, rendered with many samples.
    let blank = vec![Image::new(W, W)];
    let probe = Optimizer::new(
        &gpu,
        &scene,
        set.clone(),
        settings(Method::BASELINE, 1, 1),
        &blank,
    )
    .unwrap();
    let dark: Vec<f32> = match slot {
        Slot::Normal => [0.4, 0.6, 0.9].repeat(n / 3),
        _ => vec![0.3f32.max(lo); n],
    };
    probe.write_params(&dark).unwrap();
    let target = vec![probe.render(0, 1024, 99).unwrap()];
    drop(probe);

    // The fixed sequence of states: textures and their converged adjoints.
    let k_states = 6usize;
    let mut base = Optimizer::new(
        &gpu,
        &scene,
        set.clone(),
        settings(Method::BASELINE, 2, 5),
        &target,
    )
    .unwrap();
    let mut states = Vec::new();
    for k in 0..k_states {
        let values = state(slot, n, k, lo);
        base.write_params(&values).unwrap();
        let (adjoint, _) = base.converged_adjoint(256, 40 + k as u32).unwrap();
        states.push((values, adjoint));
    }

    // The baseline at each state: its mean (the reference) and spread, from independent
    // estimates at the same spp.
    let runs = 24u32;
    let mut reference = Vec::new();
    for (k, (values, adjoint)) in states.iter().enumerate() {
        base.write_params(values).unwrap();
        let rows: Vec<Vec<f32>> = (0..2 * runs)
            .map(|j| {
                base.estimate_gradient_with_adjoint(1000 + 2 * (j * 16 + k as u32), adjoint)
                    .unwrap()
            })
            .collect();
        reference.push(column_stats(&rows));
    }

    // The recursion along the same states, restarted for each run with other seeds (the
    // iteration number picks the seed; its parity picks the adjoint buffer).
    let mut rec_settings = settings(Method::RECURSIVE, 2, 5);
    rec_settings.estimator_options.put(&options);
    let mut rec = Optimizer::new(&gpu, &scene, set, rec_settings, &target).unwrap();
    let mut per_state: Vec<Vec<Vec<f32>>> = vec![Vec::new(); k_states];
    for run in 0..runs {
        rec.reset_estimator().unwrap();
        for (k, (values, adjoint)) in states.iter().enumerate() {
            rec.write_params(values).unwrap();
            let d = rec
                .estimate_gradient_with_adjoint(100 * (run + 1) + k as u32, adjoint)
                .unwrap();
            per_state[k].push(d);
        }
    }

    let mut z2 = 0.0;
    let mut count = 0;
    for k in 0..k_states {
        let (mean, var) = column_stats(&per_state[k]);
        let (ref_mean, ref_var) = &reference[k];
        for i in 0..n {
            let se2 = var[i] / runs as f64 + ref_var[i] / (2 * runs) as f64;
            if se2 <= 0.0 {
                assert_eq!(mean[i], ref_mean[i], "state {k}, scalar {i}");
                continue;
            }
            let z = (mean[i] - ref_mean[i]) / se2.sqrt();
            eprintln!(
                "{slot:?} {filter:?} state {k} scalar {i}: recursive {:.4e} ± {:.1e}, baseline {:.4e} ± {:.1e}, z {z:.2}",
                mean[i],
                (var[i] / runs as f64).sqrt(),
                ref_mean[i],
                (ref_var[i] / (2 * runs) as f64).sqrt()
            );
            assert!(
                z.abs() < 5.0,
                "{slot:?}/{filter:?} state {k}, scalar {i}: the recursive mean is {z:.1} standard errors from the baseline's"
            );
            z2 += z * z;
            count += 1;
        }
    }
    assert!(
        count >= n,
        "too few scalars with a gradient: the test sees nothing"
    );
    // The mean squared z-score is about 1 for an unbiased estimator; a bias of one standard
    // error on every scalar would double it.
    let mean_z2 = z2 / count as f64;
    assert!(
        mean_z2 < 1.8,
        "mean squared z-score {mean_z2:.2} over {count} values"
    );

    // The point of the recursion: at the last state its spread is well below the baseline's.
    let (_, var) = column_stats(&per_state[k_states - 1]);
    let rec_var: f64 = var.iter().sum();
    let base_var: f64 = reference[k_states - 1].1.iter().sum();
    eprintln!("variance at the last state: recursive {rec_var:.3e}, baseline {base_var:.3e}");
    assert!(
        rec_var < 0.7 * base_var,
        "the recursive estimate's variance {rec_var:.3e} is not below the baseline's {base_var:.3e}"
    );
}

#[test]
fn recursive_estimate_is_unbiased_along_fixed_states_base_color_bilinear() {
    check_unbiased_along_states(
        Slot::BaseColor,
        Filter::Bilinear,
        RecursiveOptions {
            weight: Some(0.25),
            ..Default::default()
        },
    );
}

/// A normal map: the previous state's terms are evaluated in the previous normal's frame.
#[test]
fn recursive_estimate_is_unbiased_along_fixed_states_normal_map_bilinear() {
    check_unbiased_along_states(
        Slot::Normal,
        Filter::Bilinear,
        RecursiveOptions {
            weight: Some(0.25),
            ..Default::default()
        },
    );
}

#[test]
fn recursive_estimate_is_unbiased_along_fixed_states_roughness_nearest() {
    check_unbiased_along_states(
        Slot::Roughness,
        Filter::Nearest,
        RecursiveOptions {
            weight: Some(0.25),
            ..Default::default()
        },
    );
}

/// An optimizer of a 4x4 base color texture (bilinear) on the shadow scene from renders of
/// `truth`, starting from 0.5, with `method` and `step`.
fn recovery(
    gpu: &psrestir::gpu::Gpu,
    method: Method,
    step: StepKind,
    lr: f32,
) -> (Optimizer, Vec<f32>) {
    recovery_correlated(gpu, method, step, lr, 0.0)
}

/// [`recovery`] with the variance-scaled step's `correlation`.
fn recovery_correlated(
    gpu: &psrestir::gpu::Gpu,
    method: Method,
    step: StepKind,
    lr: f32,
    correlation: f32,
) -> (Optimizer, Vec<f32>) {
    let scene = shadow_scene();
    let mut spec = spec(Slot::BaseColor, [4, 4]);
    spec.learning_rate = Some(lr);
    let set = ParamSet::from_specs(
        &scene,
        &[spec],
        Filter::Bilinear,
        std::path::Path::new("test"),
    )
    .unwrap();
    let truth: Vec<f32> = (0..set.values.len())
        .map(|i| (i % 7) as f32 / 7.0 + 0.05)
        .collect();
    let mut s = settings(method, 2, 9);
    s.width = 32;
    s.height = 32;
    s.step = step;
    s.steps.put(&psrestir::optim::VarianceStepOptions {
        correlation,
        ..Default::default()
    });
    let probe = Optimizer::new(gpu, &scene, set.clone(), s.clone(), &[Image::new(32, 32)]).unwrap();
    probe.write_params(&truth).unwrap();
    let target = probe.render(0, 1024, 77).unwrap();
    let opt = Optimizer::new(gpu, &scene, set, s, &[target]).unwrap();
    (opt, truth)
}

#[test]
fn variance_step_matches_its_cpu_reference() {
    let Some(gpu) = gpu() else { return };
    // Without and with a correlation that scales the moving variance (by 1.15 at 0.6).
    for correlation in [0.0, 0.6] {
        check_variance_step(&gpu, correlation);
    }
}

fn check_variance_step(gpu: &psrestir::gpu::Gpu, correlation: f32) {
    let lr = 0.05;
    let (mut opt, _) =
        recovery_correlated(gpu, Method::BASELINE, StepKind::VARIANCE, lr, correlation);
    let o: psrestir::optim::VarianceStepOptions = opt.settings().steps.of();
    assert_eq!(o.correlation, correlation);
    let mut p = opt.read_params().unwrap();
    let n = p.len();
    let (mut m, mut v) = (vec![0f32; n], vec![0f32; n]);
    for t in 1..=4u32 {
        opt.step().unwrap();
        // The gradient this step computed (it stays in the gradient buffer), fed to the
        // reference.
        let g = opt.read_gradient().unwrap();
        assert!(g.iter().any(|x| *x != 0.0));
        psrestir::optim::variance_step::step(
            &o,
            &mut p,
            &mut m,
            &mut v,
            &g,
            None,
            lr,
            t,
            (0.0, 1.0),
            false,
        );
        let gpu_p = opt.read_params().unwrap();
        let [gm, gv] = opt.read_moments().unwrap();
        for i in 0..n {
            // Same inputs, same formula: only the last bits may differ.
            assert!(
                (gm[i] - m[i]).abs() <= 1e-6 * m[i].abs() + 1e-20,
                "step {t}, m[{i}]"
            );
            assert!(
                (gv[i] - v[i]).abs() <= 1e-6 * v[i].abs() + 1e-30,
                "step {t}, v[{i}]"
            );
            assert!(
                (gpu_p[i] - p[i]).abs() <= 1e-5,
                "step {t}, param {i}: GPU {} CPU {}",
                gpu_p[i],
                p[i]
            );
        }
        p = gpu_p;
        m = gm;
        v = gv;
    }
}

/// RMSE over all texels (the bound below leaves room for texels the images hardly see).
fn rmse(a: &[f32], b: &[f32]) -> f64 {
    (a.iter()
        .zip(b)
        .map(|(x, y)| ((x - y) as f64).powi(2))
        .sum::<f64>()
        / a.len() as f64)
        .sqrt()
}

#[test]
fn recursive_estimator_recovers_a_texture_with_either_step() {
    let Some(gpu) = gpu() else { return };
    for (step, lr) in [(StepKind::ADAM, 0.03), (StepKind::VARIANCE, 0.03)] {
        let (mut opt, truth) = recovery(&gpu, Method::RECURSIVE, step, lr);
        let before = rmse(&opt.read_params().unwrap(), &truth);
        for _ in 0..120 {
            opt.step().unwrap();
        }
        let after = rmse(&opt.read_params().unwrap(), &truth);
        eprintln!("{step:?}: texture RMSE {before:.4} -> {after:.4}");
        // Adam at this rate moves each texel by about 0.03 per step: 120 steps reach every
        // value of the truth; what is left is noise and the texels the images hardly see.
        assert!(
            after < 0.35 * before,
            "{step:?}: texture RMSE {before:.4} -> {after:.4}"
        );
        let f = opt.faults().unwrap();
        assert_eq!(f.lost_updates + f.dropped_gradient, 0, "{f:?}");
    }
}

/// The mechanism on the default task, as the bench measures it for ReSTIR: under a converged
/// adjoint at the initial textures, the estimator-only error of the mean of 10 successive
/// recursive estimates (after 20 to settle) against that of the mean of 10 independent
/// baseline estimates, and of one estimate each. A diagnostic, not a check: about a minute.
/// `cargo test --release --test recursive -- --ignored successive --nocapture`
#[test]
#[ignore = "a diagnostic on the full default task, run by hand"]
fn successive_recursive_estimates_on_the_default_task() {
    let Some(gpu) = gpu() else { return };
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let task = psrestir::task::Task::load(&root.join("scenes/default/task.toml")).unwrap();
    let out = tempfile::tempdir().unwrap();
    let prep = psrestir::job::Problem::from_task(&gpu, &task, out.path(), false).unwrap();
    let settings =
        |method| psrestir::task::task_settings(&task, &prep.cameras, method, &Default::default());
    let mut base = Optimizer::for_problem(&gpu, &prep, settings(Method::BASELINE)).unwrap();
    let (converged, _) = base.converged_adjoint(256, 0xad).unwrap();
    // The reference: 256 gradient spp (128 estimates of the task's 2).
    let n = base.read_params().unwrap().len();
    let mut reference = vec![0f64; n];
    for j in 0..128u32 {
        let g = base
            .estimate_gradient_with_adjoint(5000 + 2 * j, &converged)
            .unwrap();
        for (r, v) in reference.iter_mut().zip(&g) {
            *r += *v as f64 / 128.0;
        }
    }
    let relmse = |g: &[f64]| {
        let g: Vec<f32> = g.iter().map(|&v| v as f32).collect();
        psrestir::bench::gradient_relmse(&g, &reference)
    };
    let mean_of = |rows: &[Vec<f32>]| -> Vec<f64> {
        (0..n)
            .map(|i| rows.iter().map(|r| r[i] as f64).sum::<f64>() / rows.len() as f64)
            .collect()
    };
    let base_rows: Vec<Vec<f32>> = (0..10u32)
        .map(|j| {
            base.estimate_gradient_with_adjoint(100 + 2 * j, &converged)
                .unwrap()
        })
        .collect();
    let mut rec = Optimizer::for_problem(&gpu, &prep, settings(Method::RECURSIVE)).unwrap();
    for j in 0..20u32 {
        rec.estimate_gradient_with_adjoint(200 + j, &converged)
            .unwrap();
    }
    let rec_rows: Vec<Vec<f32>> = (0..10u32)
        .map(|j| {
            rec.estimate_gradient_with_adjoint(220 + j, &converged)
                .unwrap()
        })
        .collect();
    let one = |r: &[f32]| relmse(&r.iter().map(|&v| v as f64).collect::<Vec<_>>());
    let (b1, r1) = (one(&base_rows[0]), one(&rec_rows[0]));
    let (b10, r10) = (relmse(&mean_of(&base_rows)), relmse(&mean_of(&rec_rows)));
    eprintln!(
        "one estimate: baseline {b1:.4e}, recursive {r1:.4e} ({:.3}x); mean of 10: baseline \
         {b10:.4e}, recursive {r10:.4e} ({:.3}x)",
        r1 / b1,
        r10 / b10
    );
}
