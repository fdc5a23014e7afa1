//! Light sampling alone, BSDF sampling alone and their MIS combination estimate the same
//! image of an area-lit scene (an emissive quad over a diffuse floor and a glossy metal panel,
//! under a dim constant sky): their difference is within noise, block by block.
mod common;

use common::*;
use glam::Vec3;
use psrestir::render::{RenderSettings, Renderer, Techniques};
use psrestir::scene::{EnvMap, Material, Scene};

fn scene() -> Scene {
    let mut s = plane_scene(material([0.7, 0.6, 0.5], 0.0, 0.7), 3.0);
    s.materials.push(material([0.9, 0.8, 0.6], 1.0, 0.35));
    s.materials.push(Material {
        emissive: Vec3::new(6.0, 5.5, 5.0),
        ..material([0.0; 3], 0.0, 1.0)
    });
    // A glossy metal panel standing behind the origin, facing the camera.
    s.triangles.extend(quad(
        Vec3::new(-1.2, 0.0, -0.8),
        Vec3::new(2.4, 0.0, 0.0),
        Vec3::new(0.0, 1.2, 0.0),
        1,
    ));
    // The light: a 0.8 x 0.8 quad at height 1.6 facing down.
    s.triangles.extend(quad(
        Vec3::new(-0.4, 1.6, -0.4),
        Vec3::new(0.0, 0.0, 0.8),
        Vec3::new(0.8, 0.0, 0.0),
        2,
    ));
    s.env = Some(EnvMap::constant([0.15, 0.17, 0.2]));
    s
}

#[test]
fn nee_bsdf_and_mis_agree_within_noise() {
    let Some(gpu) = gpu() else { return };
    let sc = scene();
    let r = Renderer::new(&gpu, &sc).unwrap();
    let w = 64;
    let render = |t: Techniques, seed: u32| {
        r.render(
            &RenderSettings {
                width: w,
                height: w,
                spp: 128,
                seed,
                camera: 0,
                techniques: t,
            },
            |_| {},
        )
        .unwrap()
        .image
        .rgb
    };
    let nee = [
        render(Techniques::NeeOnly, 1),
        render(Techniques::NeeOnly, 2),
    ];
    let bsdf = [
        render(Techniques::BsdfOnly, 3),
        render(Techniques::BsdfOnly, 4),
    ];
    let mis = [render(Techniques::Mis, 5), render(Techniques::Mis, 6)];
    let mean = |v: &[[f32; 3]]| v.iter().map(|p| lum(*p)).sum::<f64>() / v.len() as f64;
    assert!(mean(&mis[0]) > 0.05, "scene is too dark to test anything");
    for (name, a, b) in [
        ("NEE vs BSDF", &nee, &bsdf),
        ("MIS vs NEE", &mis, &nee),
        ("MIS vs BSDF", &mis, &bsdf),
    ] {
        let z = block_z_scores([&a[0], &a[1]], [&b[0], &b[1]], w as usize, 8);
        let worst = z.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        eprintln!(
            "{name}: worst block |z| = {worst:.2} over {} blocks",
            z.len()
        );
        // 64 blocks; |z| > 5 has probability below 1e-6 per block for an unbiased pair.
        assert!(
            worst < 5.0,
            "{name}: a block differs by {worst:.2} standard errors"
        );
        let whole = block_z_scores([&a[0], &a[1]], [&b[0], &b[1]], w as usize, w as usize);
        assert!(
            whole[0].abs() < 5.0,
            "{name}: image means differ by {:.2} standard errors",
            whole[0]
        );
    }
    // MIS should be no noisier than the worse of the two techniques.
    let noise = |v: &[Vec<[f32; 3]>; 2]| {
        let d: Vec<f64> = v[0]
            .iter()
            .zip(&v[1])
            .map(|(a, b)| lum(*a) - lum(*b))
            .collect();
        mean_sd(&d).1
    };
    let (n_nee, n_bsdf, n_mis) = (noise(&nee), noise(&bsdf), noise(&mis));
    eprintln!("noise: NEE {n_nee:.4}, BSDF {n_bsdf:.4}, MIS {n_mis:.4}");
    assert!(n_mis <= n_nee.max(n_bsdf) * 1.05);
}
