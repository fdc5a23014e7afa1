//! The crate's layering, read from its sources: the GPU layer names nothing above it, and no
//! two files import each other through any chain (a module and its own submodules aside:
//! a parent re-exporting its children is how modules are put together).
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Every library source file under `src/` by module path (`optim::estimator::restir` for
/// `src/optim/estimator/restir/mod.rs`), without the binary's files and the test modules'
/// own files.
fn library_files() -> BTreeMap<Vec<String>, PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = BTreeMap::new();
    for p in files_under(&root, "rs") {
        let rel = p.strip_prefix(&root).unwrap().with_extension("");
        let mut module: Vec<String> = rel
            .components()
            .map(|c| c.as_os_str().to_string_lossy().to_string())
            .collect();
        if module.last().is_some_and(|l| l == "mod") || module == ["lib"] {
            module.pop();
        }
        let test_only = module
            .iter()
            .any(|m| m == "tests" || m.ends_with("_tests") || m == "toy");
        if module == ["main"] || module == ["cli"] || test_only {
            continue;
        }
        files.insert(module, p);
    }
    files
}

/// Every file under `dir` (recursively) whose name ends in `.ext`.
pub(crate) fn files_under(dir: &Path, ext: &str) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(files_under(&p, ext));
        } else if p.extension().is_some_and(|x| x == ext) {
            out.push(p);
        }
    }
    out
}

/// `source` without comments and without its `#[cfg(test)] mod ... { ... }` blocks.
fn library_code(source: &str) -> String {
    let mut code = String::new();
    for line in source.lines() {
        let line = match line.find("//") {
            Some(i) if !line[..i].contains('"') => &line[..i],
            _ => line,
        };
        code.push_str(line);
        code.push('\n');
    }
    while let Some(at) = code.find("#[cfg(test)]") {
        let rest = code[at + 12..].trim_start();
        let Some(open) = code[at..].find('{').filter(|_| rest.starts_with("mod ")) else {
            code.replace_range(at..at + 12, "");
            continue;
        };
        let mut depth = 0;
        let mut end = code.len();
        for (i, c) in code[at + open..].char_indices() {
            depth += match c {
                '{' => 1,
                '}' => -1,
                _ => 0,
            };
            if depth == 0 {
                end = at + open + i + 1;
                break;
            }
        }
        code.replace_range(at..end, "");
    }
    code
}

/// Every path `code` names from `crate::` or `super::`, with `use` groups expanded
/// (`super::{a::B, c}` gives `super::a::B` and `super::c`), as segments.
fn paths(code: &str) -> Vec<Vec<String>> {
    fn ident(s: &str) -> usize {
        s.find(|c: char| !(c.is_alphanumeric() || c == '_'))
            .unwrap_or(s.len())
    }
    /// The paths starting at `s` after `prefix`; returns them and how far it read.
    fn read(s: &str, prefix: Vec<String>, out: &mut Vec<Vec<String>>) -> usize {
        let mut at = 0;
        let mut path = prefix;
        loop {
            let rest = s[at..].trim_start();
            at = s.len() - rest.len();
            if rest.starts_with('{') {
                at += 1;
                loop {
                    at += read(&s[at..], path.clone(), out);
                    let rest = s[at..].trim_start();
                    at = s.len() - rest.len();
                    if rest.starts_with(',') {
                        at += 1;
                    } else {
                        return at + usize::from(rest.starts_with('}'));
                    }
                }
            }
            let n = ident(rest);
            if n == 0 {
                out.push(path);
                return at;
            }
            path.push(rest[..n].to_string());
            at += n;
            if s[at..].starts_with("::") {
                at += 2;
            } else {
                out.push(path);
                return at;
            }
        }
    }
    let mut out = Vec::new();
    for start in ["crate::", "super::"] {
        for (i, _) in code.match_indices(start) {
            let before = code[..i].chars().next_back();
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':') {
                continue;
            }
            let head = start.trim_end_matches("::").to_string();
            read(&code[i + start.len()..], vec![head], &mut out);
        }
    }
    out
}

/// The file-module a path from module `from` lands in: the longest prefix that is one.
fn target(from: &[String], path: &[String], files: &BTreeMap<Vec<String>, PathBuf>) -> Vec<String> {
    let mut abs: Vec<String> = Vec::new();
    let mut segs = path.iter().peekable();
    match segs.peek().map(|s| s.as_str()) {
        Some("crate") => {
            segs.next();
        }
        _ => {
            abs = from.to_vec();
            while segs.peek().is_some_and(|s| *s == "super") {
                segs.next();
                abs.pop();
            }
        }
    }
    abs.extend(segs.cloned());
    while !abs.is_empty() && !files.contains_key(&abs) {
        abs.pop();
    }
    abs
}

#[test]
fn no_two_files_import_each_other() {
    let files = library_files();
    assert!(files.len() > 60, "{} files", files.len());
    let mut edges = Edges::new();
    for (module, path) in &files {
        // A module file's own `super` is its parent; `mod.rs` and `x.rs` alike.
        let code = library_code(&std::fs::read_to_string(path).unwrap());
        for p in paths(&code) {
            let t = target(module, &p, &files);
            let related = t.starts_with(module) || module.starts_with(&t);
            if !related {
                edges.entry(module.clone()).or_default().insert(t);
            }
        }
    }
    assert!(
        edges
            .get(&vec!["bench".to_string()])
            .is_some_and(|e| e.len() > 3),
        "the reader found too few imports: {edges:?}"
    );
    let cycles = cycles(&edges);
    assert!(cycles.is_empty(), "import circles:\n{}", cycles.join("\n"));
}

type Edges = BTreeMap<Vec<String>, BTreeSet<Vec<String>>>;

/// Every module that reaches itself through `edges`, with the way round.
fn cycles(edges: &Edges) -> Vec<String> {
    let mut cycles = Vec::new();
    for start in edges.keys() {
        let mut stack = vec![(start.clone(), vec![start.clone()])];
        let mut seen = BTreeSet::new();
        while let Some((m, trail)) = stack.pop() {
            for next in edges.get(&m).into_iter().flatten() {
                if next == start {
                    let names: Vec<String> = trail.iter().map(|m| m.join("::")).collect();
                    cycles.push(format!("{} -> {}", names.join(" -> "), start.join("::")));
                } else if seen.insert(next.clone()) {
                    let mut t = trail.clone();
                    t.push(next.clone());
                    stack.push((next.clone(), t));
                }
            }
        }
    }
    cycles
}

#[test]
fn a_circle_through_three_files_is_found() {
    let m = |s: &str| s.split("::").map(String::from).collect::<Vec<_>>();
    let mut edges = Edges::new();
    for (a, b) in [
        ("job::run", "job::metrics"),
        ("job::metrics", "optim"),
        ("optim", "gpu"),
    ] {
        edges.entry(m(a)).or_default().insert(m(b));
    }
    assert!(cycles(&edges).is_empty());
    edges.entry(m("optim")).or_default().insert(m("job::run"));
    assert_eq!(cycles(&edges).len(), 3, "{:?}", cycles(&edges));
}

#[test]
fn the_reader_finds_paths_in_use_groups() {
    let code = library_code(
        "use super::{metrics::{A, b}, Problem};\nuse crate::optim::Method; // crate::job\n\
         #[cfg(test)]\nmod tests { use crate::bench::X; }\nfn f() { crate::gpu::grid_2d(1); }",
    );
    let p: Vec<String> = paths(&code).iter().map(|p| p.join("::")).collect();
    assert_eq!(
        p,
        [
            "crate::optim::Method",
            "crate::gpu::grid_2d",
            "super::metrics::A",
            "super::metrics::b",
            "super::Problem"
        ]
    );
}

/// The GPU layer is the lowest: no file under `src/gpu` names a module above it (its composer
/// gets the WGSL it composes from the caller, [`crate::shader_library`]).
#[test]
fn the_gpu_layer_imports_nothing_above_it() {
    let files = library_files();
    let gpu = vec!["gpu".to_string()];
    let mut checked = 0;
    for (module, path) in &files {
        if !module.starts_with(&gpu) {
            continue;
        }
        checked += 1;
        let code = library_code(&std::fs::read_to_string(path).unwrap());
        for p in paths(&code) {
            let t = target(module, &p, &files);
            assert!(
                t.starts_with(&gpu) || t.is_empty(),
                "{}: the GPU layer names `{}`",
                path.display(),
                p.join("::")
            );
        }
        // Doc links name modules too.
        for line in std::fs::read_to_string(path).unwrap().lines() {
            let rest = [
                "crate::{Error, Result}",
                "crate::Error",
                "crate::Result",
                "crate::gpu",
            ]
            .iter()
            .fold(line.to_string(), |l, ok| l.replace(ok, ""));
            assert!(
                !rest.contains("crate::"),
                "{}: the GPU layer names a module above it: {line}",
                path.display()
            );
        }
    }
    assert!(checked >= 5, "{checked} files in src/gpu");
}
