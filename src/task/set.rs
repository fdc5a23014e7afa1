//! `--set KEY=VALUE`: any key of a task file from the command line. The file is read as a
//! TOML document, each assignment replaces (or adds) the value at its dotted key, and the
//! result is parsed and checked as the file would be: an unknown key or a bad value is
//! refused with the task checks' own message, naming the key.
use super::Task;
use crate::{Error, Result};
use std::path::Path;

impl Task {
    /// Load the task file at `path` with `sets` applied in order (each `KEY=VALUE`: a dotted
    /// key of the file, `textures.0.learning_rate` for an entry of an array of tables, and a
    /// TOML value, a bare word read as a string).
    pub fn load_with(path: &Path, sets: &[String]) -> Result<Task> {
        if sets.is_empty() {
            return Task::load(path);
        }
        let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, e.to_string()))?;
        let mut doc: toml::Table =
            toml::from_str(&text).map_err(|e| Error::file(path, e.to_string().trim_end()))?;
        for s in sets {
            set(&mut doc, s).map_err(|m| Error::file(path, format!("--set {s}: {m}")))?;
        }
        let text = toml::to_string(&doc).map_err(|e| Error::file(path, e.to_string()))?;
        Task::parse(&text, path).map_err(|e| match e {
            Error::File { path, msg } => Error::File {
                msg: format!("{msg} (the file with --set {})", sets.join(" --set ")),
                path,
            },
            e => e,
        })
    }
}

/// Apply one `KEY=VALUE` to `doc`; on failure, what is wrong.
fn set(doc: &mut toml::Table, assignment: &str) -> std::result::Result<(), String> {
    let (key, raw) = assignment
        .split_once('=')
        .ok_or("expected KEY=VALUE, e.g. optimizer.smoothness=0.01")?;
    let value = value(raw.trim());
    let parts: Vec<&str> = key.trim().split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        return Err(format!("`{key}` is not a dotted key"));
    }
    drop_shorthand_twin(doc, &parts);
    let (last, parents) = parts.split_last().expect("split gives at least one part");
    let mut at = Slot::Table(doc);
    for (i, p) in parents.iter().enumerate() {
        let here = parts[..=i].join(".");
        at = match at {
            Slot::Table(t) => {
                let v = t
                    .entry(p.to_string())
                    .or_insert_with(|| toml::Value::Table(Default::default()));
                Slot::of(v, &here)?
            }
            Slot::Array(a) => Slot::of(index(a, p, &here)?, &here)?,
        };
    }
    match at {
        Slot::Table(t) => {
            t.insert(last.to_string(), value);
        }
        Slot::Array(a) => *index(a, last, key)? = value,
    }
    Ok(())
}

/// A prior's option can be given by its table's key or by its shorthand
/// (`optimizer.multiscale.levels`, `optimizer.multiscale_levels`): setting one drops the
/// other from `doc`, so that the assignment replaces what the file gave either way.
fn drop_shorthand_twin(doc: &mut toml::Table, parts: &[&str]) {
    let Some(toml::Value::Table(o)) = doc.get_mut("optimizer") else {
        return;
    };
    for kind in crate::optim::prior::REGISTRY {
        let Some((short, option)) = kind.shorthand else {
            continue;
        };
        if parts == ["optimizer", short] {
            if let Some(toml::Value::Table(t)) = o.get_mut(kind.name) {
                t.remove(option);
            }
        } else if parts == ["optimizer", kind.name, option] {
            o.remove(short);
        }
    }
}

/// Where a key's next part is looked up: a table (by name) or an array (by index).
enum Slot<'a> {
    Table(&'a mut toml::Table),
    Array(&'a mut Vec<toml::Value>),
}

impl<'a> Slot<'a> {
    fn of(v: &'a mut toml::Value, key: &str) -> std::result::Result<Slot<'a>, String> {
        match v {
            toml::Value::Table(t) => Ok(Slot::Table(t)),
            toml::Value::Array(a) => Ok(Slot::Array(a)),
            other => Err(format!(
                "`{key}` is a value ({}), not a table",
                other.type_str()
            )),
        }
    }
}

fn index<'a>(
    a: &'a mut [toml::Value],
    part: &str,
    key: &str,
) -> std::result::Result<&'a mut toml::Value, String> {
    let n = a.len();
    let i: usize = part.parse().map_err(|_| {
        format!(
            "`{key}`: an array takes an index (0 to {}), not `{part}`",
            n.max(1) - 1
        )
    })?;
    a.get_mut(i)
        .ok_or_else(|| format!("`{key}`: index {i} of an array of {n}"))
}

/// A TOML value, or the text as a string (`--set optimizer.step=adam`).
fn value(raw: &str) -> toml::Value {
    toml::from_str::<toml::Table>(&format!("v = {raw}"))
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(raw.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn doc(text: &str, sets: &[&str]) -> std::result::Result<toml::Table, String> {
        let mut d: toml::Table = toml::from_str(text).unwrap();
        for s in sets {
            set(&mut d, s)?;
        }
        Ok(d)
    }

    #[test]
    fn a_prior_option_replaces_its_shorthand_twin_and_back() {
        let text = "[optimizer]\nmultiscale_levels = 4\n";
        let d = doc(text, &["optimizer.multiscale.levels=2"]).unwrap();
        assert!(d["optimizer"].get("multiscale_levels").is_none(), "{d}");
        assert_eq!(d["optimizer"]["multiscale"]["levels"].as_integer(), Some(2));
        let d = doc(
            &toml::to_string(&d).unwrap(),
            &["optimizer.multiscale_levels=1"],
        )
        .unwrap();
        assert!(d["optimizer"]["multiscale"].get("levels").is_none(), "{d}");
        assert_eq!(d["optimizer"]["multiscale_levels"].as_integer(), Some(1));
    }

    #[test]
    fn values_go_to_dotted_keys_tables_and_array_entries() {
        let text =
            "width = 8\n[optimizer]\nsmoothness = 0.03\n[[textures]]\nslot = \"roughness\"\n";
        let d = doc(
            text,
            &[
                "width=16",
                "optimizer.smoothness = 0.01",
                "optimizer.adam.beta1=0.95",
                "optimizer.step=adam",
                "textures.0.init=[0.1, 0.2, 0.3]",
                "target.lights = { main = [\"sun\"] }",
            ],
        )
        .unwrap();
        assert_eq!(d["width"].as_integer(), Some(16));
        assert_eq!(d["optimizer"]["smoothness"].as_float(), Some(0.01));
        assert_eq!(d["optimizer"]["adam"]["beta1"].as_float(), Some(0.95));
        assert_eq!(d["optimizer"]["step"].as_str(), Some("adam"));
        assert_eq!(d["textures"][0]["init"].as_array().unwrap().len(), 3);
        assert_eq!(d["target"]["lights"]["main"][0].as_str(), Some("sun"));
        for (bad, says) in [
            ("width", "expected KEY=VALUE"),
            ("optimizer..x=1", "not a dotted key"),
            ("width.x=1", "`width` is a value (integer), not a table"),
            (
                "textures.first.init=1",
                "an array takes an index (0 to 0), not `first`",
            ),
            ("textures.3.init=1", "index 3 of an array of 1"),
        ] {
            let e = doc(text, &[bad]).unwrap_err();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }
}
