//! The documentation holds together: every relative link (and image) in README.md and docs/
//! resolves to a file of the repository, and every `#anchor` to a heading of its target; the
//! README stays short; the task file it shows parses; and no text of the project cites a file
//! outside the repository.
use std::path::{Path, PathBuf};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn pages() -> Vec<PathBuf> {
    let mut v = vec![Path::new(ROOT).join("README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(Path::new(ROOT).join("docs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    docs.sort();
    v.extend(docs);
    v
}

/// Text outside fenced code blocks and inline code spans.
fn prose(text: &str) -> String {
    let mut out = String::new();
    let mut fenced = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if fenced {
            continue;
        }
        let mut in_code = false;
        for c in line.chars() {
            if c == '`' {
                in_code = !in_code;
            } else if !in_code {
                out.push(c);
            }
        }
        out.push('\n');
    }
    out
}

/// Targets of inline links and images: `[text](target)` and `![alt](target)`.
fn links(text: &str) -> Vec<String> {
    let p = prose(text);
    let mut out = Vec::new();
    let mut rest = p.as_str();
    while let Some(i) = rest.find("](") {
        let after = &rest[i + 2..];
        match after.find(')') {
            Some(j) => {
                out.push(after[..j].trim().to_string());
                rest = &after[j..];
            }
            None => break,
        }
    }
    out
}

/// GitHub's anchor of a heading: lower case, punctuation other than '-' and '_' dropped,
/// spaces to '-'.
fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter_map(|c| match c {
            ' ' => Some('-'),
            c if c.is_alphanumeric() || c == '-' || c == '_' => Some(c),
            _ => None,
        })
        .collect()
}

fn anchors(text: &str) -> Vec<String> {
    let mut fenced = false;
    let mut out = Vec::new();
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
        } else if !fenced && line.starts_with('#') {
            out.push(slug(line.trim_start_matches('#')));
        }
    }
    out
}

#[test]
fn every_relative_link_resolves() {
    let mut checked = 0;
    for page in pages() {
        let text = std::fs::read_to_string(&page).unwrap();
        for target in links(&text) {
            if target.starts_with("http://")
                || target.starts_with("https://")
                || target.starts_with("mailto:")
            {
                continue;
            }
            let (file, anchor) = match target.split_once('#') {
                Some((f, a)) => (f, Some(a)),
                None => (target.as_str(), None),
            };
            let resolved = if file.is_empty() {
                page.clone()
            } else {
                page.parent().unwrap().join(file)
            };
            assert!(
                resolved.exists(),
                "{}: link `{target}` points to {}, which does not exist",
                page.display(),
                resolved.display()
            );
            if let Some(a) = anchor {
                let t = std::fs::read_to_string(&resolved).unwrap();
                assert!(
                    anchors(&t).iter().any(|h| h == a),
                    "{}: link `{target}`: {} has no heading with anchor `{a}`",
                    page.display(),
                    resolved.display()
                );
            }
            checked += 1;
        }
    }
    assert!(
        checked > 20,
        "only {checked} links found: is the parser broken?"
    );
}

#[test]
fn the_link_checker_sees_what_it_should() {
    let text =
        "See [a](docs/guide.md#set-up) and `[not](x.md)`.\n```\n[no](y.md)\n```\n![p](img.png)\n";
    assert_eq!(links(text), ["docs/guide.md#set-up", "img.png"]);
    assert_eq!(
        slug("Optimizing: `psrestir optimize`"),
        "optimizing-psrestir-optimize"
    );
    assert_eq!(
        slug("The default task's settings"),
        "the-default-tasks-settings"
    );
    assert_eq!(anchors("# A b\n```\n# not\n```\n## C, d\n"), ["a-b", "c-d"]);
}

#[test]
fn the_readme_is_short_and_its_task_example_parses() {
    let readme = std::fs::read_to_string(Path::new(ROOT).join("README.md")).unwrap();
    let n = readme.lines().count();
    assert!(
        n <= 150,
        "README.md has {n} lines; longer material belongs in docs/"
    );
    let block = readme
        .split("```toml\n")
        .nth(1)
        .and_then(|b| b.split("```").next())
        .expect("the README shows a task file");
    psrestir::Task::parse(block, Path::new("task.toml")).unwrap();
}

#[test]
fn no_text_cites_a_file_outside_the_repository() {
    let mut files = pages();
    for dir in ["src", "shaders", "tests", "ci", "examples"] {
        let mut stack = vec![Path::new(ROOT).join(dir)];
        while let Some(d) = stack.pop() {
            for e in std::fs::read_dir(&d).unwrap() {
                let p = e.unwrap().path();
                if p.is_dir() {
                    stack.push(p);
                } else if p
                    .extension()
                    .is_some_and(|e| e == "rs" || e == "wgsl" || e == "sh" || e == "md")
                {
                    files.push(p);
                }
            }
        }
    }
    // Spelled in two parts, so that this file does not cite it either.
    let design = format!("{}.md", "DESIGN");
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap_or_default();
        assert!(
            !text.contains(&design),
            "{} cites {design}, which is not part of the repository",
            f.display()
        );
    }
}
