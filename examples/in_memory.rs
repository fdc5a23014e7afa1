//! Optimize a scene built in code, on a wgpu device that the program creates itself.
//!
//! A plane under a point light, seen from above; its true base color is a 4x4 checkerboard of
//! colors. The program renders the truth as the target photo, then recovers an 8x8 base color
//! texture from a gray start and prints how far it got.
//!
//!     cargo run --release --example in_memory [ITERATIONS]
use psrestir::glam::{Vec3, Vec4};
use psrestir::scene::{Camera, Image8, Material, PunctualLight, TextureSlot, Triangle, Wrap};
use psrestir::{
    wgpu, Filter, Gpu, Init, Optimizer, Problem, Scene, Settings, Slot, Stop, TextureSpec,
};
use std::ops::ControlFlow;

/// The scene: a 2 x 2 plane (material "plane"), a camera "top" and a point light.
pub fn scene() -> Scene {
    let plane = Material {
        name: "plane".into(),
        base_color: Vec4::new(0.5, 0.5, 0.5, 1.0),
        metallic: 0.0,
        roughness: 0.6,
        ..Default::default()
    };
    let mut scene = Scene {
        materials: vec![plane],
        ..Default::default()
    };
    scene.triangles.extend(Triangle::quad(
        Vec3::new(-1.0, 0.0, 1.0),
        2.0 * Vec3::X,
        -2.0 * Vec3::Z,
        0,
    ));
    scene.cameras.push(Camera::look_at(
        "top",
        Vec3::new(0.0, 2.6, 0.0),
        Vec3::ZERO,
        Vec3::NEG_Z,
        0.8,
    ));
    scene.lights.push(PunctualLight::point(
        "lamp",
        Vec3::new(0.3, 2.0, 0.4),
        Vec3::splat(6.0),
    ));
    scene
}

/// The same scene with the true material: a 4x4 checkerboard of `colors` (sRGB bytes).
pub fn truth(colors: [[u8; 3]; 2]) -> Scene {
    let mut s = scene();
    let rgba = (0..16)
        .map(|i| {
            let c = colors[(i % 4 + i / 4) % 2];
            [c[0], c[1], c[2], 255]
        })
        .collect();
    s.images.push(Image8 {
        name: "checker".into(),
        width: 4,
        height: 4,
        rgba,
    });
    s.materials[0].base_color = Vec4::ONE;
    s.materials[0].base_color_texture = Some(TextureSlot {
        image: 0,
        wrap_s: Wrap::Clamp,
        wrap_t: Wrap::Clamp,
        nearest: true,
        transform: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
    });
    s
}

/// The first adapter of the platform's primary backends (or of `WGPU_BACKEND`).
pub fn adapter() -> psrestir::Result<wgpu::Adapter> {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
    desc.backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::PRIMARY);
    let instance = wgpu::Instance::new(desc);
    pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))
        .map_err(|e| psrestir::Error::NoAdapter(format!("no GPU adapter: {e}")))
}

/// A device of the program's own, asked for the limits psrestir needs.
pub fn own_device() -> psrestir::Result<Gpu> {
    let adapter = adapter()?;
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("in_memory example"),
        required_limits: Gpu::required_limits(&adapter.limits())?,
        ..Default::default()
    }))
    .map_err(|e| psrestir::Error::Unsuitable(e.to_string()))?;
    Gpu::from_device(device, queue, adapter.get_info())
}

/// The 8x8 base color texture to recover, from gray.
pub fn texture() -> TextureSpec {
    TextureSpec {
        material: "plane".into(),
        slot: Slot::BaseColor,
        resolution: [8, 8],
        init: Init::Vector(vec![0.5; 3]),
        learning_rate: Some(0.03),
    }
}

/// Root-mean-square difference.
pub fn rmse(a: &[f32], b: &[f32]) -> f64 {
    let s: f64 = a.iter().zip(b).map(|(x, y)| ((x - y) as f64).powi(2)).sum();
    (s / a.len() as f64).sqrt()
}

/// Optimize for `iterations`; returns the texture RMSE against the truth before and after.
pub fn run(iterations: u32) -> psrestir::Result<(f64, f64)> {
    let gpu = own_device()?;
    println!("device: {}", gpu.describe());
    let mut problem = Problem::new(scene(), vec![0], &[texture()], Filter::Bilinear)?;
    problem.render_targets(&gpu, truth([[230, 60, 40], [40, 90, 220]]), 64, 64, 256, 7)?;
    let reference = problem
        .reference
        .clone()
        .expect("rendered from a truth scene");
    let settings = Settings {
        primal_spp: 2,
        primal: Default::default(),
        cv_max_weight: psrestir::optim::primal::DEFAULT_MAX_WEIGHT,
        path_cache: None,
        gradient_spp: 2,
        ..Settings::new(64, 64, vec![0])
    };
    let mut opt = Optimizer::for_problem(&gpu, &problem, settings)?;
    let before = rmse(&opt.texture_values(0)?, &reference);
    opt.run(Stop::iterations(iterations), |p| {
        if p.iteration % 50 == 0 {
            println!("iteration {:4}: loss {:.3e}", p.iteration, p.loss);
        }
        ControlFlow::Continue(())
    })?;
    let after = rmse(&opt.texture_values(0)?, &reference);
    println!("texture RMSE {before:.4} -> {after:.4} after {iterations} iterations");
    // The recovered texture as a GPU texture the application can bind.
    let tex = psrestir::optim::texture_export::create_texture(&opt, 0)?;
    println!(
        "GPU texture: {}x{} {:?}",
        tex.width(),
        tex.height(),
        tex.format()
    );
    Ok((before, after))
}

#[allow(dead_code)]
fn main() -> psrestir::Result<()> {
    let iterations = match std::env::args().nth(1) {
        Some(a) => a
            .parse()
            .map_err(|_| psrestir::Error::Invalid(format!("ITERATIONS: `{a}` is not a count")))?,
        None => 200,
    };
    run(iterations)?;
    Ok(())
}
