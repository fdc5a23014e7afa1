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
