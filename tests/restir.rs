//! The ReSTIR estimator: reservoir selection is exactly proportional to weight; without
//! temporal reuse it equals the baseline's sum of the same candidates for a scalar texture;
//! with reuse (parameters held fixed, or alternating between two states so that every kept
//! path is shifted across a change of base color and roughness) its mean matches a
//! high-sample baseline reference; stored paths evaluate to their stored factors; the merge
//! traces no ray; the target adjoint is the moving average of the adjoints; a texel whose
//! gradient changes sign gets gradients of the new sign; and on
//! the bundled default task, shrunk, ReSTIR recovers the texture (and beats the baseline at
//! the task's former, sparser sampling).
mod common;

use common::*;
use glam::Vec3;
use psrestir::image_io::Image;
use psrestir::optim::estimator::restir::compact::{RADIANCE_ERROR, TARGET_ERROR};
use psrestir::optim::estimator::restir::{selection_trial, MergeDiagnostics, RestirOptions};
use psrestir::optim::{EstimatorOptions, Method, Optimizer, Settings};
use psrestir::render::params::ParamSet;
use psrestir::task::{Filter, Init, Loss, Slot, TextureSpec};

const W: u32 = 16;

#[test]
fn reservoir_selection_is_proportional_to_weight() {
    let Some(gpu) = gpu() else { return };
    let weights = [0.0f32, 1.0, 2.0, 0.0, 3.0, 5.0, 0.5, 8.0];
    let total: f64 = weights.iter().map(|&w| w as f64).sum();
    let mut counts = [0u64; 8];
    let mut n = 0u64;
    for seed in 0..4 {
        // 4096 reservoirs, each offered every candidate 4 times by adjacent invocations.
        let (sel, failures) = selection_trial(&gpu, &weights, 4, 4096, seed).unwrap();
        assert_eq!(
            failures, 0,
            "offers lost: a weight-sum update ran out of tries"
        );
        for s in sel {
            assert!((s as usize) < weights.len(), "a reservoir selected nothing");
            counts[s as usize] += 1;
            n += 1;
        }
    }
    let mut chi2 = 0.0;
    for (k, &w) in weights.iter().enumerate() {
        if w == 0.0 {
            assert_eq!(counts[k], 0, "zero-weight candidate {k} was selected");
            continue;
        }
        let e = n as f64 * w as f64 / total;
        chi2 += (counts[k] as f64 - e).powi(2) / e;
    }
    // 6 non-zero weights: 5 degrees of freedom; P(chi2 > 30) < 2e-5 for a correct sampler.
    // The rule of the reference code (accept when u * Wsum_before < w) fails this badly, as
    // does a race on keys u^(1/w) compared the wrong way.
    eprintln!("counts {counts:?}, chi2 {chi2:.2}");
    assert!(
        chi2 < 30.0,
        "selection frequencies {counts:?} do not match the weights (chi2 {chi2})"
    );
}

fn optimizer(
    gpu: &psrestir::gpu::Gpu,
    slot: Slot,
    filter: Filter,
    method: Method,
    restir: RestirOptions,
    values: &[f32],
    target_values: &[f32],
) -> Optimizer {
    optimizer_seeded(
        gpu,
        &[slot],
        filter,
        method,
        restir,
        values,
        target_values,
        11,
    )
}

/// 2x2 textures of the given slots on the shadow scene's plane, at `values`, with targets
/// rendered at `target_values`, learning rate 0, run seed `seed`.
#[allow(clippy::too_many_arguments)]
fn optimizer_seeded(
    gpu: &psrestir::gpu::Gpu,
    slots: &[Slot],
    filter: Filter,
    method: Method,
    restir: RestirOptions,
    values: &[f32],
    target_values: &[f32],
    seed: u32,
) -> Optimizer {
    let o = (restir, values, target_values, seed);
    optimizer_on(gpu, shadow_scene(), slots, filter, method, o)
}

/// [`optimizer_seeded`] on `scene`, with (ReSTIR options, values, target values, seed).
fn optimizer_on(
    gpu: &psrestir::gpu::Gpu,
    scene: psrestir::scene::Scene,
    slots: &[Slot],
    filter: Filter,
    method: Method,
    o: (RestirOptions, &[f32], &[f32], u32),
) -> Optimizer {
    let textures: Vec<(&str, Slot)> = slots.iter().map(|&slot| ("plane", slot)).collect();
    optimizer_textures(gpu, scene, &textures, filter, method, o)
}

/// [`optimizer_on`] with 2x2 textures of the given (material, slot) pairs.
fn optimizer_textures(
    gpu: &psrestir::gpu::Gpu,
    scene: psrestir::scene::Scene,
    textures: &[(&str, Slot)],
    filter: Filter,
    method: Method,
    (restir, values, target_values, seed): (RestirOptions, &[f32], &[f32], u32),
) -> Optimizer {
    let specs: Vec<TextureSpec> = textures
        .iter()
        .map(|&(material, slot)| TextureSpec {
            material: material.into(),
            slot,
            resolution: [2, 2],
            init: Init::Vector(vec![0.5; slot.channels() as usize]),
            learning_rate: Some(0.0),
        })
        .collect();
    let set = ParamSet::from_specs(&scene, &specs, filter, std::path::Path::new("test")).unwrap();
    let settings = Settings {
        width: W,
        height: W,
        cameras: vec![0],
        primal_spp: 8,
        primal: Default::default(),
        cv_max_weight: psrestir::optim::primal::DEFAULT_MAX_WEIGHT,
        path_cache: None,
        gradient_spp: 2,
        loss: Loss::L2,
        seed,
        method,
        estimator_options: EstimatorOptions::default().with(&restir),
        schedule: Default::default(),
        sparse_steps: false,
        priors: Default::default(),
        exposure_learning_rate: None,
        moment_filter: Default::default(),
        step: Default::default(),
        steps: Default::default(),
    };
    let base = Settings {
        method: Method::BASELINE,
        ..settings.clone()
    };
    let opt = Optimizer::new(gpu, &scene, set.clone(), base, &[Image::new(W, W)]).unwrap();
    opt.write_params(target_values).unwrap();
    let target = opt.render(0, 2048, 99).unwrap();
    let opt = Optimizer::new(gpu, &scene, set, settings, &[target]).unwrap();
    opt.write_params(values).unwrap();
    opt
}

#[test]
fn without_reuse_restir_equals_the_baseline_for_scalar_textures() {
    let Some(gpu) = gpu() else { return };
    // Direct light, and paths of 3 vertices whose later vertices meet the textures too (the
    // first vertex's candidates carry what the rest of the path brings back; the later
    // vertices' derivatives are plain Monte Carlo in both).
    // (The corner's camera sees part of the floor: texels seen only after a bounce get plain
    // Monte Carlo in both.)
    for scene in [shadow_scene(), corner_scene(3)] {
        restir_without_reuse_equals_the_baseline(&gpu, &scene);
    }
}

/// [`scalar_textures`] on the shadow scene with bilinear filtering: the scene, the textures,
/// their values and their true values.
fn shadow_scalar_set() -> (psrestir::scene::Scene, ParamSet, [f32; 7], [f32; 7]) {
    let scene = shadow_scene();
    let (specs, values, truth) = scalar_textures();
    let path = std::path::Path::new("test");
    let set = ParamSet::from_specs(&scene, &specs, Filter::Bilinear, path).unwrap();
    (scene, set, values, truth)
}

/// Two scalar textures at once on the plane's material (roughness 2x2, metallic 3x1, learning
/// rate 0), their values and their true values.
fn scalar_textures() -> ([TextureSpec; 2], [f32; 7], [f32; 7]) {
    let spec = |slot, resolution| TextureSpec {
        material: "plane".into(),
        slot,
        resolution,
        init: Init::Scalar(0.5),
        learning_rate: Some(0.0),
    };
    (
        [spec(Slot::Roughness, [2, 2]), spec(Slot::Metallic, [3, 1])],
        [0.3, 0.5, 0.7, 0.4, 0.2, 0.6, 0.9],
        [0.8, 0.2, 0.4, 0.9, 0.7, 0.1, 0.3],
    )
}

fn restir_without_reuse_equals_the_baseline(
    gpu: &psrestir::gpu::Gpu,
    scene: &psrestir::scene::Scene,
) {
    let scene = scene.clone();
    let (specs, values, truth) = scalar_textures();
    for filter in [Filter::Nearest, Filter::Bilinear] {
        let set =
            ParamSet::from_specs(&scene, &specs, filter, std::path::Path::new("test")).unwrap();
        let opts = RestirOptions {
            temporal: false,
            ..Default::default()
        };
        let settings = Settings {
            width: W,
            height: W,
            cameras: vec![0],
            primal_spp: 8,
            primal: Default::default(),
            cv_max_weight: psrestir::optim::primal::DEFAULT_MAX_WEIGHT,
            path_cache: None,
            gradient_spp: 2,
            loss: Loss::L2,
            seed: 11,
            method: Method::BASELINE,
            estimator_options: EstimatorOptions::default().with(&opts),
            schedule: Default::default(),
            sparse_steps: false,
            priors: Default::default(),
            exposure_learning_rate: None,
            moment_filter: Default::default(),
            step: Default::default(),
            steps: Default::default(),
        };
        let opt = Optimizer::new(
            gpu,
            &scene,
            set.clone(),
            settings.clone(),
            &[Image::new(W, W)],
        )
        .unwrap();
        opt.write_params(&truth).unwrap();
        let target = opt.render(0, 1024, 99).unwrap();
        let mut base = Optimizer::new(
            gpu,
            &scene,
            set.clone(),
            settings.clone(),
            std::slice::from_ref(&target),
        )
        .unwrap();
        let mut re = Optimizer::new(
            gpu,
            &scene,
            set,
            Settings {
                method: Method::RESTIR,
                ..settings
            },
            &[target],
        )
        .unwrap();
        base.write_params(&values).unwrap();
        re.write_params(&values).unwrap();
        for it in 0..3 {
            let (gb, _) = base.estimate_gradient(it).unwrap();
            let (gr, _) = re.estimate_gradient(it).unwrap();
            let scale = gb.iter().fold(0f32, |m, x| m.max(x.abs()));
            assert!(gb[..4].iter().any(|g| *g != 0.0) && gb[4..].iter().any(|g| *g != 0.0));
            for i in 0..gb.len() {
                // The same candidates summed in another order, but ReSTIR's evaluated at the
                // rounded radiance (and, far less, hit and direction) its reservoirs store:
                // each term within compact::RADIANCE_ERROR of its own value, so the sum
                // within that of the sum of the terms' magnitudes, which exceeds |sum| where
                // terms of both signs cancel (the second part, relative to the largest entry).
                // With indirect light the rest of the path starts from the rounded hit (about
                // 1e-6 away), which now and then moves a later vertex's sample across a
                // texel's edge or a shadow's: four times the bound (measured: at most 1.0%,
                // 0.2% but for one entry).
                let bound = if scene.max_depth.get() > 1 {
                    4.0 * RADIANCE_ERROR
                } else {
                    RADIANCE_ERROR
                };
                let tol = bound * (gb[i].abs() + 0.5 * scale);
                assert!(
                    (gb[i] - gr[i]).abs() <= tol,
                    "depth {}, {filter:?} iteration {it} parameter {i}: baseline {} vs ReSTIR {}",
                    scene.max_depth.get(),
                    gb[i],
                    gr[i]
                );
            }
        }
        assert_eq!(re.faults().unwrap(), Default::default());
    }
}

/// Mean and its standard error from batch means (ReSTIR's estimates are correlated across
/// iterations; batches much longer than the correlation time are nearly independent).
fn batch_mean(samples: &[Vec<f32>], batches: usize) -> (Vec<f64>, Vec<f64>) {
    let n = samples[0].len();
    let per = samples.len() / batches;
    let mut means = vec![vec![0f64; n]; batches];
    for (b, m) in means.iter_mut().enumerate() {
        for s in &samples[b * per..(b + 1) * per] {
            for i in 0..n {
                m[i] += s[i] as f64 / per as f64;
            }
        }
    }
    let mean: Vec<f64> = (0..n)
        .map(|i| means.iter().map(|m| m[i]).sum::<f64>() / batches as f64)
        .collect();
    let se: Vec<f64> = (0..n)
        .map(|i| {
            (means.iter().map(|m| (m[i] - mean[i]).powi(2)).sum::<f64>()
                / (batches as f64 - 1.0)
                / batches as f64)
                .sqrt()
        })
        .collect();
    (mean, se)
}

fn check_unbiased_with_reuse(slot: Slot, filter: Filter, v: &[f32], t: &[f32]) {
    let Some(gpu) = gpu() else { return };
    let opts = RestirOptions::default();
    // Reference: many independent baseline estimates.
    let mut base = optimizer(&gpu, slot, filter, Method::BASELINE, opts, v, t);
    let reference: Vec<Vec<f32>> = (0..160)
        .map(|it| base.estimate_gradient(10_000 + it).unwrap().0)
        .collect();
    let (ref_mean, ref_se) = batch_mean(&reference, 16);
    // ReSTIR with temporal reuse, learning rate 0: the state evolves, the textures do not.
    let mut re = optimizer(&gpu, slot, filter, Method::RESTIR, opts, v, t);
    let mut samples = Vec::new();
    for _ in 0..320 {
        re.step().unwrap();
        samples.push(re.read_gradient().unwrap());
    }
    assert_eq!(
        re.read_params().unwrap(),
        v,
        "learning rate 0 changed the textures"
    );
    // Drop the first 20 iterations (the reservoirs start empty), batches of 25.
    let (mean, se) = batch_mean(&samples[20..], 12);
    let label = format!("{slot:?}/{filter:?}");
    assert_means_agree(&label, 4.5, (&mean, &se), (&ref_mean, &ref_se));
    assert_eq!(re.faults().unwrap(), Default::default());
}

/// Every parameter's ReSTIR mean within `k` standard errors of the difference of the
/// reference mean, plus 0.1% of the reference's largest entry for rounding.
fn assert_means_agree(
    label: &str,
    k: f64,
    (mean, se): (&[f64], &[f64]),
    (ref_mean, ref_se): (&[f64], &[f64]),
) {
    let scale = ref_mean.iter().fold(0f64, |m, x| m.max(x.abs()));
    for i in 0..mean.len() {
        let tol = k * (se[i].powi(2) + ref_se[i].powi(2)).sqrt() + 1e-3 * scale;
        eprintln!(
            "{label} {i}: ReSTIR {:.4e} +- {:.1e}, baseline {:.4e} +- {:.1e}",
            mean[i], se[i], ref_mean[i], ref_se[i]
        );
        assert!(
            (mean[i] - ref_mean[i]).abs() <= tol,
            "{label} parameter {i}: ReSTIR mean {} vs reference {} (tolerance {tol})",
            mean[i],
            ref_mean[i]
        );
    }
}

/// Learning rate 0, but the textures alternate between states A and B every iteration, so
/// that every kept path is shifted across a change of base color and roughness (both
/// textures at once): the mean of ReSTIR's gradients at A matches a high-sample baseline
/// reference at A. With the path self-check on, every kept path also evaluates to its stored
/// value under the state it was drawn at.
fn check_unbiased_across_shifts(filter: Filter) {
    let Some(gpu) = gpu() else { return };
    let trial = shift_trial(&gpu, filter, 11);
    check_shift_trial(&format!("{filter:?}"), trial);
}

/// [`check_unbiased_across_shifts`]'s checks of one trial.
fn check_shift_trial(label: &str, trial: ShiftTrial) {
    // 5.5 standard errors: the standard error comes from 24 batch means, so the difference
    // over it follows Student's t with 23 degrees of freedom: P(|t| > 5.5) x 32 parameters is
    // about 4e-4 per test. (4.5 with 12 batches was a 3% false alarm per test under that
    // model, and ReSTIR's persistent high-weight samples make the tails heavier still: it
    // failed once in CI at 6.5 estimated standard errors, with a standard error a third of
    // other runs'.)
    let means = (&trial.mean[..], &trial.se[..]);
    let reference = (&trial.ref_mean[..], &trial.ref_se[..]);
    assert_means_agree(label, 5.5, means, reference);
    let d = trial.diagnostics;
    eprintln!("{label}: {d:?}");
    // Both sides evaluate the same f32 arithmetic on the same stored path (the candidate
    // pass evaluates it at the rounded hit, direction and radiance it stores), in two
    // separately compiled shaders; the stored target is a bfloat16, so they agree to its
    // rounding (compact::TARGET_ERROR) plus float rounding.
    assert!(d.verified > 1000, "too few kept paths were checked: {d:?}");
    assert!(
        d.max_relative_error < TARGET_ERROR + 1e-4,
        "a stored path does not evaluate to its stored target: {d:?}"
    );
}

/// One run of the A/B alternation: ReSTIR's batch means at A and a baseline reference.
struct ShiftTrial {
    mean: Vec<f64>,
    se: Vec<f64>,
    ref_mean: Vec<f64>,
    ref_se: Vec<f64>,
    diagnostics: MergeDiagnostics,
}

fn shift_trial(gpu: &psrestir::gpu::Gpu, filter: Filter, seed: u32) -> ShiftTrial {
    let slots = [Slot::BaseColor, Slot::Roughness];
    let a = [
        0.5, 0.4, 0.3, 0.6, 0.5, 0.2, 0.3, 0.3, 0.3, 0.7, 0.6, 0.5, 0.3, 0.5, 0.7, 0.4,
    ];
    let b = [
        0.7, 0.2, 0.5, 0.4, 0.7, 0.4, 0.5, 0.1, 0.6, 0.5, 0.8, 0.3, 0.6, 0.2, 0.4, 0.8,
    ];
    let t = [
        0.8, 0.2, 0.1, 0.3, 0.6, 0.4, 0.5, 0.5, 0.5, 0.2, 0.3, 0.9, 0.8, 0.2, 0.4, 0.9,
    ];
    shift_trial_of(gpu, &slots, [&a, &b, &t], filter, seed)
}

/// [`shift_trial`] of 2x2 textures of `slots` on the plane, alternating between states A and
/// B (`states`: A, B, the target's).
fn shift_trial_of(
    gpu: &psrestir::gpu::Gpu,
    slots: &[Slot],
    [a, b, t]: [&[f32]; 3],
    filter: Filter,
    seed: u32,
) -> ShiftTrial {
    let opts = RestirOptions {
        verify_paths: true,
        ..Default::default()
    };
    let (base_method, re_method) = (Method::BASELINE, Method::RESTIR);
    let mut base = optimizer_seeded(gpu, slots, filter, base_method, opts, a, t, seed);
    let reference: Vec<Vec<f32>> = (0..160)
        .map(|it| base.estimate_gradient(10_000 + it).unwrap().0)
        .collect();
    let (ref_mean, ref_se) = batch_mean(&reference, 16);
    let mut re = optimizer_seeded(gpu, slots, filter, re_method, opts, a, t, seed);
    let mut samples = Vec::new();
    for it in 0..1240 {
        let at_a = it % 2 == 0;
        re.write_params(if at_a { a } else { b }).unwrap();
        re.step().unwrap();
        if at_a {
            samples.push(re.read_gradient().unwrap());
        }
    }
    // Drop the first 20 estimates at A, 24 batches of 25 (each batch spans 50 iterations).
    // Successive ReSTIR estimates stay correlated for tens of iterations (the bench's
    // successive-estimate error), so neighbouring batches are not fully independent; that
    // makes the batch standard error too small, and the test stricter, not looser.
    let (mean, se) = batch_mean(&samples[20..], 24);
    assert_eq!(re.faults().unwrap(), Default::default());
    ShiftTrial {
        mean,
        se,
        ref_mean,
        ref_se,
        diagnostics: MergeDiagnostics::from_named(&re.estimator_diagnostics().unwrap()).unwrap(),
    }
}

/// Not run by default (about 10 s per seed and filter): the A/B alternation over several
/// seeds, pooling each parameter's z-score of ReSTIR's mean against the reference. Under
/// no bias the pooled z (sum / sqrt(seeds)) is standard normal for every parameter; a
/// parameter that sits on the same side in every seed shows up as a large pooled z.
/// `cargo test --release --test restir -- --ignored bias_scan --nocapture`
#[test]
#[ignore = "a diagnostic, not a check: about 3 minutes (16 runs of the A/B test), run by hand"]
fn bias_scan_across_seeds() {
    let Some(gpu) = gpu() else { return };
    let seeds: Vec<u32> = (1..=8).collect();
    for filter in [Filter::Nearest, Filter::Bilinear] {
        let mut z_sum: Vec<f64> = Vec::new();
        let mut rel: Vec<Vec<f64>> = Vec::new();
        for &seed in &seeds {
            let t = shift_trial(&gpu, filter, seed);
            z_sum.resize(t.mean.len(), 0.0);
            rel.resize(t.mean.len(), Vec::new());
            for i in 0..t.mean.len() {
                let se = (t.se[i].powi(2) + t.ref_se[i].powi(2)).sqrt();
                z_sum[i] += (t.mean[i] - t.ref_mean[i]) / se.max(1e-30);
                rel[i].push(t.mean[i] / t.ref_mean[i]);
            }
        }
        let n = seeds.len() as f64;
        for (i, z) in z_sum.iter().enumerate() {
            let r: Vec<String> = rel[i].iter().map(|r| format!("{r:.3}")).collect();
            eprintln!(
                "{filter:?} {i}: pooled z {:+.2}, ReSTIR/reference {}",
                z / n.sqrt(),
                r.join(" ")
            );
        }
    }
}

#[test]
fn restir_is_unbiased_across_texture_changes_nearest() {
    check_unbiased_across_shifts(Filter::Nearest);
}

#[test]
fn restir_is_unbiased_across_texture_changes_bilinear() {
    check_unbiased_across_shifts(Filter::Bilinear);
}

/// The A/B alternation over base color and a normal map: every kept path is evaluated in a
/// shading frame that moved since it was stored (its direction kept in the geometric
/// normal's frame), and each candidate's target under the previous state in the previous
/// normal's frame.
#[test]
fn restir_is_unbiased_across_normal_map_changes() {
    let Some(gpu) = gpu() else { return };
    let color = |a: f32| -> Vec<f32> { (0..12).map(|i| a + 0.05 * (i % 5) as f32).collect() };
    let state = |a: f32| -> Vec<f32> { [color(a), tilted_normals(a)].concat() };
    let (a, b, t) = (state(0.3), state(0.55), state(0.45));
    let slots = [Slot::BaseColor, Slot::Normal];
    let trial = shift_trial_of(&gpu, &slots, [&a, &b, &t], Filter::Bilinear, 13);
    check_shift_trial("normal map", trial);
}

/// Whole paths at depth 3: the corner's floor (base color and roughness, and with
/// `normal_map` a normal map) lights its walls (base color), all optimized, and the camera
/// sees the walls only, so the floor's texels are reached only after a bounce. The textures
/// alternate between A and B every iteration, so every kept path is shifted across a change
/// of every vertex's material (with the normal map, of the floor's shading frame, at a path's
/// last vertex or before it); the mean of ReSTIR's gradients at A matches a high-sample
/// baseline reference at A, every stored path evaluates to its stored target, and no
/// candidate finds its texel without a reservoir.
fn check_whole_paths_unbiased(filter: Filter, normal_map: bool) {
    let Some(gpu) = gpu() else { return };
    let mut scene = corner_scene(3);
    scene.cameras = vec![look_at(
        Vec3::new(0.6, 1.3, 1.6),
        Vec3::new(-0.5, 1.4, -0.7),
        Vec3::Y,
        0.7,
    )];
    let mut textures = vec![
        ("plane", Slot::BaseColor),
        ("plane", Slot::Roughness),
        ("wall", Slot::BaseColor),
    ];
    // 2x2 texels each: 12 + 4 + 12 values (and the normal map's 12, tilted normals).
    let ramp = |a: f32, b: f32| -> Vec<f32> {
        let mut v: Vec<f32> = (0..28)
            .map(|i| a + b * ((i * 7 % 11) as f32 / 10.0))
            .collect();
        if normal_map {
            v.extend(tilted_normals(a));
        }
        v
    };
    if normal_map {
        textures.push(("plane", Slot::Normal));
    }
    let (a, b, t) = (ramp(0.3, 0.4), ramp(0.5, 0.3), ramp(0.2, 0.6));
    let opts = RestirOptions {
        verify_paths: true,
        ..Default::default()
    };
    let o = (opts, &a[..], &t[..], 7u32);
    let mut base = optimizer_textures(&gpu, scene.clone(), &textures, filter, Method::BASELINE, o);
    // Only the walls are in view: the floor's texels have no camera-observed texel.
    let seen = base.observed_texels().unwrap().to_vec();
    assert!(
        seen[..4].iter().all(|&x| !x),
        "the camera sees the floor: {seen:?}"
    );
    assert!(
        seen[8..].iter().any(|&x| x),
        "the camera sees no wall texel: {seen:?}"
    );
    let reference: Vec<Vec<f32>> = (0..160)
        .map(|it| base.estimate_gradient(10_000 + it).unwrap().0)
        .collect();
    let (ref_mean, ref_se) = batch_mean(&reference, 16);
    let mut re = optimizer_textures(&gpu, scene, &textures, filter, Method::RESTIR, o);
    let mut samples = Vec::new();
    for it in 0..840 {
        let at_a = it % 2 == 0;
        re.write_params(if at_a { &a } else { &b }).unwrap();
        re.step().unwrap();
        if at_a {
            samples.push(re.read_gradient().unwrap());
        }
    }
    // Drop the first 20 estimates at A, 16 batches of 25 (5.5 standard errors, as above).
    let (mean, se) = batch_mean(&samples[20..], 16);
    assert_eq!(re.faults().unwrap(), Default::default());
    let label = format!("whole paths {filter:?}, normal map {normal_map}");
    assert_means_agree(&label, 5.5, (&mean, &se), (&ref_mean, &ref_se));
    let d = MergeDiagnostics::from_named(&re.estimator_diagnostics().unwrap()).unwrap();
    eprintln!("{label}: {d:?}");
    assert!(d.verified > 1000, "too few kept paths were checked: {d:?}");
    assert!(
        d.max_relative_error < TARGET_ERROR + 1e-4,
        "a stored path does not evaluate to its stored target: {d:?}"
    );
    assert_eq!(
        d.unmapped, 0,
        "candidates for texels without reservoirs: {d:?}"
    );
}

#[test]
fn whole_paths_at_depth_3_are_unbiased_across_changes_of_every_surface_nearest() {
    check_whole_paths_unbiased(Filter::Nearest, false);
}

/// With a normal map on the floor as well.
#[test]
fn whole_paths_at_depth_3_are_unbiased_across_changes_of_every_surface_bilinear() {
    check_whole_paths_unbiased(Filter::Bilinear, true);
}

/// A normal map's 2x2 texels (12 values) of tilted normals, varying with `a`: Z well above
/// the floor, X and Y either side of flat.
fn tilted_normals(a: f32) -> Vec<f32> {
    (0..4)
        .flat_map(|i| {
            let s = (i as f32 - 1.5) * 0.1;
            [
                0.5 + s + 0.2 * (a - 0.4),
                0.5 - 0.5 * s + 0.1 * (a - 0.4),
                0.9,
            ]
        })
        .collect()
}

#[test]
fn the_merge_pass_traces_no_ray() {
    // Static: the composed merge module contains no traversal code at all, so no run of it
    // can trace a ray; the candidate pass, which must trace, does contain it.
    let functions = |pass: &str| -> Vec<String> {
        let m = psrestir::shader_library::validate(pass).unwrap();
        m.functions
            .iter()
            .filter_map(|(_, f)| f.name.clone())
            .collect()
    };
    let tracing = [
        "traverse",
        "trace_ray",
        "trace_closest",
        "intersect_triangle",
    ];
    let merge = functions("restir_merge");
    for f in tracing {
        assert!(!merge.iter().any(|n| n == f), "the merge pass contains {f}");
    }
    let candidates = functions("restir_candidates");
    for f in tracing {
        assert!(
            candidates.iter().any(|n| n == f),
            "the check is blind: no {f}"
        );
    }
    // At run time the merge does its work by evaluating stored paths.
    let Some(gpu) = gpu() else { return };
    let mut re = optimizer(
        &gpu,
        Slot::Roughness,
        Filter::Bilinear,
        Method::RESTIR,
        RestirOptions::default(),
        &[0.3, 0.5, 0.7, 0.4],
        &[0.8, 0.2, 0.4, 0.9],
    );
    for _ in 0..4 {
        re.step().unwrap();
    }
    let d = MergeDiagnostics::from_named(&re.estimator_diagnostics().unwrap()).unwrap();
    assert!(d.evaluations > 0, "{d:?}");
}

/// The claim log keeps the offers that led their races when they entered them, and the claim
/// pass lets the winners write their paths without tracing again; where the log is full the
/// candidate pass traces the samples a second time and the winners write theirs. Either way
/// the same offers win and write the same words: a log of one entry (full in every
/// iteration) gives the gradients of the log that holds every leader, iteration after
/// iteration with reuse, at depth 1 and with whole paths at depth 3.
#[test]
fn a_full_claim_log_writes_the_same_winners() {
    let Some(gpu) = gpu() else { return };
    for scene in [shadow_scene(), corner_scene(3)] {
        let depth = scene.max_depth.get();
        let run = |claim_entries: Option<u32>| {
            let opts = RestirOptions {
                claim_entries,
                ..Default::default()
            };
            let o = (
                opts,
                &[0.3, 0.5, 0.7, 0.4][..],
                &[0.8, 0.2, 0.4, 0.9][..],
                7,
            );
            let slots = [Slot::Roughness];
            let mut re = optimizer_on(
                &gpu,
                scene.clone(),
                &slots,
                Filter::Bilinear,
                Method::RESTIR,
                o,
            );
            let grads: Vec<Vec<f32>> = (0..6)
                .map(|it| re.estimate_gradient(it).unwrap().0)
                .collect();
            (
                grads,
                MergeDiagnostics::from_named(&re.estimator_diagnostics().unwrap()).unwrap(),
                re.faults().unwrap(),
            )
        };
        let (full, d_full, f_full) = run(None);
        let (tiny, d_tiny, f_tiny) = run(Some(1));
        eprintln!("depth {depth}: {d_full:?} / {d_tiny:?}");
        assert!(d_full.logged > 0 && d_full.overflowed == 0, "{d_full:?}");
        assert!(d_tiny.overflowed > 0 && d_tiny.logged == 6, "{d_tiny:?}");
        assert_eq!(f_full, Default::default());
        assert_eq!(f_tiny, Default::default());
        assert!(full.iter().any(|g| g.iter().any(|x| *x != 0.0)));
        for (it, (a, b)) in full.iter().zip(&tiny).enumerate() {
            // The same reservoirs; the weight sums add the same offers in an order the
            // scheduling picks: equal to float rounding, which scales with the terms summed,
            // so with the iteration's largest entry (an entry that sums terms of both signs
            // differs by more than its own 1e-5: 1.2e-5 measured at depth 3). Another winner
            // would change an entry by a whole term.
            let scale = a.iter().fold(1e-6f32, |m, x| m.max(x.abs()));
            for (i, (x, y)) in a.iter().zip(b).enumerate() {
                assert!(
                    (x - y).abs() <= 1e-5 * scale,
                    "depth {depth}, iteration {it}, parameter {i}: {x} with every leader logged, \
                     {y} with a full log"
                );
            }
        }
    }
}

/// A stored path carries the material inputs that no optimized texture replaces
/// (shaders/shared/surface.wgsl, fixed_pack), packed by which slots are optimized; the merge
/// evaluates kept paths from them. For every combination of optimized slots on a material
/// whose base color, metallic and roughness differ, with the textures alternating between
/// two states, every kept path evaluates to its stored factor (the path self-check): a
/// packing that mixed up two inputs would miss by far more than rounding.
#[test]
fn stored_paths_keep_the_inputs_no_texture_replaces() {
    let Some(gpu) = gpu() else { return };
    let combinations: [&[Slot]; 5] = [
        &[Slot::BaseColor],
        &[Slot::Metallic],
        &[Slot::Roughness],
        &[Slot::Metallic, Slot::Roughness],
        &[Slot::BaseColor, Slot::Metallic],
    ];
    let opts = RestirOptions {
        verify_paths: true,
        ..Default::default()
    };
    // The last combination again on a normal-mapped plane: the merge rebuilds the perturbed
    // shading frame from the stored hit.
    let mut bumpy = shadow_scene();
    with_normal_map(&mut bumpy);
    let runs = combinations
        .iter()
        .map(|s| (*s, shadow_scene()))
        .chain([(combinations[4], bumpy)]);
    for (slots, scene) in runs {
        let n: usize = slots.iter().map(|s| 4 * s.channels() as usize).sum();
        let a: Vec<f32> = (0..n).map(|i| 0.3 + 0.05 * (i % 7) as f32).collect();
        let b: Vec<f32> = (0..n).map(|i| 0.6 - 0.04 * (i % 5) as f32).collect();
        let t = vec![0.5; n];
        let o = (opts, &a[..], &t[..], 5);
        let mut re = optimizer_on(&gpu, scene, slots, Filter::Bilinear, Method::RESTIR, o);
        for it in 0..12 {
            re.write_params(if it % 2 == 0 { &a } else { &b }).unwrap();
            re.step().unwrap();
        }
        let d = MergeDiagnostics::from_named(&re.estimator_diagnostics().unwrap()).unwrap();
        eprintln!("{slots:?}: {d:?}");
        assert!(
            d.verified > 100,
            "{slots:?}: too few kept paths were checked: {d:?}"
        );
        assert!(
            d.max_relative_error < TARGET_ERROR + 1e-4,
            "{slots:?}: a stored path does not evaluate to its stored target: {d:?}"
        );
    }
}

#[test]
fn restir_with_reuse_is_unbiased_for_base_color_nearest() {
    let v = [0.5, 0.4, 0.3, 0.6, 0.5, 0.2, 0.3, 0.3, 0.3, 0.7, 0.6, 0.5];
    let t = [0.8, 0.2, 0.1, 0.3, 0.6, 0.4, 0.5, 0.5, 0.5, 0.2, 0.3, 0.9];
    check_unbiased_with_reuse(Slot::BaseColor, Filter::Nearest, &v, &t);
}

// Failed (about 20% small on texel 3) while base color's target was the luminance alone:
// its channels' values cancel there, and samples with a near-zero target were almost never
// selected (shared/params.wgsl, target_of).
#[test]
fn restir_with_reuse_is_unbiased_for_base_color_bilinear() {
    let v = [0.5, 0.4, 0.3, 0.6, 0.5, 0.2, 0.3, 0.3, 0.3, 0.7, 0.6, 0.5];
    let t = [0.8, 0.2, 0.1, 0.3, 0.6, 0.4, 0.5, 0.5, 0.5, 0.2, 0.3, 0.9];
    check_unbiased_with_reuse(Slot::BaseColor, Filter::Bilinear, &v, &t);
}

#[test]
fn restir_with_reuse_is_unbiased_for_roughness_nearest() {
    check_unbiased_with_reuse(
        Slot::Roughness,
        Filter::Nearest,
        &[0.3, 0.5, 0.7, 0.4],
        &[0.8, 0.2, 0.4, 0.9],
    );
}

#[test]
fn restir_with_reuse_is_unbiased_for_roughness_bilinear() {
    check_unbiased_with_reuse(
        Slot::Roughness,
        Filter::Bilinear,
        &[0.3, 0.5, 0.7, 0.4],
        &[0.8, 0.2, 0.4, 0.9],
    );
}

/// A normal map held fixed: each texel's factor is a 3x3 matrix (every image channel moves
/// each of the map's channels), its target the plain sum of the values' magnitudes.
#[test]
fn restir_with_reuse_is_unbiased_for_normal_map_bilinear() {
    let v = tilted_normals(0.3);
    let t = tilted_normals(0.6);
    check_unbiased_with_reuse(Slot::Normal, Filter::Bilinear, &v, &t);
}

#[test]
fn gradients_follow_a_sign_change() {
    let Some(gpu) = gpu() else { return };
    // One roughness texel; the target was rendered at 0.5. At 0.3 and at 0.7 the true
    // gradients have opposite signs.
    let one = |filter, method, v: f32| {
        let scene = shadow_scene();
        let spec = TextureSpec {
            material: "plane".into(),
            slot: Slot::Roughness,
            resolution: [1, 1],
            init: Init::Scalar(0.5),
            learning_rate: Some(0.0),
        };
        let set =
            ParamSet::from_specs(&scene, &[spec], filter, std::path::Path::new("test")).unwrap();
        let settings = Settings {
            width: W,
            height: W,
            cameras: vec![0],
            primal_spp: 8,
            primal: Default::default(),
            cv_max_weight: psrestir::optim::primal::DEFAULT_MAX_WEIGHT,
            path_cache: None,
            gradient_spp: 2,
            loss: Loss::L2,
            seed: 5,
            method,
            estimator_options: Default::default(),
            schedule: Default::default(),
            sparse_steps: false,
            priors: Default::default(),
            exposure_learning_rate: None,
            moment_filter: Default::default(),
            step: Default::default(),
            steps: Default::default(),
        };
        let opt = Optimizer::new(
            &gpu,
            &scene,
            set.clone(),
            Settings {
                method: Method::BASELINE,
                ..settings.clone()
            },
            &[Image::new(W, W)],
        )
        .unwrap();
        opt.write_params(&[0.5]).unwrap();
        let target = opt.render(0, 2048, 3).unwrap();
        let opt = Optimizer::new(&gpu, &scene, set, settings, &[target]).unwrap();
        opt.write_params(&[v]).unwrap();
        opt
    };
    for filter in [Filter::Nearest, Filter::Bilinear] {
        let mut reference = Vec::new();
        for v in [0.3f32, 0.7] {
            let mut b = one(filter, Method::BASELINE, v);
            let mean = (0..64)
                .map(|it| b.estimate_gradient(500 + it).unwrap().0[0] as f64)
                .sum::<f64>()
                / 64.0;
            reference.push(mean);
        }
        assert!(
            reference[0] * reference[1] < 0.0,
            "the scene does not flip the gradient: {reference:?}"
        );
        let mut re = one(filter, Method::RESTIR, 0.3);
        let mut phase = [Vec::new(), Vec::new()];
        for it in 0..80 {
            if it == 40 {
                re.write_params(&[0.7]).unwrap();
            }
            re.step().unwrap();
            let g = re.read_gradient().unwrap()[0] as f64;
            // Skip the first 10 iterations of each phase (empty reservoirs, then the change).
            if it % 40 >= 10 {
                phase[it / 40].push(g);
            }
        }
        for (k, p) in phase.iter().enumerate() {
            let mean = p.iter().sum::<f64>() / p.len() as f64;
            eprintln!(
                "{filter:?} phase {k}: ReSTIR mean {mean:.4e}, baseline {:.4e}",
                reference[k]
            );
            assert!(
                mean * reference[k] > 0.0,
                "{filter:?} phase {k}: ReSTIR mean {mean} has the wrong sign (baseline {})",
                reference[k]
            );
            // Every single estimate after the change has the new sign or is zero: kept samples
            // of the old sign are routed to the other reservoir, not kept alive.
            let wrong = p.iter().filter(|g| **g * reference[k] < 0.0).count();
            assert!(
                wrong * 4 <= p.len(),
                "{filter:?} phase {k}: {wrong} of {} estimates have the old sign",
                p.len()
            );
        }
    }
}

/// The bundled default task at `side`² pixels (a quarter of its own at 64) with targets of
/// `target_spp`.
fn shrunk_default_task(side: u32, target_spp: u32) -> psrestir::task::Task {
    let path = std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/scenes/default/task.toml"
    ));
    let mut task = psrestir::task::Task::load(path).unwrap();
    task.width = side;
    task.height = side;
    task.target.spp = target_spp;
    // These tests compare the estimators under Adam, at the rate Adam was tuned to on this
    // task (the task itself now takes the variance-scaled step at half of it), without the
    // moment filter that the task now has.
    task.optimizer.step = Some(psrestir::optim::StepKind::ADAM);
    task.optimizer.moment_filter = Some(Default::default());
    for t in &mut task.textures {
        t.learning_rate = Some(0.02);
    }
    task
}

#[test]
fn restir_beats_the_baseline_on_the_default_scene_at_low_sampling() {
    let Some(gpu) = gpu() else { return };
    // The bundled default task at a quarter of its pixels and 60 iterations (to keep the
    // suite short): same scene, cameras, texture, learning rate and schedule, with the
    // sampling the task had before it moved to 4 and 2 spp with the control-variate primal:
    // a 2-spp independent primal and 1 gradient spp, the sparse regime where reuse gains.
    // (With the task's own sampling the two estimators end level: README, Quickstart.)
    let mut task = shrunk_default_task(64, 128);
    task.optimizer.primal_spp = 2;
    task.optimizer.gradient_spp = 1;
    task.optimizer.primal = psrestir::optim::PrimalMode::Independent;
    task.optimizer.set("smoothness", 0.03);
    let iterations = 60;
    let dir = tempfile::tempdir().unwrap();
    let prep = psrestir::job::Problem::from_task(&gpu, &task, dir.path(), false).unwrap();
    let truth = prep.reference.clone().unwrap();
    let mut final_rmse = [0f64; 2];
    let seeds = [1u32, 2, 3];
    for (m, method) in [Method::RESTIR, Method::BASELINE].into_iter().enumerate() {
        for &seed in &seeds {
            let settings = Settings {
                seed,
                ..psrestir::task::task_settings(&task, &prep.cameras, method, &Default::default())
            };
            let mut opt =
                Optimizer::new(&gpu, &prep.scene, prep.set.clone(), settings, &prep.targets)
                    .unwrap();
            for _ in 0..iterations {
                opt.step().unwrap();
            }
            final_rmse[m] +=
                psrestir::job::run::rmse(&opt.read_params().unwrap(), &truth) / seeds.len() as f64;
        }
    }
    let initial = psrestir::job::run::rmse(&prep.set.values, &truth);
    eprintln!("texture RMSE after {iterations} iterations: initial {initial:.4}, ReSTIR {:.4}, baseline {:.4}", final_rmse[0], final_rmse[1]);
    assert!(
        final_rmse[0] < final_rmse[1],
        "ReSTIR {} is not below the baseline {}",
        final_rmse[0],
        final_rmse[1]
    );
}

#[test]
fn the_shrunk_default_task_recovers_its_texture() {
    let Some(gpu) = gpu() else { return };
    // The bundled default task with its settings and whole schedule, at a quarter of its
    // pixels and a quarter of its texels (the same texels per pixel), with ReSTIR, the
    // command line's default. The full task ends at 0.33x its initial observed-texel RMSE
    // (README, Quickstart). This one ends higher, measured with seeds 1 / 2 / 3: 0.482x /
    // 0.470x / 0.478x, each within 0.2% of its value at a third of the run. Its targets take
    // 512 spp: with 128 the optimizer fits their noise and the error rose late (by 1-2%
    // after a third, at 64^2 and at 96^2). The bounds leave room for other devices' rounding
    // and fail on a late rise or on the speckle the task gave before its schedule and
    // multiscale gradient (all-texel RMSE 0.94x after 150 iterations).
    let mut task = shrunk_default_task(64, 512);
    task.textures[0].resolution = [128, 64];
    let dir = tempfile::tempdir().unwrap();
    let prep = psrestir::job::Problem::from_task(&gpu, &task, dir.path(), false).unwrap();
    let truth = prep.reference.clone().unwrap();
    let settings =
        psrestir::task::task_settings(&task, &prep.cameras, Method::RESTIR, &Default::default());
    let mut opt =
        Optimizer::new(&gpu, &prep.scene, prep.set.clone(), settings, &prep.targets).unwrap();
    let observed = opt.observed_texels().unwrap().to_vec();
    let rmse = |values: &[f32]| {
        psrestir::optim::observed::rmse_observed(&prep.set, values, &truth, &observed)
    };
    let initial = rmse(&prep.set.values);
    let iterations = task.optimizer.iterations.unwrap();
    let mut at_third = 0.0;
    for i in 0..iterations {
        opt.step().unwrap();
        if i + 1 == iterations / 3 {
            at_third = rmse(&opt.read_params().unwrap());
        }
    }
    let last = rmse(&opt.read_params().unwrap());
    eprintln!(
        "observed-texel RMSE: initial {initial:.4}, at a third {at_third:.4}, final {last:.4} ({:.3}x)",
        last / initial
    );
    assert!(
        last <= 1.01 * at_third,
        "the error rose late: {at_third} -> {last}"
    );
    let bound = 0.55;
    assert!(
        last <= bound * initial,
        "observed-texel RMSE {last} is above {bound} x its initial {initial}"
    );
}

#[test]
fn without_priors_at_tuned_settings_neither_estimator_drifts() {
    let Some(gpu) = gpu() else { return };
    // The default task without its priors (no multiscale gradient, no smoothness), shrunk to
    // 64^2 images and a 128x64 texture, each estimator at the settings `bench --tune` chose
    // for it on the full task (docs/studies.md, "Reuse and the reconstruction"): half the
    // learning rate, and for ReSTIR an M cap of 2. At the task's own rate both drift (the
    // error rises after an early low: ReSTIR ended 1.13x above its lowest in 60 s, the
    // baseline 1.05x); at these settings neither ends more than 5% above its lowest value,
    // over three seeds, and both recover most of the way. At about equal time (ReSTIR's
    // iteration costs 1.08-1.09x the baseline's on the default task, so the baseline gets 9%
    // more iterations) the two end level here: mean over the seeds 0.1580 (ReSTIR, 150
    // iterations) against 0.1581 (baseline, 164; 0.1603 at 150). That is too close to assert
    // an order, and the full task's 60 s runs end with the baseline ahead (0.1381 against
    // 0.1467), which is why the default estimator is the baseline.
    let mut task = shrunk_default_task(64, 512);
    task.textures[0].resolution = [128, 64];
    task.textures[0].learning_rate = task.textures[0].learning_rate.map(|r| r * 0.5);
    task.optimizer.priors_off();
    let dir = tempfile::tempdir().unwrap();
    let prep = psrestir::job::Problem::from_task(&gpu, &task, dir.path(), false).unwrap();
    let truth = prep.reference.clone().unwrap();
    for method in [Method::BASELINE, Method::RESTIR] {
        let iterations = if method == Method::RESTIR { 150 } else { 164 };
        for seed in [1u32, 2, 3] {
            let restir = RestirOptions {
                m_cap: 2.0,
                ..Default::default()
            };
            let settings = Settings {
                seed,
                ..psrestir::task::task_settings(
                    &task,
                    &prep.cameras,
                    method,
                    &EstimatorOptions::default().with(&restir),
                )
            };
            let mut opt =
                Optimizer::new(&gpu, &prep.scene, prep.set.clone(), settings, &prep.targets)
                    .unwrap();
            let observed = opt.observed_texels().unwrap().to_vec();
            let rmse = |values: &[f32]| {
                psrestir::optim::observed::rmse_observed(&prep.set, values, &truth, &observed)
            };
            let initial = rmse(&prep.set.values);
            let mut lowest = initial;
            for i in 0..iterations {
                opt.set_progress(i as f64 / iterations as f64);
                opt.step().unwrap();
                lowest = lowest.min(rmse(&opt.read_params().unwrap()));
            }
            let last = rmse(&opt.read_params().unwrap());
            eprintln!(
                "{method:?} seed {seed}: observed-texel RMSE {initial:.4} -> {last:.4}, lowest {lowest:.4}"
            );
            assert!(
                last <= 1.05 * lowest,
                "{method:?} seed {seed}: ends at {last}, more than 5% above its lowest {lowest}"
            );
            assert!(
                last <= 0.7 * initial,
                "{method:?} seed {seed}: {last} is above 0.7 x the initial {initial}"
            );
        }
    }
}

#[test]
fn a_restored_state_continues_like_the_original() {
    let Some(gpu) = gpu() else { return };
    let make = |target_smoothing| {
        optimizer(
            &gpu,
            Slot::BaseColor,
            Filter::Bilinear,
            Method::RESTIR,
            RestirOptions {
                target_smoothing,
                ..Default::default()
            },
            &[0.5; 12],
            &[0.9, 0.2, 0.2, 0.2, 0.9, 0.2, 0.2, 0.2, 0.9, 0.7, 0.7, 0.1],
        )
    };
    // With the default target adjoint: the round trip through the GPU buffers (reservoirs,
    // target adjoints and the rest) is exact.
    let beta = Some(psrestir::optim::estimator::restir::TARGET_SMOOTHING_INDEPENDENT);
    let mut a = make(beta);
    for _ in 0..6 {
        a.step().unwrap();
    }
    let state = a.state().unwrap();
    let names = psrestir::optim::estimator::restir::state_names::HISTORY;
    assert!(state.estimator.counter(names).unwrap() > 0);
    let mut b = make(beta);
    b.restore(&state).unwrap();
    assert_eq!(b.state().unwrap(), state);
    // The next gradient is compared with the target adjoint equal to the adjoint (β = 0): for
    // a fresh reservoir whose target is then |value|, the estimate does not depend on which
    // candidate it selects, so the order in which invocations take the locks (not
    // deterministic) hardly moves it. With another target adjoint it depends on the
    // selection, and two runs from one state differ by the selection's variance (measured:
    // 0 to 60% of the norm).
    let make = || make(Some(0.0));
    let mut a = make();
    for _ in 0..6 {
        a.step().unwrap();
    }
    let state = a.state().unwrap();
    let restored = || {
        let mut b = make();
        b.restore(&state).unwrap();
        assert_eq!(b.state().unwrap(), state);
        b
    };
    // A state without reservoirs: the next gradient starts from empty ones.
    let mut c = make();
    c.restore(&psrestir::optim::OptimizerState {
        estimator: psrestir::optim::EstimatorState::new(Method::RESTIR),
        ..state.clone()
    })
    .unwrap();
    let it = state.iteration;
    let (ga, _) = a.estimate_gradient(it).unwrap();
    let (gc, _) = c.estimate_gradient(it).unwrap();
    let dist = |x: &[f32], y: &[f32]| -> f64 {
        x.iter()
            .zip(y)
            .map(|(p, q)| (*p as f64 - *q as f64).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let norm = dist(&ga, &[0.0; 12]);
    // Same seeds, same reservoirs: a restored optimizer draws the same gradient up to the
    // order in which invocations take the reservoir locks and add floats. Two runs of one
    // iteration from one state usually differ by 0-8% of the norm here, but in about one run
    // of four the lock order changes a selection and they differ by 37% (measured over 8
    // runs each, since the area light reaches the whole plane; before, 0-3%). So the
    // closest of six restorations is compared: all six land that far apart with
    // probability about 2e-4 if restoring is exact, and always if it is not.
    let ab = (0..6)
        .map(|_| dist(&ga, &restored().estimate_gradient(it).unwrap().0))
        .fold(f64::INFINITY, f64::min);
    let ac = dist(&ga, &gc);
    eprintln!("|g| {norm:.3e}, closest restored {ab:.3e}, without reservoirs {ac:.3e}");
    // Dropping the reservoirs changes the gradient by more than its norm.
    assert!(
        ab <= 0.15 * norm,
        "restored gradient differs by {ab:.3e} of {norm:.3e}"
    );
    assert!(
        ac > 0.3 * norm,
        "the reservoirs made no difference ({ac:.3e} of {norm:.3e})"
    );
}

#[test]
fn the_target_adjoint_is_a_moving_average_of_the_adjoints() {
    let Some(gpu) = gpu() else { return };
    let t = [0.9, 0.2, 0.2, 0.2, 0.9, 0.2, 0.2, 0.2, 0.9, 0.7, 0.7, 0.1];
    let beta = 0.9f32;
    let n = (W * W) as usize;
    // Two adjoints (RGBA per pixel) with every channel of every pixel different.
    let a1: Vec<f32> = (0..4 * n)
        .map(|i| ((i * 37 % 101) as f32 - 50.0) * 1e-3)
        .collect();
    let a2: Vec<f32> = (0..4 * n)
        .map(|i| ((i * 53 % 97) as f32 - 48.0) * 2e-3)
        .collect();
    for temporal in [true, false] {
        let opts = RestirOptions {
            target_smoothing: Some(beta),
            temporal,
            ..Default::default()
        };
        let mut o = optimizer(
            &gpu,
            Slot::BaseColor,
            Filter::Bilinear,
            Method::RESTIR,
            opts,
            &[0.5; 12],
            &t,
        );
        o.estimate_gradient_with_adjoint(0, &a1).unwrap();
        o.estimate_gradient_with_adjoint(1, &a2).unwrap();
        let state = o.state().unwrap();
        let names = psrestir::optim::estimator::restir::state_names::TARGETS;
        let targets: Vec<f32> =
            bytemuck::cast_slice(state.estimator.array(names).unwrap()).to_vec();
        // Both parities, the even iteration's first.
        assert_eq!(targets.len(), 2 * 4 * n);
        let (even, odd) = targets.split_at(4 * n);
        for p in 0..n {
            for c in 0..3 {
                let i = 4 * p + c;
                // The first iteration has no history: its target adjoint is its adjoint.
                assert_eq!(even[i], a1[i], "pixel {p} channel {c}");
                // Then beta of the last plus 1 - beta of the new one (without temporal
                // reuse, nothing is kept and the target is the adjoint itself).
                let (want, scale) = if temporal {
                    (
                        beta * a1[i] + (1.0 - beta) * a2[i],
                        beta * a1[i].abs() + (1.0 - beta) * a2[i].abs(),
                    )
                } else {
                    (a2[i], a2[i].abs())
                };
                // Rounding relative to the terms, not to their sum, which can cancel: a GPU
                // that fuses the mix into one multiply-add (NVIDIA's) differs from this by
                // about one ulp of the terms (1.2e-9 of a sum of -1.9e-9 from terms of 3e-3).
                assert!(
                    (odd[i] - want).abs() <= 1e-6 * scale.max(1e-3),
                    "temporal {temporal}, pixel {p} channel {c}: {} vs {want}",
                    odd[i]
                );
            }
        }
    }
}

/// ReSTIR's own variance (`own_variance`) rests on moving moments of its *fresh* estimate:
/// what this iteration's candidates alone estimate, without what the reservoirs kept. With the
/// target adjoint equal to the adjoint (β = 0) a fresh reservoir of a scalar texture estimates
/// the sum of its candidates' values over their densities, the baseline's estimate from the
/// same samples (`restir_without_reuse_equals_the_baseline`), whichever it selects. So, with
/// reuse on and the textures held, the moving mean and second moment ReSTIR keeps per value
/// (decay 0.9, from 0) are those of the baseline's estimates at the same seeds, within the
/// rounding of the stored radiance summed over the moving average.
#[test]
fn restirs_fresh_moments_are_those_of_independent_estimates() {
    let Some(gpu) = gpu() else { return };
    let (scene, set, values, truth) = shadow_scalar_set();
    let opts = RestirOptions {
        target_smoothing: Some(0.0),
        own_variance: true,
        ..Default::default()
    };
    let settings = Settings {
        gradient_spp: 2,
        estimator_options: EstimatorOptions::default().with(&opts),
        ..Settings::new(W, W, vec![0])
    };
    let make = |method, target: &[Image]| {
        let s = Settings {
            method,
            ..settings.clone()
        };
        Optimizer::new(&gpu, &scene, set.clone(), s, target).unwrap()
    };
    let t = make(Method::BASELINE, &[Image::new(W, W)]);
    t.write_params(&truth).unwrap();
    let target = [t.render(0, 1024, 99).unwrap()];
    let (mut base, mut re) = (
        make(Method::BASELINE, &target),
        make(Method::RESTIR, &target),
    );
    base.write_params(&values).unwrap();
    re.write_params(&values).unwrap();
    let decay = 0.9f64;
    let n = values.len();
    // The baseline's moving moments, and the bound of each: the moving average of each
    // estimate's rounding bound (as in restir_without_reuse_equals_the_baseline).
    let (mut m1, mut m2) = (vec![0f64; n], vec![0f64; n]);
    let (mut b1, mut b2) = (vec![0f64; n], vec![0f64; n]);
    for it in 0..40 {
        let (g, _) = base.estimate_gradient(it).unwrap();
        re.estimate_gradient(it).unwrap();
        let scale = g.iter().fold(0f64, |m, x| m.max(x.abs() as f64));
        for i in 0..n {
            let g = g[i] as f64;
            let tol = RADIANCE_ERROR as f64 * (g.abs() + 0.5 * scale);
            m1[i] = decay * m1[i] + (1.0 - decay) * g;
            m2[i] = decay * m2[i] + (1.0 - decay) * g * g;
            b1[i] = decay * b1[i] + (1.0 - decay) * tol;
            b2[i] = decay * b2[i] + (1.0 - decay) * tol * (2.0 * g.abs() + tol);
        }
    }
    let state = re.state().unwrap();
    let names = psrestir::optim::estimator::restir::state_names::FRESH_MOMENTS;
    let moments: Vec<f64> = state
        .estimator
        .array(names)
        .expect("no fresh moments")
        .iter()
        .map(|&w| f32::from_bits(w) as f64)
        .collect();
    assert_eq!(moments.len(), 2 * n);
    assert!(m2.iter().all(|&s| s > 0.0), "every value has samples");
    for i in 0..n {
        let (r1, r2) = (moments[2 * i], moments[2 * i + 1]);
        // 1e-6 of the largest second moment for the f32 sums.
        let slack = 1e-6 * m2.iter().fold(0f64, |a, &b| a.max(b));
        assert!(
            (r1 - m1[i]).abs() <= b1[i] + slack.sqrt() * 1e-3
                && (r2 - m2[i]).abs() <= b2[i] + slack,
            "value {i}: ReSTIR's fresh moments ({r1:.4e}, {r2:.4e}), the baseline's \
             ({:.4e}, {:.4e}), bounds ({:.1e}, {:.1e})",
            m1[i],
            m2[i],
            b1[i],
            b2[i]
        );
    }
    assert_eq!(re.faults().unwrap(), Default::default());
}

/// With `own_variance` off (the default) ReSTIR allocates no moments (12 bytes per value:
/// 150 MB for a 2048² base color), saves none, and a run resumed from such a state with the
/// option on starts its moments afresh, as a new run would; the other way round the saved
/// moments are dropped.
#[test]
fn restir_without_its_own_variance_keeps_no_moments() {
    let Some(gpu) = gpu() else { return };
    let (scene, set, values, _) = shadow_scalar_set();
    let with = |own_variance| Settings {
        method: Method::RESTIR,
        gradient_spp: 2,
        estimator_options: EstimatorOptions::default().with(&RestirOptions {
            own_variance,
            ..Default::default()
        }),
        ..Settings::new(W, W, vec![0])
    };
    let moments_planned = |own| {
        let plan = psrestir::optim::memory_plan(&set, &with(own), 1, 4, 1);
        plan.buffers.iter().any(|b| b.0 == "restir fresh moments")
    };
    assert!(moments_planned(true) && !moments_planned(false));
    let names = psrestir::optim::estimator::restir::state_names::FRESH_MOMENTS;
    let run = |own| {
        let o = Optimizer::new(&gpu, &scene, set.clone(), with(own), &[Image::new(W, W)]).unwrap();
        o.write_params(&values).unwrap();
        o
    };
    let (mut off, mut on) = (run(false), run(true));
    for _ in 0..3 {
        off.step().unwrap();
        on.step().unwrap();
    }
    let saved_off = off.state().unwrap();
    assert_eq!(saved_off.estimator.array(names), Some(&[][..]));
    let saved_on = on.state().unwrap();
    let moments = |o: &Optimizer| o.state().unwrap().estimator.array(names).unwrap().to_vec();
    assert_eq!(moments(&on).len(), 2 * values.len());
    // Off into on: the moments start from zero and fill again.
    on.restore(&saved_off).unwrap();
    assert!(moments(&on).iter().all(|&w| w == 0));
    on.step().unwrap();
    assert!(moments(&on).iter().any(|&w| w != 0));
    // On into off: the saved moments are dropped.
    off.restore(&saved_on).unwrap();
    off.step().unwrap();
    assert!(moments(&off).is_empty());
    assert_eq!(on.faults().unwrap(), Default::default());
}
