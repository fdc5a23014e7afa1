//! The registry's tests: estimator options as tables, and the seam.

mod options_tests {
    use super::super::restir::RestirOptions;
    use super::super::*;

    #[test]
    fn default_tables_round_trip_and_optional_keys_are_options() {
        for m in Method::all() {
            let toml = EstimatorOptions::defaults_toml(m);
            let table: toml::Table = toml::from_str(&toml).unwrap();
            let mut o = EstimatorOptions::default();
            o.set_table(m.table(), table.clone());
            assert_eq!(o.check(), Ok(()), "{m}: {toml}");
            // Each optional key, commented out in the listing, is an option of its own.
            for line in toml.lines().filter_map(|l| l.strip_prefix("# ")) {
                let key = line.split(' ').next().unwrap();
                // A fraction (`target_smoothing`) or a count (`claim_entries`).
                let valid = [toml::Value::Float(0.5), toml::Value::Integer(1)]
                    .into_iter()
                    .any(|v| {
                        let mut o = o.clone();
                        o.set(m.table(), key, v);
                        o.check().is_ok()
                    });
                assert!(valid, "{m}.{key}");
            }
        }
    }

    #[test]
    fn assignments_parse_merge_and_name_what_is_wrong() {
        let mut o = EstimatorOptions::default();
        o.assign("restir.m_cap=16").unwrap();
        o.assign(" restir.confidence = candidates ").unwrap();
        let r: RestirOptions = o.get().unwrap();
        assert_eq!(r.m_cap, 16.0);
        assert_eq!(r.confidence, restir::Confidence::Candidates);
        // Over a task's table, option by option.
        let mut task = EstimatorOptions::default();
        task.set(Method::RESTIR, "m_cap", toml::Value::Float(2.0));
        task.set(Method::RESTIR, "temporal", toml::Value::Boolean(false));
        let both: RestirOptions = task.merged(&o).get().unwrap();
        assert_eq!((both.m_cap, both.temporal), (16.0, false));
        for (bad, says) in [
            ("m_cap=3", "METHOD.KEY=VALUE"),
            ("restir.m_cap", "METHOD.KEY=VALUE"),
            ("sgd.lr=3", "unknown gradient estimator"),
            ("restir.m_capp=3", "m_capp"),
            ("restir.m_cap=-1", "optimizer.restir.m_cap"),
            ("recursive.min_weight=2", "optimizer.recursive.min_weight"),
            ("baseline.m_cap=2", "unknown field `m_cap`"),
            ("baseline.cache=0", "optimizer.baseline.cache"),
        ] {
            let e = EstimatorOptions::default()
                .assign(bad)
                .unwrap_err()
                .to_string();
            assert!(e.contains(says) && e.contains(bad), "{bad}: {e}");
        }
        let mut unknown = EstimatorOptions::default();
        unknown
            .tables_mut()
            .insert("sgd".into(), toml::Table::new());
        assert_eq!(unknown.check().unwrap_err().0, "optimizer.sgd");
    }
}

mod seam_tests {
    //! The seam between the estimators and the rest: outside its folder no source file names
    //! an estimator's internals. The registry (the files of `src/optim/estimator/` itself) is
    //! the one place that names each folder's items; everything else sees a method's name and
    //! its options table.
    use std::collections::BTreeSet;
    use std::path::{Path, PathBuf};

    fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                rust_files(&p, out);
            } else if p.extension().is_some_and(|x| x == "rs" || x == "wgsl") {
                out.push(p);
            }
        }
    }

    /// `source` without comments and string literals (what names code, not what talks about it).
    fn code_of(source: &str) -> String {
        let mut out = String::new();
        for line in source.lines() {
            let mut in_string = false;
            let mut prev = ' ';
            let mut kept = String::new();
            let chars: Vec<char> = line.chars().collect();
            let mut i = 0;
            while i < chars.len() {
                let c = chars[i];
                if !in_string && c == '/' && chars.get(i + 1) == Some(&'/') {
                    break;
                }
                if c == '"' && prev != '\\' {
                    in_string = !in_string;
                } else if !in_string {
                    kept.push(c);
                }
                prev = c;
                i += 1;
            }
            out.push_str(&kept);
            out.push('\n');
        }
        out
    }

    /// The name an item declaration on `line` introduces (`pub struct X`, `pub(crate) fn y_z`,
    /// `pub const Z`, `pub mod m`, ...). A function whose name is one word (`new`, `of`,
    /// `memory`) is too common to find by name; it is found by its path (`restir::memory`).
    fn declared(line: &str, public_only: bool) -> Option<String> {
        let t = line.trim_start();
        let public = t
            .strip_prefix("pub(crate) ")
            .or_else(|| t.strip_prefix("pub(super) "))
            .or_else(|| t.strip_prefix("pub "));
        let t = match public {
            Some(t) => t,
            None if public_only => return None,
            None => t,
        };
        let t = t.strip_prefix("unsafe ").unwrap_or(t);
        for kw in [
            "struct ", "enum ", "fn ", "const ", "static ", "mod ", "type ", "trait ",
        ] {
            if let Some(rest) = t.strip_prefix(kw) {
                let name: String = rest
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                let one_word = kw == "fn " && !name.contains('_');
                return (!name.is_empty() && !one_word).then_some(name);
            }
        }
        None
    }

    fn has_word(code: &str, word: &str) -> bool {
        code.match_indices(word).any(|(i, _)| {
            let before = code[..i].chars().next_back();
            let after = code[i + word.len()..].chars().next();
            let boundary = |c: Option<char>| !c.is_some_and(|c| c.is_alphanumeric() || c == '_');
            boundary(before) && boundary(after)
        })
    }

    #[test]
    fn outside_its_folder_no_source_names_an_estimators_internals() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let mut files = Vec::new();
        rust_files(&root.join("src"), &mut files);
        rust_files(&root.join("shaders"), &mut files);
        let here = root.join("src/optim/estimator");
        let sources: Vec<(PathBuf, String)> = files
            .iter()
            .map(|p| (p.clone(), std::fs::read_to_string(p).unwrap()))
            .collect();
        let mut checked = 0;
        let mut violations = Vec::new();
        for method in super::super::Method::all() {
            let name = method.name();
            let folder = here.join(name);
            let inside = |p: &Path| p.starts_with(&folder);
            // Every name the folder declares public that no file outside it declares too
            // (those are the shared interface, `PASSES`, `WGSL`, or names of its own there).
            let decl = |pred: &dyn Fn(&Path) -> bool, public_only: bool| -> BTreeSet<String> {
                sources
                    .iter()
                    .filter(|(p, _)| pred(p))
                    .flat_map(|(_, s)| {
                        s.lines()
                            .filter_map(|l| declared(l, public_only))
                            .collect::<Vec<_>>()
                    })
                    .collect()
            };
            let own = decl(&|p| inside(p), true);
            let elsewhere = decl(&|p| !inside(p), false);
            let mut internal: Vec<String> = own.difference(&elsewhere).cloned().collect();
            // The folder's modules by path, its WGSL modules and generated constants by
            // their import names.
            internal.push(format!("{name}::"));
            let wgsl_import = format!("#import {name}/");
            let gen_import = format!("#import gen/{name}");
            for (p, source) in &sources {
                // The registry: the files of the estimator module itself.
                if inside(p) || p.parent() == Some(here.as_path()) {
                    continue;
                }
                let is_wgsl = p.extension().is_some_and(|x| x == "wgsl");
                let shown = p.strip_prefix(root).unwrap().display();
                if is_wgsl {
                    if source.contains(&wgsl_import) || source.contains(&gen_import) {
                        violations.push(format!("{shown} imports {name}'s WGSL"));
                    }
                    continue;
                }
                let code = code_of(source);
                for item in &internal {
                    let found = if let Some(path) = item.strip_suffix("::") {
                        code.contains(&format!("{path}::"))
                            && has_word(&code.replace("::", " :: "), path)
                    } else {
                        has_word(&code, item)
                    };
                    if found {
                        violations.push(format!("{shown} names `{item}` ({name})"));
                    }
                }
                checked += 1;
            }
            // At least its `KIND` and its options (the toy has no more).
            assert!(own.len() >= 2, "{name}: {} declarations found", own.len());
        }
        assert!(
            violations.is_empty(),
            "outside its folder a source names an estimator's internals (go through the \
             registry, src/optim/estimator/, or the Estimator trait):\n{}",
            violations.join("\n")
        );
        assert!(checked > 100, "only {checked} files checked");
    }
}
