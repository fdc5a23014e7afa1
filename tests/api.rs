//! The library API as an application uses it: the two examples run to completion and
//! recover their textures; a device without the limits psrestir needs is refused with the
//! limits named; a task too large for the device is refused before allocating; two optimizers
//! on one device, their steps interleaved, each end where they would alone; textures come out
//! as a GPU texture equal to the CPU values; injected non-finite values are dropped and
//! counted, never stored; passes whose grid is split over two rows (past the device's
//! workgroups per dimension) still cover every pixel and texel once; invalid ReSTIR options
//! are refused by name.
mod common;
#[path = "../examples/gltf_textures.rs"]
mod gltf_textures;
#[path = "../examples/in_memory.rs"]
mod in_memory;

use psrestir::optim::{texture_export, StepKind};
use psrestir::{Filter, Gpu, Method, Optimizer, Problem, Settings, Stop};
use std::ops::ControlFlow;

fn no_gpu() -> bool {
    let none = std::env::var_os("CI").is_none() && Gpu::new().is_err();
    if none {
        eprintln!("skipped: no GPU adapter");
    }
    none
}

#[test]
fn in_memory_example_recovers_the_texture() {
    if no_gpu() {
        return;
    }
    let (before, after) = in_memory::run(150).unwrap();
    // From gray to the checkerboard: the error must fall by well over half (it falls to
    // about a tenth in 150 iterations; bilinear 8x8 texels cannot copy the sharp 4x4
    // checker exactly).
    assert!(after < 0.5 * before, "RMSE {before} -> {after}");
}

#[test]
fn gltf_example_writes_the_recovered_texture() {
    if no_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/default/scene.gltf");
    let o = gltf_textures::run(&scene, dir.path(), 60).unwrap();
    assert!(o.rmse.1 < o.rmse.0, "RMSE {:?}", o.rmse);
    let exr = psrestir::image_io::load_linear(&o.files[0]).unwrap();
    assert_eq!((exr.width, exr.height), (64, 32));
    let png = image::open(&o.files[1]).unwrap();
    assert_eq!((png.width(), png.height()), (64, 32));
}

#[test]
fn a_device_without_the_needed_limits_is_refused_by_name() {
    if no_gpu() {
        return;
    }
    let adapter = in_memory::adapter().unwrap();
    // WebGPU's default limits: 8 storage buffers per stage, fewer than psrestir binds.
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        required_limits: wgpu::Limits::default(),
        ..Default::default()
    }))
    .unwrap();
    let e = Gpu::from_device(device, queue, adapter.get_info())
        .unwrap_err()
        .to_string();
    let needs = format!(
        "max_storage_buffers_per_shader_stage is 8, psrestir needs {}",
        psrestir::gpu::REQUIRED_STORAGE_BUFFERS
    );
    assert!(e.contains(&needs) && e.contains("required_limits"), "{e}");
    // With the limits psrestir asks for, the same adapter is accepted.
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        required_limits: Gpu::required_limits(&adapter.limits()).unwrap(),
        ..Default::default()
    }))
    .unwrap();
    Gpu::from_device(device, queue, adapter.get_info()).unwrap();
}

/// A plane problem whose checkerboard has the colors `colors`.
fn problem(gpu: &Gpu, colors: [[u8; 3]; 2]) -> Problem {
    let mut p = Problem::new(
        in_memory::scene(),
        vec![0],
        &[in_memory::texture()],
        Filter::Bilinear,
    )
    .unwrap();
    p.render_targets(gpu, in_memory::truth(colors), 32, 32, 128, 3)
        .unwrap();
    p
}

fn settings(method: Method) -> Settings {
    Settings {
        primal_spp: 2,
        primal: Default::default(),
        cv_max_weight: psrestir::optim::primal::DEFAULT_MAX_WEIGHT,
        path_cache: None,
        gradient_spp: 2,
        method,
        ..Settings::new(32, 32, vec![0])
    }
}

#[test]
fn two_optimizers_on_one_device_interleaved_end_as_alone() {
    if no_gpu() {
        return;
    }
    let gpu = Gpu::new().unwrap();
    let (pa, pb) = (
        problem(&gpu, [[230, 60, 40], [40, 90, 220]]),
        problem(&gpu, [[20, 200, 60], [240, 240, 30]]),
    );
    const N: u32 = 40;
    for method in [Method::BASELINE, Method::RESTIR, Method::RECURSIVE] {
        let alone = |p: &Problem| {
            let mut o = Optimizer::for_problem(&gpu, p, settings(method)).unwrap();
            o.run(Stop::iterations(N), |_| ControlFlow::Continue(()))
                .unwrap();
            o.texture_values(0).unwrap()
        };
        let (a, b) = (alone(&pa), alone(&pb));
        let mut oa = Optimizer::for_problem(&gpu, &pa, settings(method)).unwrap();
        let mut ob = Optimizer::for_problem(&gpu, &pb, settings(method)).unwrap();
        for _ in 0..N {
            oa.step().unwrap();
            ob.step().unwrap();
        }
        let (ia, ib) = (oa.texture_values(0).unwrap(), ob.texture_values(0).unwrap());
        let d = in_memory::rmse;
        let ab = d(&a, &b);
        assert!(ab > 0.5, "the two problems should end far apart ({ab})");
        let (ia_a, ib_b) = (d(&ia, &a), d(&ib, &b));
        eprintln!("{method:?}: interleaved vs alone {ia_a:.2e} {ib_b:.2e}; a vs b {ab:.2e}");
        // Crossed state (one optimizer reading the other's buffers) would put the results
        // about `ab` (0.7) apart. The baseline is deterministic up to the order of float
        // atomics (1e-8 here), so it must match tightly. ReSTIR's reservoirs depend on the
        // order in which invocations take their locks, and 40 Adam steps amplify that: two
        // runs alone end 0.02 to 0.11 apart (eight pairs measured), so 0.2. The recursive
        // estimator is as deterministic as the baseline, but its running estimate carries
        // the rounding of every earlier iteration.
        let tol = if method == Method::BASELINE {
            1e-5
        } else if method == Method::RESTIR {
            0.2
        } else {
            1e-3
        };
        assert!(
            ia_a <= tol,
            "{method:?}: A interleaved ends {ia_a} from A alone"
        );
        assert!(
            ib_b <= tol,
            "{method:?}: B interleaved ends {ib_b} from B alone"
        );
    }
}

/// A device returns the layout and the pipeline it made before for the same pass (a second
/// optimizer on one device creates none), and another pass gets its own.
#[test]
fn a_device_reuses_the_layouts_and_pipelines_it_made() {
    if no_gpu() {
        return;
    }
    let gpu = Gpu::new().unwrap();
    let layout = gpu.pass_layout("adam", 0).unwrap();
    assert_eq!(gpu.pass_layout("adam", 0).unwrap(), layout);
    let first = gpu.compute_pipeline("adam", &[&layout]).unwrap();
    let again = gpu.pass_layout("adam", 0).unwrap();
    assert_eq!(gpu.compute_pipeline("adam", &[&again]).unwrap(), first);
    let other = gpu.pass_layout("variance_step", 0).unwrap();
    assert_ne!(other, layout);
    assert_ne!(
        gpu.compute_pipeline("variance_step", &[&other]).unwrap(),
        first
    );
    // Both requests of `adam` are listed (the second a lookup).
    let adam = gpu
        .pipeline_times()
        .iter()
        .filter(|t| t.pass == "adam")
        .count();
    assert_eq!(adam, 2);
}

/// lavapipe compiles a shader at its first dispatch unless psrestir makes it compile at
/// creation; either way each pass's compilation must fall before the clock, and
/// `Optimizer::passes` (what a second device compiles ahead) must name what is created. A pipeline
/// created inside a step would be compiled inside the optimization's timed work (up to 20 s
/// on a 2-core machine for the gradient pass): after `prepare`, steps create none, for every
/// estimator and step, with both priors on (their passes are created lazily).
#[test]
fn steps_after_prepare_create_no_pipeline() {
    if no_gpu() {
        return;
    }
    let gpu = Gpu::new().unwrap();
    let p = problem(&gpu, [[230, 60, 40], [40, 90, 220]]);
    for method in [Method::BASELINE, Method::RESTIR, Method::RECURSIVE] {
        for step in [
            psrestir::optim::StepKind::ADAM,
            psrestir::optim::StepKind::VARIANCE,
        ] {
            let mut s = settings(method);
            s.step = step;
            s.priors = Default::default();
            s.priors
                .put(&psrestir::optim::smoothness::SmoothnessOptions { weight: 0.01 });
            s.priors
                .put(&psrestir::optim::multiscale::MultiscaleOptions { levels: 2 });
            let created = gpu.pipeline_times().len();
            let mut o = Optimizer::for_problem(&gpu, &p, s.clone()).unwrap();
            o.prepare().unwrap();
            let before = gpu.pipeline_times();
            // The list that a second device compiles ahead (Gpu::compile_elsewhere) is what
            // the optimizer creates, besides the renderer's passes.
            let mut made: Vec<&str> = before[created..]
                .iter()
                .map(|t| t.pass.as_str())
                .filter(|p| !["render", "trace_rays"].contains(p))
                .collect();
            let mut listed = Optimizer::passes(&s);
            made.sort_unstable();
            listed.sort_unstable();
            assert_eq!(made, listed, "{method:?}/{step:?}: Optimizer::passes");
            assert!(
                before.iter().any(|t| t.pass == "smoothness")
                    && before.iter().any(|t| t.pass == "multiscale_gradient"),
                "{method:?}/{step:?}: prepare created the priors' passes"
            );
            for _ in 0..3 {
                o.step().unwrap();
            }
            let after = gpu.pipeline_times();
            assert_eq!(
                after.len(),
                before.len(),
                "{method:?}/{step:?}: steps created {:?}",
                &after[before.len()..]
            );
        }
    }
}

#[test]
fn the_gpu_texture_holds_the_current_values() {
    if no_gpu() {
        return;
    }
    let gpu = Gpu::new().unwrap();
    let p = problem(&gpu, [[230, 60, 40], [40, 90, 220]]);
    let mut o = Optimizer::for_problem(&gpu, &p, settings(Method::RESTIR)).unwrap();
    o.run(Stop::iterations(5), |_| ControlFlow::Continue(()))
        .unwrap();
    let values = o.texture_values(0).unwrap();
    let tex = texture_export::create_texture(&o, 0).unwrap();
    assert_eq!((tex.width(), tex.height()), (8, 8));
    // Read the texture back: 8 texels x 16 bytes per row, padded to 256.
    let buf = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("test readback"),
        size: 256 * 8,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    enc.copy_texture_to_buffer(
        tex.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buf,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(256),
                rows_per_image: Some(8),
            },
        },
        tex.size(),
    );
    gpu.queue.submit([enc.finish()]);
    let rows: Vec<f32> = gpu.read_pod(&buf).unwrap();
    for y in 0..8 {
        for x in 0..8 {
            let t = &rows[y * 64 + x * 4..y * 64 + x * 4 + 4];
            let v = &values[(y * 8 + x) * 3..(y * 8 + x) * 3 + 3];
            assert_eq!(&t[..3], v, "texel ({x}, {y})");
            assert_eq!(t[3], 1.0);
        }
    }
    // The parameter buffer is the same data, laid out as documented.
    let all: Vec<f32> = gpu.read_pod(o.params_buffer()).unwrap();
    let off = o.set.textures[0].offset as usize;
    assert_eq!(&all[off..off + values.len()], &values[..]);
    let e = texture_export::create_texture(&o, 1)
        .unwrap_err()
        .to_string();
    assert!(e.contains("texture 1 does not exist"), "{e}");
}

#[test]
fn a_task_too_large_for_the_device_is_refused_before_allocating() {
    if no_gpu() {
        return;
    }
    // A device that binds at most 1 MiB per storage buffer.
    let adapter = in_memory::adapter().unwrap();
    let limits = wgpu::Limits {
        max_storage_buffer_binding_size: 1 << 20,
        max_buffer_size: 1 << 20,
        ..Gpu::required_limits(&adapter.limits()).unwrap()
    };
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        required_limits: limits,
        ..Default::default()
    }))
    .unwrap();
    let gpu = Gpu::from_device(device, queue, adapter.get_info()).unwrap();
    // 360x360 roughness texels: 0.5 MB of values, which fit (as would the 1.04 MB of
    // ReSTIR's moving moments with its own variance on), but ReSTIR keeps each of its four
    // reservoir slots of every observed texel in its own buffer (28 bytes per observed texel
    // each), which does not once more than 37449 texels are observed.
    let spec = psrestir::TextureSpec {
        material: "plane".into(),
        slot: psrestir::Slot::Roughness,
        resolution: [360, 360],
        init: psrestir::Init::Scalar(0.5),
        learning_rate: Some(0.01),
    };
    let mut p = Problem::new(in_memory::scene(), vec![0], &[spec], Filter::Bilinear).unwrap();
    p.render_targets(&gpu, in_memory::scene(), 64, 64, 4, 1)
        .unwrap();
    let at = |method| Settings {
        method,
        ..Settings::new(64, 64, vec![0])
    };
    // The baseline has no reservoirs and fits; it counts the observed texels.
    let base = Optimizer::for_problem(&gpu, &p, at(Method::BASELINE)).unwrap();
    let observed = base
        .observed_texels()
        .unwrap()
        .iter()
        .filter(|&&o| o)
        .count() as u64;
    let bytes = observed * psrestir::optim::estimator::restir::reservoir::WORDS as u64 * 4;
    assert!(bytes > 1 << 20, "{observed} observed texels fit the device");
    let e = Optimizer::for_problem(&gpu, &p, at(Method::RESTIR))
        .err()
        .expect("refused")
        .to_string();
    assert!(
        e.contains(&format!("reservoir slots0 buffer needs {bytes} bytes"))
            && e.contains("1048576 bytes")
            && e.contains(&format!("{observed} observed")),
        "{e}"
    );
    drop(base);

    // A scene whose images hold more than one binding can: 600x600 RGBA8 = 1.44 MB.
    let mut big = in_memory::truth([[200, 40, 40], [40, 40, 200]]);
    big.images[0] = psrestir::scene::Image8 {
        name: "big".into(),
        width: 600,
        height: 600,
        rgba: vec![[128; 4]; 600 * 600],
    };
    let e = psrestir::render::Renderer::new(&gpu, &big)
        .map(|_| ())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("the texture buffer needs 1440000 bytes") && e.contains("at most 1048576"),
        "{e}"
    );
}

/// A 2048x2048 base color texture that the cameras observe entirely plans within the lavapipe
/// device's limits with ReSTIR (each reservoir slot in its own buffer, 112 MiB each), at no
/// more than 128 bytes per observed texel.
#[test]
fn a_2048_squared_texture_plans_within_the_device_with_restir() {
    if no_gpu() {
        return;
    }
    let gpu = Gpu::new().unwrap();
    let spec = psrestir::TextureSpec {
        resolution: [2048, 2048],
        ..in_memory::texture()
    };
    let set = psrestir::render::params::ParamSet::from_specs(
        &in_memory::scene(),
        &[spec],
        Filter::Bilinear,
        std::path::Path::new("test"),
    )
    .unwrap();
    let s = Settings {
        width: 128,
        height: 128,
        ..settings(Method::RESTIR)
    };
    let plan = psrestir::optim::memory_plan(&set, &s, 4, 2048 * 2048, 1);
    eprintln!("{}", plan.summary());
    plan.check(&gpu).unwrap();
    let per_observed = plan.bytes_per(psrestir::optim::Scale::ObservedTexel);
    assert!(
        per_observed <= 128.0,
        "{per_observed} bytes per observed texel"
    );
}

/// A 1024x1024 base color texture (the regime the method is meant for) plans within the
/// lavapipe device's limits and optimizes with ReSTIR: the loss stays finite and falls, and
/// the reservoirs exist for the observed texels only.
#[test]
fn a_1024_squared_texture_optimizes_with_restir() {
    if no_gpu() {
        return;
    }
    let gpu = Gpu::new().unwrap();
    let spec = psrestir::TextureSpec {
        resolution: [1024, 1024],
        learning_rate: Some(0.2),
        ..in_memory::texture()
    };
    let mut p = Problem::new(in_memory::scene(), vec![0], &[spec], Filter::Bilinear).unwrap();
    p.render_targets(
        &gpu,
        in_memory::truth([[230, 60, 40], [40, 90, 220]]),
        64,
        64,
        64,
        3,
    )
    .unwrap();
    // With the multiscale gradient, as a texture of many texels per pixel needs (each texel
    // alone is seen by a few samples at most).
    let s = Settings {
        priors: psrestir::optim::Priors::default()
            .with(&psrestir::optim::multiscale::MultiscaleOptions { levels: 4 }),
        gradient_spp: 4,
        ..Settings {
            width: 64,
            height: 64,
            ..settings(Method::RESTIR)
        }
    };
    let mut o = Optimizer::for_problem(&gpu, &p, s).unwrap();
    let losses: Vec<f64> = (0..10).map(|_| o.step().unwrap().loss).collect();
    eprintln!("1024^2 ReSTIR losses {losses:?}");
    assert!(losses.iter().all(|l| l.is_finite()), "{losses:?}");
    // The last two iterations' loss at least 5% below the first two's (the primal noise
    // moves one iteration's loss by about 0.5%).
    let (first, last) = (losses[0] + losses[1], losses[8] + losses[9]);
    assert!(last < 0.95 * first, "the loss does not fall: {losses:?}");
    assert_eq!(o.faults().unwrap(), Default::default());
    // Reservoirs for the observed texels only: the extra state per texel is far below the
    // 120 bytes of a fully observed texture.
    let observed = o.observed_texels().unwrap().iter().filter(|&&x| x).count();
    assert!(observed > 1000 && observed < 1024 * 1024 / 2, "{observed}");
}

#[test]
fn non_finite_values_are_dropped_and_counted_never_stored() {
    if no_gpu() {
        return;
    }
    let gpu = Gpu::new().unwrap();
    for method in [Method::BASELINE, Method::RESTIR] {
        // Inject: a quarter of the target pixels are NaN or infinite, so their adjoints and
        // every gradient sample through them are not finite.
        let mut p = problem(&gpu, [[230, 60, 40], [40, 90, 220]]);
        for (i, px) in p.targets[0].rgb.iter_mut().enumerate() {
            match i % 8 {
                0 => *px = [f32::NAN; 3],
                1 => *px = [f32::INFINITY, 0.5, f32::NEG_INFINITY],
                _ => {}
            }
        }
        let mut o = Optimizer::for_problem(&gpu, &p, settings(method)).unwrap();
        o.run(Stop::iterations(10), |_| ControlFlow::Continue(()))
            .unwrap();
        let values = o.texture_values(0).unwrap();
        assert!(
            values.iter().all(|v| v.is_finite()),
            "{method:?}: {values:?}"
        );
        assert!(o.read_gradient().unwrap().iter().all(|g| g.is_finite()));
        let state = o.state().unwrap();
        assert!(state.m1.iter().chain(&state.m2).all(|v| v.is_finite()));
        let reservoirs = state
            .estimator
            .array(psrestir::optim::estimator::restir::state_names::RESERVOIRS);
        assert_eq!(reservoirs.is_some(), method == Method::RESTIR);
        if let Some(r) = reservoirs {
            // The weight and the stored previous-state target (a bfloat16 in the high bits of
            // the direction's words) of every reservoir.
            use psrestir::optim::estimator::restir::abi::reservoir as layout;
            let words = state.estimator.counter("reservoir words").unwrap() as usize;
            for res in r.chunks_exact(words) {
                let w = f32::from_bits(res[layout::W as usize]);
                assert!(w.is_finite(), "{method:?}: reservoir weight {w}");
                let hi = |k: u32| res[k as usize] >> layout::OCT_BITS;
                let q = f32::from_bits((hi(layout::WI_X) | (hi(layout::WI_Y) << 8)) << 16);
                assert!(q.is_finite(), "{method:?}: stored target {q}");
            }
        }
        let f = o.faults().unwrap();
        eprintln!("{method:?}: {f:?}");
        // 2 of every 8 pixels of 32x32, every iteration: 10 x 256.
        assert_eq!(f.dropped_pixels, 10 * 256, "{method:?}: {f:?}");
        // The textures still move toward the finite part of the target.
        assert!(
            values.iter().any(|v| (v - 0.5).abs() > 0.05),
            "{method:?}: no progress"
        );

        // Inject into the samples: a light of the largest finite intensity (an infinite one
        // is refused by `Scene::validate`) 2 cm above the plane makes the samples around it
        // overflow to infinity.
        let mut p = problem(&gpu, [[230, 60, 40], [40, 90, 220]]);
        p.scene.lights[0].intensity = psrestir::glam::Vec3::splat(f32::MAX);
        p.scene.lights[0].position = psrestir::glam::Vec3::new(0.3, 0.02, 0.4);
        let mut o = Optimizer::for_problem(&gpu, &p, settings(method)).unwrap();
        o.run(Stop::iterations(5), |_| ControlFlow::Continue(()))
            .unwrap();
        let values = o.texture_values(0).unwrap();
        assert!(
            values.iter().all(|v| v.is_finite()),
            "{method:?}: {values:?}"
        );
        let state = o.state().unwrap();
        assert!(state.m1.iter().chain(&state.m2).all(|v| v.is_finite()));
        let f = o.faults().unwrap();
        eprintln!("{method:?}, light of intensity f32::MAX: {f:?}");
        assert!(f.dropped_primal > 0, "{method:?}: {f:?}");
        assert!(f.dropped_gradient > 0, "{method:?}: {f:?}");
    }
}

#[test]
fn a_lost_device_is_a_clear_error_not_a_panic() {
    if no_gpu() {
        return;
    }
    let gpu = Gpu::new().unwrap();
    let p = problem(&gpu, [[230, 60, 40], [40, 90, 220]]);
    let mut o = Optimizer::for_problem(&gpu, &p, settings(Method::RESTIR)).unwrap();
    o.step().unwrap();
    // What a driver reset looks like to the application: the device is gone.
    gpu.device.destroy();
    let e = o.step().unwrap_err();
    assert!(matches!(e, psrestir::Error::DeviceLost { .. }), "{e:?}");
    let text = e.to_string();
    assert!(
        text.contains("device was lost") && text.contains("--resume"),
        "{text}"
    );
    // It stays lost: every later call says so, none panics.
    assert!(matches!(
        o.texture_values(0).unwrap_err(),
        psrestir::Error::DeviceLost { .. }
    ));
}

#[test]
fn scenes_built_in_code_are_checked_before_they_reach_the_gpu() {
    if no_gpu() {
        return;
    }
    use psrestir::glam::{Vec2, Vec3};
    let gpu = Gpu::new().unwrap();
    type Case<'a> = (&'a str, Box<dyn Fn(&mut psrestir::Scene)>, &'a str);
    let cases: Vec<Case> = vec![
        (
            "material out of range",
            Box::new(|s| s.triangles[0].material = 99),
            "uses material 99",
        ),
        (
            "NaN vertex",
            Box::new(|s| s.triangles[1].p[2].x = f32::NAN),
            "triangle 1 has a non-finite vertex",
        ),
        (
            "zero normal",
            Box::new(|s| s.triangles[0].n[0] = Vec3::ZERO),
            "normal that is not unit length",
        ),
        (
            "infinite UV",
            Box::new(|s| s.triangles[0].uv[1] = Vec2::new(f32::INFINITY, 0.0)),
            "non-finite UV",
        ),
        (
            "image of the wrong size",
            Box::new(|s| s.images[0].rgba.pop().map(|_| ()).unwrap_or(())),
            "holds 15 pixels",
        ),
        (
            "texture of a missing image",
            Box::new(|s| {
                if let Some(t) = s.materials[0].base_color_texture.as_mut() {
                    t.image = 5
                }
            }),
            "uses image 5",
        ),
        (
            "negative light",
            Box::new(|s| s.lights[0].intensity = Vec3::splat(-1.0)),
            "negative intensity",
        ),
        (
            "camera without a field of view",
            Box::new(|s| s.cameras[0].yfov = 0.0),
            "field of view outside (0, pi)",
        ),
    ];
    for (what, break_it, expect) in cases {
        let mut s = in_memory::truth([[200, 40, 40], [40, 40, 200]]);
        assert!(s.validate().is_ok(), "the example scene is valid");
        break_it(&mut s);
        let e = psrestir::render::Renderer::new(&gpu, &s)
            .map(|_| ())
            .unwrap_err()
            .to_string();
        assert!(e.contains(expect), "{what}: {e}");
        assert!(e.starts_with("invalid scene"), "{what}: {e}");
    }
}

/// A device limited to `groups` workgroups per grid dimension.
fn device_with_workgroups_per_dimension(groups: u32) -> Gpu {
    let adapter = in_memory::adapter().unwrap();
    let limits = wgpu::Limits {
        max_compute_workgroups_per_dimension: groups,
        ..Gpu::required_limits(&adapter.limits()).unwrap()
    };
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        required_limits: limits,
        ..Default::default()
    }))
    .unwrap();
    Gpu::from_device(device, queue, adapter.get_info()).unwrap()
}

#[test]
fn passes_split_over_two_grid_rows_cover_every_item_once() {
    if no_gpu() {
        return;
    }
    // 272 x 256 pixels (1,088 groups of 64) and 160 x 160 RGB texels (76,800 Adam entries,
    // 1,200 groups): on a device with 1,024 workgroups per dimension (the least psrestir
    // accepts) the loss, control-variate, gradient and Adam passes run on grids of two rows,
    // as they do on any device for images or textures past 2048 x 2048 (65,535 x 64
    // invocations). A pass that reads only the first row's index runs part of its items
    // twice and never reaches the rest.
    let (w, h) = (272, 256);
    let spec = psrestir::TextureSpec {
        resolution: [160, 160],
        ..in_memory::texture()
    };
    let (lo, hi) = spec.slot.range();
    let run = |gpu: &Gpu, check_adam: bool| {
        let mut p = Problem::new(
            in_memory::scene(),
            vec![0],
            std::slice::from_ref(&spec),
            Filter::Bilinear,
        )
        .unwrap();
        p.render_targets(
            gpu,
            in_memory::truth([[200, 40, 40], [40, 40, 200]]),
            w,
            h,
            8,
            3,
        )
        .unwrap();
        let settings = Settings {
            primal_spp: 2,
            primal: psrestir::optim::PrimalMode::ControlVariate,
            gradient_spp: 1,
            method: Method::BASELINE,
            ..Settings::new(w, h, vec![0])
        };
        let mut o = Optimizer::for_problem(gpu, &p, settings).unwrap();
        let mut losses = Vec::new();
        let mut p_ref = o.read_params().unwrap();
        let n = p_ref.len();
        let (mut m, mut v) = (vec![0.0; n], vec![0.0; n]);
        for t in 1..=4u32 {
            losses.push(o.step().unwrap().loss);
            if check_adam {
                // Every texel's Adam step, against the Rust reference from the same gradient.
                let g = o.read_gradient().unwrap();
                let lr = o.last_learning_rates()[0];
                psrestir::optim::adam::step(&mut p_ref, &mut m, &mut v, &g, lr, t, lo, hi);
                let gpu_p = o.read_params().unwrap();
                let [gm, gv] = o.read_moments().unwrap();
                let bad = (0..n)
                    .filter(|&i| {
                        (gm[i] - m[i]).abs() > 1e-6 * m[i].abs() + 1e-20
                            || (gv[i] - v[i]).abs() > 1e-6 * v[i].abs() + 1e-30
                            || (gpu_p[i] - p_ref[i]).abs() > 1e-6
                    })
                    .count();
                assert_eq!(bad, 0, "step {t}: {bad} of {n} Adam entries differ");
                // The entries the second row of groups holds have gradients too.
                assert!(g[n / 2..].iter().any(|x| *x != 0.0), "step {t}");
                (p_ref, m, v) = (gpu_p, gm, gv);
            }
        }
        let image = o
            .control_variate_image(0)
            .unwrap()
            .expect("control variate");
        (losses, image)
    };
    let (loss_wide, img_wide) = run(&Gpu::new().unwrap(), false);
    let (loss_narrow, img_narrow) = run(&device_with_workgroups_per_dimension(1024), true);
    // The first loss is the same render and the same partial sums in the same order: equal
    // to the bit. Later ones follow textures that differ only by the order of the gradient
    // pass's float atomics (relative 1e-6 or less); a loss pass that dropped or repeated a
    // row of groups would be off by a large fraction.
    assert_eq!(loss_narrow[0], loss_wide[0]);
    for (a, b) in loss_narrow.iter().zip(&loss_wide) {
        assert!(
            (a - b).abs() <= 1e-4 * b.abs(),
            "losses {loss_narrow:?} vs {loss_wide:?}"
        );
    }
    // The control-variate image after four iterations: the same up to the same rounding.
    let (a, b) = (&img_narrow.rgb, &img_wide.rgb);
    assert_eq!(a.len(), (w * h) as usize);
    let diff: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (0..3).map(|c| ((x[c] - y[c]) as f64).powi(2)).sum::<f64>())
        .sum();
    let norm: f64 = b
        .iter()
        .map(|y| (0..3).map(|c| (y[c] as f64).powi(2)).sum::<f64>())
        .sum();
    assert!(
        norm > 0.0 && diff <= 1e-8 * norm,
        "image difference {diff:.3e} of {norm:.3e}"
    );
}

#[test]
fn invalid_restir_options_are_refused_by_name() {
    if no_gpu() {
        return;
    }
    let gpu = Gpu::new().unwrap();
    let p = problem(&gpu, [[230, 60, 40], [40, 90, 220]]);
    for (m_cap, target_smoothing, name) in [
        (0.0, 0.9, "m_cap"),
        (f32::NAN, 0.9, "m_cap"),
        (8.0, 1.0, "target_smoothing"),
        (8.0, -0.1, "target_smoothing"),
        (8.0, f32::NAN, "target_smoothing"),
    ] {
        let s = Settings {
            estimator_options: psrestir::EstimatorOptions::default().with(
                &psrestir::optim::estimator::restir::RestirOptions {
                    m_cap,
                    target_smoothing: Some(target_smoothing),
                    ..Default::default()
                },
            ),
            ..settings(Method::RESTIR)
        };
        let e = Optimizer::for_problem(&gpu, &p, s)
            .err()
            .expect("refused")
            .to_string();
        assert!(e.contains(name), "{m_cap} {target_smoothing}: {e}");
    }
}

/// The differentiable render's step after a backward of the optimizer's own adjoint is the
/// optimizer's own iteration, for both steps with the priors, the filtered moments and a
/// schedule, over iterations that carry their moments and ReSTIR's reservoirs: what a Python
/// loop with `psrestir.Step` and an L2 loss runs is `psrestir optimize`'s update.
#[test]
fn a_step_after_backward_is_the_optimizers_iteration() {
    if no_gpu() {
        return;
    }
    let gpu = Gpu::new().unwrap();
    let p = problem(&gpu, [[230, 60, 40], [40, 90, 220]]);
    for (method, step) in [
        (Method::BASELINE, StepKind::VARIANCE),
        (Method::RESTIR, StepKind::ADAM),
    ] {
        let s = Settings {
            primal: psrestir::optim::PrimalMode::Independent,
            step,
            priors: psrestir::optim::Priors::default()
                .with(&psrestir::optim::smoothness::SmoothnessOptions { weight: 0.01 })
                .with(&psrestir::optim::multiscale::MultiscaleOptions { levels: 2 }),
            moment_filter: psrestir::optim::moment_filter::MomentFilterOptions {
                levels: 2,
                ..Default::default()
            },
            schedule: psrestir::optim::Schedule {
                kind: psrestir::optim::ScheduleKind::Cosine,
                ..Default::default()
            },
            ..settings(method)
        };
        let mut opt = Optimizer::for_problem(&gpu, &p, s.clone()).unwrap();
        let mut op = psrestir::optim::DiffRender::new(&gpu, &p.scene, p.set.clone(), s).unwrap();
        let n = 4;
        for t in 0..n {
            let progress = t as f64 / n as f64;
            opt.set_progress(progress);
            opt.step().unwrap();
            let a = opt.read_adjoint(t).unwrap();
            let adjoint = psrestir::Image {
                width: 32,
                height: 32,
                rgb: a.chunks(4).map(|c| [c[0], c[1], c[2]]).collect(),
            };
            op.set_progress(progress);
            op.render(1, t, None).unwrap();
            op.backward(&[adjoint], None).unwrap();
            op.step(None).unwrap();
            let (want, got) = (opt.texture_values(0).unwrap(), op.texture(0).unwrap());
            let moved = want.iter().zip(&p.set.values).any(|(a, b)| a != b);
            assert!(
                moved,
                "{method:?}: the optimizer did not move: the test sees nothing"
            );
            let worst = want
                .iter()
                .zip(&got)
                .fold(0f32, |m, (a, b)| m.max((a - b).abs()));
            // The same passes on the same gradient; float atomics may add in another order
            // (1e-4 of a gradient, far below a step of ~1e-2).
            assert!(
                worst <= 1e-5,
                "{method:?} {step:?} iteration {t}: the textures differ by {worst}"
            );
        }
        let err = op.step(None).unwrap_err().to_string();
        assert!(err.contains("step needs a gradient"), "{err}");
    }
}

/// The differentiable render's backward, given the adjoint the optimizer's own loss pass
/// wrote, is the optimizer's own gradient, for every estimator and across a texture change
/// (ReSTIR and the recursive estimator pair each call with the previous one's textures and
/// adjoint); and a backward without a render at the current textures is refused.
#[test]
fn backward_from_an_external_adjoint_is_the_optimizers_gradient() {
    if no_gpu() {
        return;
    }
    let gpu = Gpu::new().unwrap();
    let p = problem(&gpu, [[230, 60, 40], [40, 90, 220]]);
    for method in [Method::BASELINE, Method::RESTIR, Method::RECURSIVE] {
        let s = Settings {
            primal: psrestir::optim::PrimalMode::Independent,
            ..settings(method)
        };
        let mut opt = Optimizer::for_problem(&gpu, &p, s.clone()).unwrap();
        let moved: Vec<f32> = p.set.values.iter().map(|v| 0.8 * v + 0.1).collect();
        let (g0, _) = opt.estimate_gradient(0).unwrap();
        let a0 = opt.read_adjoint(0).unwrap();
        opt.write_params(&moved).unwrap();
        let (g1, _) = opt.estimate_gradient(1).unwrap();
        let a1 = opt.read_adjoint(1).unwrap();
        let rgb = |a: &[f32]| psrestir::Image {
            width: 32,
            height: 32,
            rgb: a.chunks(4).map(|c| [c[0], c[1], c[2]]).collect(),
        };
        let mut op = psrestir::optim::DiffRender::new(&gpu, &p.scene, p.set.clone(), s).unwrap();
        let err = op.backward(&[rgb(&a0)], None).unwrap_err().to_string();
        assert!(err.contains("backward needs a render"), "{err}");
        op.render(1, 0, None).unwrap();
        let h0 = op.backward(&[rgb(&a0)], None).unwrap().textures.remove(0);
        assert!(
            op.backward(&[rgb(&a0)], None).is_err(),
            "a second backward per render"
        );
        op.set_texture(0, &moved).unwrap();
        op.render(1, 1, None).unwrap();
        let h1 = op.backward(&[rgb(&a1)], None).unwrap().textures.remove(0);
        for (g, h, it) in [(&g0, &h0, 0), (&g1, &h1, 1)] {
            let scale = g.iter().fold(0f32, |m, v| m.max(v.abs()));
            let worst = g.iter().zip(h).fold(0f32, |m, (a, b)| m.max((a - b).abs()));
            assert!(scale > 0.0, "{method:?}: a zero gradient tests nothing");
            // The same samples and arithmetic; float atomics may add in another order.
            assert!(
                worst <= 1e-4 * scale,
                "{method:?} iteration {it}: backward differs by {worst} (largest {scale})"
            );
        }
    }
}

/// A capture that sees some of the scene's lights (`Camera::lights`, a task's
/// `target.lights`) is the scene without the others: its target renders bit for bit the
/// same (the same light choices: a light that is off has an empty interval of the choice's
/// CDF, the others their shares of the lights that are on), and every estimator's gradient
/// the same up to the order of its atomic sums; the same camera seeing every light differs.
#[test]
fn a_capture_sees_only_its_own_lights() {
    if no_gpu() {
        return;
    }
    use psrestir::scene::{EnvMap, PunctualLight, Scene};
    let gpu = Gpu::new().unwrap();
    // The example's lamp A, a brighter lamp B listed before it, a sky; `sees`: the camera's
    // lights, or None for a scene without B.
    let lit = |mut s: Scene, sees: Option<Option<Vec<usize>>>| {
        s.env = Some(EnvMap::constant([0.2, 0.25, 0.3]));
        if let Some(sees) = sees {
            let b = glam::Vec3::new(-0.6, 1.5, -0.2);
            s.lights
                .insert(0, PunctualLight::point("B", b, glam::Vec3::splat(9.0)));
            s.cameras[0].lights = sees;
        }
        s
    };
    let colors = [[230, 60, 40], [40, 90, 220]];
    let problem = |sees: Option<Option<Vec<usize>>>| {
        let mut p = Problem::new(
            lit(in_memory::scene(), sees.clone()),
            vec![0],
            &[in_memory::texture()],
            Filter::Bilinear,
        )
        .unwrap();
        p.render_targets(&gpu, lit(in_memory::truth(colors), sees), 32, 32, 64, 3)
            .unwrap();
        p
    };
    let (alone, seen, all) = (
        problem(None),
        problem(Some(Some(vec![1]))),
        problem(Some(None)),
    );
    assert_eq!(alone.targets[0].rgb, seen.targets[0].rgb);
    let d = in_memory::rmse;
    let flat = |p: &Problem| -> Vec<f32> { p.targets[0].rgb.iter().flatten().copied().collect() };
    assert!(d(&flat(&alone), &flat(&all)) > 0.05);
    for method in [Method::BASELINE, Method::RESTIR, Method::RECURSIVE] {
        let gradient = |p: &Problem| {
            let mut o = Optimizer::for_problem(&gpu, p, settings(method)).unwrap();
            let mut g = o.estimate_gradient(0).unwrap().0;
            g.extend(o.estimate_gradient(1).unwrap().0);
            g
        };
        let (ga, gs, gall) = (gradient(&alone), gradient(&seen), gradient(&all));
        let scale = ga.iter().fold(0f32, |m, x| m.max(x.abs())) as f64;
        let (same, other) = (d(&ga, &gs) / scale, d(&ga, &gall) / scale);
        assert!(
            same < 1e-5 && other > 0.05,
            "{}: gradient differences relative to its largest entry: {same:e} seeing lamp A \
             alone, {other:e} seeing both lamps",
            method.name()
        );
    }
}

/// An evaluation's `expected` error estimates the relMSE of the render's expectation, so its
/// mean does not depend on the evaluation's samples, while a render's own relMSE carries its
/// noise. At the start (gray against a checkerboard near gray, so that the noise is most of
/// a 16-sample render's error), the mean of 24 seeds' 16-sample `expected` is within 4
/// standard errors of a 1024-sample evaluation's, and their `relmse` more than 4 above it.
#[test]
fn the_expected_image_error_does_not_depend_on_the_evaluations_samples() {
    if no_gpu() {
        return;
    }
    let gpu = Gpu::new().unwrap();
    let p = problem(&gpu, [[196, 182, 190], [182, 194, 186]]);
    let o = Optimizer::for_problem(&gpu, &p, settings(Method::BASELINE)).unwrap();
    let eval = |spp, seed| psrestir::job::run::evaluate(&o, &p.targets, spp, seed).unwrap();
    let hi = eval(1024, 1);
    let lo: Vec<_> = (1..25).map(|seed| eval(16, seed)).collect();
    let mean_se = |v: Vec<f64>| {
        let (m, sd) = common::mean_sd(&v);
        (m, sd / (v.len() as f64).sqrt())
    };
    let (e, e_se) = mean_se(lo.iter().map(|l| l.expected).collect());
    let (r, r_se) = mean_se(lo.iter().map(|l| l.relmse).collect());
    let report = format!(
        "16 spp: expected {e:.4e} ± {e_se:.1e}, relmse {r:.4e} ± {r_se:.1e}; 1024 spp: \
         expected {:.4e}, relmse {:.4e}",
        hi.expected, hi.relmse
    );
    assert!((e - hi.expected).abs() < 4.0 * e_se, "{report}");
    assert!(r - hi.expected > 4.0 * r_se, "{report}");
    eprintln!("{report}");
}
