//! The `psrestir` command-line tool.
use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use psrestir::assets;
use psrestir::gpu::Gpu;
use psrestir::optim::{self, run::RunOptions};
use psrestir::render::{RenderSettings, Renderer, Techniques};
use psrestir::scene::{self, EnvMap};
use psrestir::task::Task;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

#[derive(Parser)]
#[command(
    name = "psrestir",
    version,
    about = "Inverse texture optimization with parameter-space ReSTIR gradients, on wgpu"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum TechniqueArg {
    /// Light and BSDF sampling combined by MIS (power heuristic).
    Mis,
    /// Light sampling (next-event estimation) only.
    Nee,
    /// BSDF sampling only (delta lights still use light sampling).
    Bsdf,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum MethodArg {
    /// Parameter-space ReSTIR: per-texel reservoirs reused across iterations.
    Restir,
    /// Plain Monte Carlo: every sample adds its derivative to the texels it touches.
    Baseline,
}

/// Choice of gradient estimator, shared by the commands that estimate gradients.
#[derive(clap::Args)]
struct EstimatorArgs {
    /// Gradient estimator.
    #[arg(long, value_enum, default_value = "restir")]
    method: MethodArg,
    #[command(flatten)]
    restir: RestirArgs,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum ConfidenceArg {
    /// Gradient samples per pixel (the reference code's convention).
    Samples,
    /// Candidates per pixel and texel: 2 techniques x gradient spp x cameras.
    Candidates,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum PrimalArg {
    /// An independent render at the primal spp.
    Independent,
    /// The recursive control variate: the render carried over from the last iteration.
    ControlVariate,
}

impl PrimalArg {
    fn mode(self) -> optim::PrimalMode {
        match self {
            PrimalArg::Independent => optim::PrimalMode::Independent,
            PrimalArg::ControlVariate => optim::PrimalMode::ControlVariate,
        }
    }
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum ProtocolArg {
    /// Each task's own sampling settings.
    Default,
    /// The paper's: primal 32 spp, gradient 1 spp, nearest filtering.
    Paper,
}

#[derive(clap::Args)]
struct RestirArgs {
    /// ReSTIR: cap on the confidence of the kept sample.
    #[arg(long, default_value_t = optim::RestirOptions::default().m_cap)]
    m_cap: f32,
    /// ReSTIR: confidence of the fresh candidates in the merge.
    #[arg(long, value_enum, default_value = "samples")]
    confidence: ConfidenceArg,
    /// ReSTIR ablation: resample within each iteration only.
    #[arg(long)]
    no_temporal: bool,
    /// ReSTIR ablation: one reservoir per texel over |target| instead of two.
    #[arg(long)]
    no_positivization: bool,
    /// ReSTIR: weight of the last target adjoint in this iteration's (an exponential moving
    /// average of the adjoints for the resampling targets; 0: this iteration's adjoint).
    /// Default: 0.9 with the independent primal, 0 with the control variate.
    #[arg(long)]
    target_smoothing: Option<f32>,
}

impl RestirArgs {
    /// The options, refused here (before any scene is loaded) when invalid.
    fn resolve(&self) -> Result<optim::RestirOptions> {
        let o = optim::RestirOptions {
            m_cap: self.m_cap,
            confidence: match self.confidence {
                ConfidenceArg::Samples => optim::Confidence::Samples,
                ConfidenceArg::Candidates => optim::Confidence::Candidates,
            },
            temporal: !self.no_temporal,
            positivization: !self.no_positivization,
            verify_paths: false,
            target_smoothing: self.target_smoothing,
        };
        o.validate()?;
        Ok(o)
    }
}

impl EstimatorArgs {
    fn resolve(&self) -> Result<(optim::Method, optim::RestirOptions)> {
        let method = match self.method {
            MethodArg::Restir => optim::Method::Restir,
            MethodArg::Baseline => optim::Method::Baseline,
        };
        Ok((method, self.restir.resolve()?))
    }
}

/// The bundled default task.
const DEFAULT_TASK: &str = "scenes/default/task.toml";

#[derive(Subcommand)]
enum Command {
    /// Render a glTF scene with direct lighting.
    Render {
        /// The scene (.gltf or .glb).
        scene: PathBuf,
        /// Camera, by name or index (default: the first).
        #[arg(long)]
        camera: Option<String>,
        /// Samples per pixel.
        #[arg(long, default_value_t = 64)]
        spp: u32,
        /// Image size WxH (default: 512 wide, height from the camera's aspect ratio).
        #[arg(long, value_parser = parse_size)]
        size: Option<(u32, u32)>,
        /// Environment light: an equirectangular .exr or .hdr image.
        #[arg(long)]
        env: Option<PathBuf>,
        /// Multiplier for the environment light.
        #[arg(long, default_value_t = 1.0)]
        env_scale: f32,
        /// Random seed.
        #[arg(long, default_value_t = 1)]
        seed: u32,
        /// Sampling techniques for area and environment lights.
        #[arg(long, value_enum, default_value = "mis")]
        technique: TechniqueArg,
        /// Output image: .exr (linear) or .png (sRGB).
        #[arg(short, long)]
        output: PathBuf,
        /// A camera file from a capture tool (NeRF-style transforms.json, or a COLMAP text
        /// model: its folder, cameras.txt or images.txt); render its frame `--frame`.
        #[arg(long)]
        cameras: Option<PathBuf>,
        /// The frame of `--cameras` to render (index, or the image's name).
        #[arg(long, default_value = "0")]
        frame: String,
    },
    /// Recover textures from target images by gradient descent.
    Optimize {
        /// The task file (TOML); the bundled default task when absent.
        task: Option<PathBuf>,
        #[command(flatten)]
        estimator: EstimatorArgs,
        /// Iterations (overrides the task).
        #[arg(long)]
        iterations: Option<u32>,
        /// Wall-clock budget in seconds (overrides the task).
        #[arg(long)]
        time_budget: Option<f64>,
        /// Output folder (overrides the task).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Continue from the checkpoint in the output folder.
        #[arg(long)]
        resume: bool,
        /// Primal estimator (overrides the task).
        #[arg(long, value_enum)]
        primal: Option<PrimalArg>,
        /// Levels of the multiscale gradient, 0 (off) to 4 (overrides the task).
        #[arg(long, value_parser = clap::value_parser!(u32).range(0..=4))]
        multiscale_levels: Option<u32>,
        /// Weight of the smoothness prior, 0 (off) or more (overrides the task).
        #[arg(long)]
        smoothness: Option<f32>,
    },
    /// Write one gradient estimate at the task's initial textures, as images in texel space.
    Gradient {
        /// The task file (TOML).
        task: PathBuf,
        #[command(flatten)]
        estimator: EstimatorArgs,
        /// Output folder.
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Print what a scene holds: triangles, materials, textures, cameras, lights.
    Info {
        /// The scene (.gltf or .glb).
        scene: PathBuf,
    },
    /// Benchmark baseline against ReSTIR (equal-time gradient error, equal-time optimization,
    /// cost) on the bundled benchmark scenes or given tasks; writes bench.json, report.md and
    /// plots.
    Bench {
        /// Scenes: names of bundled benchmark scenes (vase, lattice, dish, sphere), task
        /// files, or folders holding task.toml (default: every bundled benchmark scene).
        scenes: Vec<String>,
        /// Seconds of optimization per estimator and scene.
        #[arg(long, default_value_t = 60.0)]
        budget_s: f64,
        /// Output folder.
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
        /// Multiply image and texture sizes (e.g. 4 for GPU-size runs, 0.5 for a quick look).
        #[arg(long, default_value_t = 1.0)]
        scale: f64,
        /// ReSTIR iterations before the gradient error is measured.
        #[arg(long, default_value_t = 20)]
        warmup: u32,
        /// ReSTIR estimates under the converged adjoint, at the textures after the warm-up,
        /// before its estimator-only gradient error is measured.
        #[arg(long, default_value_t = 20)]
        settle: u32,
        /// Successive estimates averaged for the error of their mean (estimator-only).
        #[arg(long, default_value_t = 10)]
        successive: u32,
        /// Seeds the gradient error is averaged over.
        #[arg(long, default_value_t = 3)]
        repeats: u32,
        /// Gradient samples per pixel of the reference gradient.
        #[arg(long, default_value_t = 256)]
        reference_spp: u32,
        /// Samples per pixel of the primal render of the converged adjoint (the reference and
        /// the estimator-only errors are computed under it).
        #[arg(long, default_value_t = 256)]
        reference_primal_spp: u32,
        /// Sampling settings: the tasks' own, or the paper's (primal 32 spp, gradient 1 spp,
        /// nearest filtering).
        #[arg(long, value_enum, default_value = "default")]
        protocol: ProtocolArg,
        /// Measure the gradient error only (skip the equal-time optimization).
        #[arg(long)]
        gradient_only: bool,
        /// Primal estimator of every run (default: each task's own).
        #[arg(long, value_enum)]
        primal: Option<PrimalArg>,
        /// Samples per pixel of the renders that measure image error.
        #[arg(long, default_value_t = 64)]
        eval_spp: u32,
        /// Also write the report to the checkout in the current folder: docs/results.md,
        /// and the headline table in README.md (between its `bench:headline` markers).
        #[arg(long)]
        report: bool,
        #[command(flatten)]
        restir: RestirArgs,
    },
    /// Print the GPU adapter psrestir would use, its features and limits.
    Adapter,
    /// Regenerate the bundled scenes (scenes/default and scenes/bench/*).
    #[command(hide = true)]
    MakeScenes {
        /// Output folder.
        #[arg(default_value = "scenes")]
        dir: PathBuf,
    },
}

fn parse_size(s: &str) -> std::result::Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("`{s}` is not WxH, e.g. 256x256"))?;
    let w: u32 = w
        .trim()
        .parse()
        .map_err(|_| format!("bad width in `{s}`"))?;
    let h: u32 = h
        .trim()
        .parse()
        .map_err(|_| format!("bad height in `{s}`"))?;
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(format!("size `{s}` out of range (1..16384)"));
    }
    Ok((w, h))
}

fn main() {
    // Mesa's Vulkan loader complains on stderr when this is unset (headless machines, CI).
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir());
    }
    // A panic inside a third-party decoder is caught and reported as an error naming the
    // file; the default hook would also print it as a crash.
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if !psrestir::error::panic_is_guarded() {
            default_hook(info)
        }
    }));
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("psrestir=info"))
        .format_timestamp(None)
        .init();
    let cli = Cli::parse();
    if let Err(e) = run(cli) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Render {
            scene: path,
            camera,
            spp,
            size,
            env,
            env_scale,
            seed,
            technique,
            output,
            cameras,
            frame,
        } => {
            let ext = output
                .extension()
                .map(|e| e.to_string_lossy().to_ascii_lowercase());
            if !matches!(ext.as_deref(), Some("exr") | Some("png")) {
                bail!(
                    "{}: output must end in .exr (linear) or .png (sRGB)",
                    output.display()
                );
            }
            if spp == 0 {
                bail!("--spp must be at least 1");
            }
            if !(env_scale.is_finite() && env_scale >= 0.0) {
                bail!("--env-scale must be a finite number >= 0");
            }
            let mut sc = scene::load(&path)?;
            if let Some(env) = env {
                let mut map = EnvMap::load(&env)?;
                map.scale = env_scale;
                sc.env = Some(map);
            }
            let cam = match &cameras {
                Some(file) => {
                    if camera.is_some() {
                        bail!("give --camera or --cameras, not both");
                    }
                    let frames = scene::capture::load_frames(file)?;
                    let i = frames
                        .iter()
                        .position(|f| f.camera.name == frame)
                        .or_else(|| frame.parse::<usize>().ok().filter(|&i| i < frames.len()))
                        .with_context(|| {
                            format!(
                                "{}: no frame `{frame}` ({} frames: 0..{} or their names)",
                                file.display(),
                                frames.len(),
                                frames.len()
                            )
                        })?;
                    sc.cameras.push(frames[i].camera.clone());
                    sc.cameras.len() - 1
                }
                None => {
                    for note in sc.add_defaults() {
                        log::warn!("{}: {note}", path.display());
                    }
                    sc.camera(camera.as_deref())?
                }
            };
            if cameras.is_some() {
                for note in sc.add_defaults() {
                    log::warn!("{}: {note}", path.display());
                }
            }
            let (width, height) = size.unwrap_or_else(|| {
                match sc.cameras[cam].intrinsics {
                    // A capture's own image size.
                    Some(k) => (k.width, k.height),
                    None => {
                        let aspect = sc.cameras[cam].aspect.unwrap_or(1.0).clamp(0.05, 20.0);
                        (512, ((512.0 / aspect).round() as u32).max(1))
                    }
                }
            });
            let gpu = Gpu::new()?;
            let renderer = Renderer::new(&gpu, &sc)
                .with_context(|| format!("preparing {} for the GPU", path.display()))?;
            let bar = ProgressBar::new(spp as u64).with_style(
                ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} spp, ETA {eta}")
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            bar.set_message("rendering");
            let out = renderer.render(
                &RenderSettings {
                    width,
                    height,
                    spp,
                    seed,
                    camera: cam,
                    techniques: match technique {
                        TechniqueArg::Mis => Techniques::Mis,
                        TechniqueArg::Nee => Techniques::NeeOnly,
                        TechniqueArg::Bsdf => Techniques::BsdfOnly,
                    },
                },
                |done| bar.set_position(done as u64),
            )?;
            bar.finish_and_clear();
            out.image.save(&output)?;
            if out.dropped > 0 {
                log::warn!("{} non-finite samples were dropped", out.dropped);
            }
            println!(
                "wrote {} ({width}x{height}, {spp} spp, camera `{}`) in {:.2} s: {:.2} M rays/s \
                 ({} camera, {} shadow, {} BSDF rays; {} triangles)",
                output.display(),
                sc.cameras[cam].name,
                out.seconds,
                out.rays_per_second() / 1e6,
                out.camera_rays,
                out.shadow_rays,
                out.bsdf_rays,
                sc.triangles.len()
            );
        }
        Command::Optimize {
            task,
            estimator,
            iterations,
            time_budget,
            out,
            resume,
            primal,
            multiscale_levels,
            smoothness,
        } => {
            let path = task.unwrap_or_else(|| PathBuf::from(DEFAULT_TASK));
            let mut task = Task::load(&path)?;
            if let Some(p) = primal {
                task.optimizer.primal = p.mode();
            }
            if let Some(l) = multiscale_levels {
                task.optimizer.multiscale_levels = l;
            }
            if let Some(s) = smoothness {
                task.optimizer.smoothness = s;
            }
            if let Some(b) = time_budget {
                if !(b.is_finite() && b > 0.0) {
                    bail!("--time-budget must be a positive number of seconds");
                }
            }
            let (method, restir) = estimator.resolve()?;
            let gpu = Gpu::new()?;
            // Ctrl-C (or SIGTERM) finishes the iteration under way, then writes the checkpoint
            // and the outputs; a second one exits at once.
            let interrupt = Arc::new(AtomicBool::new(false));
            let flag = interrupt.clone();
            ctrlc::set_handler(move || {
                if flag.swap(true, Ordering::SeqCst) {
                    std::process::exit(130);
                }
                eprintln!(
                    "\ninterrupted: writing the checkpoint and outputs (Ctrl-C again to quit now)"
                );
            })
            .context("installing the Ctrl-C handler")?;
            let summary = optim::run::run(
                &gpu,
                &task,
                &RunOptions {
                    method,
                    restir,
                    iterations,
                    time_budget_s: time_budget,
                    out,
                    resume,
                    progress: true,
                    interrupt: Some(interrupt),
                },
            )
            .with_context(|| format!("optimizing {}", path.display()))?;
            println!(
                "{} iterations in {:.1} s ({:.1} ms/iteration), final loss {:.4e}{}; outputs in {}",
                summary.iterations,
                summary.elapsed_s,
                summary.ms_per_iteration,
                summary.final_loss,
                match (summary.initial_rmse, summary.final_rmse) {
                    (Some(a), Some(b)) => format!(", texture RMSE {a:.4} -> {b:.4}"),
                    _ => String::new(),
                } + &match (summary.initial_rmse_observed, summary.final_rmse_observed) {
                    (Some(a), Some(b)) => format!(" (observed texels {a:.4} -> {b:.4})"),
                    _ => String::new(),
                },
                summary.out.display()
            );
            if let Some(t) = summary.pass_times {
                println!(
                    "GPU time per iteration: primal {:.1} ms, loss {:.2} ms, gradient {:.1} ms, merge {:.1} ms, Adam {:.2} ms",
                    t.primal_ms, t.loss_ms, t.gradient_ms, t.merge_ms, t.adam_ms
                );
            }
            if summary.interrupted {
                println!(
                    "interrupted at iteration {}; continue with: psrestir optimize {} --out {} --resume",
                    summary.iterations,
                    path.display(),
                    summary.out.display()
                );
                std::process::exit(130);
            }
        }
        Command::Gradient {
            task,
            estimator,
            output,
        } => {
            let (method, restir) = estimator.resolve()?;
            let task_path = task;
            let task = Task::load(&task_path)?;
            let gpu = Gpu::new()?;
            let written = optim::run::write_gradient(&gpu, &task, &output, method, restir)
                .with_context(|| format!("estimating the gradient of {}", task_path.display()))?;
            for p in written {
                println!("wrote {}", p.display());
            }
        }
        Command::Info { scene: path } => {
            let sc = scene::load(&path)?;
            println!("{}", path.display());
            println!("  triangles: {}", sc.triangles.len());
            println!("  materials: {}", sc.materials.len());
            for m in &sc.materials {
                println!(
                    "    {}: base color {:?}{}, metallic {}, roughness {}{}, emissive {:?}{}",
                    m.name,
                    m.base_color.to_array(),
                    if m.base_color_texture.is_some() {
                        " x texture"
                    } else {
                        ""
                    },
                    m.metallic,
                    m.roughness,
                    if m.metallic_roughness_texture.is_some() {
                        " x texture"
                    } else {
                        ""
                    },
                    m.emissive.to_array(),
                    if m.double_sided { ", double-sided" } else { "" },
                );
            }
            println!("  images: {}", sc.images.len());
            for i in &sc.images {
                println!("    {}: {}x{}", i.name, i.width, i.height);
            }
            println!("  cameras: {}", sc.cameras.len());
            for (i, c) in sc.cameras.iter().enumerate() {
                println!("    {i}: {} (yfov {:.3} rad)", c.name, c.yfov);
            }
            println!("  punctual lights: {}", sc.lights.len());
            for l in &sc.lights {
                println!(
                    "    {}: {:?}, intensity {:?}",
                    l.name,
                    l.kind,
                    l.intensity.to_array()
                );
            }
            for w in &sc.warnings {
                println!("  warning: {w}");
            }
        }
        Command::Bench {
            scenes,
            budget_s,
            out,
            scale,
            warmup,
            settle,
            successive,
            repeats,
            reference_spp,
            reference_primal_spp,
            protocol,
            gradient_only,
            primal,
            eval_spp,
            report: to_docs,
            restir,
        } => {
            if to_docs {
                // Before the hours of measuring: the checkout must be where the report goes.
                let readme = std::fs::read_to_string("README.md").context(
                    "--report: README.md in the current folder (run it in the checkout)",
                )?;
                psrestir::bench::report::replace_headline(&readme, "")
                    .map_err(|m| anyhow::anyhow!("--report: README.md: {m}"))?;
            }
            let names: Vec<String> = if scenes.is_empty() {
                assets::bench_scenes::BENCH_SCENES
                    .iter()
                    .map(|s| s.to_string())
                    .collect()
            } else {
                scenes
            };
            let tasks = names
                .iter()
                .map(|n| psrestir::bench::resolve_scene(n))
                .collect::<std::result::Result<Vec<_>, _>>()?;
            let opts = psrestir::bench::BenchOptions {
                budget_s,
                scale,
                warmup,
                settle,
                successive,
                repeats,
                reference_spp,
                reference_primal_spp,
                protocol: match protocol {
                    ProtocolArg::Default => psrestir::bench::Protocol::Default,
                    ProtocolArg::Paper => psrestir::bench::Protocol::Paper,
                },
                gradient_only,
                primal: primal.map(PrimalArg::mode),
                eval_spp,
                restir: restir.resolve()?,
                out: out.clone(),
                progress: std::io::IsTerminal::is_terminal(&std::io::stderr()),
                ..Default::default()
            };
            let gpu = Gpu::new()?;
            let report = psrestir::bench::bench(&gpu, &tasks, &opts)?;
            println!("{}", psrestir::bench::report::table(&report));
            println!("wrote {}", out.join("report.md").display());
            if to_docs {
                let command: Vec<String> = std::env::args().skip(1).collect();
                psrestir::bench::report::write_docs(
                    std::path::Path::new("."),
                    &report,
                    &format!("psrestir {}", command.join(" ")),
                )?;
                println!("wrote docs/results.md and the headline table in README.md");
            }
        }
        Command::Adapter => {
            let gpu = Gpu::new()?;
            println!("{}", gpu.describe());
            println!("device type: {:?}", gpu.info.device_type);
            println!("timestamp queries: {}", gpu.timestamps);
            let l = gpu.device.limits();
            println!(
                "max storage buffer binding: {} MiB, storage buffers per stage: {}, workgroups per dimension: {}",
                l.max_storage_buffer_binding_size >> 20,
                l.max_storage_buffers_per_shader_stage,
                l.max_compute_workgroups_per_dimension
            );
            let offered = gpu
                .adapter_features
                .is_some_and(|f| f.contains(wgpu::Features::EXPERIMENTAL_RAY_QUERY));
            println!(
                "hardware ray queries: {}",
                if offered { "offered" } else { "not offered" }
            );
            println!(
                "tracing with: {} (PSRESTIR_TRACER=software|ray-query|auto chooses)",
                match gpu.tracer {
                    psrestir::gpu::Tracer::Software => "the software BVH (binned SAH, in WGSL)",
                    psrestir::gpu::Tracer::RayQuery => "ray queries",
                }
            );
        }
        Command::MakeScenes { dir } => {
            assets::bundled::write_default_scene(&dir.join("default"))?;
            println!("wrote {}", dir.join("default").display());
            assets::bench_scenes::write_bench_scenes(&dir.join("bench"))?;
            println!("wrote {}", dir.join("bench").display());
        }
    }
    Ok(())
}
