//! Adam on the GPU equals the Rust reference, and an optimization from a constant texture
//! recovers a known texture.
mod common;

use common::*;
use glam::Vec3;
use psrestir::image_io::Image;
use psrestir::optim::{adam, run::rmse, Optimizer, Settings};
use psrestir::render::params::ParamSet;
use psrestir::scene::{Material, PunctualKind, PunctualLight, Scene};
use psrestir::task::{Filter, Init, Loss, Slot, TextureSpec};

/// A unit plane seen from above, lit by a point light and a dim sky.
fn plane() -> Scene {
    let mut s = Scene::default();
    s.materials.push(Material {
        name: "plane".into(),
        ..material([0.5; 3], 0.0, 0.6)
    });
    s.triangles.extend(quad(
        Vec3::new(-1.0, 0.0, 1.0),
        Vec3::new(2.0, 0.0, 0.0),
        Vec3::new(0.0, 0.0, -2.0),
        0,
    ));
    s.lights.push(PunctualLight {
        name: "p".into(),
        kind: PunctualKind::Point,
        position: Vec3::new(0.3, 2.0, 0.4),
        direction: Vec3::NEG_Y,
        intensity: Vec3::splat(5.0),
        range: 0.0,
    });
    s.env = Some(psrestir::scene::EnvMap::constant([0.3, 0.3, 0.35]));
    s.cameras.push(look_at(
        Vec3::new(0.0, 2.6, 0.01),
        Vec3::ZERO,
        Vec3::NEG_Z,
        0.8,
    ));
    s
}

fn setup(
    gpu: &psrestir::gpu::Gpu,
    slot: Slot,
    lr: f32,
    res: u32,
    truth: &[f32],
) -> (Optimizer, Vec<f32>) {
    let scene = plane();
    let spec = TextureSpec {
        material: "plane".into(),
        slot,
        resolution: [res, res],
        init: Init::Scalar(0.5),
        learning_rate: lr,
    };
    let set = ParamSet::from_specs(
        &scene,
        &[spec],
        Filter::Bilinear,
        std::path::Path::new("test"),
    )
    .unwrap();
    let settings = Settings {
        width: 48,
        height: 48,
        cameras: vec![0],
        primal_spp: 4,
        gradient_spp: 4,
        loss: Loss::L2,
        seed: 3,
        method: psrestir::optim::Method::Baseline,
        restir: Default::default(),
        schedule: Default::default(),
        adam_mask: false,
    };
    let init = set.values.clone();
    let opt = Optimizer::new(
        gpu,
        &scene,
        set.clone(),
        settings.clone(),
        &[Image::new(48, 48)],
    )
    .unwrap();
    opt.write_params(truth).unwrap();
    let target = opt.render(0, 1024, 77).unwrap();
    let opt = Optimizer::new(gpu, &scene, set, settings, &[target]).unwrap();
    (opt, init)
}

#[test]
fn adam_steps_on_the_gpu_equal_the_rust_reference() {
    let Some(gpu) = gpu() else { return };
    let truth: Vec<f32> = (0..4 * 4 * 3)
        .map(|i| (i % 7) as f32 / 7.0 + 0.05)
        .collect();
    let lr = 0.05;
    let (mut opt, init) = setup(&gpu, Slot::BaseColor, lr, 4, &truth);
    let n = init.len();
    let (mut p, mut m, mut v) = (init.clone(), vec![0.0; n], vec![0.0; n]);
    for t in 1..=3u32 {
        opt.step().unwrap();
        // The gradient this step computed (it stays in the gradient buffer), fed to the
        // reference.
        let g = opt.read_gradient().unwrap();
        assert!(g.iter().any(|x| *x != 0.0));
        adam::step(&mut p, &mut m, &mut v, &g, lr, t, 0.0, 1.0);
        let gpu_p = opt.read_params().unwrap();
        let [gm, gv] = opt.read_moments().unwrap();
        for i in 0..n {
            // Same inputs, same formula: only the last bits of sqrt and division may differ.
            assert!(
                (gm[i] - m[i]).abs() <= 1e-6 * m[i].abs() + 1e-20,
                "step {t}, m[{i}]: {} vs {}",
                gm[i],
                m[i]
            );
            assert!(
                (gv[i] - v[i]).abs() <= 1e-6 * v[i].abs() + 1e-30,
                "step {t}, v[{i}]: {} vs {}",
                gv[i],
                v[i]
            );
            assert!(
                (gpu_p[i] - p[i]).abs() <= 1e-6,
                "step {t}, param {i}: {} vs {}",
                gpu_p[i],
                p[i]
            );
        }
        // Continue from the GPU's state so that rounding does not accumulate.
        p = gpu_p;
        m = gm;
        v = gv;
    }
}

#[test]
fn optimization_recovers_a_known_texture() {
    let Some(gpu) = gpu() else { return };
    // A 4x4 texture of distinct colors.
    let truth: Vec<f32> = (0..16)
        .flat_map(|k| {
            let (x, y) = ((k % 4) as f32, (k / 4) as f32);
            [
                0.15 + 0.2 * x,
                0.8 - 0.18 * y,
                0.2 + 0.1 * ((k * 5) % 7) as f32,
            ]
        })
        .collect();
    let (mut opt, init) = setup(&gpu, Slot::BaseColor, 0.03, 4, &truth);
    let before = rmse(&init, &truth);
    let mut losses = Vec::new();
    for _ in 0..120 {
        losses.push(opt.step().unwrap().loss);
    }
    let after = rmse(&opt.read_params().unwrap(), &truth);
    eprintln!(
        "texture RMSE {before:.4} -> {after:.4}; loss {:.3e} -> {:.3e}",
        losses[0],
        losses[losses.len() - 1]
    );
    assert!(
        after < before / 3.0,
        "texture RMSE fell only from {before} to {after}"
    );
    assert_eq!(opt.faults().unwrap(), Default::default());
}
