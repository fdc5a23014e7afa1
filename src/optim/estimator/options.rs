//! Estimator options: each estimator's own type ([`Options`]) in its folder, read from its
//! table of [`EstimatorOptions`] (the task file's `[optimizer.<method>]` tables and the
//! command line's `--estimator-option`), and what the registry knows of them without their
//! type ([`OptionsKind`]).
use super::Method;
use crate::Result;

/// An estimator's options as its folder defines them: read from and written to that
/// estimator's table in [`EstimatorOptions`] (missing keys take their defaults).
pub trait Options:
    Clone + Default + serde::Serialize + serde::de::DeserializeOwned + std::fmt::Debug
{
    /// The estimator they belong to.
    const METHOD: Method;
    /// The options whose default is to be absent (an `Option` left `None`).
    const OPTIONAL: &'static [&'static str] = &[];
    /// An error naming the option (its key in the table) and what is wrong.
    fn check(&self) -> std::result::Result<(), (String, String)>;
    /// A short description for reports (empty: nothing to say), e.g. `M cap 8`.
    fn describe(&self) -> String;
    /// What `bench --tune` varies, in search order: for each option searched, the
    /// candidates around the best options so far (none: the estimator's options are not
    /// tuned).
    fn tuning() -> Vec<TypedAxis<Self>> {
        Vec::new()
    }
}

/// What the registry knows of an estimator's options, without their type: functions of its
/// table in [`EstimatorOptions`]. [`OptionsKind::of`] makes them from an [`Options`] type;
/// [`OptionsKind::NONE`] is for an estimator without options.
#[derive(Clone, Copy)]
pub struct OptionsKind {
    check: fn(&EstimatorOptions) -> std::result::Result<(), (String, String)>,
    defaults_toml: fn() -> String,
    describe: fn(&EstimatorOptions) -> String,
    tuning: fn() -> Vec<TuningAxis>,
    /// Whether the estimator has no options at all (any key in its table is an error).
    none: bool,
}

impl OptionsKind {
    /// The options of an estimator that has none: its table must be empty.
    pub const NONE: OptionsKind = OptionsKind {
        check: |_| Ok(()),
        defaults_toml: String::new,
        describe: |_| String::new(),
        tuning: Vec::new,
        none: true,
    };

    /// The options `T` defines.
    pub const fn of<T: Options + 'static>() -> OptionsKind {
        OptionsKind {
            check: |o| o.get::<T>().map(|_| ()),
            defaults_toml: || {
                let mut s = toml::to_string(&T::default()).unwrap_or_default();
                for key in T::OPTIONAL {
                    s.push_str(&format!("# {key} = ...  (absent by default)\n"));
                }
                s
            },
            describe: |o| o.get::<T>().map(|t| t.describe()).unwrap_or_default(),
            tuning: || typed_axes(T::tuning()),
            none: false,
        }
    }
}

/// Every estimator's options, one table of TOML values per method name: the task file's
/// `[optimizer.<method>]` tables, with the command line's `--estimator-option
/// METHOD.KEY=VALUE` on top. The optimizer, the job and the bench only pass the tables on;
/// each estimator reads its own ([`Options`]) and [`EstimatorOptions::check`] asks each to
/// check its table.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(transparent)]
pub struct EstimatorOptions {
    pub(super) tables: std::collections::BTreeMap<String, toml::Table>,
}

impl EstimatorOptions {
    /// Options with one estimator's table: `options`.
    pub fn with<T: Options>(options: &T) -> EstimatorOptions {
        let mut o = EstimatorOptions::default();
        o.put(options);
        o
    }

    /// `method`'s table (empty: every option at its default).
    pub fn table(&self, method: Method) -> toml::Table {
        self.tables.get(method.name()).cloned().unwrap_or_default()
    }

    /// Replace `method`'s table.
    pub fn set_table(&mut self, method: Method, table: toml::Table) {
        self.tables.insert(method.name().to_string(), table);
    }

    /// These tables with `over`'s options on top, option by option.
    pub fn merged(mut self, over: &EstimatorOptions) -> EstimatorOptions {
        for (name, table) in &over.tables {
            let mine = self.tables.entry(name.clone()).or_default();
            for (k, v) in table {
                mine.insert(k.clone(), v.clone());
            }
        }
        self
    }

    /// Set one option of `method`'s table.
    pub fn set(&mut self, method: Method, key: &str, value: toml::Value) {
        self.tables
            .entry(method.name().to_string())
            .or_default()
            .insert(key.to_string(), value);
    }

    /// Apply `METHOD.KEY=VALUE` (the value as TOML, or else as a string: `restir.m_cap=16`,
    /// `restir.confidence=candidates`).
    pub fn assign(&mut self, assignment: &str) -> Result<()> {
        let bad = |why: String| {
            crate::Error::Invalid(format!("--estimator-option `{assignment}`: {why}"))
        };
        let (path, value) = assignment
            .split_once('=')
            .ok_or_else(|| bad("expected METHOD.KEY=VALUE".into()))?;
        let (method, key) = path
            .trim()
            .split_once('.')
            .ok_or_else(|| bad("expected METHOD.KEY=VALUE".into()))?;
        let method = method.parse::<Method>().map_err(|e| bad(e.to_string()))?;
        let value = value.trim();
        let value = toml::from_str::<toml::Table>(&format!("v = {value}"))
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(value.to_string()));
        self.set(method, key.trim(), value);
        self.check_one(method)
            .map_err(|(key, msg)| bad(format!("{key} {msg}")))
    }

    /// The options of `T`'s estimator, parsed from its table.
    pub fn get<T: Options>(&self) -> std::result::Result<T, (String, String)> {
        let name = T::METHOD.name();
        let o: T = crate::optim::parse_table(name, self.tables.get(name))?;
        o.check()
            .map_err(|(k, m)| (format!("optimizer.{name}.{k}"), m))?;
        Ok(o)
    }

    /// Replace the table of `T`'s estimator by `options`.
    pub fn put<T: Options>(&mut self, options: &T) {
        self.set_table(T::METHOD, crate::optim::as_table(options));
    }

    /// Check `method`'s table: an error names the task-file key and what is wrong.
    pub fn check_one(&self, method: Method) -> std::result::Result<(), (String, String)> {
        let options = method.kind().options;
        if options.none {
            if let Some(k) = self.table(method).keys().next() {
                return Err((
                    format!("optimizer.{method}.{k}"),
                    format!("is not an option: the {method} estimator has none"),
                ));
            }
        }
        (options.check)(self)
    }

    /// Check every table.
    pub fn check(&self) -> std::result::Result<(), (String, String)> {
        for name in self.tables.keys() {
            let method = Method::by_name(name).ok_or_else(|| {
                (
                    format!("optimizer.{name}"),
                    format!("is no gradient estimator ({})", Method::names().join(", ")),
                )
            })?;
            self.check_one(method)?;
        }
        Ok(())
    }

    /// Every table as `METHOD.KEY=VALUE` assignments, comma-separated (`none` without any).
    pub fn summary(&self) -> String {
        let all: Vec<String> = self
            .tables
            .iter()
            .flat_map(|(m, t)| t.iter().map(move |(k, v)| format!("{m}.{k}={v}")))
            .collect();
        if all.is_empty() {
            "none".into()
        } else {
            all.join(", ")
        }
    }

    /// `method`'s options at their defaults, as the TOML of its task-file table (empty when
    /// it has none; options whose default is to be absent as comments).
    pub fn defaults_toml(method: Method) -> String {
        (method.kind().options.defaults_toml)()
    }

    /// A short description of `method`'s options for reports (empty for none).
    pub fn describe(&self, method: Method) -> String {
        (method.kind().options.describe)(self)
    }

    /// What `bench --tune` tries for `method`'s own options: for each option searched, in
    /// search order, a function from the best table so far to the tables to try.
    pub fn tuning(method: Method) -> Vec<TuningAxis> {
        (method.kind().options.tuning)()
    }
}

/// One option an estimator's search varies: the tables to try around the best so far.
pub type TuningAxis = Box<dyn Fn(&toml::Table) -> Vec<toml::Table>>;

/// An axis over typed options: the candidates a function of the options gives.
pub type TypedAxis<T> = fn(&T) -> Vec<T>;

fn typed_axes<T: Options + 'static>(axes: Vec<TypedAxis<T>>) -> Vec<TuningAxis> {
    axes.into_iter()
        .map(|axis| -> TuningAxis {
            Box::new(move |table: &toml::Table| {
                let mut o = EstimatorOptions::default();
                o.set_table(T::METHOD, table.clone());
                let best = o.get::<T>().unwrap_or_default();
                axis(&best)
                    .iter()
                    .map(|c| {
                        o.put(c);
                        o.table(T::METHOD)
                    })
                    .collect()
            })
        })
        .collect()
}
