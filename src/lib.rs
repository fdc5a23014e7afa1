//! psrestir: inverse texture optimization on wgpu with parameter-space ReSTIR gradients.
//!
//! psrestir recovers material textures (base color, roughness, metallic) of a scene whose
//! geometry, lights and cameras are known, from target images, by gradient descent. It has
//! three gradient estimators ([`Method`]): plain Monte Carlo (the baseline), parameter-space
//! ReSTIR, which reuses Monte Carlo samples across iterations through two reservoirs per
//! texel, and a recursive control variate; `auto` picks by the task's sampling
//! ([`MethodChoice`]). Each is followed by Adam or a variance-scaled step, optionally with
//! moments filtered across texels. All GPU work is WGSL compute shaders on [`wgpu`].
//!
//! # Use from a wgpu application
//! The application keeps its device and queue; psrestir checks their limits and works on
//! them ([`Gpu::from_device`]). A problem is a [`Scene`] (loaded with [`scene::load`] or
//! built in code), the cameras to render, the textures to recover ([`TextureSpec`]) and one
//! target image per camera ([`Problem`]). An [`Optimizer`] steps it, runs it for a number of
//! iterations or a time budget ([`Optimizer::run`]), renders the current state, estimates
//! gradients, and hands the textures over as a `wgpu::Buffer`
//! ([`Optimizer::params_buffer`]), a `wgpu::Texture`
//! ([`create_texture`](optim::texture_export::create_texture)) or CPU values
//! ([`Optimizer::texture_values`]). Every fallible call returns [`Error`].
//!
//! ```no_run
//! use psrestir::glam::Vec3;
//! use psrestir::scene::{Camera, Material, PunctualLight, Triangle};
//! use psrestir::{Gpu, Init, Optimizer, Problem, Scene, Settings, Slot, Stop, TextureSpec};
//! use std::ops::ControlFlow;
//!
//! # fn main() -> psrestir::Result<()> {
//! // A gray plane under a point light, seen from above.
//! let plane = Material { name: "plane".into(), metallic: 0.0, roughness: 0.6, ..Default::default() };
//! let mut scene = Scene { materials: vec![plane], ..Default::default() };
//! scene.triangles.extend(Triangle::quad(Vec3::new(-1.0, 0.0, 1.0), 2.0 * Vec3::X, -2.0 * Vec3::Z, 0));
//! scene.cameras.push(Camera::look_at("top", Vec3::new(0.0, 2.5, 0.0), Vec3::ZERO, Vec3::NEG_Z, 0.8));
//! scene.lights.push(PunctualLight::point("lamp", Vec3::new(0.3, 2.0, 0.4), Vec3::splat(6.0)));
//!
//! // Recover an 8x8 base color texture from one 64x64 photo (here: a render of the truth).
//! let texture = TextureSpec {
//!     material: "plane".into(),
//!     slot: Slot::BaseColor,
//!     resolution: [8, 8],
//!     init: Init::Vector(vec![0.5; 3]),
//!     learning_rate: Some(0.03), // None: the step's default
//! };
//! let mut problem = Problem::new(scene.clone(), vec![0], &[texture], Default::default())?;
//! let mut truth = scene;
//! truth.materials[0].base_color = psrestir::glam::Vec4::new(0.8, 0.3, 0.1, 1.0);
//! let gpu = Gpu::new()?; // or Gpu::from_device(device, queue, adapter.get_info())?
//! problem.render_targets(&gpu, truth, 64, 64, 256, 1)?;
//!
//! let mut opt = Optimizer::for_problem(&gpu, &problem, Settings::new(64, 64, vec![0]))?;
//! opt.run(Stop::iterations(100), |p| {
//!     if p.iteration % 25 == 0 {
//!         println!("iteration {}: loss {:.3e}", p.iteration, p.loss);
//!     }
//!     ControlFlow::Continue(())
//! })?;
//! let base_color: Vec<f32> = opt.texture_values(0)?; // 8 x 8 x RGB
//! let on_gpu = psrestir::optim::texture_export::create_texture(&opt, 0)?; // Rgba32Float
//! # Ok(())
//! # }
//! ```
//!
//! With a loss of its own, an application renders and differentiates through
//! [`optim::DiffRender`]: `render` the cameras, compute dL/dI, and `backward` returns each
//! texture's gradient from the chosen estimator (the Python package is built on it).
//!
//! The `psrestir` binary is built on the same API: task files ([`Task`]) are turned into
//! problems with [`Problem::from_task`], and [`job::run::run`] adds progress, metrics,
//! checkpoints and outputs. `examples/` holds two complete programs.
#![warn(missing_docs)]

#[cfg(test)]
mod architecture_tests;
pub mod assets;
pub mod auto;
pub mod bench;
#[cfg(test)]
mod contract_tests;
pub mod error;
pub mod gpu;
pub mod image_io;
pub mod job;
#[cfg(test)]
mod layering_tests;
pub mod optim;
pub mod render;
pub mod scene;
pub mod shader_library;
pub mod task;
pub mod vocab;

pub use error::{Error, Result};
pub use gpu::Gpu;
pub use image_io::Image;
pub use job::Problem;
pub use optim::{
    EstimatorOptions, Method, MethodChoice, Optimizer, OptimizerState, Progress, Settings, Stop,
};
pub use scene::Scene;
pub use task::{Filter, Init, Loss, Slot, Task, TextureSpec};

/// The glam version of psrestir's vector types (scenes built in code use it).
pub use glam;
/// The wgpu version psrestir works with (an application's device must come from it).
pub use wgpu;
