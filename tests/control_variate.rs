//! The control-variate primal (src/optim/primal_cv.wgsl): with textures that change every
//! iteration, its image is an unbiased estimate of the current render (the mean over many
//! independent runs matches a converged render), it has less variance than an independent
//! render of the same spp, and checkpoints restore its running statistics exactly.
mod common;

use common::*;
use psrestir::image_io::Image;
use psrestir::optim::{Method, Optimizer, PrimalMode, Settings};
use psrestir::render::params::ParamSet;
use psrestir::task::{Filter, Init, Slot, TextureSpec};

const W: u32 = 16;

/// Base color and roughness (2x2 each) on the shadow scene's plane, learning rate 0, with
/// the control-variate primal at 2 spp.
fn optimizer(gpu: &psrestir::gpu::Gpu, primal: PrimalMode) -> Optimizer {
    let scene = shadow_scene();
    let specs: Vec<TextureSpec> = [Slot::BaseColor, Slot::Roughness]
        .iter()
        .map(|&slot| TextureSpec {
            material: "plane".into(),
            slot,
            resolution: [2, 2],
            init: Init::Vector(vec![0.5; slot.channels() as usize]),
            learning_rate: Some(0.0),
        })
        .collect();
    let set =
        ParamSet::from_specs(&scene, &specs, Filter::Bilinear, std::path::Path::new("t")).unwrap();
    let settings = Settings {
        primal_spp: 2,
        primal,
        method: Method::BASELINE,
        seed: 21,
        ..Settings::new(W, W, vec![0])
    };
    Optimizer::new(gpu, &scene, set, settings, &[Image::new(W, W)]).unwrap()
}

/// The textures of iteration t: a known path through texture space (every texel moves every
/// iteration).
fn params_at(t: u32) -> Vec<f32> {
    let s = (t as f32 * 0.7).sin();
    let c = (t as f32 * 0.45).cos();
    let mut v = Vec::new();
    for k in 0..4 {
        let k = k as f32;
        v.extend([
            0.5 + 0.3 * s * (0.5 + 0.1 * k),
            0.4 + 0.25 * c,
            0.45 - 0.2 * s * c,
        ]);
    }
    for k in 0..4 {
        v.push(0.5 + 0.3 * (t as f32 * 0.3 + k as f32).sin());
    }
    v
}

#[test]
fn the_control_variate_image_is_unbiased_under_changing_textures() {
    let Some(gpu) = gpu() else { return };
    let mut opt = optimizer(&gpu, PrimalMode::ControlVariate);
    let fresh = opt.state().unwrap();
    let (runs, steps) = (96u32, 24u32);
    let n = (W * W) as usize;
    // Statistics of 4x4-pixel block means (48 numbers per image): a block gathers 32 samples
    // per run, so even dim blocks are not all-zero rare events, which would make a per-pixel
    // standard error from the runs meaningless.
    let blocks = (W / 4) * (W / 4);
    let block_means = |img: &Image| -> Vec<f64> {
        let mut b = vec![0f64; 3 * blocks as usize];
        for y in 0..W {
            for x in 0..W {
                let k = ((y / 4) * (W / 4) + x / 4) as usize;
                for c in 0..3 {
                    b[3 * k + c] += img.rgb[(y * W + x) as usize][c] as f64 / 16.0;
                }
            }
        }
        b
    };
    let m = 3 * blocks as usize;
    let (mut sum, mut sum2) = (vec![0f64; m], vec![0f64; m]);
    let mut pixel_var = 0.0;
    let (mut psum, mut psum2) = (vec![0f64; 3 * n], vec![0f64; 3 * n]);
    for r in 0..runs {
        // Each run starts afresh; its iterations (the random numbers' stream) are its own.
        let mut st = fresh.clone();
        st.iteration = 1000 * (r + 1);
        opt.restore(&st).unwrap();
        for t in 0..steps {
            opt.write_params(&params_at(t)).unwrap();
            opt.step().unwrap();
        }
        let img = opt.control_variate_image(0).unwrap().unwrap();
        for (i, v) in block_means(&img).iter().enumerate() {
            sum[i] += v;
            sum2[i] += v * v;
        }
        for (p, px) in img.rgb.iter().enumerate() {
            for c in 0..3 {
                psum[3 * p + c] += px[c] as f64;
                psum2[3 * p + c] += (px[c] as f64).powi(2);
            }
        }
    }
    for i in 0..3 * n {
        let mean = psum[i] / runs as f64;
        pixel_var += (psum2[i] / runs as f64 - mean * mean).max(0.0) / (3 * n) as f64;
    }
    let cv_var = pixel_var * runs as f64 / (runs as f64 - 1.0);
    // The last image is at the textures of the last iteration.
    opt.write_params(&params_at(steps - 1)).unwrap();
    let truth = block_means(&opt.render(0, 8192, 5).unwrap());
    let independent_var = {
        // The per-pixel variance of an independent 2-spp render at the same textures.
        let imgs: Vec<Image> = (0..32)
            .map(|s| opt.render(0, 2, 100 + s).unwrap())
            .collect();
        let mut v = 0.0;
        for p in 0..n {
            for c in 0..3 {
                let m = imgs.iter().map(|i| i.rgb[p][c] as f64).sum::<f64>() / 32.0;
                v += imgs
                    .iter()
                    .map(|i| (i.rgb[p][c] as f64 - m).powi(2))
                    .sum::<f64>()
                    / 31.0;
            }
        }
        v / (3 * n) as f64
    };
    let (mut z2, mut worst, mut dof) = (0.0, 0f64, 0usize);
    for i in 0..m {
        let mean = sum[i] / runs as f64;
        let var =
            (sum2[i] / runs as f64 - mean * mean).max(0.0) * runs as f64 / (runs as f64 - 1.0);
        if var == 0.0 && truth[i] == 0.0 {
            continue; // a block that nothing lights (background)
        }
        // The reference's own noise (8192 spp) is a few percent of the runs' standard error.
        let z = (mean - truth[i]) / (var / runs as f64).sqrt().max(1e-9);
        z2 += z * z;
        worst = worst.max(z.abs());
        dof += 1;
    }
    let dof = dof as f64;
    eprintln!(
        "chi2/dof {:.3} over {dof} block means (worst |z| {worst:.2}); pixel variance control \
         variate {cv_var:.3e}, independent {independent_var:.3e}",
        z2 / dof
    );
    // An unbiased mean gives chi2/dof near 1 (standard deviation sqrt(2/dof) = 0.2 for 48
    // blocks); a bias of half a standard error in every block would give 1.25.
    assert!(dof >= 24.0, "too few lit blocks: {dof}");
    assert!(
        z2 / dof < 1.8,
        "the control-variate image is biased: chi2/dof {}",
        z2 / dof
    );
    assert!(worst < 4.5, "a block is off by {worst} standard errors");
    // The variate is active: the image carries earlier samples and is less noisy.
    assert!(
        cv_var < 0.7 * independent_var,
        "no variance reduction: {cv_var:.3e} vs {independent_var:.3e}"
    );
}

#[test]
fn a_checkpoint_restores_the_control_variate_exactly() {
    let Some(gpu) = gpu() else { return };
    let mut a = optimizer(&gpu, PrimalMode::ControlVariate);
    for t in 0..6 {
        a.write_params(&params_at(t)).unwrap();
        a.step().unwrap();
    }
    let state = a.state().unwrap();
    let cv = state
        .control_variate
        .as_ref()
        .expect("the state holds the control variate");
    assert_eq!(cv.iterations, 6);
    assert!(cv.state.iter().any(|&v| v != 0.0));
    // Through a file, as a resumed run does.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c.bin");
    psrestir::optim::checkpoint::Checkpoint {
        header: psrestir::optim::checkpoint::Header {
            elapsed_s: 0.0,
            layout: String::new(),
            metrics: Vec::new(),
        },
        state: state.clone(),
        kept: None,
    }
    .save(&path)
    .unwrap();
    let loaded = psrestir::optim::checkpoint::Checkpoint::load(&path)
        .unwrap()
        .state;
    assert_eq!(loaded, state);
    let mut b = optimizer(&gpu, PrimalMode::ControlVariate);
    b.restore(&loaded).unwrap();
    assert_eq!(b.state().unwrap(), state);
    // The next iteration is the same in both: the primal render is deterministic per seed and
    // iteration, and the statistics and last image were restored bit for bit.
    for o in [&mut a, &mut b] {
        o.write_params(&params_at(6)).unwrap();
        o.step().unwrap();
    }
    assert_eq!(
        a.control_variate_image(0).unwrap(),
        b.control_variate_image(0).unwrap()
    );
}
