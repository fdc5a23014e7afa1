//! The one shape of the optimizer's three kinds of plugin: gradient estimators, steps and
//! priors. A kind lives in its own folder and exports one value, its `Kind`; its family's
//! `REGISTRY` lists the kinds (`registry!`, the one line to add for a new one). A
//! [`Handle`] names a kind (`Method`, `StepKind`); each kind's options are its own type
//! ([`Options`]), read from its table under the task file's `[optimizer]`, which [`Tables`]
//! holds for the whole family (`EstimatorOptions`, `Steps`, `Priors`). [`Family`] is what
//! this module knows of a family: its registry, and its kinds' names, tables and options.

use std::collections::BTreeMap;
use std::marker::PhantomData;

/// Declares the folders of a registry and lists each one's `KIND` in the module's
/// `REGISTRY` of `&Kind`, documented by the string given first.
macro_rules! registry {
    ($doc:literal, $($(#[$attr:meta])* $folder:ident),* $(,)?) => {
        $($(#[$attr])* pub mod $folder;)*
        #[doc = $doc]
        pub const REGISTRY: &[&Kind] = &[$($(#[$attr])* &$folder::KIND),*];
    };
}
pub(crate) use registry;

/// A family of plugins, as the generic [`Handle`] and [`Tables`] reach its kinds.
pub trait Family: Sized + 'static {
    /// What one of its kinds is called in messages: `gradient estimator`, `step`, `prior`.
    const WHAT: &'static str;
    /// What a kind's folder exports.
    type Kind: 'static;
    /// Every kind, in the registry's order.
    fn registry() -> &'static [&'static Self::Kind];
    /// A kind's name: the command line's, the task file's and the reports'.
    fn name(kind: &'static Self::Kind) -> &'static str;
    /// A kind's options table under `[optimizer]` (its name unless it says otherwise).
    fn table(kind: &'static Self::Kind) -> &'static str {
        Self::name(kind)
    }
    /// What the registry knows of a kind's options.
    fn options(kind: &'static Self::Kind) -> OptionsKind<Self>;

    /// The kind whose options table is `table`.
    fn by_table(table: &str) -> Option<&'static Self::Kind> {
        Self::registry()
            .iter()
            .copied()
            .find(|k| Self::table(k) == table)
    }

    /// Every kind's options table, in the registry's order.
    fn tables() -> Vec<&'static str> {
        Self::registry().iter().map(|k| Self::table(k)).collect()
    }
}

/// A kind's options as its folder defines them: read from and written to its table in
/// [`Tables`] (missing keys take their defaults).
pub trait Options<F: Family>:
    Clone + Default + serde::Serialize + serde::de::DeserializeOwned + std::fmt::Debug + 'static
{
    /// The kind they belong to.
    const KIND: &'static F::Kind;
    /// The options whose default is to be absent (an `Option` left `None`).
    const OPTIONAL: &'static [&'static str] = &[];
    /// An error naming the option (its key in the table) and what is wrong.
    fn check(&self) -> std::result::Result<(), (String, String)>;
    /// A short description for reports (empty: nothing to say), e.g. `smoothness 0.03`.
    fn describe(&self) -> String {
        String::new()
    }
    /// Whether the kind acts at all with these options (a prior may be off).
    fn on(&self) -> bool {
        true
    }
    /// What `bench --tune` varies, in search order: for each option searched, the
    /// candidates around the best options so far (none: these options are not tuned).
    fn tuning(_context: &TuningContext) -> Vec<TypedAxis<Self>> {
        Vec::new()
    }
}

/// What a kind's search may depend on besides its own options.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TuningContext {
    /// The run filters the step's moments (`moment_filter`).
    pub filtered: bool,
}

/// One option a search varies: the tables to try around the best so far.
pub type TuningAxis = Box<dyn Fn(&toml::Table) -> Vec<toml::Table>>;

/// An axis over typed options: the candidates a function of the options gives.
pub type TypedAxis<T> = fn(&T) -> Vec<T>;

/// What the registry knows of a kind's options without their type: functions of the
/// family's [`Tables`], made from an [`Options`] type by [`OptionsKind::of`];
/// [`OptionsKind::NONE`] is for a kind without options.
pub struct OptionsKind<F: Family> {
    check: fn(&Tables<F>) -> std::result::Result<(), (String, String)>,
    on: fn(&Tables<F>) -> bool,
    describe: fn(&Tables<F>) -> String,
    defaults: fn() -> toml::Table,
    defaults_toml: fn() -> String,
    tuning: fn(&TuningContext) -> Vec<TuningAxis>,
    /// Whether the kind has no options at all (any key in its table is an error).
    none: bool,
}

impl<F: Family> Clone for OptionsKind<F> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<F: Family> Copy for OptionsKind<F> {}

impl<F: Family> OptionsKind<F> {
    /// The options of a kind that has none: its table must be empty.
    pub const NONE: OptionsKind<F> = OptionsKind {
        check: |_| Ok(()),
        on: |_| true,
        describe: |_| String::new(),
        defaults: toml::Table::new,
        defaults_toml: String::new,
        tuning: |_| Vec::new(),
        none: true,
    };

    /// The options `T` defines.
    pub const fn of<T: Options<F>>() -> OptionsKind<F> {
        OptionsKind {
            check: |t| t.get::<T>().map(|_| ()),
            on: |t| t.get::<T>().is_ok_and(|o| o.on()),
            describe: |t| t.get::<T>().map(|o| o.describe()).unwrap_or_default(),
            defaults: || as_table(&T::default()),
            defaults_toml: || {
                let mut s = toml::to_string(&T::default()).unwrap_or_default();
                for key in T::OPTIONAL {
                    s.push_str(&format!("# {key} = ...  (absent by default)\n"));
                }
                s
            },
            tuning: |context| {
                T::tuning(context)
                    .into_iter()
                    .map(|axis| -> TuningAxis {
                        Box::new(move |table: &toml::Table| {
                            let mut t = Tables::<F>::default();
                            t.set_table(F::table(T::KIND), table.clone());
                            axis(&t.of::<T>()).iter().map(|c| as_table(c)).collect()
                        })
                    })
                    .collect()
            },
            none: false,
        }
    }

    /// The options at their defaults, as a table.
    pub fn defaults(&self) -> toml::Table {
        (self.defaults)()
    }
}

/// A kind of family `F`, as a [`Handle`] or as what its folder exports.
pub trait AsKind<F: Family>: Copy {
    /// What its folder exports.
    fn as_kind(self) -> &'static F::Kind;
}

impl<F: Family> AsKind<F> for &'static F::Kind {
    fn as_kind(self) -> &'static F::Kind {
        self
    }
}

impl<F: Family> AsKind<F> for Handle<F> {
    fn as_kind(self) -> &'static F::Kind {
        self.0
    }
}

/// An options table of family `F`, by its name or by its kind's [`Handle`].
pub trait TableName<F: Family> {
    /// The table's name under `[optimizer]`.
    fn table_name(&self) -> &str;
}

impl<F: Family> TableName<F> for &str {
    fn table_name(&self) -> &str {
        self
    }
}

impl<F: Family> TableName<F> for Handle<F> {
    fn table_name(&self) -> &str {
        self.table()
    }
}

/// A kind of family `F`, by reference to what its folder exports (`Method`, `StepKind`):
/// compared, hashed, shown, parsed and serialized by its name.
pub struct Handle<F: Family>(&'static F::Kind);

impl<F: Family> Handle<F> {
    /// The kind whose folder exports `kind`.
    pub const fn of(kind: &'static F::Kind) -> Handle<F> {
        Handle(kind)
    }

    /// Every kind, in the order reports list them.
    pub fn all() -> impl Iterator<Item = Handle<F>> {
        F::registry().iter().map(|k| Handle(*k))
    }

    /// The name used on the command line, in task files and in reports.
    pub fn name(self) -> &'static str {
        F::name(self.0)
    }

    /// Everything the registry knows of it.
    pub fn kind(self) -> &'static F::Kind {
        self.0
    }

    /// Its options table under `[optimizer]`.
    pub fn table(self) -> &'static str {
        F::table(self.0)
    }

    /// Every kind's name.
    pub fn names() -> Vec<&'static str> {
        Handle::<F>::all().map(|h| h.name()).collect()
    }

    /// The kind called `name`.
    pub fn by_name(name: &str) -> Option<Handle<F>> {
        Handle::<F>::all().find(|h| h.name() == name)
    }
}

impl<F: Family> Clone for Handle<F> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<F: Family> Copy for Handle<F> {}

impl<F: Family> Default for Handle<F> {
    /// The registry's first kind.
    fn default() -> Handle<F> {
        Handle(F::registry()[0])
    }
}

impl<F: Family> PartialEq for Handle<F> {
    fn eq(&self, other: &Handle<F>) -> bool {
        self.name() == other.name()
    }
}

impl<F: Family> Eq for Handle<F> {}

impl<F: Family> std::hash::Hash for Handle<F> {
    fn hash<H: std::hash::Hasher>(&self, h: &mut H) {
        self.name().hash(h)
    }
}

impl<F: Family> std::fmt::Debug for Handle<F> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl<F: Family> std::fmt::Display for Handle<F> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl<F: Family> std::str::FromStr for Handle<F> {
    type Err = crate::Error;
    fn from_str(s: &str) -> crate::Result<Handle<F>> {
        Handle::by_name(s).ok_or_else(|| {
            crate::Error::Invalid(format!(
                "unknown {} `{s}` (one of: {})",
                F::WHAT,
                Handle::<F>::names().join(", ")
            ))
        })
    }
}

impl<F: Family> serde::Serialize for Handle<F> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de, F: Family> serde::Deserialize<'de> for Handle<F> {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Handle<F>, D::Error> {
        let name = <String as serde::Deserialize>::deserialize(d)?;
        name.parse().map_err(serde::de::Error::custom)
    }
}

/// Every kind's options of family `F`, one table of TOML values per kind's table name: the
/// task file's `[optimizer.<table>]` tables (and the command line's assignments on top).
/// The optimizer, the job and the bench only pass the tables on; each kind reads its own
/// ([`Options`]) and [`Tables::check`] asks each to check its table.
#[derive(serde::Serialize, serde::Deserialize)]
#[serde(transparent, bound = "")]
pub struct Tables<F: Family> {
    tables: BTreeMap<String, toml::Table>,
    #[serde(skip)]
    family: PhantomData<fn() -> F>,
}

#[cfg(test)]
impl<F: Family> Tables<F> {
    /// Every table by name, unchecked (for the tests of what a check finds).
    pub(crate) fn tables_mut(&mut self) -> &mut BTreeMap<String, toml::Table> {
        &mut self.tables
    }
}

impl<F: Family> Clone for Tables<F> {
    fn clone(&self) -> Self {
        Tables {
            tables: self.tables.clone(),
            family: PhantomData,
        }
    }
}

impl<F: Family> Default for Tables<F> {
    fn default() -> Self {
        Tables {
            tables: BTreeMap::new(),
            family: PhantomData,
        }
    }
}

impl<F: Family> PartialEq for Tables<F> {
    fn eq(&self, other: &Self) -> bool {
        self.tables == other.tables
    }
}

impl<F: Family> std::fmt::Debug for Tables<F> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.tables.fmt(f)
    }
}

impl<F: Family> Tables<F> {
    /// These tables with `options` in place of their kind's table:
    /// `Priors::default().with(&SmoothnessOptions { weight: 0.01 })`.
    pub fn with<T: Options<F>>(mut self, options: &T) -> Self {
        self.put(options);
        self
    }

    /// The options of `T`'s kind, parsed from its table and checked: an error names the
    /// task-file key and what is wrong.
    pub fn get<T: Options<F>>(&self) -> std::result::Result<T, (String, String)> {
        let table = F::table(T::KIND);
        let o: T = parse_table(table, self.tables.get(table))?;
        o.check()
            .map_err(|(k, m)| (format!("optimizer.{table}.{k}"), m))?;
        Ok(o)
    }

    /// The options of `T`'s kind, at their defaults where the table is not valid (settings
    /// are checked before an optimizer reads them).
    pub fn of<T: Options<F>>(&self) -> T {
        self.get().unwrap_or_default()
    }

    /// Replace the table of `T`'s kind by `options`.
    pub fn put<T: Options<F>>(&mut self, options: &T) {
        self.set_table(F::table(T::KIND), as_table(options));
    }

    /// The table called `table` (empty: every option at its default).
    pub fn table(&self, table: impl TableName<F>) -> toml::Table {
        let table = table.table_name();
        self.tables.get(table).cloned().unwrap_or_default()
    }

    /// Replace the table called `table`.
    pub fn set_table(&mut self, table: impl TableName<F>, values: toml::Table) {
        self.tables.insert(table.table_name().to_string(), values);
    }

    /// Set one option of the table `table` (checked by [`Tables::check`]).
    pub fn set(&mut self, table: impl TableName<F>, key: &str, value: toml::Value) {
        self.tables
            .entry(table.table_name().to_string())
            .or_default()
            .insert(key.to_string(), value);
    }

    /// These tables with `over`'s options on top, option by option.
    pub fn merged(mut self, over: &Tables<F>) -> Tables<F> {
        for (name, table) in &over.tables {
            let mine = self.tables.entry(name.clone()).or_default();
            for (k, v) in table {
                mine.insert(k.clone(), v.clone());
            }
        }
        self
    }

    /// Check `kind`'s table: an error names the task-file key and what is wrong.
    pub fn check_one(&self, kind: impl AsKind<F>) -> std::result::Result<(), (String, String)> {
        let kind = kind.as_kind();
        let options = F::options(kind);
        if options.none {
            if let Some(k) = self.table(F::table(kind)).keys().next() {
                return Err((
                    format!("optimizer.{}.{k}", F::table(kind)),
                    format!(
                        "is not an option: the {} {} has none",
                        F::name(kind),
                        F::WHAT
                    ),
                ));
            }
        }
        (options.check)(self)
    }

    /// Check every table: an error names the task-file key and what is wrong.
    pub fn check(&self) -> std::result::Result<(), (String, String)> {
        for table in self.tables.keys() {
            let kind = F::by_table(table).ok_or_else(|| {
                (
                    format!("optimizer.{table}"),
                    format!("is no {}'s table ({})", F::WHAT, F::tables().join(", ")),
                )
            })?;
            self.check_one(kind)?;
        }
        Ok(())
    }

    /// The kinds whose options say they act, in the registry's order.
    pub fn active(&self) -> Vec<&'static F::Kind> {
        F::registry()
            .iter()
            .copied()
            .filter(|k| (F::options(k).on)(self))
            .collect()
    }

    /// A short description of `kind`'s options for reports (empty: nothing to say).
    pub fn describe(&self, kind: impl AsKind<F>) -> String {
        (F::options(kind.as_kind()).describe)(self)
    }

    /// `kind`'s options at their defaults, as the TOML of its task-file table (empty when
    /// it has none; options whose default is to be absent as comments).
    pub fn defaults_toml(kind: impl AsKind<F>) -> String {
        (F::options(kind.as_kind()).defaults_toml)()
    }

    /// What `bench --tune` tries for `kind`'s options in `context`: for each option
    /// searched, in search order, a function from the best table so far to the tables to try.
    pub fn tuning(kind: impl AsKind<F>, context: &TuningContext) -> Vec<TuningAxis> {
        (F::options(kind.as_kind()).tuning)(context)
    }

    /// Every table as `TABLE.KEY=VALUE` assignments, comma-separated (`none` without any).
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
}

/// A kind's options as the TOML table they serialize to, by way of their text, so that an
/// `f32` reads as written (0.9, not 0.8999999761581421) where the table is shown.
pub(crate) fn as_table<T: serde::Serialize>(options: &T) -> toml::Table {
    toml::to_string(options)
        .ok()
        .and_then(|text| toml::from_str(&text).ok())
        .expect("a kind's options serialize to a table")
}

/// The options in the task file's `[optimizer.<name>]` table (None: every option at its
/// default); an error names that table and what is wrong with it.
pub(crate) fn parse_table<T: serde::de::DeserializeOwned>(
    name: &str,
    table: Option<&toml::Table>,
) -> std::result::Result<T, (String, String)> {
    let table = table.cloned().unwrap_or_default();
    T::deserialize(toml::Value::Table(table)).map_err(|e| {
        let msg = e.to_string().trim().replace('\n', " ");
        (format!("optimizer.{name}"), msg)
    })
}
