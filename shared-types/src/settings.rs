//! Settings: each algorithm's tuning as a serde structure with its defaults, set from a launch
//! file (`[planning.dwa] heading = 0.4`), from `mole up --set planning.dwa.critics.heading=0.4`
//! and, while a process runs, by `mole param set`.
//!
//! A settings struct derives `serde::{Serialize, Deserialize}` (`#[serde(default,
//! deny_unknown_fields)]`), `Default` and [`Setting`] (`#[derive(Setting)]`, crate
//! mole-types-derive): its doc comments and `#[setting(min = …, above = …, max = …, fixed =
//! "why")]` give the check of every value and the rows of docs/settings.md.

use core::fmt;
use serde::Serialize;
use serde::de::DeserializeOwned;

/// A setting that is not what its key allows.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SettingError {
    /// The key, dotted from the role's table: `dwa.critics.heading`.
    pub key: String,
    /// What the key takes.
    pub expected: String,
    /// What it was given.
    pub found: String,
}

impl SettingError {
    /// `found` at `key`, where `expected` was.
    pub fn new(key: &str, expected: &str, found: &dyn fmt::Debug) -> Self {
        Self {
            key: key.to_owned(),
            expected: expected.to_owned(),
            found: format!("{found:?}"),
        }
    }

    /// The same error, its key below `prefix` (`planning` + `dwa.lookahead`).
    #[must_use]
    pub fn below(mut self, prefix: &str) -> Self {
        self.key = join(prefix, &self.key);
        self
    }
}

impl fmt::Display for SettingError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "setting `{}`: {}, expected {}",
            self.key, self.found, self.expected
        )
    }
}

impl std::error::Error for SettingError {}

/// What a key's doc comment, bounds and `fixed` say.
#[derive(Debug, Clone, Default)]
pub struct About {
    pub doc: &'static str,
    /// `≥ 0, ≤ 1`; empty without bounds. A bound that is a constant is given by its value.
    pub rule: String,
    /// Why it cannot change while the process runs; `None`: it can.
    pub fixed: Option<&'static str>,
}

/// One leaf key of a role's settings.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Key {
    /// Dotted from the role's table: `dwa.critics.heading`.
    pub path: String,
    /// What it takes: `number`, `integer`, `true or false`, `one of: …`.
    pub kind: String,
    pub doc: String,
    pub rule: String,
    pub fixed: Option<String>,
}

impl Key {
    /// The key of a leaf of type `T` at `path`.
    pub fn leaf<T: Setting>(path: &str, about: About) -> Self {
        Self {
            path: path.to_owned(),
            kind: T::kind(),
            doc: about.doc.to_owned(),
            rule: about.rule,
            fixed: about.fixed.map(str::to_owned),
        }
    }
}

/// `a.b` from `a` and `b`; `b` alone below the root (`""`).
pub fn join(prefix: &str, key: &str) -> String {
    if key.is_empty() {
        prefix.to_owned()
    } else if prefix.is_empty() {
        key.to_owned()
    } else {
        format!("{prefix}.{key}")
    }
}

/// A value a settings table holds: a number, a flag, a choice, or a table of settings.
pub trait Setting {
    /// What a user writes for it, as the docs say it.
    fn kind() -> String;
    /// Whether the value is allowed (a number finite, a table each of its values), the error
    /// naming `at`.
    fn check_at(&self, at: &str) -> Result<(), SettingError>;
    /// Its leaf keys at and below `at`.
    fn keys_at(at: &str, about: About, out: &mut Vec<Key>);
}

macro_rules! leaves {
    ($kind:literal, $finite:expr, $($t:ty),+) => {$(
        impl Setting for $t {
            fn kind() -> String {
                $kind.to_owned()
            }
            fn check_at(&self, at: &str) -> Result<(), SettingError> {
                let finite: fn(&$t) -> bool = $finite;
                if finite(self) {
                    Ok(())
                } else {
                    Err(SettingError::new(at, "a finite number", self))
                }
            }
            fn keys_at(at: &str, about: About, out: &mut Vec<Key>) {
                out.push(Key::leaf::<Self>(at, about));
            }
        }
    )+};
}
leaves!("number", |v| v.is_finite(), f64, f32);
leaves!("integer", |_| true, u8, u16, u32, u64, usize, i32, i64);
leaves!("true or false", |_| true, bool);

impl<T: Setting> Setting for Option<T> {
    fn kind() -> String {
        T::kind()
    }
    fn check_at(&self, at: &str) -> Result<(), SettingError> {
        self.as_ref().map_or(Ok(()), |v| v.check_at(at))
    }
    fn keys_at(at: &str, about: About, out: &mut Vec<Key>) {
        T::keys_at(at, about, out);
    }
}

/// The bounds of `#[setting(min, above, max)]`, on a number or an optional one (unset passes).
pub trait Bound<T> {
    fn is_at_least(&self, bound: T) -> bool;
    fn is_above(&self, bound: T) -> bool;
    fn is_at_most(&self, bound: T) -> bool;
}

impl<T: PartialOrd + Copy> Bound<T> for T {
    fn is_at_least(&self, bound: T) -> bool {
        *self >= bound
    }
    fn is_above(&self, bound: T) -> bool {
        *self > bound
    }
    fn is_at_most(&self, bound: T) -> bool {
        *self <= bound
    }
}

impl<T: PartialOrd + Copy> Bound<T> for Option<T> {
    fn is_at_least(&self, bound: T) -> bool {
        self.is_none_or(|v| v >= bound)
    }
    fn is_above(&self, bound: T) -> bool {
        self.is_none_or(|v| v > bound)
    }
    fn is_at_most(&self, bound: T) -> bool {
        self.is_none_or(|v| v <= bound)
    }
}

/// A role's settings: one table of [`Setting`]s with defaults.
pub trait Settings: Setting + Clone + Default + Serialize + DeserializeOwned {
    /// Every value checked.
    fn check(&self) -> Result<(), SettingError> {
        self.check_at("")
    }

    /// Every leaf key.
    fn keys() -> Vec<Key> {
        let mut out = Vec::new();
        Self::keys_at("", About::default(), &mut out);
        out
    }

    /// These settings with `key` (dotted) set to `value`, written as in TOML (`0.4`, `true`,
    /// `"critics"`), type-checked and checked: an unknown key is refused naming the keys there
    /// are.
    fn with(&self, key: &str, value: &str) -> Result<Self, SettingError> {
        // A TOML value, or a bare word as a shell user types it (`replan_with=apf`).
        let bare = !value.is_empty()
            && value
                .chars()
                .all(|c| c.is_alphanumeric() || c == '-' || c == '_');
        let value = match format!("v = {value}").parse::<toml::Table>() {
            Ok(parsed) => parsed["v"].clone(),
            Err(_) if bare => toml::Value::String(value.to_owned()),
            Err(_) => {
                return Err(SettingError {
                    key: key.to_owned(),
                    expected: "a TOML value (a number, true or false, a word or a \"string\")"
                        .to_owned(),
                    found: value.to_owned(),
                });
            }
        };
        let mut table = toml::Table::try_from(self).expect("settings serialize to a table");
        let mut at = &mut table;
        let parts: Vec<&str> = key.split('.').collect();
        let known = Self::keys();
        // The keys of the deepest table the key names correctly, so the choices fit a line.
        let unknown = || {
            let table = (0..parts.len())
                .rev()
                .map(|n| parts[..n].join("."))
                .find(|t| {
                    t.is_empty() || known.iter().any(|k| k.path.starts_with(&format!("{t}.")))
                })
                .unwrap_or_default();
            let prefix = if table.is_empty() {
                String::new()
            } else {
                format!("{table}.")
            };
            let mut keys: Vec<String> = known
                .iter()
                .filter_map(|k| k.path.strip_prefix(&prefix))
                .map(|rest| match rest.split_once('.') {
                    Some((child, _)) => format!("{prefix}{child}.…"),
                    None => format!("{prefix}{rest}"),
                })
                .collect();
            keys.sort_unstable();
            keys.dedup();
            SettingError {
                key: key.to_owned(),
                expected: format!("one of the keys: {}", keys.join(", ")),
                found: "an unknown key".to_owned(),
            }
        };
        let Some(this) = known.iter().find(|k| k.path == key) else {
            return Err(unknown());
        };
        for part in &parts[..parts.len() - 1] {
            at = match at
                .entry((*part).to_owned())
                .or_insert_with(|| toml::Table::new().into())
            {
                toml::Value::Table(t) => t,
                _ => return Err(unknown()),
            };
        }
        at.insert(parts[parts.len() - 1].to_owned(), value.clone());
        let new: Self = table
            .try_into()
            .map_err(|e: toml::de::Error| SettingError {
                key: key.to_owned(),
                expected: match this.rule.as_str() {
                    "" => this.kind.clone(),
                    rule => format!("{} {rule}", this.kind),
                },
                found: format!("{value} ({})", e.message().trim_end_matches('\n')),
            })?;
        new.check()?;
        Ok(new)
    }

    /// The value of `key` as TOML writes it; `None` for an unknown key.
    fn get(&self, key: &str) -> Option<String> {
        let table = toml::Table::try_from(self).ok()?;
        let mut at = &toml::Value::Table(table);
        for part in key.split('.') {
            at = at.as_table()?.get(part)?;
        }
        Some(match at {
            // An `f32` setting reaches TOML widened: written as the `f32` it is (0.847, not
            // 0.847000002861023), which reads back to the same value.
            toml::Value::Float(v) if f64::from(*v as f32) == *v && v.is_finite() => {
                let short = (*v as f32).to_string();
                if short.contains(['.', 'e']) {
                    short
                } else {
                    format!("{short}.0")
                }
            }
            other => other.to_string(),
        })
    }
}

impl<T: Setting + Clone + Default + Serialize + DeserializeOwned> Settings for T {}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Setting;
    use serde::Deserialize;

    /// How the robot brakes.
    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, Setting)]
    #[serde(rename_all = "kebab-case")]
    enum Brake {
        #[default]
        Soft,
        HardStop,
    }

    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Setting)]
    #[serde(default, deny_unknown_fields)]
    struct Inner {
        /// Weight of the goal.
        #[setting(min = 0.0)]
        goal: f64,
        /// How it brakes.
        brake: Brake,
    }

    impl Default for Inner {
        fn default() -> Self {
            Self {
                goal: 1.0,
                brake: Brake::Soft,
            }
        }
    }

    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Setting)]
    #[serde(default, deny_unknown_fields)]
    struct Outer {
        /// Horizon (s).
        #[setting(above = 0.0, max = 10.0)]
        horizon: f64,
        /// Samples per axis.
        #[setting(min = 2, fixed = "the buffers are sized at start")]
        samples: u32,
        /// The inner table.
        #[serde(rename = "the-inner")]
        inner: Inner,
        #[serde(skip)]
        seed: u64,
    }

    impl Default for Outer {
        fn default() -> Self {
            Self {
                horizon: 2.0,
                samples: 11,
                inner: Inner::default(),
                seed: 0,
            }
        }
    }

    #[test]
    fn keys_carry_their_docs_bounds_and_kinds() {
        let keys = Outer::keys();
        let paths: Vec<&str> = keys.iter().map(|k| k.path.as_str()).collect();
        assert_eq!(
            paths,
            ["horizon", "samples", "the-inner.goal", "the-inner.brake"]
        );
        assert_eq!(keys[0].rule, "> 0.0, ≤ 10.0");
        assert_eq!(keys[0].doc, "Horizon (s).");
        assert_eq!(keys[0].kind, "number");
        assert_eq!(
            keys[1].fixed.as_deref(),
            Some("the buffers are sized at start")
        );
        assert_eq!(keys[3].kind, "one of: soft, hard-stop");
    }

    #[test]
    fn a_key_set_is_type_checked_and_bounded_and_an_unknown_one_refused() {
        let s = Outer::default();
        let t = s.with("the-inner.goal", "0.5").unwrap();
        assert_eq!(t.inner.goal, 0.5);
        assert_eq!(
            t.with("the-inner.brake", "\"hard-stop\"")
                .unwrap()
                .inner
                .brake,
            Brake::HardStop
        );
        assert_eq!(t.get("the-inner.goal").as_deref(), Some("0.5"));
        let e = s.with("the-inner.goal", "-1.0").unwrap_err();
        assert_eq!(e.key, "the-inner.goal");
        assert_eq!(e.expected, "a value ≥ 0.0");
        let e = s.with("horizon", "nan").unwrap_err();
        assert_eq!(e.expected, "a finite number");
        let e = s.with("horizon", "11.0").unwrap_err();
        assert_eq!(e.expected, "a value ≤ 10.0");
        let e = s.with("samples", "1").unwrap_err();
        assert_eq!(e.expected, "a value ≥ 2");
        let e = s.with("horizon", "\"long\"").unwrap_err();
        assert_eq!(e.expected, "number > 0.0, ≤ 10.0");
        assert!(e.found.contains("invalid type"), "{e}");
        let e = s.with("the-inner.gaol", "1.0").unwrap_err();
        assert_eq!(
            e.expected,
            "one of the keys: the-inner.brake, the-inner.goal"
        );
        let e = s.with("gaol", "1.0").unwrap_err();
        assert!(e.expected.contains("the-inner.…"), "{e}");
        assert!(s.with("horizon", "1.0 2.0").is_err());
        assert!(s.check().is_ok());
    }

    /// A number reads back as written: an `f32` as the `f32` it is, an `f64` whole.
    #[test]
    fn numbers_are_written_as_their_own_type_reads_them() {
        #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, Setting)]
        struct Numbers {
            /// Single.
            single: f32,
            /// Double.
            double: f64,
        }
        let n = Numbers {
            single: 0.847,
            double: 0.1,
        };
        assert_eq!(n.get("single").as_deref(), Some("0.847"));
        assert_eq!(n.get("double").as_deref(), Some("0.1"));
        let whole = n.with("single", "3").unwrap();
        assert_eq!(whole.get("single").as_deref(), Some("3.0"));
        let back = n.with("single", &n.get("single").unwrap()).unwrap();
        assert_eq!(back, n);
    }
}
