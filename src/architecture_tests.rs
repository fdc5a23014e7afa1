//! The shape the code keeps, read from its sources: the optimizer is the per-iteration engine
//! and no more (its fields, the files its methods live in, the files at `src/optim/`'s root),
//! and no source file grows past what a reader takes in at once.
use crate::layering_tests::{files_under, without_strings};
use std::path::Path;

fn src() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

/// The engine holds at most 12 fields (its GPU, renderer, textures, settings, buffers, passes,
/// plugins, inputs, and the fit's and the run's state as values of their own rooms), its
/// methods live in at most 3 files (`optim/mod.rs`, `run/snapshot.rs`, `api/outward.rs`), and
/// `src/optim/` holds at most 10 files at its root, each other role in a folder of its own.
#[test]
fn the_optimizer_is_the_engine_and_no_more() {
    let engine = std::fs::read_to_string(src().join("optim/mod.rs")).unwrap();
    let body = engine
        .split_once("pub struct Optimizer {")
        .and_then(|(_, rest)| rest.split_once("\n}"))
        .expect("optim/mod.rs defines `pub struct Optimizer { ... }`")
        .0;
    let fields = body
        .lines()
        .map(str::trim)
        .filter(|l| !l.starts_with("//") && l.contains(':') && l.ends_with(','))
        .count();
    assert!((8..=12).contains(&fields), "Optimizer has {fields} fields");

    let mut with_methods: Vec<String> = files_under(&src(), "rs")
        .into_iter()
        .filter(|p| {
            std::fs::read_to_string(p)
                .unwrap()
                .contains("\nimpl Optimizer {")
        })
        .map(|p| p.strip_prefix(src()).unwrap().display().to_string())
        .collect();
    with_methods.sort();
    assert!(
        !with_methods.is_empty() && with_methods.len() <= 3,
        "`impl Optimizer` in {} files: {with_methods:?}",
        with_methods.len()
    );

    let root: Vec<String> = std::fs::read_dir(src().join("optim"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file() && p.extension().is_some_and(|x| x == "rs"))
        .map(|p| p.file_name().unwrap().to_string_lossy().to_string())
        .collect();
    assert!(
        root.len() <= 10,
        "{} files at src/optim/'s root: {root:?}",
        root.len()
    );
}

/// No source file under `src/` is longer than 700 lines.
#[test]
fn no_source_file_is_longer_than_700_lines() {
    let files = files_under(&src(), "rs");
    assert!(files.len() > 60, "{} files", files.len());
    let long: Vec<String> = files
        .iter()
        .map(|p| (p, std::fs::read_to_string(p).unwrap().lines().count()))
        .filter(|(_, n)| *n > 700)
        .map(|(p, n)| format!("{} ({n} lines)", p.display()))
        .collect();
    assert!(long.is_empty(), "files over 700 lines: {long:?}");
}

/// No function under `src/` is longer than 120 lines, from its `fn` to its closing brace.
#[test]
fn no_function_is_longer_than_120_lines() {
    let mut long = Vec::new();
    let mut counted = 0;
    for path in files_under(&src(), "rs") {
        let code = without_strings(&std::fs::read_to_string(&path).unwrap());
        let lines: Vec<&str> = code.lines().collect();
        for (start, line) in lines.iter().enumerate() {
            let Some(name) = fn_name(line) else {
                continue;
            };
            // The body: from the first `{` after the signature to the brace that closes it
            // (a declaration without a body, in a trait, ends at `;` first).
            let (mut depth, mut nested) = (0i32, 0i32);
            let mut opened = false;
            let mut end = None;
            'lines: for (i, l) in lines.iter().enumerate().skip(start) {
                // Strings are blanked, so what follows `//` is a comment.
                let l = l.split("//").next().unwrap_or_default();
                for c in l.chars() {
                    match c {
                        '(' | '[' => nested += 1,
                        ')' | ']' => nested -= 1,
                        ';' if !opened && nested == 0 => break 'lines,
                        '{' => {
                            depth += 1;
                            opened = true;
                        }
                        '}' => depth -= 1,
                        _ => {}
                    }
                    if opened && depth == 0 {
                        end = Some(i);
                        break 'lines;
                    }
                }
            }
            if let Some(end) = end {
                counted += 1;
                let n = end - start + 1;
                if n > 120 {
                    long.push(format!("{}: fn {name} ({n} lines)", path.display()));
                }
            }
        }
    }
    assert!(counted > 1000, "{counted} functions read");
    assert!(long.is_empty(), "functions over 120 lines: {long:#?}");
}

/// The name of the function a line starts (`fn`, `pub fn`, `pub(crate) const fn`, ...).
fn fn_name(line: &str) -> Option<&str> {
    let mut rest = line.trim_start();
    if rest.starts_with("//") {
        return None;
    }
    if let Some(r) = rest.strip_prefix("pub") {
        rest = match r.strip_prefix('(') {
            Some(r) => r.split_once(')')?.1,
            None => r,
        }
        .trim_start();
    }
    for q in ["const ", "async ", "unsafe ", "extern \"C\" "] {
        rest = rest.strip_prefix(q).unwrap_or(rest);
    }
    let rest = rest.strip_prefix("fn ")?;
    let n = rest.find(|c: char| !(c.is_alphanumeric() || c == '_'))?;
    (n > 0).then(|| &rest[..n])
}
