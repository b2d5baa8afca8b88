//! The paper's experiments by name ([`ExperimentName`]), what a key of an experiment file is
//! ([`Key`]: its name, range and reason, where it applies)
//! and what can be wrong with its value; [`ConfigError`] is the message a user
//! reads, naming the option or the file and line.

use crate::settings::LearnerName;
use acps_learner::Method;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// The built-in experiments: the paper's, and BOLeRo's benchmark of the C-CMA-ES paper.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum ExperimentName {
    /// Section 4's model of the learning process (Fig. 2 and 3).
    Toy,
    /// Section 5.1.2's contextual function on a 5x5 grid of contexts (Fig. 4 and 5).
    Function,
    /// Section 5.1.3: the contextual function for 1 to 4 context dimensions (Fig. 6).
    Dims,
    /// Section 5.2.3: the PA-10 throws at a 5x5 grid of targets, tested on a 4x4 grid (Fig. 8).
    Grid,
    /// Section 5.2.4: the PA-10 throws at the 81 fields of a dartboard on the ground (Fig. 10).
    Dartboard,
    /// BOLeRo's contextual sphere: 20 parameters, a 2-D context in [1, 2]^2 (not the paper's).
    Sphere,
    /// BOLeRo's contextual Rosenbrock: 20 parameters, a 1-D context in [1, 2] (not the paper's).
    Rosenbrock,
}

impl ExperimentName {
    /// The name on the command line and in files.
    pub fn name(self) -> &'static str {
        match self {
            Self::Toy => "toy",
            Self::Function => "function",
            Self::Dims => "dims",
            Self::Grid => "grid",
            Self::Dartboard => "dartboard",
            Self::Sphere => "sphere",
            Self::Rosenbrock => "rosenbrock",
        }
    }
}

/// What an experiment file describes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// One of the paper's experiments.
    Paper(ExperimentName),
    /// A `[problem]` table.
    File,
}

impl Kind {
    /// How a message names it.
    pub(crate) fn describe(self) -> String {
        match self {
            Kind::Paper(name) => format!("the {} experiment", name.name()),
            Kind::File => "a [problem] table".into(),
        }
    }

    /// How a list of where a key applies names it.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Kind::Paper(name) => name.name(),
            Kind::File => "[problem] tables",
        }
    }
}

/// Every built-in experiment.
pub const PAPER: &[Kind] = &[
    Kind::Paper(ExperimentName::Toy),
    Kind::Paper(ExperimentName::Function),
    Kind::Paper(ExperimentName::Dims),
    Kind::Paper(ExperimentName::Grid),
    Kind::Paper(ExperimentName::Dartboard),
    Kind::Paper(ExperimentName::Sphere),
    Kind::Paper(ExperimentName::Rosenbrock),
];
/// Everything a file can describe.
pub const ALL: &[Kind] = &[
    Kind::Paper(ExperimentName::Toy),
    Kind::Paper(ExperimentName::Function),
    Kind::Paper(ExperimentName::Dims),
    Kind::Paper(ExperimentName::Grid),
    Kind::Paper(ExperimentName::Dartboard),
    Kind::Paper(ExperimentName::Sphere),
    Kind::Paper(ExperimentName::Rosenbrock),
    Kind::File,
];
/// What learns a policy (all but the Section 4 model).
pub const WITH_CREPS: &[Kind] = &[
    Kind::Paper(ExperimentName::Function),
    Kind::Paper(ExperimentName::Dims),
    Kind::Paper(ExperimentName::Grid),
    Kind::Paper(ExperimentName::Dartboard),
    Kind::Paper(ExperimentName::Sphere),
    Kind::Paper(ExperimentName::Rosenbrock),
    Kind::File,
];
/// Problem files only.
pub const FILE: &[Kind] = &[Kind::File];
/// A key that every method takes.
pub const ANY_METHOD: &[Method] = &[];

/// A key of an experiment file (`problem.KEY` for the keys of its `[problem]` table): what it
/// means, accepts and applies to.
#[derive(Debug)]
pub struct Key {
    /// Its name in files; `--name-with-dashes` is its option.
    pub name: &'static str,
    /// What it sets, for `--help`.
    pub doc: &'static str,
    /// Its default, for `--help` and the accepted-ranges table.
    pub default: &'static str,
    /// What it accepts, as errors and `--help` say it.
    pub accepted: &'static str,
    /// Why the range is what it is (docs/CHOICES.md, "Accepted ranges").
    pub why: &'static str,
    /// Where it applies.
    pub applies: &'static [Kind],
    /// The methods it sets a parameter of (empty: every method).
    pub methods: &'static [Method],
    /// The one learner it sets a parameter of (`None`: either).
    pub learner: Option<LearnerName>,
}

impl Key {
    /// The command-line option of the key.
    pub fn flag(&self) -> String {
        match self.name {
            "experiment" => "NAME".into(),
            "methods" => "--method".into(),
            name => format!("--{}", name.replace('_', "-")),
        }
    }
}

/// What is wrong with a key's value, before it is known where the value came from.
#[derive(Debug)]
pub(crate) struct Invalid {
    pub(crate) key: &'static str,
    pub(crate) problem: Problem,
}

/// The ways a key's value can be refused.
#[derive(Debug)]
pub(crate) enum Problem {
    /// Outside the key's accepted range: the value as written in the file, else `got`.
    Range { got: String },
    /// A part of the value is out of range: `got` says which.
    Element { got: String },
    /// The key does not apply to this experiment.
    NotApplicable(Kind),
    /// A required key is not set.
    Missing,
    /// The key and this other one cannot both be set.
    Conflict(&'static str),
    /// The key sets a parameter of these methods, and `methods` lists none of them.
    NoMethod(&'static [Method]),
    /// The key sets a parameter of learner `only`, and the experiment's learner is `chosen`.
    OtherLearner {
        /// The learner the key belongs to.
        only: LearnerName,
        /// The experiment's.
        chosen: LearnerName,
    },
}

/// `key`'s value, shown as `got`, is out of range.
pub(crate) fn out_of_range(key: &'static str, got: impl std::fmt::Display) -> Invalid {
    Invalid {
        key,
        problem: Problem::Range { got: got.to_string() },
    }
}

impl Invalid {
    /// `key` is required and not set.
    pub(crate) fn missing(key: &'static str) -> Self {
        Self {
            key,
            problem: Problem::Missing,
        }
    }

    /// A part of `key`'s value, described by `got`, is out of range.
    pub(crate) fn element(key: &'static str, got: String) -> Self {
        Self {
            key,
            problem: Problem::Element { got },
        }
    }

    /// `key` and `other` are both set.
    pub(crate) fn conflict(key: &'static str, other: &'static str) -> Self {
        Self {
            key,
            problem: Problem::Conflict(other),
        }
    }
}

/// A refused experiment file, option or request; each message names the file and line or the
/// option, and what is accepted.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{}: cannot read", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The system's reason.
        #[source]
        source: std::io::Error,
    },
    /// Not TOML, or a value of the wrong type or an unknown key: `message` names the line.
    #[error("{message}")]
    Syntax {
        /// The file, line and what is wrong.
        message: String,
    },
    /// A value out of its range, a key that does not apply, a missing or conflicting key.
    #[error("{message}")]
    Invalid {
        /// Which key (`problem.KEY` inside the `[problem]` table).
        key: &'static str,
        /// The option or file and line, the key, what it accepts and what it got.
        message: String,
    },
    /// The request would hold more in memory than the machine has available.
    #[error("{message}")]
    Memory {
        /// The estimate, what is available and the settings to lower.
        message: String,
    },
    /// A file could not be written.
    #[error("{}: cannot write", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The system's reason.
        #[source]
        source: std::io::Error,
    },
    /// `--save-config` would replace an existing file.
    #[error("{} exists; remove it or choose another name", path.display())]
    Exists {
        /// The file.
        path: PathBuf,
    },
    /// A value TOML cannot hold.
    #[error("not representable in TOML: {0}")]
    Toml(#[from] toml::ser::Error),
}
