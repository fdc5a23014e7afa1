//! psrestir: inverse texture optimization on wgpu with parameter-space ReSTIR gradients.
//!
//! This crate holds the engine behind the `psrestir` binary: headless device creation
//! ([`gpu`]), glTF scene loading and the BVH ([`scene`]), and the direct-lighting renderer
//! ([`render`]), all GPU work being WGSL compute shaders under `shaders/`.

pub mod bench;
pub mod error;
pub mod gpu;
pub mod image_io;
pub mod optim;
pub mod render;
pub mod scene;
pub mod task;

pub use error::{Error, Result};
