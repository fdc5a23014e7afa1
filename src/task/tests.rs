//! Task-file parsing and validation tests.
use super::*;

const GOOD: &str = r#"
scene = "scene.gltf"
width = 32
height = 16
[target]
scene = "gt.gltf"
[optimizer]
iterations = 10
[[textures]]
material = "m"
slot = "roughness"
resolution = [8, 8]
init = 0.5
learning_rate = 0.01
"#;

fn err(text: &str) -> String {
    Task::parse(text, Path::new("t.toml"))
        .unwrap_err()
        .to_string()
}

#[test]
fn a_good_task_parses_with_defaults() {
    let t = Task::parse(GOOD, Path::new("dir/t.toml")).unwrap();
    assert_eq!(t.optimizer.loss, Loss::L2);
    assert_eq!(t.optimizer.filter, Filter::Bilinear);
    assert_eq!(t.target.spp, 256);
    assert_eq!(t.max_depth, 1);
    assert_eq!(t.textures[0].init_values(), vec![0.5]);
    assert_eq!(
        t.resolve(Path::new("scene.gltf")),
        PathBuf::from("dir/scene.gltf")
    );
    assert_eq!(t.output_dir(), PathBuf::from("out/t"));
}

#[test]
fn unknown_keys_and_bad_values_name_the_key() {
    let e = err(&GOOD
        .replace("seed", "x")
        .replace("width = 32", "width = 32\nwidht = 3"));
    assert!(e.contains("t.toml") && e.contains("widht"), "{e}");
    for depth in [0, 65] {
        let e = err(&GOOD.replace("width = 32", &format!("width = 32\nmax_depth = {depth}")));
        assert!(
            e.contains("max_depth") && e.contains("1 (direct light only)"),
            "{e}"
        );
    }
    let t = Task::parse(
        &GOOD.replace("width = 32", "width = 32\nmax_depth = 3"),
        Path::new("t.toml"),
    );
    assert_eq!(t.unwrap().max_depth, 3);
    let e = err(&GOOD.replace("init = 0.5", "init = 0.5\nlearning_rat = 1"));
    assert!(e.contains("learning_rat"), "{e}");
    let e = err(&GOOD.replace("learning_rate = 0.01", "learning_rate = -1"));
    assert!(e.contains("textures[0].learning_rate"), "{e}");
    let e = err(&GOOD.replace("init = 0.5", "init = [0.5, 0.5, 0.5]"));
    assert!(
        e.contains("textures[0].init") && e.contains("1 value"),
        "{e}"
    );
    let e = err(&GOOD.replace("init = 0.5", "init = 0.0"));
    assert!(e.contains("textures[0].init") && e.contains("0.02"), "{e}");
    let e = err(&GOOD.replace("slot = \"roughness\"", "slot = \"shininess\""));
    assert!(e.contains("shininess"), "{e}");
    let e = err(&GOOD.replace("iterations = 10", ""));
    assert!(e.contains("`optimizer`"), "{e}");
    let e = err(&GOOD.replace("width = 32", "width = 0"));
    assert!(e.contains("`width`"), "{e}");
    let e = err(&GOOD.replace("resolution = [8, 8]", "resolution = [8, 0]"));
    assert!(e.contains("textures[0].resolution"), "{e}");
    let e = err(&GOOD.replace("[target]\nscene = \"gt.gltf\"", "[target]"));
    assert!(e.contains("`target`"), "{e}");
    let e = err(&GOOD.replace("iterations = 10", "iterations = 10\nprimal_spp = 0"));
    assert!(e.contains("optimizer.primal_spp"), "{e}");
    let e = err(&GOOD.replace("iterations = 10", "iterations = 10\nsmoothness = -0.1"));
    assert!(
        e.contains("optimizer.smoothness") && e.contains("between 0"),
        "{e}"
    );
    let e = err(&GOOD.replace("iterations = 10", "iterations = 10\ncv_max_weight = 1.5"));
    assert!(e.contains("optimizer.cv_max_weight"), "{e}");
    let e = err(&GOOD.replace("iterations = 10", "iterations = 10\nmultiscale_levels = 5"));
    assert!(
        e.contains("optimizer.multiscale_levels") && e.contains("between 0 and 4"),
        "{e}"
    );
}

#[test]
fn the_method_defaults_to_auto_and_resolves_by_the_tasks_sampling() {
    use crate::optim::{Method, MethodChoice};
    let t = Task::parse(GOOD, Path::new("t.toml")).unwrap();
    assert_eq!(t.optimizer.method, MethodChoice::Auto);
    // 32x16 pixels over 8x8 texels: dense, the baseline.
    assert_eq!(
        task_method(&t, t.optimizer.method, 1).method,
        Method::BASELINE
    );
    // 64x64 texels, sparse (1 gradient sample per 8 texels); a 32-spp primal: ReSTIR.
    let paper = GOOD
        .replace("iterations = 10", "iterations = 10\nprimal_spp = 32")
        .replace("resolution = [8, 8]", "resolution = [64, 64]");
    let t = Task::parse(&paper, Path::new("t.toml")).unwrap();
    let c = task_method(&t, t.optimizer.method, 1);
    assert_eq!((c.method, c.automatic), (Method::RESTIR, true));
    // A named estimator is kept.
    let fixed = paper.replace("primal_spp = 32", "primal_spp = 32\nmethod = \"baseline\"");
    let t = Task::parse(&fixed, Path::new("t.toml")).unwrap();
    assert_eq!(
        task_method(&t, t.optimizer.method, 1).method,
        Method::BASELINE
    );
    let e = err(&GOOD.replace("iterations = 10", "iterations = 10\nmethod = \"restri\""));
    assert!(
        e.contains("t.toml") && e.contains("restri") && e.contains("auto"),
        "{e}"
    );
}

#[test]
fn the_environment_table_parses_and_names_what_is_wrong() {
    let with = |table: &str| format!("{GOOD}\n[environment]\n{table}\n");
    let t = Task::parse(
        &with("resolution = [16, 8]\ninit = [0.4, 0.5, 0.6]"),
        Path::new("t.toml"),
    )
    .unwrap();
    let e = t.environment.as_ref().unwrap();
    assert!(e.optimize);
    let start = e.start(Path::new(".")).unwrap();
    assert_eq!((start.width, start.height), (16, 8));
    assert_eq!(start.rgb[5], [0.4, 0.5, 0.6]);
    for (table, key) in [
        ("learning_rate = 0", "environment.learning_rate"),
        ("rebuild_every = 0", "environment.rebuild_every"),
        ("resolution = [0, 8]", "environment.resolution"),
        ("resolution = [4096, 8]", "environment.resolution"),
        ("init = -1.0", "environment.init"),
        (
            "init = \"sky.exr\"\nresolution = [8, 4]",
            "environment.resolution",
        ),
        ("smoothness = -1", "environment.smoothness"),
        ("gauge = \"median\"", "gauge"),
        ("resolutoin = [8, 4]", "resolutoin"),
    ] {
        let e = err(&with(table));
        assert!(e.contains("t.toml") && e.contains(key), "{table}: {e}");
    }
    // A start file that is not there names itself.
    let t = Task::parse(&with("init = \"missing.exr\""), Path::new("t.toml")).unwrap();
    let e = t
        .environment
        .unwrap()
        .start(Path::new("d"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("missing.exr"), "{e}");
    // Relighting needs a ground truth to compare with.
    let photos = GOOD.replace("scene = \"gt.gltf\"", "images = { main = \"a.exr\" }");
    let e = err(&format!("relight = [\"dusk.exr\"]\n{photos}"));
    assert!(e.contains("relight") && e.contains("target.scene"), "{e}");
    let e = err(&GOOD.replace(
        "iterations = 10",
        "iterations = 10\nwhite_balance_learning_rate = 0",
    ));
    assert!(e.contains("optimizer.white_balance_learning_rate"), "{e}");
}

#[test]
fn set_options_are_checked_as_the_file_is_and_named() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.toml");
    std::fs::write(&path, GOOD).unwrap();
    let sets = |s: &[&str]| s.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    let t = Task::load_with(
        &path,
        &sets(&["optimizer.smoothness=0.1", "optimizer.step=adam"]),
    )
    .unwrap();
    assert_eq!(t.optimizer.smoothness(), Some(0.1));
    assert_eq!(t.optimizer.step, Some(crate::optim::StepKind::ADAM));
    for (bad, says) in [
        (
            "optimizer.smoothnes=0.1",
            "`optimizer.smoothnes`: unknown key",
        ),
        (
            "optimizer.smoothness=-1",
            "`optimizer.smoothness`: must be a number",
        ),
        ("optimizer.step=sideways", "unknown step `sideways`"),
    ] {
        let e = Task::load_with(&path, &sets(&[bad]))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("t.toml") && e.contains(says) && e.contains(&format!("--set {bad}")),
            "{e}"
        );
    }
}

/// The priors' tables and shorthands reach the settings as one table per prior; a clash, an
/// unknown option or a bad value names the key the task gave.
#[test]
fn prior_tables_and_shorthands_reach_the_settings() {
    use crate::optim::multiscale::MultiscaleOptions;
    use crate::optim::smoothness::SmoothnessOptions;
    use crate::optim::Method;
    let with = |extra: &str| GOOD.replace("iterations = 10", &format!("iterations = 10\n{extra}"));
    let settings = |text: &str| {
        let t = Task::parse(text, Path::new("t.toml")).unwrap();
        task_settings(&t, &[0], Method::BASELINE, &Default::default())
    };
    let s = settings(&with("multiscale_levels = 3\nsmoothness = 0.2"));
    assert_eq!(s.priors.of::<MultiscaleOptions>().levels, 3);
    assert_eq!(s.priors.of::<SmoothnessOptions>().weight, 0.2);
    let s = settings(&with(
        "[optimizer.multiscale]\nlevels = 2\n[optimizer.smoothness]\nweight = 0.5",
    ));
    assert_eq!(s.priors.of::<MultiscaleOptions>().levels, 2);
    assert_eq!(s.priors.of::<SmoothnessOptions>().weight, 0.5);
    assert_eq!(
        s.priors.describe_active(),
        "smoothness 0.5, multiscale 2 levels"
    );
    // Absent, the smoothness weight is auto's and the multiscale gradient off.
    let s = settings(GOOD);
    assert!(s.priors.of::<SmoothnessOptions>().weight > 0.0);
    assert_eq!(s.priors.active().len(), 1);
    // Every prior off.
    let mut t = Task::parse(&with("multiscale_levels = 3"), Path::new("t.toml")).unwrap();
    t.optimizer.priors_off();
    let s = task_settings(&t, &[0], Method::BASELINE, &Default::default());
    assert_eq!(s.priors.describe_active(), "none");
    let e = err(&with(
        "multiscale_levels = 3\n[optimizer.multiscale]\nlevels = 2",
    ));
    assert!(
        e.contains("`optimizer.multiscale_levels`") && e.contains("give one"),
        "{e}"
    );
    let e = err(&with("[optimizer.multiscale]\nlevls = 2"));
    assert!(
        e.contains("optimizer.multiscale") && e.contains("levls"),
        "{e}"
    );
    let e = err(&with("[optimizer.multiscale]\nlevels = 7"));
    assert!(
        e.contains("`optimizer.multiscale.levels`: must be between 0 and 4"),
        "{e}"
    );
    let e = err(&with("multiscale = 3"));
    assert!(
        e.contains("`optimizer.multiscale`: must be a table of the prior's options"),
        "{e}"
    );
}

/// Sparse steps apply to either step; the key's earlier, Adam-named spelling still reads.
#[test]
fn sparse_steps_read_under_both_names() {
    for key in ["sparse_steps", "adam_mask"] {
        let text = GOOD.replace("iterations = 10", &format!("iterations = 10\n{key} = true"));
        let t = Task::parse(&text, Path::new("t.toml")).unwrap();
        assert!(t.optimizer.sparse_steps, "{key}");
    }
    assert!(
        !Task::parse(GOOD, Path::new("t.toml"))
            .unwrap()
            .optimizer
            .sparse_steps
    );
}
