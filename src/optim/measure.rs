//! Gradient error of the estimators, as DESIGN.md section 6 measures it: relMSE against a
//! high-sample reference at the same parameter state, at equal iterations and equal time.
use super::run::prepare;
use super::{Method, Optimizer, RestirOptions, Settings};
use crate::gpu::Gpu;
use crate::task::Task;
use crate::Result;
use std::time::Instant;

/// relMSE over entries with a non-zero reference: mean of (g - r)^2 / (r^2 + 1e-2).
pub fn rel_mse(g: &[f32], reference: &[f64]) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for (a, r) in g.iter().zip(reference) {
        if *r != 0.0 {
            s += (*a as f64 - r).powi(2) / (r * r + 1e-2);
            n += 1;
        }
    }
    s / n.max(1) as f64
}

/// What [`gradient_error`] measured.
#[derive(Clone, Debug)]
pub struct GradientError {
    /// Milliseconds per ReSTIR iteration (GPU work finished).
    pub ms_restir: f64,
    /// Milliseconds per baseline iteration at the task's gradient spp.
    pub ms_baseline: f64,
    /// relMSE of ReSTIR's gradient (mean over repeats).
    pub relmse_restir: f64,
    /// relMSE of the baseline at the same spp (equal iterations).
    pub relmse_baseline: f64,
    /// Gradient spp the baseline gets in the time of one ReSTIR iteration.
    pub baseline_spp_equal_time: u32,
    /// relMSE of the baseline at that spp (equal time).
    pub relmse_baseline_equal_time: f64,
}

fn settings(
    task: &Task,
    cameras: &[usize],
    method: Method,
    restir: RestirOptions,
    spp: u32,
    seed: u32,
) -> Settings {
    Settings {
        gradient_spp: spp,
        seed,
        ..super::run::task_settings(task, cameras, method, restir)
    }
}

/// Run ReSTIR `warmup` iterations from the task's initial textures; at that state, compare
/// ReSTIR's next gradient and baseline gradients with a reference of `reference_estimates`
/// baseline estimates, averaged over `repeats` seeds.
pub fn gradient_error(
    gpu: &Gpu,
    task: &Task,
    restir: RestirOptions,
    warmup: u32,
    reference_estimates: u32,
    repeats: u32,
) -> Result<GradientError> {
    let dir = std::env::temp_dir().join(format!("psrestir-measure-{}", std::process::id()));
    let prep = prepare(gpu, task, &dir, false)?;
    let spp = task.optimizer.gradient_spp;
    let mut out = GradientError {
        ms_restir: 0.0,
        ms_baseline: 0.0,
        relmse_restir: 0.0,
        relmse_baseline: 0.0,
        baseline_spp_equal_time: spp,
        relmse_baseline_equal_time: 0.0,
    };
    for rep in 0..repeats {
        let seed = task.seed.wrapping_add(1000 * rep);
        let mut re = Optimizer::new(
            gpu,
            &prep.scene,
            prep.set.clone(),
            settings(task, &prep.cameras, Method::Restir, restir, spp, seed),
            &prep.targets,
        )?;
        let t0 = Instant::now();
        for _ in 0..warmup {
            re.step()?;
        }
        let ms_restir = 1000.0 * t0.elapsed().as_secs_f64() / warmup.max(1) as f64;
        let state = re.read_params()?;
        let (g_re, _) = re.estimate_gradient(re.iteration)?;
        let mut base = Optimizer::new(
            gpu,
            &prep.scene,
            prep.set.clone(),
            settings(
                task,
                &prep.cameras,
                Method::Baseline,
                restir,
                spp,
                seed ^ 0x5eed,
            ),
            &prep.targets,
        )?;
        base.write_params(&state)?;
        let t0 = Instant::now();
        let (g_base, _) = base.estimate_gradient(0)?;
        for it in 1..4 {
            base.estimate_gradient(it)?;
        }
        let ms_base = 1000.0 * t0.elapsed().as_secs_f64() / 4.0;
        // Reference: many baseline estimates with independent seeds.
        let mut reference = vec![0f64; state.len()];
        for it in 0..reference_estimates {
            let (g, _) = base.estimate_gradient(100_000 + it)?;
            for (r, v) in reference.iter_mut().zip(&g) {
                *r += *v as f64 / reference_estimates as f64;
            }
        }
        let eq_spp = ((spp as f64 * ms_restir / ms_base).floor() as u32).max(1);
        let mut eq = Optimizer::new(
            gpu,
            &prep.scene,
            prep.set.clone(),
            settings(
                task,
                &prep.cameras,
                Method::Baseline,
                restir,
                eq_spp,
                seed ^ 0xe9,
            ),
            &prep.targets,
        )?;
        eq.write_params(&state)?;
        let (g_eq, _) = eq.estimate_gradient(0)?;
        let n = repeats as f64;
        out.ms_restir += ms_restir / n;
        out.ms_baseline += ms_base / n;
        out.relmse_restir += rel_mse(&g_re, &reference) / n;
        out.relmse_baseline += rel_mse(&g_base, &reference) / n;
        out.relmse_baseline_equal_time += rel_mse(&g_eq, &reference) / n;
        out.baseline_spp_equal_time = eq_spp;
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok(out)
}
