//! The `psrestir` command-line tool.
mod cli;
mod inspect;

use anyhow::{bail, Context, Result};
use clap::Parser;
use cli::*;
use indicatif::{ProgressBar, ProgressStyle};
use psrestir::assets;
use psrestir::gpu::Gpu;
use psrestir::job::{self, run::RunOptions};
use psrestir::render::{RenderSettings, Renderer, Techniques};
use psrestir::scene::{self, EnvMap};
use psrestir::task::Task;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

fn main() {
    // Mesa's Vulkan loader complains on stderr when this is unset (headless machines, CI).
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir());
    }
    // lavapipe's shaders at 4 lanes: half the compilation, the same speed (see the function).
    psrestir::gpu::prefer_narrow_cpu_simd();
    // A panic inside a third-party decoder is caught and reported as an error naming the
    // file; the default hook would also print it as a crash.
    // Output piped into a reader that stops early (`psrestir estimators | head`) ends the
    // program quietly, as the usual command-line tools do, not with a panic's backtrace.
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let message = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .unwrap_or_default();
        if message.starts_with("failed printing to stdout") && message.contains("Broken pipe") {
            std::process::exit(0);
        }
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
        Command::Render(args) => cmd_render(args)?,
        Command::Optimize(args) => cmd_optimize(args)?,
        Command::Gradient {
            task,
            estimator,
            output,
        } => {
            let task_path = task;
            let task = Task::load(&task_path)?;
            let (method, options) = estimator.resolve(task.optimizer.method)?;
            let gpu = Gpu::new()?;
            let written = job::run::write_gradient(&gpu, &task, &output, method, &options)
                .with_context(|| format!("estimating the gradient of {}", task_path.display()))?;
            for p in written {
                println!("wrote {}", p.display());
            }
        }
        Command::Info { scene: path } => inspect::cmd_info(&path)?,
        Command::Bench(args) => cmd_bench(args)?,
        Command::Estimators => inspect::cmd_estimators(),
        Command::Adapter => inspect::cmd_adapter()?,
        Command::MakeScenes {
            dir,
            family: Some(split),
            count,
        } => {
            for task in assets::family::write_split(&dir, split, count)? {
                println!("wrote {}", task.display());
            }
        }
        Command::MakeScenes { dir, .. } => {
            assets::bundled::write_default_scene(&dir.join("default"))?;
            println!("wrote {}", dir.join("default").display());
            assets::bench_scenes::write_bench_scenes(&dir.join("bench"))?;
            println!("wrote {}", dir.join("bench").display());
        }
    }
    Ok(())
}

/// The camera of `psrestir render`: a frame of a camera file (`--cameras`, `--frame`) or one
/// of the scene's (`--camera`), with the scene's defaults added.
fn choose_camera(
    sc: &mut scene::Scene,
    path: &std::path::Path,
    camera: Option<&str>,
    cameras: Option<&std::path::Path>,
    frame: &str,
    no_default_env: bool,
) -> Result<usize> {
    let cam = match cameras {
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
            for note in sc.add_defaults(!no_default_env) {
                log::warn!("{}: {note}", path.display());
            }
            sc.camera(camera)?
        }
    };
    if cameras.is_some() {
        for note in sc.add_defaults(!no_default_env) {
            log::warn!("{}: {note}", path.display());
        }
    }
    Ok(cam)
}

/// `psrestir render`.
fn cmd_render(args: RenderArgs) -> Result<()> {
    let RenderArgs {
        scene: path,
        camera,
        spp,
        size,
        env,
        env_scale,
        no_default_env,
        lights,
        seed,
        technique,
        max_depth,
        output,
        cameras,
        frame,
    } = args;
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
    sc.max_depth = scene::MaxDepth::new(max_depth.unwrap_or(1)).map_err(anyhow::Error::msg)?;
    if let Some(env) = env {
        let mut map = EnvMap::load(&env)?;
        map.scale = env_scale;
        sc.env = Some(map);
    }
    let cam = choose_camera(
        &mut sc,
        &path,
        camera.as_deref(),
        cameras.as_deref(),
        &frame,
        no_default_env,
    )?;
    if let Some(names) = lights {
        let on = sc
            .light_indices(&names)
            .map_err(|m| anyhow::anyhow!("{}: --lights: {m}", path.display()))?;
        sc.cameras[cam].lights = Some(on);
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
    log::info!(
        "preparing the render passes (a driver's first run on a machine compiles their \
         shaders; later runs load them from its cache)"
    );
    let renderer = Renderer::new(&gpu, &sc)
        .with_context(|| format!("preparing {} for the GPU", path.display()))?;
    let (n, seconds) = gpu.pipeline_seconds_since(0);
    log::info!("{n} GPU passes ready after {seconds:.1} s of pipeline creation");
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
    Ok(())
}

/// The task of `psrestir optimize` with its flags applied (the task file's path, the task).
fn task_with_flags(args: &OptimizeArgs) -> Result<(PathBuf, Task)> {
    let &OptimizeArgs {
        ref task,
        lr_scale,
        moment_filter,
        moment_filter_sigma,
        moment_filter_taps,
        moment_filter_own_weight,
        moment_filter_log,
        moment_filter_write_back,
        ..
    } = args;
    let path = task.clone().unwrap_or_else(|| PathBuf::from(DEFAULT_TASK));
    let sets = args.task_sets();
    let mut task = Task::load_with(&path, &sets)?;
    if let Some(f) = lr_scale {
        if !(f.is_finite() && f > 0.0) {
            bail!("--lr-scale must be a positive number");
        }
        // A texture without a rate scales the one `auto` gives it under the task's step.
        let config = psrestir::task::task_configuration(
            &task,
            task.optimizer.method,
            psrestir::task::named_cameras(&task),
        );
        for t in &mut task.textures {
            let rate = t.learning_rate.unwrap_or_else(|| config.rate(t.slot));
            t.learning_rate = Some(rate * f);
        }
    }
    // A flag on the filter changes the filter the task would run with (its own, or `auto`'s
    // for its step).
    let filter_flags = moment_filter.is_some()
        || moment_filter_sigma.is_some()
        || moment_filter_taps.is_some()
        || moment_filter_own_weight.is_some()
        || moment_filter_log
        || moment_filter_write_back;
    if filter_flags && task.optimizer.moment_filter.is_none() {
        let cameras = psrestir::task::named_cameras(&task);
        let c = psrestir::task::task_configuration(&task, task.optimizer.method, cameras);
        task.optimizer.moment_filter = Some(c.moment_filter);
    }
    let mut unset = Default::default();
    let mf = task.optimizer.moment_filter.as_mut().unwrap_or(&mut unset);
    mf.levels = moment_filter.unwrap_or(mf.levels);
    mf.sigma = moment_filter_sigma.unwrap_or(mf.sigma);
    mf.taps = moment_filter_taps.unwrap_or(mf.taps);
    mf.own_weight = moment_filter_own_weight.unwrap_or(mf.own_weight);
    mf.log_space |= moment_filter_log;
    mf.write_back |= moment_filter_write_back;
    Ok((path, task))
}

/// `psrestir optimize`.
fn cmd_optimize(args: OptimizeArgs) -> Result<()> {
    let (path, task) = task_with_flags(&args)?;
    if let Some(b) = args.time_budget {
        if !(b.is_finite() && b > 0.0) {
            bail!("--time-budget must be a positive number of seconds");
        }
    }
    let OptimizeArgs {
        estimator,
        iterations,
        time_budget,
        out,
        resume,
        ..
    } = args;
    let (method, estimator_options) = estimator.resolve(task.optimizer.method)?;
    let gpu = Gpu::new()?;
    // Ctrl-C (or SIGTERM) finishes the iteration under way, then writes the checkpoint
    // and the outputs; a second one exits at once.
    let interrupt = Arc::new(AtomicBool::new(false));
    let flag = interrupt.clone();
    ctrlc::set_handler(move || {
        if flag.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
        eprintln!("\ninterrupted: writing the checkpoint and outputs (Ctrl-C again to quit now)");
    })
    .context("installing the Ctrl-C handler")?;
    let summary = job::run::run(
        &gpu,
        &task,
        &RunOptions {
            method,
            estimator_options,
            iterations,
            time_budget_s: time_budget,
            out,
            resume,
            progress: true,
            interrupt: Some(interrupt),
            on_row: None,
        },
    )
    .with_context(|| format!("optimizing {}", path.display()))?;
    print_summary(&summary, &path);
    Ok(())
}

/// What `psrestir optimize` prints at the end (and the exit after an interrupt).
fn print_summary(summary: &job::run::RunSummary, path: &std::path::Path) {
    println!(
        "{} iterations in {:.1} s ({}), final loss {:.4e}{}; outputs in {}",
        summary.iterations,
        summary.elapsed_s,
        // NaN where a resumed run found every iteration done and ran none.
        if summary.ms_per_iteration.is_finite() {
            format!("{:.1} ms/iteration", summary.ms_per_iteration)
        } else {
            "none run in this session".to_string()
        },
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
    if summary.per_texture.len() > 1 {
        let parts: Vec<String> = summary
            .per_texture
            .iter()
            .map(|t| {
                let angle = t
                    .angle_deg_observed
                    .map(|(a, b)| format!(" (mean angle {a:.2} -> {b:.2} degrees)"))
                    .unwrap_or_default();
                format!(
                    "{} {:.4} -> {:.4}{angle}",
                    t.texture, t.initial_rmse_observed, t.final_rmse_observed
                )
            })
            .collect();
        println!("observed-texel RMSE per texture: {}", parts.join(", "));
    }
    if let Some(t) = summary.pass_times {
        let timed = t.total();
        println!(
            "GPU time per iteration: primal {:.1} ms, loss {:.2} ms, gradient {:.1} ms, combine {:.1} ms, priors {:.2} ms, step {:.2} ms{}; \
             the other {:.1} ms of the {:.1} ms per iteration are outside these passes (untimed \
             copies and clears, submission, host work)",
            t.primal_ms,
            t.loss_ms,
            t.gradient_ms,
            t.combine_ms,
            t.prior_ms,
            t.step_ms,
            if t.filter_ms > 0.0 {
                format!(", moment filter {:.2} ms", t.filter_ms)
            } else {
                String::new()
            },
            (summary.ms_per_iteration - timed).max(0.0),
            summary.ms_per_iteration
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

/// `psrestir bench`.
fn cmd_bench(args: BenchArgs) -> Result<()> {
    let BenchArgs {
        scenes,
        budget_s,
        out,
        scale,
        warmup,
        settle,
        successive,
        repeats,
        seeds,
        reference_spp,
        reference_primal_spp,
        protocol,
        gradient_only,
        end_to_end_only,
        contenders,
        no_priors,
        peers,
        peer_python,
        tune_peers,
        max_depth,
        throughput,
        tune,
        tune_budget,
        primal,
        path_cache,
        eval_spp,
        report: to_docs,
        report_from,
        options,
        gradient_method,
    } = args;
    let mut estimator_options = psrestir::optim::EstimatorOptions::default();
    for a in &options {
        estimator_options.assign(a)?;
    }
    let contenders = parse_contenders(&contenders)?;
    if let Some(b) = tune_budget {
        if !(b.is_finite() && b > 0.0) {
            bail!("--tune-budget must be a positive number of seconds");
        }
    }
    if let Some(path) = report_from {
        return bench_report_from(&path);
    }
    if throughput {
        let name = scenes.first().map_or(DEFAULT_TASK, |s| s.as_str());
        return bench_throughput(name, max_depth, &out);
    }
    if to_docs {
        check_report_target()?;
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
    let command = format!(
        "psrestir {}",
        std::env::args().skip(1).collect::<Vec<_>>().join(" ")
    );
    let opts = psrestir::bench::BenchOptions {
        budget_s: budget_s.unwrap_or(60.0),
        task_budgets: budget_s.is_none(),
        scale,
        warmup,
        settle,
        successive,
        repeats,
        seeds,
        reference_spp,
        reference_primal_spp,
        protocol: match protocol {
            ProtocolArg::Default => psrestir::bench::Protocol::Default,
            ProtocolArg::Paper => psrestir::bench::Protocol::Paper,
        },
        gradient_only,
        end_to_end_only,
        contenders,
        no_priors,
        tune,
        tune_budget_s: tune_budget,
        tune_peers,
        mitsuba: mitsuba_python(&peers, peer_python),
        primal: primal.map(PrimalArg::mode),
        path_cache,
        max_depth,
        eval_spp,
        estimator_options,
        gradient_method,
        out: out.clone(),
        command: Some(command.clone()),
        progress: std::io::IsTerminal::is_terminal(&std::io::stderr()),
        ..Default::default()
    };
    let gpu = Gpu::new()?;
    let report = psrestir::bench::bench(&gpu, &tasks, &opts)?;
    println!("{}", psrestir::bench::report::table(&report));
    println!("wrote {}", out.join("report.md").display());
    if to_docs {
        psrestir::bench::report::write_docs(std::path::Path::new("."), &report, &command)?;
        println!("wrote docs/results.md and the headline table in README.md");
    }
    Ok(())
}

/// `--report`, before the hours of measuring: the checkout must be where the report goes.
fn check_report_target() -> Result<()> {
    let readme = std::fs::read_to_string("README.md")
        .context("--report: README.md in the current folder (run it in the checkout)")?;
    psrestir::bench::report::replace_headline(&readme, "")
        .map_err(|m| anyhow::anyhow!("--report: README.md: {m}"))?;
    Ok(())
}

/// `--contenders`: the bench's contenders (`none` for none).
fn parse_contenders(list: &[String]) -> Result<Vec<psrestir::bench::Contender>> {
    list.iter()
        .filter(|c| c.as_str() != "none")
        .map(|c| psrestir::bench::Contender::parse(c))
        .collect::<std::result::Result<Vec<_>, _>>()
        .map_err(|m| anyhow::anyhow!("--contenders: {m}"))
}

/// With `mitsuba` among `peers`, `python` when it can run Mitsuba 3's race; else a warning
/// that says how to get it, and None: the bench runs without it.
fn mitsuba_python(peers: &[String], python: String) -> Option<String> {
    if !peers.iter().any(|p| p == "mitsuba") {
        return None;
    }
    match psrestir::bench::peer::check_mitsuba(&python) {
        Ok(v) => {
            eprintln!("racing Mitsuba {v} (llvm_ad_rgb) too");
            Some(python)
        }
        Err(why) => {
            eprintln!("warning: no Mitsuba 3 rows: {why}");
            None
        }
    }
}

/// `bench --report-from`: docs/results.md and README.md's headline written from an earlier
/// run's bench.json, without measuring.
fn bench_report_from(path: &std::path::Path) -> Result<()> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("--report-from: reading {}", path.display()))?;
    let report: psrestir::bench::BenchReport = serde_json::from_str(&text)
        .with_context(|| format!("--report-from: {} is not a bench.json", path.display()))?;
    let command = report.command.clone().unwrap_or_else(|| {
        "psrestir bench (an older bench.json: its command is not recorded)".into()
    });
    psrestir::bench::report::write_docs(std::path::Path::new("."), &report, &command)?;
    println!(
        "wrote docs/results.md and the headline table in README.md from {}",
        path.display()
    );
    Ok(())
}

/// `bench --throughput`: rays per second and pipeline creation on one scene.
fn bench_throughput(name: &str, max_depth: Option<u32>, out: &std::path::Path) -> Result<()> {
    let path = psrestir::bench::resolve_scene(name)?;
    let mut task = Task::load(&path)?;
    task.max_depth = max_depth.unwrap_or(task.max_depth);
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let gpu = Gpu::new()?;
    let r = psrestir::bench::throughput::throughput(&gpu, &task, &path, out)?;
    let md = psrestir::bench::throughput::markdown(&r);
    println!("{md}");
    let json = serde_json::to_string_pretty(&r).context("throughput.json")?;
    psrestir::image_io::write_atomic(&out.join("throughput.json"), json.as_bytes())?;
    psrestir::image_io::write_atomic(&out.join("throughput.md"), md.as_bytes())?;
    println!("wrote {}", out.join("throughput.md").display());
    Ok(())
}
