//! The baseline gradient is unbiased: its mean over many independent estimates equals the
//! central finite difference of the loss, per texel, for base color, roughness and metallic,
//! with nearest and bilinear filters, on a small scene with hard and soft shadows; also with
//! the control-variate primal (whose adjoint carries earlier iterations' samples), and on a
//! normal-mapped plane; and with indirect light (depth 3), where the texture is seen again at
//! the later vertices of paths (path replay), for every slot and filter, with the baseline
//! and the recursive estimator.
mod common;

use common::*;
use psrestir::image_io::Image;
use psrestir::optim::{loss, Optimizer, PrimalMode, Settings};
use psrestir::render::params::ParamSet;
use psrestir::task::{Filter, Init, Loss, Slot, TextureSpec};

const W: u32 = 16;

fn spec(slot: Slot, init: Init) -> TextureSpec {
    TextureSpec {
        material: "plane".into(),
        slot,
        resolution: [2, 2],
        init,
        learning_rate: Some(0.0),
    }
}

fn check_gradient(slot: Slot, filter: Filter, values: &[f32], target_values: &[f32]) {
    check_gradient_with(slot, filter, values, target_values, PrimalMode::Independent)
}

fn check_gradient_with(
    slot: Slot,
    filter: Filter,
    values: &[f32],
    target_values: &[f32],
    primal: PrimalMode,
) {
    check_gradient_on(shadow_scene(), slot, filter, values, target_values, primal)
}

fn check_gradient_on(
    scene: psrestir::scene::Scene,
    slot: Slot,
    filter: Filter,
    values: &[f32],
    target_values: &[f32],
    primal: PrimalMode,
) {
    let Some(gpu) = gpu() else { return };
    let init = Init::Vector(vec![0.5; slot.channels() as usize]);
    let set = ParamSet::from_specs(
        &scene,
        &[spec(slot, init)],
        filter,
        std::path::Path::new("test"),
    )
    .unwrap();
    let settings = Settings {
        width: W,
        height: W,
        cameras: vec![0],
        primal_spp: 16,
        primal,
        cv_max_weight: psrestir::optim::primal::DEFAULT_MAX_WEIGHT,
        path_cache: None,
        gradient_spp: 16,
        loss: Loss::L2,
        seed: 7,
        method: psrestir::optim::Method::BASELINE,
        estimator_options: Default::default(),
        schedule: Default::default(),
        sparse_steps: false,
        priors: Default::default(),
        exposure_learning_rate: None,
        moment_filter: Default::default(),
        step: Default::default(),
        steps: Default::default(),
    };
    // Target: the scene with other texel values, rendered with many samples.
    let blank = Image::new(W, W);
    let opt = Optimizer::new(&gpu, &scene, set.clone(), settings.clone(), &[blank]).unwrap();
    opt.write_params(target_values).unwrap();
    let target = opt.render(0, 4096, 99).unwrap();
    let mut opt =
        Optimizer::new(&gpu, &scene, set, settings, std::slice::from_ref(&target)).unwrap();
    opt.write_params(values).unwrap();

    // Mean and spread of K independent baseline estimates.
    let k = 48;
    let n = values.len();
    let mut sum = vec![0f64; n];
    let mut sum2 = vec![0f64; n];
    for it in 0..k {
        let (g, _) = opt.estimate_gradient(1000 + it).unwrap();
        for i in 0..n {
            sum[i] += g[i] as f64;
            sum2[i] += (g[i] as f64).powi(2);
        }
    }
    let mean: Vec<f64> = sum.iter().map(|s| s / k as f64).collect();
    let var_mean: Vec<f64> = (0..n)
        .map(|i| {
            ((sum2[i] / k as f64 - mean[i] * mean[i]).max(0.0)) * k as f64
                / (k as f64 - 1.0)
                / k as f64
        })
        .collect();

    // Central differences of an unbiased loss estimate: the product of two independent
    // renders' residuals has expectation (I - G)^2 exactly. Common random numbers on both
    // sides; two independent repetitions estimate the difference's own noise.
    let h = 0.02f32;
    let spp = 512;
    let lossf = |vals: &[f32], seed: u32| -> f64 {
        opt.write_params(vals).unwrap();
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
    let mut fd = vec![0f64; n];
    let mut fd_var = 0.0;
    for i in 0..n {
        let mut reps = [0f64; 2];
        for (r, rep) in reps.iter_mut().enumerate() {
            let seed = 5000 + 10 * r as u32;
            let mut plus = values.to_vec();
            let mut minus = values.to_vec();
            plus[i] += h;
            minus[i] -= h;
            *rep = (lossf(&plus, seed) - lossf(&minus, seed)) / (2.0 * h as f64);
        }
        fd[i] = 0.5 * (reps[0] + reps[1]);
        eprintln!("fd reps {i}: {:.5e} {:.5e}", reps[0], reps[1]);
        fd_var += 0.25 * (reps[0] - reps[1]).powi(2) / n as f64;
    }
    // Sanity of the CPU loss used by the renders: the same as the optimizer's.
    let l_cpu = loss::loss(Loss::L2, &opt.render(0, 64, 1).unwrap().rgb, &target.rgb);
    assert!(l_cpu.is_finite());

    let scale = fd.iter().fold(0f64, |m, v| m.max(v.abs()));
    assert!(
        scale > 0.0,
        "all finite differences are zero: the test sees nothing"
    );
    for i in 0..n {
        // 4 standard errors of the difference (estimator mean, and FD noise pooled over the
        // texture), plus 5% of the derivative for the O(h^2) truncation of the difference
        // quotient, plus 0.1% of the largest derivative for float rounding.
        let tol = 4.0 * (var_mean[i] + fd_var).sqrt() + 0.05 * fd[i].abs() + 1e-3 * scale;
        eprintln!(
            "{slot:?} {filter:?} param {i}: gradient {:.5e} +- {:.1e}, finite difference {:.5e}",
            mean[i],
            var_mean[i].sqrt(),
            fd[i]
        );
        assert!(
            (mean[i] - fd[i]).abs() <= tol,
            "{slot:?}/{filter:?} parameter {i}: gradient {} vs finite difference {} (tolerance {tol})",
            mean[i],
            fd[i]
        );
    }
}

#[test]
fn base_color_gradient_matches_finite_differences_nearest() {
    let v = [0.5, 0.4, 0.3, 0.6, 0.5, 0.2, 0.3, 0.3, 0.3, 0.7, 0.6, 0.5];
    let t = [0.8, 0.2, 0.1, 0.3, 0.6, 0.4, 0.5, 0.5, 0.5, 0.2, 0.3, 0.9];
    check_gradient(Slot::BaseColor, Filter::Nearest, &v, &t);
}

#[test]
fn base_color_gradient_matches_finite_differences_bilinear() {
    let v = [0.5, 0.4, 0.3, 0.6, 0.5, 0.2, 0.3, 0.3, 0.3, 0.7, 0.6, 0.5];
    let t = [0.8, 0.2, 0.1, 0.3, 0.6, 0.4, 0.5, 0.5, 0.5, 0.2, 0.3, 0.9];
    check_gradient(Slot::BaseColor, Filter::Bilinear, &v, &t);
}

#[test]
fn roughness_gradient_matches_finite_differences_nearest() {
    check_gradient(
        Slot::Roughness,
        Filter::Nearest,
        &[0.3, 0.5, 0.7, 0.4],
        &[0.8, 0.2, 0.4, 0.9],
    );
}

#[test]
fn roughness_gradient_matches_finite_differences_bilinear() {
    check_gradient(
        Slot::Roughness,
        Filter::Bilinear,
        &[0.3, 0.5, 0.7, 0.4],
        &[0.8, 0.2, 0.4, 0.9],
    );
}

#[test]
fn metallic_gradient_matches_finite_differences_nearest() {
    check_gradient(
        Slot::Metallic,
        Filter::Nearest,
        &[0.2, 0.5, 0.7, 0.4],
        &[0.9, 0.1, 0.3, 0.6],
    );
}

#[test]
fn metallic_gradient_matches_finite_differences_bilinear() {
    check_gradient(
        Slot::Metallic,
        Filter::Bilinear,
        &[0.2, 0.5, 0.7, 0.4],
        &[0.9, 0.1, 0.3, 0.6],
    );
}

#[test]
fn base_color_gradient_with_the_control_variate_matches_finite_differences() {
    let v = [0.5, 0.4, 0.3, 0.6, 0.5, 0.2, 0.3, 0.3, 0.3, 0.7, 0.6, 0.5];
    let t = [0.8, 0.2, 0.1, 0.3, 0.6, 0.4, 0.5, 0.5, 0.5, 0.2, 0.3, 0.9];
    check_gradient_with(
        Slot::BaseColor,
        Filter::Bilinear,
        &v,
        &t,
        PrimalMode::ControlVariate,
    );
}

#[test]
fn roughness_gradient_with_the_control_variate_matches_finite_differences() {
    check_gradient_with(
        Slot::Roughness,
        Filter::Nearest,
        &[0.3, 0.5, 0.7, 0.4],
        &[0.8, 0.2, 0.4, 0.9],
        PrimalMode::ControlVariate,
    );
}

/// The plane with a normal map of bumps: the gradient passes shade with the same perturbed
/// normal as the renders.
#[test]
fn base_color_gradient_with_a_normal_map_matches_finite_differences() {
    let mut scene = shadow_scene();
    with_normal_map(&mut scene);
    let v = [0.5, 0.4, 0.3, 0.6, 0.5, 0.2, 0.3, 0.3, 0.3, 0.7, 0.6, 0.5];
    let t = [0.8, 0.2, 0.1, 0.3, 0.6, 0.4, 0.5, 0.5, 0.5, 0.2, 0.3, 0.9];
    check_gradient_on(
        scene,
        Slot::BaseColor,
        Filter::Bilinear,
        &v,
        &t,
        PrimalMode::Independent,
    );
}

#[test]
fn roughness_gradient_with_a_normal_map_matches_finite_differences() {
    let mut scene = shadow_scene();
    with_normal_map(&mut scene);
    let v = [0.5, 0.3, 0.7, 0.4];
    let t = [0.3, 0.6, 0.4, 0.8];
    check_gradient_on(
        scene,
        Slot::Roughness,
        Filter::Bilinear,
        &v,
        &t,
        PrimalMode::Independent,
    );
}

/// Without the later vertices' derivatives the base color's gradient here comes out about 30%
/// short on the texel the walls see most (measured: -1.11e-4 against -1.56e-4), which this
/// test fails; roughness and metallic agree within their noise either way on this scene.
#[test]
fn base_color_gradient_at_depth_3_matches_finite_differences() {
    let v = [0.3, 0.5, 0.7, 0.6, 0.4, 0.5, 0.5, 0.6, 0.3, 0.7, 0.5, 0.4];
    let t = [0.5, 0.4, 0.6, 0.4, 0.6, 0.5, 0.7, 0.5, 0.5, 0.5, 0.6, 0.6];
    for filter in [Filter::Nearest, Filter::Bilinear] {
        check_gradient_on(
            corner_scene(3),
            Slot::BaseColor,
            filter,
            &v,
            &t,
            PrimalMode::Independent,
        );
    }
}

#[test]
fn roughness_and_metallic_gradients_at_depth_3_match_finite_differences() {
    for filter in [Filter::Nearest, Filter::Bilinear] {
        check_gradient_on(
            corner_scene(3),
            Slot::Roughness,
            filter,
            &[0.3, 0.6, 0.5, 0.8],
            &[0.5, 0.4, 0.7, 0.6],
            PrimalMode::Independent,
        );
        check_gradient_on(
            corner_scene(3),
            Slot::Metallic,
            filter,
            &[0.2, 0.6, 0.4, 0.8],
            &[0.5, 0.3, 0.7, 0.4],
            PrimalMode::Independent,
        );
    }
}

/// A normal map's values and the target's for the 2x2 tests: tilted normals (Z well above
/// the floor), different per texel.
const NORMAL_VALUES: [f32; 12] = [
    0.6, 0.45, 0.9, 0.4, 0.55, 0.95, 0.5, 0.35, 0.85, 0.65, 0.6, 0.9,
];
const NORMAL_TARGET: [f32; 12] = [
    0.4, 0.55, 0.9, 0.55, 0.4, 0.9, 0.62, 0.5, 0.95, 0.45, 0.45, 0.85,
];

/// An optimized normal map: its texels move the shading frame of every BRDF evaluation (light
/// and BSDF samples, the directions held fixed), which the derivative follows through the
/// normalization and the tangent frame: under the point light alone (light samples only) and
/// under the area lamp alone (light and BSDF samples by MIS), and over a glTF normal map,
/// which it replaces, with the control-variate primal. (The lights apart: under both, the
/// finite difference this test affords, 512 spp and two repetitions, misjudges its own noise
/// at the point light's highlight; one texel's read -1.99e-3 where 4096 spp and four
/// repetitions give -1.83e-3, and the gradient's mean over 200 estimates -1.71e-3 +- 0.05e-3.)
#[test]
fn normal_map_gradient_matches_finite_differences() {
    let mut point_only = shadow_scene();
    point_only.triangles.retain(|t| t.material != 2);
    let mut lamp_only = shadow_scene();
    lamp_only.lights.clear();
    for (scene, filter) in [
        (point_only, Filter::Nearest),
        (lamp_only.clone(), Filter::Bilinear),
    ] {
        check_gradient_on(
            scene,
            Slot::Normal,
            filter,
            &NORMAL_VALUES,
            &NORMAL_TARGET,
            PrimalMode::Independent,
        );
    }
    with_normal_map(&mut lamp_only);
    check_gradient_on(
        lamp_only,
        Slot::Normal,
        Filter::Nearest,
        &NORMAL_VALUES,
        &NORMAL_TARGET,
        PrimalMode::ControlVariate,
    );
}

/// At depth 3 the floor is seen again after a bounce off the walls (path replay), often at
/// grazing angles, where the normal map would turn the surface away from the viewer: the
/// normal is bent back towards the viewer continuously there (a fallback to the geometric
/// normal would jump, and the finite differences see the jump: without the bend one texel's
/// derivative came out -1.1e-4 against +8e-6).
#[test]
fn normal_map_gradient_at_depth_3_matches_finite_differences() {
    for filter in [Filter::Nearest, Filter::Bilinear] {
        check_gradient_on(
            corner_scene(3),
            Slot::Normal,
            filter,
            &NORMAL_VALUES,
            &NORMAL_TARGET,
            PrimalMode::Independent,
        );
    }
}
