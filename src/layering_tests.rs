//! The crate's layering, read from its sources: the GPU layer names nothing above it, and no
//! two files import each other through any chain, each path followed through re-exports to
//! the file that defines what it names (a module and its own submodules aside: a parent
//! re-exporting its children is how modules are put together).
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

/// Every path `code` names from `crate::`, `super::`, `self::` or one of `children` (the
/// module's own submodules, named relative to it), with `use` groups expanded
/// (`super::{a::B, c}` gives `super::a::B` and `super::c`), as segments; and the children a
/// `registry!` lists.
fn paths(code: &str, children: &[String]) -> Vec<Vec<String>> {
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
                // A group's trailing comma leaves nothing to name.
                if !rest.starts_with('}') {
                    out.push(path);
                }
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
    let starts = ["crate", "super", "self"]
        .into_iter()
        .chain(children.iter().map(String::as_str))
        .map(|head| format!("{head}::"));
    for start in starts {
        for (i, _) in code.match_indices(&start) {
            let before = code[..i].chars().next_back();
            if before.is_some_and(|c| c.is_alphanumeric() || "_:.".contains(c))
                || code[..i].trim_end().ends_with("pub(in")
            {
                continue;
            }
            let head = start.trim_end_matches("::").to_string();
            read(&code[i + start.len()..], vec![head], &mut out);
        }
    }
    // A registry names its kinds' folders bare: `registry!("...", adam, variance_step)`.
    for (i, _) in code.match_indices("registry!(") {
        let args = &code[i..];
        let args = &args[..args.find(')').unwrap_or(args.len())];
        for word in args.split(|c: char| !(c.is_alphanumeric() || c == '_')) {
            if children.iter().any(|c| c == word) {
                out.push(vec![word.to_string()]);
            }
        }
    }
    out
}

/// `code` without its re-exports: the names of `pub use` items (of any visibility) that the
/// rest of the file never uses (string literals and other re-exports aside). A module
/// re-exporting a name it does not use itself does not depend on it; its importers' paths
/// are followed through the re-export instead.
fn without_re_exports(code: &str) -> String {
    let word = |c: char| c.is_alphanumeric() || c == '_';
    // Each `pub use` item's span and the names it binds.
    let mut items = Vec::new();
    for (at, _) in code.match_indices("pub") {
        if code[..at].chars().next_back().is_some_and(word) {
            continue;
        }
        let after = &code[at + 3..];
        let vis = if after.starts_with('(') {
            after.find(')').map_or(0, |i| i + 1)
        } else {
            0
        };
        let item = after[vis..].trim_start();
        let Some(end) = item.find(';').filter(|_| item.starts_with("use ")) else {
            continue;
        };
        let mut bound = Vec::new();
        use_tree(&item[4..end], &[], &mut bound);
        let item_end = code.len() - item.len() + end + 1;
        items.push((at..item_end, bound));
    }
    let mut rest = String::new();
    let mut last = 0;
    for (span, _) in &items {
        rest.push_str(&code[last..span.start]);
        last = span.end;
    }
    rest.push_str(&code[last..]);
    let rest = without_strings(&rest);
    // A use: the name as a word, not a module's declaration, a function's or a method call.
    let used = |name: &str| {
        rest.match_indices(name).any(|(i, _)| {
            let before = rest[..i].trim_end();
            !rest[..i].chars().next_back().is_some_and(word)
                && !rest[i + name.len()..].chars().next().is_some_and(word)
                && !before.ends_with('.')
                && !["mod", "fn"].iter().any(|k| {
                    before.ends_with(k) && !before[..before.len() - k.len()].ends_with(word)
                })
        })
    };
    // Each item keeps only the names the file uses.
    let mut out = code.to_string();
    for (span, bound) in items.iter().rev() {
        let kept: String = bound
            .iter()
            .filter(|(name, _)| name != "*" && used(name))
            .map(|(_, path)| format!("use {};", path.join("::")))
            .collect();
        out.replace_range(span.clone(), &kept);
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

/// What a file-module defines and what its `use` items bring in: the names its own items
/// take (structs, enums, functions, traits, types, constants, statics, modules, macros), and
/// each `use` binding as (the name it binds, `*` for a glob; the path it names).
struct Names {
    defined: BTreeSet<String>,
    uses: Vec<(String, Vec<String>)>,
}

/// `code` with the contents of its string literals and the braces of its character literals
/// blanked (braces in them would not balance).
pub(crate) fn without_strings(code: &str) -> String {
    let (mut out, mut in_string, mut escaped) = (String::new(), false, false);
    let code = code
        .replace("'{'", "' '")
        .replace("'}'", "' '")
        .replace("'\"'", "' '");
    for c in code.chars() {
        let blank = in_string && c != '"';
        if in_string && !escaped && c == '"' {
            in_string = false;
        } else if !in_string && c == '"' {
            in_string = true;
        }
        escaped = in_string && !escaped && c == '\\';
        out.push(if blank { ' ' } else { c });
    }
    out
}

/// `code`'s definitions and `use` bindings.
fn names(code: &str) -> Names {
    let mut defined = BTreeSet::new();
    // The module's own items only: those outside any braces (not an impl's associated types).
    let mut depth = 0i32;
    let top: String = without_strings(code)
        .chars()
        .map(|c| {
            depth += match c {
                '{' => 1,
                '}' => -1,
                _ => 0,
            };
            if depth > 0 || c == '}' {
                ' '
            } else {
                c
            }
        })
        .collect();
    // `'static` is a lifetime, not a static item.
    let top = top.replace("'static", "");
    let words: Vec<&str> = top
        .split(|c: char| !(c.is_alphanumeric() || c == '_' || c == '!'))
        .filter(|w| !w.is_empty())
        .collect();
    for w in words.windows(2) {
        let item = [
            "struct",
            "enum",
            "fn",
            "trait",
            "type",
            "const",
            "static",
            "mod",
            "union",
            "macro_rules!",
        ];
        if item.contains(&w[0]) {
            defined.insert(w[1].to_string());
        }
    }
    let mut uses = Vec::new();
    let mut rest = code;
    while let Some(at) = rest.find("use ") {
        let before = rest[..at].chars().next_back();
        let body_start = at + 4;
        let Some(end) = rest[body_start..].find(';') else {
            break;
        };
        if !before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
            use_tree(&rest[body_start..body_start + end], &[], &mut uses);
        }
        rest = &rest[body_start + end..];
    }
    Names { defined, uses }
}

/// The bindings of a `use` tree (`a::{b::C as D, e::*, self}`) under `prefix`.
fn use_tree(tree: &str, prefix: &[String], out: &mut Vec<(String, Vec<String>)>) {
    let tree = tree.trim();
    if let Some(open) = tree.find('{') {
        let mut path = prefix.to_vec();
        path.extend(segments(&tree[..open]));
        let inner = &tree[open + 1..tree.rfind('}').unwrap_or(tree.len())];
        let (mut depth, mut start) = (0, 0);
        for (i, c) in inner.char_indices() {
            match c {
                '{' => depth += 1,
                '}' => depth -= 1,
                ',' if depth == 0 => {
                    use_tree(&inner[start..i], &path, out);
                    start = i + 1;
                }
                _ => {}
            }
        }
        use_tree(&inner[start..], &path, out);
        return;
    }
    let (tree, alias) = match tree.split_once(" as ") {
        Some((t, a)) => (t, Some(a.trim().to_string())),
        None => (tree, None),
    };
    let mut path = prefix.to_vec();
    path.extend(segments(tree));
    if path.last().is_some_and(|l| l == "self") {
        path.pop();
    }
    if let Some(last) = path.last().cloned() {
        out.push((alias.unwrap_or(last), path));
    }
}

/// The segments of a path (`super::a::B` gives `super`, `a`, `B`; a glob ends in `*`).
fn segments(path: &str) -> Vec<String> {
    path.split("::")
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .collect()
}

/// The crate's file-modules with what each defines and brings in.
struct Modules {
    files: BTreeMap<Vec<String>, PathBuf>,
    names: BTreeMap<Vec<String>, Names>,
}

impl Modules {
    fn read() -> Modules {
        let files = library_files();
        let names = files
            .iter()
            .map(|(m, p)| {
                let code = library_code(&std::fs::read_to_string(p).unwrap());
                (m.clone(), names(&code))
            })
            .collect();
        Modules { files, names }
    }

    /// The names of `module`'s own submodules that are files.
    fn children(&self, module: &[String]) -> Vec<String> {
        self.files
            .keys()
            .filter(|m| m.len() == module.len() + 1 && m.starts_with(module))
            .map(|m| m[module.len()].clone())
            .collect()
    }

    /// `path` as written in module `from`, made absolute (None: another crate's).
    fn absolute(&self, from: &[String], path: &[String]) -> Option<Vec<String>> {
        let (first, rest) = path.split_first()?;
        let mut abs =
            match first.as_str() {
                "crate" => Vec::new(),
                "self" => from.to_vec(),
                "super" => {
                    let mut abs = from.to_vec();
                    abs.pop();
                    let supers = rest.iter().take_while(|s| *s == "super").count();
                    for _ in 0..supers {
                        abs.pop();
                    }
                    abs.extend(rest[supers..].iter().cloned());
                    return Some(abs);
                }
                _ => {
                    let mut child = from.to_vec();
                    child.push(first.clone());
                    if !self.files.contains_key(&child) {
                        // A name a `use` of `from` binds (`pub use run::schedule;` then
                        // `schedule::Schedule`).
                        let (_, bound) =
                            self.names.get(from)?.uses.iter().find(|(n, p)| {
                                n == first && p.first().is_some_and(|h| h != first)
                            })?;
                        let mut abs = self.absolute(from, bound)?;
                        abs.extend(rest.iter().cloned());
                        return Some(abs);
                    }
                    from.to_vec()
                }
            };
        if first != "crate" && first != "self" {
            abs.push(first.clone());
        }
        abs.extend(rest.iter().cloned());
        Some(abs)
    }

    /// The file-module that defines what absolute path `abs` names, following `use`
    /// bindings (re-exports and globs) to the file that defines the name.
    fn defining(&self, abs: &[String], depth: u32) -> Vec<String> {
        let mut m = abs.to_vec();
        while !m.is_empty() && !self.files.contains_key(&m) {
            m.pop();
        }
        let Some(name) = abs.get(m.len()) else {
            return m;
        };
        let names = &self.names[&m];
        if depth > 8 || names.defined.contains(name) {
            return m;
        }
        for (bound, path) in &names.uses {
            let glob = bound == "*";
            if !(glob || bound == name) {
                continue;
            }
            let mut target = path.clone();
            if glob {
                target.pop();
                target.push(name.clone());
            }
            let Some(mut target) = self.absolute(&m, &target) else {
                continue;
            };
            target.extend(abs[m.len() + 1..].iter().cloned());
            let found = self.defining(&target, depth + 1);
            let defines =
                |f: &Vec<String>| self.names.get(f).is_some_and(|n| n.defined.contains(name));
            if found != m && (!glob || defines(&found) || found == target) {
                return found;
            }
        }
        m
    }
}

/// Every import edge between the crate's files: from each file to the files that define what
/// it names, parents and children included.
fn import_edges(modules: &Modules) -> Edges {
    let mut edges = Edges::new();
    for (module, path) in &modules.files {
        let code = library_code(&std::fs::read_to_string(path).unwrap());
        for p in paths(&without_re_exports(&code), &modules.children(module)) {
            let Some(abs) = modules.absolute(module, &p) else {
                continue;
            };
            let t = modules.defining(&abs, 0);
            if t != *module {
                edges.entry(module.clone()).or_default().insert(t);
            }
        }
    }
    edges
}

/// No two files import each other through any chain, a module and its own submodules
/// included: a parent that uses its children (a registry, a field of a child's type) does
/// not also define what they use (the plugins' contract is a file of its own). A path is
/// followed to the file that defines what it names, through re-exports
/// (`crate::optim::Settings` is `optim/settings.rs`'s, whichever module re-exports it), so
/// that no circle hides behind a re-export; a parent's re-export of a child's name that the
/// parent does not use itself is no import of its own.
#[test]
fn no_two_files_import_each_other() {
    let modules = Modules::read();
    assert!(modules.files.len() > 60, "{} files", modules.files.len());
    let edges = import_edges(&modules);
    assert!(
        edges
            .get(&vec!["bench".to_string()])
            .is_some_and(|e| e.len() > 3),
        "the reader found too few imports: {edges:?}"
    );
    let cycles = cycles(&edges);
    assert!(cycles.is_empty(), "import circles:\n{}", cycles.join("\n"));
}

/// Parent-child edges are counted: a registry's bare list of its folders, a parent's own use
/// of its child, a child's use of what its parent defines; and a parent's re-export alone
/// is none.
#[test]
fn edges_between_a_parent_and_its_children_are_counted() {
    let m = |s: &str| s.split("::").map(String::from).collect::<Vec<_>>();
    let modules = Modules::read();
    let edges = import_edges(&modules);
    let has = |a: &str, b: &str| edges.get(&m(a)).is_some_and(|e| e.contains(&m(b)));
    // `registry!(..., baseline, restir, recursive)`.
    assert!(has("optim::estimator", "optim::estimator::restir"));
    // `optim/mod.rs` builds its fit (`fit::Fit`) and its run state (`run::RunState`).
    assert!(has("optim", "optim::fit"));
    assert!(has("optim", "optim::run"));
    // A step folder implements its parent's contract (`super::Step`, from `contract.rs`).
    assert!(has("optim::step::adam", "optim::step::contract"));
    assert!(!has("optim::step::adam", "optim::step"));
    // The parent of a file it only re-exports: `pub use binding::GroupDecl`.
    assert!(!has("gpu", "gpu::binding"));
    let code = library_code(
        "mod a;\nmod b;\npub use a::{A, B};\npub(crate) use b::C;\nfn f(x: A) { b::g(); }",
    );
    let kept = without_re_exports(&code);
    let p: Vec<String> = paths(&kept, &["a".into(), "b".into()])
        .iter()
        .map(|p| p.join("::"))
        .collect();
    assert_eq!(p, ["a::A", "b::g"], "{kept}");
    let n = names("impl K for T { type Kind = Kind; const N: &'static str = \"\"; }\nstruct S;");
    assert_eq!(n.defined.into_iter().collect::<Vec<_>>(), ["S"]);
}

/// A path through a parent's re-export lands in the file that defines the name: the circle
/// `optim::step` -> `crate::optim::Settings` (re-exported from `optim/settings.rs`) ->
/// `optim::step` is seen, and a glob re-export is followed too.
#[test]
fn a_path_through_a_re_export_lands_where_the_name_is_defined() {
    let m = |s: &str| s.split("::").map(String::from).collect::<Vec<_>>();
    let modules = Modules::read();
    let settings = modules.absolute(&m("optim::step"), &m("crate::optim::Settings"));
    assert_eq!(
        modules.defining(&settings.unwrap(), 0),
        m("optim::settings")
    );
    let timer = modules.absolute(&m("optim::prior"), &m("super::PassTimer"));
    assert_eq!(modules.defining(&timer.unwrap(), 0), m("optim::timing"));
    let method = modules.absolute(&m("bench"), &m("crate::optim::Method::RESTIR"));
    assert_eq!(
        modules.defining(&method.unwrap(), 0),
        m("optim::estimator::handle")
    );
    let own = modules.absolute(&m("optim"), &m("crate::optim::Optimizer"));
    assert_eq!(modules.defining(&own.unwrap(), 0), m("optim"));
    let uses = names("use a::{b::C as D, e::*, self};").uses;
    let got: Vec<String> = uses
        .iter()
        .map(|(n, p)| format!("{n}={}", p.join("::")))
        .collect();
    assert_eq!(got, ["D=a::b::C", "*=a::e::*", "a=a"]);
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
    let p: Vec<String> = paths(&code, &[]).iter().map(|p| p.join("::")).collect();
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
        for p in paths(&code, &[]) {
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
