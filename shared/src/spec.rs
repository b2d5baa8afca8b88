//! What an environment is: the identity a problem is defined for, every task names and every
//! worker declares, so that rollouts of differently configured environments are never mixed.

use crate::{FNV_OFFSET, fnv1a};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt;
use std::sync::{Arc, Mutex, PoisonError};

/// The name of [`EnvironmentSpec::unnamed`].
const UNNAMED: &str = "unnamed";

/// Most bytes of an environment's name (a fixed capacity, so that a spec crosses a wire as is).
pub const MAX_NAME: usize = 32;

/// Which environment a problem is defined for: a name, a hash of the settings that change its
/// rollouts, and three numbers a factory may build it from (for example a problem seed). Two
/// environments whose specs are equal perform the same rollouts; anything that would make them
/// differ (another time step, another random instance, another robot) must change the spec.
///
/// # Stability of the settings hash
/// [`EnvironmentSpec::new`] hashes the `Debug` text of a settings value with FNV-1a (64 bit).
/// The hash is the same in every process and on every platform of one build, and in builds that
/// print the settings the same way. A change of the settings' types, or of how a dependency or
/// the compiler prints them, changes the hash: processes of such builds then refuse each other's
/// tasks, which errs on the safe side. The hash may cover settings that happen not to change
/// rollouts; it must cover every one that does.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(try_from = "SpecFields", into = "SpecFields")]
pub struct EnvironmentSpec {
    /// ASCII, padded with zeros.
    name: [u8; MAX_NAME],
    settings: u64,
    parameters: [u64; 3],
}

/// A spec that cannot be made.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SpecBuildError {
    /// The name is empty, too long, or has a character outside the accepted set.
    #[error("environment name {0:?} must be 1 to {MAX_NAME} characters of ASCII letters, digits, '-', '_' and '.'")]
    Name(String),
    /// A saved settings hash is not 16 hexadecimal digits.
    #[error("environment settings {0:?} must be 16 hexadecimal digits")]
    Settings(String),
}

impl EnvironmentSpec {
    /// The spec of the environment `name` built from `parameters` with `settings`, everything
    /// that changes its rollouts (see the type's documentation for what the hash promises).
    pub fn new(name: &str, parameters: [u64; 3], settings: &impl fmt::Debug) -> Result<Self, SpecBuildError> {
        Self::from_text(name, parameters, &format!("{settings:?}"))
    }

    /// The spec of an environment whose settings are given as text, such as a problem file's
    /// `settings` string: the hash is FNV-1a (64 bit) of the text's UTF-8 bytes, so a worker in
    /// any language computes the same spec from the same text (docs/PROTOCOL.md).
    ///
    /// ```
    /// use acps_shared::EnvironmentSpec;
    /// let spec = EnvironmentSpec::from_text("reach-2d", [1, 0, 0], "dt=0.01").unwrap();
    /// assert_eq!(spec.to_string(), "reach-2d [1, 0, 0] (settings 30178b206d634ad5)");
    /// ```
    pub fn from_text(name: &str, parameters: [u64; 3], settings: &str) -> Result<Self, SpecBuildError> {
        let spec = Self::from_parts(name.as_bytes(), fnv1a(FNV_OFFSET, settings.as_bytes()), parameters)?;
        remember(spec.settings, settings);
        Ok(spec)
    }

    /// The identity of an environment nobody named: a problem file without one, and a worker
    /// that declares none, have it, so that they match each other and nothing else
    /// (docs/PROTOCOL.md, "Environment identity").
    pub fn unnamed() -> Self {
        Self::from_parts(UNNAMED.as_bytes(), FNV_OFFSET, [0; 3]).expect("a valid name")
    }

    /// Whether this is [`EnvironmentSpec::unnamed`].
    pub fn is_unnamed(&self) -> bool {
        *self == Self::unnamed()
    }

    /// A spec from its parts as they were stored or sent: `name` may be padded with zeros.
    pub fn from_parts(name: &[u8], settings: u64, parameters: [u64; 3]) -> Result<Self, SpecBuildError> {
        let len = name.iter().position(|&b| b == 0).unwrap_or(name.len());
        let (text, padding) = name.split_at(len);
        let valid = (1..=MAX_NAME).contains(&len)
            && padding.iter().all(|&b| b == 0)
            && text
                .iter()
                .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.'));
        if !valid {
            return Err(SpecBuildError::Name(String::from_utf8_lossy(name).into_owned()));
        }
        let mut padded = [0; MAX_NAME];
        padded[..len].copy_from_slice(text);
        Ok(Self {
            name: padded,
            settings,
            parameters,
        })
    }

    /// The environment's name.
    pub fn name(&self) -> &str {
        let len = self.name.iter().position(|&b| b == 0).unwrap_or(MAX_NAME);
        std::str::from_utf8(&self.name[..len]).expect("names are ASCII")
    }

    /// The name padded with zeros to [`MAX_NAME`] bytes.
    pub fn padded_name(&self) -> [u8; MAX_NAME] {
        self.name
    }

    /// The hash of the settings that change rollouts.
    pub fn settings(&self) -> u64 {
        self.settings
    }

    /// The numbers a factory builds the environment from.
    pub fn parameters(&self) -> [u64; 3] {
        self.parameters
    }

    /// The settings text this process hashed into this spec's settings (by
    /// [`new`](Self::new) or [`from_text`](Self::from_text)), `None` for a spec made only from
    /// its hash (one read from a file or a message): what a refusal shows beside the hash, since
    /// two hashes alone do not tell a user which setting differs.
    ///
    /// ```
    /// use acps_shared::EnvironmentSpec;
    /// let spec = EnvironmentSpec::new("arm", [0; 3], &(0.01, 3)).unwrap();
    /// assert_eq!(spec.settings_text().as_deref(), Some("(0.01, 3)"));
    /// let sent = EnvironmentSpec::from_parts(b"arm", 0x1234, [0; 3]).unwrap();
    /// assert_eq!(sent.settings_text(), None);
    /// ```
    pub fn settings_text(&self) -> Option<Arc<str>> {
        TEXTS
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .get(&self.settings)
            .cloned()
    }
}

/// The settings texts hashed in this process, by hash. It grows with the distinct settings a
/// process builds environments of (a handful), not with their uses.
static TEXTS: Mutex<BTreeMap<u64, Arc<str>>> = Mutex::new(BTreeMap::new());

/// Keep `text` as the settings text of `hash`.
fn remember(hash: u64, text: &str) {
    TEXTS
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .entry(hash)
        .or_insert_with(|| Arc::from(text));
}

/// `contextual-function [2, 20, 7] (settings 9f3a0c12d4e5b6a7)`.
impl fmt::Display for EnvironmentSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.is_unnamed() {
            return f.write_str("no named environment");
        }
        let [a, b, c] = self.parameters;
        write!(f, "{} [{a}, {b}, {c}] (settings {:016x})", self.name(), self.settings)
    }
}

impl fmt::Debug for EnvironmentSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "EnvironmentSpec({self})")
    }
}

/// How a spec is saved: the hash as hexadecimal text, which any JSON reader keeps exactly.
#[derive(Serialize, Deserialize)]
struct SpecFields {
    name: String,
    settings: String,
    parameters: [u64; 3],
}

impl From<EnvironmentSpec> for SpecFields {
    fn from(spec: EnvironmentSpec) -> Self {
        Self {
            name: spec.name().to_string(),
            settings: format!("{:016x}", spec.settings),
            parameters: spec.parameters,
        }
    }
}

impl TryFrom<SpecFields> for EnvironmentSpec {
    type Error = SpecBuildError;

    fn try_from(fields: SpecFields) -> Result<Self, SpecBuildError> {
        let settings = (fields.settings.len() == 16)
            .then(|| u64::from_str_radix(&fields.settings, 16).ok())
            .flatten()
            .ok_or_else(|| SpecBuildError::Settings(fields.settings.clone()))?;
        Self::from_parts(fields.name.as_bytes(), settings, fields.parameters)
    }
}

/// The environments a worker serves, as it declares them to a learner.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Serves {
    /// This one only: the learner hands the worker only tasks that need it.
    One(EnvironmentSpec),
    /// Whatever its factory builds: the worker checks the environment of every task it gets.
    Any,
}

impl Serves {
    /// Whether a task that needs `spec` may go to the worker.
    pub fn includes(&self, spec: &EnvironmentSpec) -> bool {
        match self {
            Serves::One(served) => served == spec,
            Serves::Any => true,
        }
    }
}

/// `contextual-function [...] (settings ...)`, or "any environment its factory builds".
impl fmt::Display for Serves {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Serves::One(spec) => spec.fmt(f),
            Serves::Any => f.write_str("any environment its factory builds"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_that_differ_give_specs_that_differ() {
        let spec = |dt: f64| EnvironmentSpec::new("arm.v2", [1, 0, 0], &(dt, 3)).unwrap();
        assert_eq!(spec(0.008), spec(0.008));
        assert_ne!(spec(0.008), spec(0.004));
        assert_eq!(spec(0.008).name(), "arm.v2");
        // The hash is FNV-1a over the Debug text: the same in every process and build that
        // prints the settings the same way.
        assert_eq!(spec(0.008).settings(), fnv1a(FNV_OFFSET, b"(0.008, 3)"));
        let other = EnvironmentSpec::new("arm.v2", [2, 0, 0], &(0.008, 3)).unwrap();
        assert_ne!(other, spec(0.008), "the parameters count");
        assert_eq!(
            spec(0.008).to_string(),
            format!("arm.v2 [1, 0, 0] (settings {:016x})", spec(0.008).settings())
        );
    }

    #[test]
    fn text_settings_hash_their_bytes_and_unnamed_matches_only_itself() {
        let spec = EnvironmentSpec::from_text("reach-2d", [1, 0, 0], "dt=0.01").unwrap();
        assert_eq!(spec.settings(), fnv1a(FNV_OFFSET, b"dt=0.01"));
        assert_ne!(
            spec,
            EnvironmentSpec::new("reach-2d", [1, 0, 0], &"dt=0.01").unwrap(),
            "Debug quotes"
        );
        let unnamed = EnvironmentSpec::unnamed();
        assert!(unnamed.is_unnamed() && !spec.is_unnamed());
        assert_eq!(unnamed.to_string(), "no named environment");
        assert!(!EnvironmentSpec::from_text("unnamed", [0; 3], "x").unwrap().is_unnamed());
    }

    #[test]
    fn names_are_short_ascii() {
        for bad in ["", "with space", "ünïcode", &"x".repeat(MAX_NAME + 1)] {
            let error = EnvironmentSpec::new(bad, [0; 3], &()).unwrap_err();
            assert_eq!(error, SpecBuildError::Name(bad.to_string()));
        }
        let longest = "x".repeat(MAX_NAME);
        assert_eq!(EnvironmentSpec::new(&longest, [0; 3], &()).unwrap().name(), longest);
        // Padding only at the end: a zero byte cannot hide characters behind it.
        assert!(EnvironmentSpec::from_parts(b"ab\0c", 0, [0; 3]).is_err());
        assert_eq!(EnvironmentSpec::from_parts(b"ab\0\0", 0, [0; 3]).unwrap().name(), "ab");
    }

    #[test]
    fn specs_are_saved_readably_and_read_back_checked() {
        let spec = EnvironmentSpec::new("trivial", [u64::MAX, 0, 7], &()).unwrap();
        let json = serde_json::to_string(&spec).unwrap();
        assert_eq!(
            json,
            format!(
                r#"{{"name":"trivial","settings":"{:016x}","parameters":[18446744073709551615,0,7]}}"#,
                spec.settings()
            )
        );
        assert_eq!(serde_json::from_str::<EnvironmentSpec>(&json).unwrap(), spec);
        let short = json.replace(&format!("{:016x}", spec.settings()), "abc");
        assert!(serde_json::from_str::<EnvironmentSpec>(&short).is_err());
        let renamed = json.replace("trivial", "not valid");
        assert!(serde_json::from_str::<EnvironmentSpec>(&renamed).is_err());
    }

    #[test]
    fn a_worker_serving_one_environment_takes_only_its_tasks() {
        let a = EnvironmentSpec::new("a", [0; 3], &()).unwrap();
        let b = EnvironmentSpec::new("b", [0; 3], &()).unwrap();
        assert!(Serves::One(a).includes(&a) && !Serves::One(a).includes(&b));
        assert!(Serves::Any.includes(&b));
    }
}
