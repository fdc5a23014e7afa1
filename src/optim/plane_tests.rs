//! A lit plane that tests optimize end to end: the toy estimator's and the toy prior's,
//! which show that each is its folder and one registry line.
use crate::glam::Vec3;
use crate::gpu::Gpu;
use crate::scene::{Camera, Material, PunctualLight, Triangle};
use crate::{Init, Optimizer, Problem, Scene, Settings, Slot, Stop, TextureSpec};

/// The texture values (8 x 8 base color, from 0.5) after `iterations` of Adam at 0.01 on
/// a lit plane seen from above, with the settings `configure` gives.
pub(crate) fn run_on_plane(iterations: u32, configure: impl FnOnce(&mut Settings)) -> Vec<f32> {
    let mut opt = plane_optimizer(configure);
    opt.run(Stop::iterations(iterations), |_| {
        std::ops::ControlFlow::Continue(())
    })
    .unwrap();
    let values = opt.texture_values(0).unwrap();
    assert_eq!(values.len(), 8 * 8 * 3);
    values
}

/// An optimizer of the lit plane's 8 x 8 base color (Adam at 0.01, from 0.5, its target
/// rendered at 16 x 16), with the settings `configure` gives.
pub(crate) fn plane_optimizer(configure: impl FnOnce(&mut Settings)) -> Optimizer {
    let plane = Material {
        name: "plane".into(),
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
        Vec3::new(0.0, 2.5, 0.0),
        Vec3::ZERO,
        Vec3::NEG_Z,
        0.8,
    ));
    scene.lights.push(PunctualLight::point(
        "lamp",
        Vec3::new(0.3, 2.0, 0.4),
        Vec3::splat(6.0),
    ));
    let texture = TextureSpec {
        material: "plane".into(),
        slot: Slot::BaseColor,
        resolution: [8, 8],
        init: Init::Vector(vec![0.5; 3]),
        learning_rate: Some(0.01),
    };
    let mut problem = Problem::new(scene.clone(), vec![0], &[texture], Default::default());
    let problem = problem.as_mut().unwrap();
    let gpu = Gpu::quiet(Default::default()).unwrap();
    problem.render_targets(&gpu, scene, 16, 16, 1, 1).unwrap();
    let mut settings = Settings::new(16, 16, vec![0]);
    configure(&mut settings);
    Optimizer::for_problem(&gpu, problem, settings).unwrap()
}
