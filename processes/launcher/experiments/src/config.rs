//! Experiment files: a TOML file defines what a run computes (the experiment, its methods,
//! runs, seeds and every setting the paper leaves open). Command-line options and files resolve to
//! the same [`ExperimentFile`] and are checked here, in one place; every run writes its resolved
//! file to `DIR/config.toml`, which re-runs it bit for bit.
//!
//! How a run is executed (output directory, progress, the fleet's workers) stays on the command
//! line: it does not change the results.
//!
//! Instead of naming one of the paper's experiments, a file may describe a problem of the user's
//! in a `[problem]` table ([`crate::problem_file`]); its keys are in the same key table.

use crate::experiment::Experiment;
use crate::paper::{self, Options, Overrides};
use crate::problem_file::{CheckedProblem, ProblemFile};
use acps_learner::creps::MemoryConfig;
use acps_learner::selection::{AlpGmmConfig, EmaRates, FirstVisit};
use acps_learner::{Method, SelectorConfig};
use acps_wire::ipc;
use acps_wire::wire::MAX_THETA;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::ops::{Range, RangeInclusive};
use std::path::{Path, PathBuf};

/// Training tasks in flight at most: what a full fleet holds (every worker's every request).
pub const MAX_IN_FLIGHT: usize = ipc::MAX_WORKERS * ipc::MAX_IN_FLIGHT_PER_WORKER;

/// The largest integer TOML holds (a signed 64-bit integer).
const TOML_MAX: u64 = i64::MAX as u64;

/// Most runs per method: statistical repetitions (the paper uses 20); each is a learner held in
/// memory at once (docs/CHOICES.md, "Accepted ranges").
pub const MAX_RUNS: usize = 1000;

/// Most training episodes per run: every episode is recorded in memory while the run lasts.
pub const MAX_EPISODES: u64 = 10_000_000;

/// Accepted Sigma_0 = X I: a variance in the parameters' units, standard deviations 1e-6..=1e6.
const INITIAL_SIGMA: RangeInclusive<f64> = 1e-12..=1e12;

/// Accepted C-REPS KL bounds, in nats: below, a policy barely moves in a run; above, the bound
/// binds for no memory acps keeps (at most 400 samples: ln 400 = 6.0).
const EPSILON: RangeInclusive<f64> = 1e-4..=10.0;

/// Largest D-UCB xi: its bonus 2 B sqrt(xi ln n / N_i) is then about 2000 B, beyond any spread of
/// the discounted means.
const MAX_XI: f64 = 1e6;

/// The paper's experiments.
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
        }
    }
}

/// How throws are simulated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum SimName {
    /// Forward kinematics at release and closed-form flight (exact for perfect tracking).
    Analytic,
    /// The rapier3d multibody arm tracking the throw with joint motors (1.5-2 ms per throw on one
    /// idle core of a 2-core machine, up to 3 ms on a busy one; `acps bench` measures yours).
    Rapier,
}

/// Baseline of a context's first visit for the progress heuristics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum FirstVisitName {
    /// The initial greedy policy's return in that context.
    InitialReturn,
    /// None: the first visit scores 0.
    Zero,
    /// The first visit scores D-UCB's reward bound B.
    Optimistic,
}

/// C-REPS sample memory.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Memory {
    /// The last N rollouts (BOLeRo).
    Window,
    /// The paper's Section 5.2 memory of the best N/K rollouts per task.
    BestPerTask,
}

/// Everything that defines a run, as an experiment file or as command-line options. Every key is
/// optional except `experiment` (or, in a file, a `[problem]` table instead); an unset key takes
/// the experiment's default, and a resolved file (`DIR/config.toml`) sets every key that applies
/// to its experiment.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(deny_unknown_fields)]
pub struct ExperimentFile {
    /// Which experiment (or give an experiment file with --config).
    #[arg(value_name = "NAME", required_unless_present = "config", conflicts_with = "config")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub experiment: Option<ExperimentName>,
    /// toy only: one panel of Fig. 2 (a: sigma_r 0, sigma_b 0; b: 0.01, 0; c: 0, 0.2; d: 0.01, 0.2)
    /// into DIR; without it all four go to DIR/a .. DIR/d.
    #[arg(long)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub panel: Option<char>,
    /// dims only: one context dimension (1..=4) into DIR; without it all four go to DIR/ns-1 .. DIR/ns-4.
    #[arg(long, allow_hyphen_values = true, value_parser = parse_option::<usize>("n_s"))]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub n_s: Option<usize>,
    /// grid and dartboard only: how throws are simulated [default: analytic].
    #[arg(long, value_enum)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sim: Option<SimName>,
    /// Runs per method (1..=1000; all are held in memory at once) [default: 20].
    #[arg(long, allow_hyphen_values = true, value_parser = parse_option::<usize>("runs"))]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub runs: Option<usize>,
    /// Training episodes per run (1..=10000000; each is kept in memory, about 300 bytes per episode
    /// and run) [default: the paper's: toy 1000, function 2500, dims 5000, grid 10000, dartboard
    /// 50000].
    #[arg(long, allow_hyphen_values = true, value_parser = parse_option::<u64>("episodes"))]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub episodes: Option<u64>,
    /// Seed of run 0; run r uses seed + r for the problem instance and the learner (seed + runs - 1
    /// at most 2^63-1) [default: 0].
    #[arg(long, allow_hyphen_values = true, value_parser = parse_option::<u64>("seed"))]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Training tasks in flight (P, 1..=16384): task t is created after outcome t - P is consumed;
    /// 1 is the paper's sequential algorithm [default: 1].
    #[arg(long, allow_hyphen_values = true, value_parser = parse_option::<usize>("in_flight"))]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub in_flight: Option<usize>,
    /// Run only this method (repeatable): round-robin, random, random-continuous, corners,
    /// best-reward, diversity, one-step-progress, monotonic-progress, sagg-riac, or beyond the
    /// paper absolute-progress, alp-gmm or self-paced [default: the methods of the paper's
    /// figure].
    #[arg(long = "method", value_name = "METHOD")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub methods: Option<Vec<Method>>,
    /// function and dims only: number of low-level parameters n_theta of the contextual function
    /// (5..=64; the paper does not say) [default: 20].
    #[arg(long, allow_hyphen_values = true, value_parser = parse_option::<usize>("n_theta"))]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub n_theta: Option<usize>,
    /// Baseline of a context's first visit for the progress heuristics [default: initial-return].
    #[arg(long, value_enum)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub first_visit: Option<FirstVisitName>,
    /// Not toy: C-REPS sample memory [default: window for function and dims, best-per-task for
    /// grid and dartboard, as in the paper].
    #[arg(long, value_enum)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub memory: Option<Memory>,
    /// Not toy: initial exploration covariance Sigma_0 = X I (1e-12..=1e12, a variance in the
    /// parameters' units) [default: 1 for function and dims, 0.02 for grid and dartboard].
    #[arg(long, value_name = "X", allow_hyphen_values = true, value_parser = parse_option::<f64>("initial_sigma"))]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub initial_sigma: Option<f64>,
    /// Not toy: C-REPS KL bound epsilon (1e-4..=10 nats) [default: function 2, dims 1, grid and
    /// dartboard 0.5].
    #[arg(long, allow_hyphen_values = true, value_parser = parse_option::<f64>("epsilon"))]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub epsilon: Option<f64>,
    /// D-UCB padding strength xi (0..=1e6; the bonus is 2 B sqrt(xi ln n / N_i)) [default: 1e-8,
    /// grid and dartboard 1e-9].
    #[arg(long, allow_hyphen_values = true, value_parser = parse_option::<f64>("xi"))]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub xi: Option<f64>,
    /// D-UCB methods and absolute-progress: retire a context whose return has reached a plateau,
    /// probe it every 10th choice and bring it back when its return falls (beyond the paper;
    /// docs/CHOICES.md) [default: false].
    #[arg(long, num_args = 0..=1, require_equals = true, default_missing_value = "true", value_name = "BOOL")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub retire: Option<bool>,
    /// absolute-progress and alp-gmm: share of contexts drawn uniformly (0..=1) [default: 0.2].
    #[arg(long, value_name = "SHARE", allow_hyphen_values = true, value_parser = parse_option::<f64>("random_share"))]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub random_share: Option<f64>,
    /// absolute-progress: rate of the fast moving average of a context's return, in (0, 1] and
    /// above --ema-slow [default: 0.1].
    #[arg(long, value_name = "RATE", allow_hyphen_values = true, value_parser = parse_option::<f64>("ema_fast"))]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ema_fast: Option<f64>,
    /// absolute-progress: rate of the slow moving average, in (0, 1) and below --ema-fast
    /// [default: 0.05].
    #[arg(long, value_name = "RATE", allow_hyphen_values = true, value_parser = parse_option::<f64>("ema_slow"))]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ema_slow: Option<f64>,
    /// alp-gmm: contexts between two fits of its Gaussian mixture, and the points each fit uses
    /// (10 x --max-components ..=100000) [default: 250].
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = parse_option::<usize>("fit_rate"))]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit_rate: Option<usize>,
    /// alp-gmm: mixtures of 2 ..= N components are fitted and compared by AIC (2..=20)
    /// [default: 10].
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = parse_option::<usize>("max_components"))]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_components: Option<usize>,
    /// alp-gmm: replace every context by the nearest training context, for an experiment that
    /// takes only those (toy) [default: false].
    #[arg(long, num_args = 0..=1, require_equals = true, default_missing_value = "true", value_name = "BOOL")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub snap: Option<bool>,
    /// self-paced: alpha KL(q || target) as a share of the returns' standard deviation, in
    /// (0, 100] [default: 8].
    #[arg(long, value_name = "SHARE", allow_hyphen_values = true, value_parser = parse_option::<f64>("zeta"))]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zeta: Option<f64>,
    /// self-paced: C-REPS updates before its context distribution is pulled towards the target
    /// (0..=1000000) [default: 60].
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = parse_option::<usize>("alpha_offset"))]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alpha_offset: Option<usize>,
    /// toy only: use the learning factors of the paper's Fig. 3 in every run instead of a random
    /// permutation per run [default: false].
    #[arg(long, num_args = 0..=1, require_equals = true, default_missing_value = "true", value_name = "BOOL")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fig3_learning_factors: Option<bool>,
    /// Files only: a problem of your own, simulated by your workers, instead of `experiment`.
    #[arg(skip)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub problem: Option<ProblemFile>,
}

use ExperimentName::{Dartboard, Dims, Function, Grid, Toy};

/// What an experiment file describes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// One of the paper's experiments.
    Paper(ExperimentName),
    /// A `[problem]` table.
    File,
}

impl Kind {
    /// How a message names it.
    fn describe(self) -> String {
        match self {
            Kind::Paper(name) => format!("the {} experiment", name.name()),
            Kind::File => "a [problem] table".into(),
        }
    }

    /// How a list of where a key applies names it.
    fn name(self) -> &'static str {
        match self {
            Kind::Paper(name) => name.name(),
            Kind::File => "[problem] tables",
        }
    }
}

/// A key of [`ExperimentFile`] (`problem.KEY` for the keys of its `[problem]` table): what it
/// accepts and what it applies to.
struct Key {
    name: &'static str,
    accepted: &'static str,
    applies: &'static [Kind],
}

const PAPER: &[Kind] = &[
    Kind::Paper(Toy),
    Kind::Paper(Function),
    Kind::Paper(Dims),
    Kind::Paper(Grid),
    Kind::Paper(Dartboard),
];
const ALL: &[Kind] = &[
    Kind::Paper(Toy),
    Kind::Paper(Function),
    Kind::Paper(Dims),
    Kind::Paper(Grid),
    Kind::Paper(Dartboard),
    Kind::File,
];
const WITH_CREPS: &[Kind] = &[
    Kind::Paper(Function),
    Kind::Paper(Dims),
    Kind::Paper(Grid),
    Kind::Paper(Dartboard),
    Kind::File,
];
const FILE: &[Kind] = &[Kind::File];
/// What a list of contexts accepts.
const CONTEXTS: &str = "a non-empty list of points, each of 1 to 8 coordinates in -1e6..=1e6 (as many as context_low's), inside the context box";
/// What a context grid accepts.
const GRID: &str = "a table { low = [..], high = [..], points = [..] } of 1 to 8 dimensions: low <= high in -1e6..=1e6, points >= 1 per dimension and at most 100000 in all, inside the context box";

/// Every key, in file order.
const KEYS: &[Key] = &[
    Key {
        name: "experiment",
        accepted: "one of toy, function, dims, grid, dartboard (or, in a file, a [problem] table of your own)",
        applies: PAPER,
    },
    Key {
        name: "panel",
        accepted: "one of a, b, c, d",
        applies: &[Kind::Paper(Toy)],
    },
    Key {
        name: "n_s",
        accepted: "an integer in 1..=4",
        applies: &[Kind::Paper(Dims)],
    },
    Key {
        name: "sim",
        accepted: "analytic or rapier",
        applies: &[Kind::Paper(Grid), Kind::Paper(Dartboard)],
    },
    Key {
        name: "runs",
        accepted: "an integer in 1..=1000 (repetitions with seeds seed ..= seed + runs - 1, all in memory at once)",
        applies: ALL,
    },
    Key {
        name: "episodes",
        accepted: "an integer in 1..=10000000 (training episodes per run, each kept in memory: about 300 bytes per episode and run)",
        applies: ALL,
    },
    Key {
        name: "seed",
        accepted: "an integer in 0..=2^63-1 - (runs - 1) (run r uses seed + r)",
        applies: ALL,
    },
    Key {
        name: "in_flight",
        accepted: "an integer in 1..=16384 (what a full fleet holds)",
        applies: ALL,
    },
    Key {
        name: "methods",
        accepted: "a non-empty list of distinct methods: round-robin, random, random-continuous, corners, best-reward, diversity, one-step-progress, monotonic-progress, sagg-riac, absolute-progress, alp-gmm, self-paced",
        applies: ALL,
    },
    Key {
        name: "n_theta",
        accepted: "an integer in 5..=64 (more than the largest context dimension, at most what a task carries)",
        applies: &[Kind::Paper(Function), Kind::Paper(Dims)],
    },
    Key {
        name: "first_visit",
        accepted: "one of initial-return, zero, optimistic",
        applies: ALL,
    },
    Key {
        name: "memory",
        accepted: "window or best-per-task",
        applies: WITH_CREPS,
    },
    Key {
        name: "initial_sigma",
        accepted: "a number in 1e-12..=1e12 (a variance in the parameters' units: standard deviations 1e-6 to 1e6)",
        applies: WITH_CREPS,
    },
    Key {
        name: "epsilon",
        accepted: "a number in 1e-4..=10 (C-REPS's KL bound in nats)",
        applies: WITH_CREPS,
    },
    Key {
        name: "xi",
        accepted: "a number in 0..=1e6 (D-UCB's exploration bonus is 2 B sqrt(xi ln n / N_i))",
        applies: ALL,
    },
    Key {
        name: "retire",
        accepted: "true or false",
        applies: ALL,
    },
    Key {
        name: "random_share",
        accepted: "a number in 0..=1 (the share of contexts drawn uniformly)",
        applies: ALL,
    },
    Key {
        name: "ema_fast",
        accepted: "a number in (0, 1], above ema_slow (0.05 unless set)",
        applies: ALL,
    },
    Key {
        name: "ema_slow",
        accepted: "a number in (0, 1), below ema_fast (0.1 unless set)",
        applies: ALL,
    },
    Key {
        name: "fit_rate",
        accepted: "an integer in 10 * max_components (10 unless set) ..=100000 (10 points per component of the largest mixture)",
        applies: ALL,
    },
    Key {
        name: "max_components",
        accepted: "an integer in 2..=20",
        applies: ALL,
    },
    Key {
        name: "snap",
        accepted: "true or false",
        applies: ALL,
    },
    Key {
        name: "zeta",
        accepted: "a number in (0, 100] (alpha KL(q || target) as a share of the returns' standard deviation)",
        applies: ALL,
    },
    Key {
        name: "alpha_offset",
        accepted: "an integer in 0..=1000000 (C-REPS updates before the pull towards the target)",
        applies: ALL,
    },
    Key {
        name: "fig3_learning_factors",
        accepted: "true or false",
        applies: &[Kind::Paper(Toy)],
    },
    Key {
        name: "problem",
        accepted: "a table describing a problem of your own (README, \"Your own problem\")",
        applies: FILE,
    },
    Key {
        name: "problem.name",
        accepted: "1 to 32 characters of ASCII letters, digits, '-', '_' and '.' (default: the file's name without .toml)",
        applies: FILE,
    },
    Key {
        name: "problem.training_contexts",
        accepted: CONTEXTS,
        applies: FILE,
    },
    Key {
        name: "problem.training_grid",
        accepted: GRID,
        applies: FILE,
    },
    Key {
        name: "problem.test_contexts",
        accepted: CONTEXTS,
        applies: FILE,
    },
    Key {
        name: "problem.test_grid",
        accepted: GRID,
        applies: FILE,
    },
    Key {
        name: "problem.context_low",
        accepted: "a list of 1 to 8 numbers in -1e6..=1e6, one per context dimension (default: the lower corner of the contexts' bounding box)",
        applies: FILE,
    },
    Key {
        name: "problem.context_high",
        accepted: "a list of numbers in -1e6..=1e6, one per context dimension, each above context_low's (default: the upper corner of the contexts' bounding box)",
        applies: FILE,
    },
    Key {
        name: "problem.theta0",
        accepted: "a list of 1 to 64 numbers in -1e6..=1e6 (the initial parameters)",
        applies: FILE,
    },
    Key {
        name: "problem.features",
        accepted: "one of affine, quadratic, polar (2-D contexts only)",
        applies: FILE,
    },
    Key {
        name: "problem.score",
        accepted: "one of sum, mean, log-mean",
        applies: FILE,
    },
    Key {
        name: "problem.metric",
        accepted: "a text that is not blank",
        applies: FILE,
    },
    Key {
        name: "problem.unit",
        accepted: "a text",
        applies: FILE,
    },
    Key {
        name: "problem.lower_is_better",
        accepted: "true or false",
        applies: FILE,
    },
    Key {
        name: "problem.environment",
        accepted: "a table with name, settings and optionally parameters",
        applies: FILE,
    },
    Key {
        name: "problem.environment.name",
        accepted: "1 to 32 characters of ASCII letters, digits, '-', '_' and '.'",
        applies: FILE,
    },
    Key {
        name: "problem.environment.settings",
        accepted: "a text (its FNV-1a 64-bit hash is the environment's settings identity)",
        applies: FILE,
    },
    Key {
        name: "problem.environment.parameters",
        accepted: "three integers in 0..=2^63-1",
        applies: FILE,
    },
];

/// The value parser of the option of key `name`: a value that is not a `T` (a negative count, a
/// word) is refused with what the key accepts, like an out-of-range one by [`Plan::new`].
pub fn parse_option<T: std::str::FromStr>(
    name: &'static str,
) -> impl Fn(&str) -> Result<T, String> + Clone + Send + Sync + 'static {
    move |text: &str| text.parse().map_err(|_| format!("must be {}", key(name).accepted))
}

/// Keys that set a parameter of one of the teachers beyond the paper: they apply only when
/// `methods` lists one of the teachers that has it.
const METHOD_KEYS: &[(&str, &[Method])] = &[
    ("random_share", &[Method::AbsoluteProgress, Method::AlpGmm]),
    ("ema_fast", &[Method::AbsoluteProgress]),
    ("ema_slow", &[Method::AbsoluteProgress]),
    ("fit_rate", &[Method::AlpGmm]),
    ("max_components", &[Method::AlpGmm]),
    ("snap", &[Method::AlpGmm]),
    ("zeta", &[Method::SelfPaced]),
    ("alpha_offset", &[Method::SelfPaced]),
];

fn key(name: &str) -> &'static Key {
    KEYS.iter()
        .find(|k| k.name == name)
        .expect("every field of ExperimentFile is in KEYS (tested)")
}

/// A refused experiment file or option; the message names the file and line or the option, and
/// the accepted range.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct ConfigError(String);

/// What is wrong with a key's value, before it is known where the value came from.
pub(crate) struct Invalid {
    key: &'static str,
    problem: Problem,
}

enum Problem {
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
}

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

/// An experiment file as read: its values and where each top-level key stands.
pub struct LoadedFile {
    path: PathBuf,
    text: String,
    positions: BTreeMap<String, Position>,
    /// The file's values.
    pub values: ExperimentFile,
}

/// Where a top-level key and its value stand in a file.
struct Position {
    line: usize,
    value: Range<usize>,
}

impl LoadedFile {
    /// Read and parse an experiment file. Unknown keys, wrong types and malformed TOML are refused
    /// with the file and line; ranges are checked by [`Plan::new`].
    pub fn read(path: &Path) -> Result<Self, ConfigError> {
        let text =
            std::fs::read_to_string(path).map_err(|e| ConfigError(format!("{}: cannot read: {e}", path.display())))?;
        Self::parse(path, text)
    }

    /// Parse `text`; `path` names it in errors.
    pub fn parse(path: &Path, text: String) -> Result<Self, ConfigError> {
        let at = |span: Option<Range<usize>>, message: &str| {
            let line = span.map_or(String::new(), |s| format!("{}:", line_of(&text, s.start)));
            ConfigError(format!("{}:{line} {message}", path.display()))
        };
        let document = toml::de::DeTable::parse(&text).map_err(|e| at(e.span(), e.message()))?;
        let mut positions = BTreeMap::new();
        collect_positions(document.get_ref(), "", &text, &mut positions);
        let values = match toml::from_str::<ExperimentFile>(&text) {
            Ok(values) => values,
            Err(error) => {
                // A wrong type or an unknown name inside a known key's value: say what the key
                // accepts. Unknown keys keep toml's message, which lists the known ones.
                let span = error.span();
                // The innermost key whose value holds the error.
                let owner = span.as_ref().and_then(|span| {
                    positions
                        .iter()
                        .filter(|(name, p)| {
                            p.value.start <= span.start
                                && span.end <= p.value.end
                                && KEYS.iter().any(|k| k.name == name.as_str())
                        })
                        .min_by_key(|(_, p)| p.value.len())
                });
                return Err(match (owner, span) {
                    (Some((name, _)), Some(span)) => {
                        let key = key(name);
                        ConfigError(format!(
                            "{}:{}: {} must be {}, got {}",
                            path.display(),
                            line_of(&text, span.start),
                            key.name,
                            key.accepted,
                            &text[span]
                        ))
                    }
                    (_, span) => at(span, error.message()),
                });
            }
        };
        Ok(Self {
            path: path.to_path_buf(),
            text,
            positions,
            values,
        })
    }
}

/// Where every key of `table` stands, named `prefix` + key, and those of the tables inside it.
fn collect_positions(table: &toml::de::DeTable, prefix: &str, text: &str, positions: &mut BTreeMap<String, Position>) {
    for (key, value) in table.iter() {
        let name = format!("{prefix}{}", key.get_ref());
        if let toml::de::DeValue::Table(inner) = value.get_ref() {
            collect_positions(inner, &format!("{name}."), text, positions);
        }
        let position = Position {
            line: line_of(text, key.span().start),
            value: value.span(),
        };
        positions.insert(name, position);
    }
}

fn line_of(text: &str, offset: usize) -> usize {
    text[..offset.min(text.len())].matches('\n').count() + 1
}

/// A checked request: the experiment file's values overridden by command-line options.
pub struct Plan {
    settings: ExperimentFile,
    subject: Subject,
    options: Options,
}

/// What a plan runs: one of the paper's experiments or a problem file's problem.
enum Subject {
    Paper(ExperimentName),
    File(Box<CheckedProblem>),
}

/// One experiment to run, where its results go, and its resolved experiment file.
pub struct Job {
    /// The experiment.
    pub experiment: Experiment,
    /// Its output directory.
    pub dir: PathBuf,
    /// Every setting of the job, the experiment's defaults filled in: re-runs it bit for bit.
    pub config: ExperimentFile,
}

impl Plan {
    /// Check `file`'s values overridden by the options set in `cli`. Errors name the option for
    /// values given on the command line and the file and line for values from the file.
    pub fn new(file: Option<&LoadedFile>, cli: &ExperimentFile) -> Result<Self, ConfigError> {
        let base = file.map(|f| f.values.clone()).unwrap_or_default();
        let settings = cli.over(base);
        let stem = file.and_then(|f| f.path.file_stem()).and_then(|s| s.to_str());
        let subject = settings.check(stem).map_err(|invalid| describe(invalid, file, cli))?;
        let overrides = Overrides {
            n_theta: settings.n_theta,
            first_visit: settings.first_visit.map(|f| match f {
                FirstVisitName::InitialReturn => FirstVisit::InitialReturn,
                FirstVisitName::Zero => FirstVisit::Zero,
                FirstVisitName::Optimistic => FirstVisit::Optimistic,
            }),
            best_per_task: settings.memory.map(|m| m == Memory::BestPerTask),
            initial_sigma: settings.initial_sigma,
            xi: settings.xi,
            epsilon: settings.epsilon,
            learning_factors: (settings.fig3_learning_factors == Some(true)).then_some(paper::FIG3_LEARNING_FACTORS),
            retire: settings.retire,
            random_share: settings.random_share,
            ema_fast: settings.ema_fast,
            ema_slow: settings.ema_slow,
            fit_rate: settings.fit_rate,
            max_components: settings.max_components,
            snap: settings.snap,
            zeta: settings.zeta,
            alpha_offset: settings.alpha_offset,
        };
        let defaults = Options::default();
        let options = Options {
            runs: settings.runs.unwrap_or(defaults.runs),
            episodes: settings.episodes,
            seed: settings.seed.unwrap_or(defaults.seed),
            in_flight: settings.in_flight.unwrap_or(defaults.in_flight),
            methods: settings.methods.clone(),
            overrides,
        };
        Ok(Self {
            settings,
            subject,
            options,
        })
    }

    /// The experiment's name, or the problem's.
    pub fn name(&self) -> &str {
        match &self.subject {
            Subject::Paper(name) => name.name(),
            Subject::File(checked) => &checked.problem.name,
        }
    }

    /// The experiments to run into `out`: toy without a panel and dims without n_s expand to
    /// their four panels or dimensions in subdirectories.
    pub fn jobs(&self, out: &Path) -> Vec<Job> {
        let options = &self.options;
        let sim = match self.settings.sim.unwrap_or(SimName::Analytic) {
            SimName::Analytic => paper::Sim::Analytic,
            SimName::Rapier => paper::Sim::Rapier,
        };
        let job = |experiment: Experiment, dir: PathBuf, panel, n_s| {
            let config = self.resolved_for(&experiment, panel, n_s);
            Job {
                experiment,
                dir,
                config,
            }
        };
        let name = match &self.subject {
            Subject::Paper(name) => *name,
            Subject::File(checked) => {
                let experiment = crate::problem_file::experiment(checked, options);
                return vec![job(experiment, out.to_path_buf(), None, None)];
            }
        };
        match name {
            Toy => {
                let panels: Vec<(char, PathBuf)> = match self.settings.panel {
                    Some(panel) => vec![(panel, out.to_path_buf())],
                    None => "abcd".chars().map(|p| (p, out.join(p.to_string()))).collect(),
                };
                panels
                    .into_iter()
                    .map(|(panel, dir)| {
                        let model = paper::toy_panel(panel).expect("the panel was checked");
                        job(paper::toy(model, options), dir, Some(panel), None)
                    })
                    .collect()
            }
            Function => vec![job(paper::function(options), out.to_path_buf(), None, None)],
            Dims => {
                let dims: Vec<(usize, PathBuf)> = match self.settings.n_s {
                    Some(n_s) => vec![(n_s, out.to_path_buf())],
                    None => (1..=4).map(|n| (n, out.join(format!("ns-{n}")))).collect(),
                };
                dims.into_iter()
                    .map(|(n_s, dir)| job(paper::dims(n_s, options), dir, None, Some(n_s)))
                    .collect()
            }
            Grid => vec![job(paper::grid(sim, options), out.to_path_buf(), None, None)],
            Dartboard => vec![job(paper::dartboard(sim, options), out.to_path_buf(), None, None)],
        }
    }

    /// The request with the experiment's defaults filled in; the panel or n_s stays unset when it
    /// was, meaning all four. (Every panel and dimension shares the other defaults; tested.)
    pub fn resolved(&self) -> ExperimentFile {
        let first = self.jobs(Path::new("")).swap_remove(0);
        ExperimentFile {
            panel: self.settings.panel,
            n_s: self.settings.n_s,
            ..first.config
        }
    }

    /// Every setting of `experiment`, read back from what it runs, so the file cannot drift from
    /// the experiment's defaults.
    fn resolved_for(&self, experiment: &Experiment, panel: Option<char>, n_s: Option<usize>) -> ExperimentFile {
        let creps = experiment.learner.creps.as_ref();
        // The D-UCB settings as the summary records them: they are set for every experiment,
        // also when none of its methods uses D-UCB.
        let recorded = &experiment.settings;
        let first_visit: FirstVisit = serde_json::from_value(recorded["first_visit"].clone())
            .expect("every experiment records its first-visit rule");
        let paper = match &self.subject {
            Subject::Paper(name) => Some(*name),
            Subject::File(_) => None,
        };
        let throws = matches!(paper, Some(Grid | Dartboard));
        ExperimentFile {
            experiment: paper,
            panel,
            n_s,
            sim: throws.then(|| self.settings.sim.unwrap_or(SimName::Analytic)),
            runs: Some(experiment.runs),
            episodes: Some(experiment.learner.episodes),
            seed: Some(experiment.base_seed),
            in_flight: Some(experiment.learner.in_flight),
            methods: Some(experiment.methods.iter().map(SelectorConfig::method).collect()),
            n_theta: experiment.settings["n_theta"].as_u64().map(|n| n as usize),
            first_visit: Some(match first_visit {
                FirstVisit::InitialReturn => FirstVisitName::InitialReturn,
                FirstVisit::Zero => FirstVisitName::Zero,
                FirstVisit::Optimistic => FirstVisitName::Optimistic,
            }),
            memory: creps.map(|c| match c.memory {
                MemoryConfig::SlidingWindow { .. } => Memory::Window,
                MemoryConfig::BestPerTask { .. } => Memory::BestPerTask,
            }),
            initial_sigma: creps.map(|c| c.initial_sigma),
            epsilon: creps.map(|c| c.epsilon),
            xi: recorded["ducb"]["xi"].as_f64(),
            retire: Some(recorded["retire"].is_object()),
            random_share: recorded["absolute_progress"]["random_share"]
                .as_f64()
                .or(recorded["alp_gmm"]["random_share"].as_f64()),
            ema_fast: recorded["absolute_progress"]["rates"]["fast"].as_f64(),
            ema_slow: recorded["absolute_progress"]["rates"]["slow"].as_f64(),
            fit_rate: recorded["alp_gmm"]["fit_rate"].as_u64().map(|n| n as usize),
            max_components: recorded["alp_gmm"]["max_components"].as_u64().map(|n| n as usize),
            snap: recorded["alp_gmm"]["snap"].as_bool(),
            zeta: recorded["self_paced"]["zeta"].as_f64(),
            alpha_offset: recorded["self_paced"]["offset"].as_u64().map(|n| n as usize),
            fig3_learning_factors: (paper == Some(Toy)).then(|| self.settings.fig3_learning_factors == Some(true)),
            problem: match &self.subject {
                Subject::File(checked) => Some(checked.resolved.clone()),
                Subject::Paper(_) => None,
            },
        }
    }
}

/// Memory a (method, run) job holds besides its episodes and evaluations: its learner and
/// problem instance (measured: 85 kB for the function, 235 kB for the rapier arm).
const JOB_BYTES: f64 = 256e3;
/// Memory per training episode of a job until its experiment is written: the episode's record,
/// its share of the updates and of the run directory's records (measured: 180 to 300 bytes for
/// toy, function, grid and dartboard), plus 8 per context coordinate.
const EPISODE_BYTES: f64 = 300.0;
/// Memory per test context of an evaluation: the outcome and its diagnostics.
const OUTCOME_BYTES: f64 = 80.0;

/// Refuse experiments whose records cannot fit the memory available now: every (method, run)
/// job of an experiment runs at once and keeps every episode and evaluation until the
/// experiment is written; experiments (toy's panels, dims' dimensions) run one after another.
pub fn check_memory(jobs: &[Job]) -> Result<(), ConfigError> {
    // Without /proc/meminfo (not Linux) there is nothing to compare with.
    let Some(available) = available_memory() else {
        return Ok(());
    };
    for Job { experiment, .. } in jobs {
        let problem = (experiment.instance)(experiment.base_seed).problem;
        let dim = problem.training_contexts.first().map_or(0, Vec::len) as f64;
        let episodes = experiment.learner.episodes;
        // At episode 0, every eval_every episodes, and after the last one.
        let evaluations = episodes / experiment.learner.eval_every.max(1) + 2;
        let tests = problem.test_contexts.len();
        let per_job = JOB_BYTES
            + episodes as f64 * (EPISODE_BYTES + 8.0 * dim)
            + evaluations as f64 * tests as f64 * OUTCOME_BYTES;
        let jobs = experiment.methods.len() * experiment.runs;
        let need = jobs as f64 * per_job;
        if need > available {
            return Err(ConfigError(format!(
                "{}: {} methods x {} runs of {episodes} episodes ({evaluations} evaluations on {tests} test contexts each) would hold about {} in memory, more than the {} available now (MemAvailable in /proc/meminfo): lower runs (--runs), episodes (--episodes) or the number of methods (--method)",
                experiment.name,
                experiment.methods.len(),
                experiment.runs,
                bytes(need),
                bytes(available)
            )));
        }
    }
    Ok(())
}

/// The memory available for starting new programs without swapping, in bytes.
fn available_memory() -> Option<f64> {
    let meminfo = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = meminfo.lines().find_map(|line| line.strip_prefix("MemAvailable:"))?;
    let kib: f64 = line.trim().strip_suffix("kB")?.trim().parse().ok()?;
    Some(kib * 1024.0)
}

/// `n` bytes in decimal units, such as "3.2 GB".
fn bytes(n: f64) -> String {
    let units = ["bytes", "kB", "MB", "GB", "TB", "PB", "EB"];
    let power = ((n.max(1.0).log10() / 3.0).floor() as usize).min(units.len() - 1);
    match power {
        0 => format!("{n:.0} bytes"),
        _ => format!("{:.1} {}", n / 1e3f64.powi(power as i32), units[power]),
    }
}

/// The default output directory: runs/STEM for an experiment file STEM.toml, else runs/NAME.
pub fn default_out(file: Option<&Path>, name: &str) -> PathBuf {
    let stem = file.and_then(|f| f.file_stem()).and_then(|s| s.to_str());
    Path::new("runs").join(stem.unwrap_or(name))
}

impl ExperimentFile {
    /// `self`'s set values over `base`'s.
    fn over(&self, base: ExperimentFile) -> ExperimentFile {
        let s = self.clone();
        ExperimentFile {
            experiment: s.experiment.or(base.experiment),
            panel: s.panel.or(base.panel),
            n_s: s.n_s.or(base.n_s),
            sim: s.sim.or(base.sim),
            runs: s.runs.or(base.runs),
            episodes: s.episodes.or(base.episodes),
            seed: s.seed.or(base.seed),
            in_flight: s.in_flight.or(base.in_flight),
            methods: s.methods.or(base.methods),
            n_theta: s.n_theta.or(base.n_theta),
            first_visit: s.first_visit.or(base.first_visit),
            memory: s.memory.or(base.memory),
            initial_sigma: s.initial_sigma.or(base.initial_sigma),
            epsilon: s.epsilon.or(base.epsilon),
            xi: s.xi.or(base.xi),
            retire: s.retire.or(base.retire),
            random_share: s.random_share.or(base.random_share),
            ema_fast: s.ema_fast.or(base.ema_fast),
            ema_slow: s.ema_slow.or(base.ema_slow),
            fit_rate: s.fit_rate.or(base.fit_rate),
            max_components: s.max_components.or(base.max_components),
            snap: s.snap.or(base.snap),
            zeta: s.zeta.or(base.zeta),
            alpha_offset: s.alpha_offset.or(base.alpha_offset),
            fig3_learning_factors: s.fig3_learning_factors.or(base.fig3_learning_factors),
            problem: s.problem.or(base.problem),
        }
    }

    /// The keys that are set.
    fn set_keys(&self) -> Vec<String> {
        // Unset keys are skipped when serialising; JSON, unlike TOML, holds every u64 and f64.
        match serde_json::to_value(self) {
            Ok(serde_json::Value::Object(map)) => map.keys().cloned().collect(),
            _ => unreachable!("a struct of plain values serialises to an object"),
        }
    }

    /// Every value in its accepted range, and only keys that apply to the experiment; `stem`
    /// names a problem file's problem by default.
    fn check(&self, stem: Option<&str>) -> Result<Subject, Invalid> {
        let kind = match (self.experiment, &self.problem) {
            (Some(name), None) => Kind::Paper(name),
            (None, Some(_)) => Kind::File,
            (Some(_), Some(_)) => return Err(Invalid::conflict("problem", "experiment")),
            (None, None) => return Err(Invalid::missing("experiment")),
        };
        let listed = self.methods.as_deref().unwrap_or_default();
        for set in self.set_keys() {
            let key = key(&set);
            if !key.applies.contains(&kind) {
                return Err(Invalid {
                    key: key.name,
                    problem: Problem::NotApplicable(kind),
                });
            }
            if let Some((_, methods)) = METHOD_KEYS.iter().find(|(name, _)| *name == key.name)
                && !methods.iter().any(|m| listed.contains(m))
            {
                return Err(Invalid {
                    key: key.name,
                    problem: Problem::NoMethod(methods),
                });
            }
        }
        let in_range = |key, ok: bool, got: String| if ok { Ok(()) } else { Err(out_of_range(key, got)) };
        if let Some(panel) = self.panel {
            in_range("panel", paper::toy_panel(panel).is_some(), format!("'{panel}'"))?;
        }
        if let Some(n_s) = self.n_s {
            in_range("n_s", (1..=4).contains(&n_s), n_s.to_string())?;
        }
        let runs = self.runs.unwrap_or(Options::default().runs);
        in_range("runs", (1..=MAX_RUNS).contains(&runs), runs.to_string())?;
        if let Some(episodes) = self.episodes {
            in_range("episodes", (1..=MAX_EPISODES).contains(&episodes), episodes.to_string())?;
        }
        if let Some(seed) = self.seed {
            let last = seed.checked_add(runs as u64 - 1);
            in_range("seed", last.is_some_and(|l| l <= TOML_MAX), seed.to_string())?;
        }
        if let Some(in_flight) = self.in_flight {
            in_range(
                "in_flight",
                (1..=MAX_IN_FLIGHT).contains(&in_flight),
                in_flight.to_string(),
            )?;
        }
        if let Some(methods) = &self.methods {
            let distinct = methods.iter().enumerate().all(|(i, m)| !methods[..i].contains(m));
            let names: Vec<&str> = methods.iter().map(|m| m.name()).collect();
            in_range("methods", !methods.is_empty() && distinct, format!("{names:?}"))?;
        }
        if let Some(n_theta) = self.n_theta {
            in_range("n_theta", (5..=MAX_THETA).contains(&n_theta), n_theta.to_string())?;
        }
        for (key, value, range) in [
            ("initial_sigma", self.initial_sigma, INITIAL_SIGMA),
            ("epsilon", self.epsilon, EPSILON),
            ("xi", self.xi, 0.0..=MAX_XI),
        ] {
            if let Some(value) = value {
                // Debug writes 1e300 as such, where Display spells out 301 digits.
                in_range(key, range.contains(&value), format!("{value:?}"))?;
            }
        }
        self.check_teachers()?;
        Ok(match (kind, &self.problem) {
            (Kind::File, Some(problem)) => Subject::File(Box::new(problem.check(stem)?)),
            (Kind::Paper(name), _) => Subject::Paper(name),
            (Kind::File, None) => unreachable!("a file's kind is that of its [problem] table"),
        })
    }

    /// The parameters of the teachers beyond the paper, each also against the other it is
    /// bounded by (unless set, that one's default).
    fn check_teachers(&self) -> Result<(), Invalid> {
        let in_range = |key, ok: bool, got: String| if ok { Ok(()) } else { Err(out_of_range(key, got)) };
        if let Some(share) = self.random_share {
            in_range("random_share", (0.0..=1.0).contains(&share), format!("{share:?}"))?;
        }
        let rates = EmaRates::default();
        let (fast, slow) = (self.ema_fast.unwrap_or(rates.fast), self.ema_slow.unwrap_or(rates.slow));
        if let Some(fast) = self.ema_fast {
            in_range("ema_fast", fast > slow && fast <= 1.0, format!("{fast:?}"))?;
        }
        if let Some(slow) = self.ema_slow {
            in_range("ema_slow", slow > 0.0 && slow < fast && slow < 1.0, format!("{slow:?}"))?;
        }
        let defaults = AlpGmmConfig::default();
        let components = self.max_components.unwrap_or(defaults.max_components);
        if let Some(components) = self.max_components {
            let accepted = AlpGmmConfig::MAX_COMPONENTS.contains(&components);
            in_range("max_components", accepted, components.to_string())?;
        }
        if let Some(fit_rate) = self.fit_rate {
            let fewest = AlpGmmConfig::POINTS_PER_COMPONENT * components;
            let accepted = (fewest..=AlpGmmConfig::MAX_FIT_RATE).contains(&fit_rate);
            in_range("fit_rate", accepted, fit_rate.to_string())?;
        }
        if let Some(zeta) = self.zeta {
            in_range("zeta", zeta > 0.0 && zeta <= 100.0, format!("{zeta:?}"))?;
        }
        if let Some(offset) = self.alpha_offset {
            in_range("alpha_offset", offset <= 1_000_000, offset.to_string())?;
        }
        Ok(())
    }

    /// The file's text: `header` (comment lines) and every set key. Fails on integers TOML cannot
    /// hold, which [`Plan::new`] refuses.
    fn to_toml(&self, header: &str) -> Result<String, ConfigError> {
        let body = toml::to_string(self).map_err(|e| ConfigError(format!("not representable in TOML: {e}")))?;
        Ok(format!("{header}{body}"))
    }

    /// Write the resolved file of a run into its directory (`config.toml`).
    pub fn write_resolved(&self, dir: &Path) -> Result<(), ConfigError> {
        let path = dir.join("config.toml");
        let command = match self.problem {
            None => "acps experiment --config config.toml --out NEW_DIR",
            Some(_) => "acps run --config config.toml --worker-command CMD --out NEW_DIR",
        };
        let text = self.to_toml(&header("the run in this directory", command))?;
        std::fs::create_dir_all(dir)
            .and_then(|()| std::fs::write(&path, text))
            .map_err(|e| cannot_write(&path, e))
    }

    /// Write the file to `path`, which must not exist yet: a hand-edited file is never replaced.
    pub fn save_new(&self, path: &Path) -> Result<(), ConfigError> {
        let command = match self.problem {
            None => "acps experiment --config FILE",
            Some(_) => "acps run --config FILE --worker-command CMD",
        };
        let text = self.to_toml(&header("an experiment", command))?;
        let mut file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(path)
            .map_err(|e| match e.kind() {
                std::io::ErrorKind::AlreadyExists => {
                    ConfigError(format!("{} exists; remove it or choose another name", path.display()))
                }
                _ => cannot_write(path, e),
            })?;
        std::io::Write::write_all(&mut file, text.as_bytes()).map_err(|e| cannot_write(path, e))
    }
}

fn cannot_write(path: &Path, error: std::io::Error) -> ConfigError {
    ConfigError(format!("{}: cannot write: {error}", path.display()))
}

/// The comment lines that open a written file: what it describes and how to run it.
fn header(what: &str, command: &str) -> String {
    format!(
        "# Every setting of {what}, written by acps {}.\n\
         # Run it with `{command}` (docs/EXPERIMENTS.md, \"Experiment files\").\n\n",
        env!("CARGO_PKG_VERSION")
    )
}

/// The message for `invalid`: the option when the value came from the command line, else the
/// file and line.
fn describe(invalid: Invalid, file: Option<&LoadedFile>, cli: &ExperimentFile) -> ConfigError {
    let key = key(invalid.key);
    let from_cli = cli.set_keys().iter().any(|k| k == key.name);
    let file = file.filter(|_| !from_cli);
    let position = file.and_then(|f| f.positions.get(key.name).map(|p| (f, p)));
    // A key that is not in the file (unset, or defaulted) is placed at its table's line.
    let table = file.and_then(|f| {
        let tables = std::iter::successors(key.name.rsplit_once('.'), |(table, _)| table.rsplit_once('.'));
        tables
            .filter_map(|(table, _)| f.positions.get(table))
            .map(|p| (f, p.line))
            .next()
    });
    let (subject, got) = match (from_cli, position, table, file) {
        (true, ..) => (flag(key.name), None),
        (false, Some((f, p)), ..) => (
            format!("{}:{}: {}", f.path.display(), p.line, key.name),
            Some(f.text[p.value.clone()].to_string()),
        ),
        (false, None, Some((f, line)), _) => (format!("{}:{line}: {}", f.path.display(), key.name), None),
        (false, None, None, Some(f)) => (format!("{}: {}", f.path.display(), key.name), None),
        (false, None, None, None) => (key.name.to_string(), None),
    };
    ConfigError(match invalid.problem {
        Problem::Range { got: value } => {
            format!("{subject} must be {}, got {}", key.accepted, got.unwrap_or(value))
        }
        Problem::Element { got } => format!("{subject} must be {}, got {got}", key.accepted),
        Problem::NotApplicable(kind) => {
            let applies: Vec<&str> = key.applies.iter().map(|k| k.name()).collect();
            format!(
                "{subject} applies to {} only, not to {}",
                applies.join(", "),
                kind.describe()
            )
        }
        Problem::Missing => format!("{subject} must be set: {}", key.accepted),
        Problem::Conflict(other) => {
            format!("{subject} and {other} exclude each other: give one of them")
        }
        Problem::NoMethod(methods) => {
            let names: Vec<&str> = methods.iter().map(|m| m.name()).collect();
            format!("{subject} applies only when methods lists {}", names.join(" or "))
        }
    })
}

/// The command-line option of a key.
fn flag(key: &str) -> String {
    match key {
        "experiment" => "NAME".into(),
        "methods" => "--method".into(),
        _ => format!("--{}", key.replace('_', "-")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn error(text: &str) -> String {
        let file = LoadedFile::parse(Path::new("e.toml"), text.to_string());
        match file {
            Err(e) => e.to_string(),
            Ok(file) => match Plan::new(Some(&file), &ExperimentFile::default()) {
                Err(e) => e.to_string(),
                Ok(_) => panic!("{text} was accepted"),
            },
        }
    }

    #[test]
    fn every_field_has_a_key_in_file_order() {
        let every = ExperimentFile {
            experiment: Some(Toy),
            panel: Some('a'),
            n_s: Some(1),
            sim: Some(SimName::Analytic),
            runs: Some(1),
            episodes: Some(1),
            seed: Some(0),
            in_flight: Some(1),
            methods: Some(vec![Method::Random]),
            n_theta: Some(5),
            first_visit: Some(FirstVisitName::Zero),
            memory: Some(Memory::Window),
            initial_sigma: Some(1.0),
            epsilon: Some(1.0),
            xi: Some(0.0),
            retire: Some(true),
            random_share: Some(0.5),
            ema_fast: Some(0.2),
            ema_slow: Some(0.1),
            fit_rate: Some(300),
            max_components: Some(5),
            snap: Some(true),
            zeta: Some(1.0),
            alpha_offset: Some(3),
            fig3_learning_factors: Some(true),
            problem: Some(ProblemFile::default()),
        };
        let names: Vec<&str> = KEYS.iter().map(|k| k.name).filter(|k| !k.contains('.')).collect();
        assert_eq!(every.set_keys().len(), names.len());
        let text = every.to_toml("").unwrap();
        let order: Vec<&str> = text
            .lines()
            .filter(|l| !l.is_empty())
            .map(|l| l.split(" = ").next().unwrap().trim_matches(['[', ']']))
            .collect();
        assert_eq!(order, names);
    }

    #[test]
    fn file_errors_name_line_key_and_range() {
        let cases = [
            ("experiment = \"toy\"\nrunz = 3\n", "e.toml:2: unknown field `runz`"),
            (
                "experiment = \"toy\"\n\nruns = \"3\"\n",
                "e.toml:3: runs must be an integer in 1..=1000 (repetitions with seeds seed ..= seed + runs - 1, all in memory at once), got \"3\"",
            ),
            (
                "experiment = \"toy\"\nruns = 0\n",
                "e.toml:2: runs must be an integer in 1..=1000 (repetitions with seeds seed ..= seed + runs - 1, all in memory at once), got 0",
            ),
            (
                "experiment = \"toy\"\nxi = nan\n",
                "e.toml:2: xi must be a number in 0..=1e6 (D-UCB's exploration bonus is 2 B sqrt(xi ln n / N_i)), got nan",
            ),
            (
                "experiment = \"grid\"\nepsilon = -inf\n",
                "e.toml:2: epsilon must be a number in 1e-4..=10 (C-REPS's KL bound in nats), got -inf",
            ),
            (
                "experiment = \"toy\"\nepsilon = 1.0\n",
                "e.toml:2: epsilon applies to function, dims, grid, dartboard, [problem] tables only, not to the toy experiment",
            ),
            (
                "experiment = \"dims\"\nn_s = 5\n",
                "e.toml:2: n_s must be an integer in 1..=4, got 5",
            ),
            (
                "experiment = \"toy\"\npanel = \"e\"\n",
                "e.toml:2: panel must be one of a, b, c, d, got \"e\"",
            ),
            (
                "experiment = \"function\"\nmethods = [\n  \"random\",\n  \"monotonic\",\n]\n",
                "e.toml:4: methods must be a non-empty list of distinct methods",
            ),
            (
                "experiment = \"function\"\nmethods = [\"random\", \"random\"]\n",
                "got [\"random\", \"random\"]",
            ),
            (
                "experiment = \"function\"\nmethods = []\n",
                "e.toml:2: methods must be a non-empty",
            ),
            (
                "experiment = \"function\"\nn_theta = 65\n",
                "e.toml:2: n_theta must be an integer in 5..=64",
            ),
            (
                "experiment = \"function\"\nin_flight = 16385\n",
                "e.toml:2: in_flight must be an integer in 1..=16384",
            ),
            (
                "experiment = \"function\"\nruns = 2\nseed = 9223372036854775807\n",
                "e.toml:3: seed must be an integer in 0..=2^63-1 - (runs - 1)",
            ),
            (
                "experiment = \"throw\"\n",
                "e.toml:1: experiment must be one of toy, function",
            ),
            ("runs = 2\n", "e.toml: experiment must be set"),
            ("experiment = \"toy\"\nruns = \n", "e.toml:2:"),
            (
                "experiment = \"toy\"\n[fleet]\nworkers = 2\n",
                "e.toml:2: unknown field `fleet`",
            ),
        ];
        for (text, expected) in cases {
            let message = error(text);
            assert!(
                message.starts_with(expected) || message.contains(expected),
                "{text:?}: {message}"
            );
        }
    }

    /// Every numeric key, just outside its range and absurdly far outside it (the values a
    /// program could not run with: too large to allocate, finite but meaningless, negative).
    #[test]
    fn numbers_outside_their_ranges_are_refused() {
        let cases = [
            ("toy", "runs = 1001", "runs must be an integer in 1..=1000"),
            ("grid", "runs = 9223372036854775807", "got 9223372036854775807"),
            ("grid", "runs = -1", "runs must be an integer in 1..=1000"),
            (
                "toy",
                "episodes = 10000001",
                "episodes must be an integer in 1..=10000000",
            ),
            ("toy", "episodes = 9223372036854775807", "episodes must be an integer"),
            ("toy", "episodes = 0", "episodes must be an integer"),
            ("toy", "seed = -1", "seed must be an integer in 0..=2^63-1"),
            ("toy", "in_flight = 0", "in_flight must be an integer in 1..=16384"),
            ("dims", "n_theta = 4", "n_theta must be an integer in 5..=64"),
            ("dims", "n_s = 0", "n_s must be an integer in 1..=4"),
            (
                "function",
                "initial_sigma = 1e300",
                "initial_sigma must be a number in 1e-12..=1e12",
            ),
            ("function", "initial_sigma = 1e-300", "got 1e-300"),
            ("function", "initial_sigma = 9.9e-13", "got 9.9e-13"),
            ("function", "initial_sigma = 0.0", "got 0.0"),
            ("function", "initial_sigma = inf", "got inf"),
            ("grid", "epsilon = 1e308", "epsilon must be a number in 1e-4..=10"),
            ("grid", "epsilon = 1e-300", "got 1e-300"),
            ("grid", "epsilon = 10.000001", "got 10.000001"),
            ("grid", "epsilon = 0.0", "got 0.0"),
            ("toy", "xi = 1e308", "xi must be a number in 0..=1e6"),
            ("toy", "xi = 1000001.0", "got 1000001.0"),
            ("toy", "xi = -1e-9", "got -1e-9"),
        ];
        for (experiment, line, expected) in cases {
            let text = format!("experiment = \"{experiment}\"\n{line}\n");
            let message = error(&text);
            assert!(
                message.starts_with("e.toml:2: ") && message.contains(expected),
                "{text:?}: {message}"
            );
        }
    }

    #[test]
    fn numbers_on_the_bounds_of_their_ranges_are_accepted() {
        for text in [
            "experiment = \"function\"\nruns = 1\nepisodes = 1\ninitial_sigma = 1e-12\nepsilon = 1e-4\nxi = 0.0\nn_theta = 5\n",
            "experiment = \"function\"\nruns = 1000\nepisodes = 10000000\ninitial_sigma = 1e12\nepsilon = 10.0\nxi = 1e6\nn_theta = 64\nin_flight = 16384\n",
        ] {
            let file = LoadedFile::parse(Path::new("e.toml"), text.into()).unwrap();
            assert!(Plan::new(Some(&file), &ExperimentFile::default()).is_ok(), "{text}");
        }
    }

    #[test]
    fn options_name_the_flag_and_override_the_file() {
        let file = LoadedFile::parse(Path::new("e.toml"), "experiment = \"toy\"\nruns = 0\n".into()).unwrap();
        let cli = ExperimentFile {
            runs: Some(3),
            ..Default::default()
        };
        let plan = Plan::new(Some(&file), &cli).unwrap();
        assert_eq!(plan.resolved().runs, Some(3));
        let cli = ExperimentFile {
            epsilon: Some(f64::NAN),
            ..Default::default()
        };
        let message = Plan::new(Some(&file), &cli).err().unwrap().to_string();
        assert_eq!(
            message,
            "--epsilon applies to function, dims, grid, dartboard, [problem] tables only, not to the toy experiment"
        );
        let cli = ExperimentFile {
            experiment: Some(Grid),
            xi: Some(f64::INFINITY),
            ..Default::default()
        };
        let message = Plan::new(None, &cli).err().unwrap().to_string();
        assert_eq!(
            message,
            "--xi must be a number in 0..=1e6 (D-UCB's exploration bonus is 2 B sqrt(xi ln n / N_i)), got inf"
        );
    }

    /// The resolved file's xi and first-visit rule are read from the recorded settings; they
    /// must be what the D-UCB methods run with, by default and when set.
    #[test]
    fn resolved_d_ucb_settings_are_the_methods() {
        for name in [Toy, Function, Dims, Grid, Dartboard] {
            for (xi, first_visit) in [(None, None), (Some(0.5), Some(FirstVisitName::Zero))] {
                let cli = ExperimentFile {
                    experiment: Some(name),
                    xi,
                    first_visit,
                    ..Default::default()
                };
                for job in Plan::new(None, &cli).unwrap().jobs(Path::new("out")) {
                    let bandits: Vec<_> = job
                        .experiment
                        .methods
                        .iter()
                        .filter_map(|m| match m {
                            SelectorConfig::Bandit(bandit) => Some(bandit),
                            _ => None,
                        })
                        .collect();
                    assert!(!bandits.is_empty(), "{name:?}");
                    for bandit in bandits {
                        assert_eq!(job.config.xi, Some(bandit.ducb.xi), "{name:?}");
                        let rule = serde_json::to_value(bandit.first_visit).unwrap();
                        assert_eq!(serde_json::to_value(job.config.first_visit).unwrap(), rule, "{name:?}");
                    }
                    if let Some(xi) = xi {
                        assert_eq!(job.config.xi, Some(xi));
                    }
                }
            }
        }
    }

    #[test]
    fn resolved_files_validate_and_panels_share_their_defaults() {
        for name in [Toy, Function, Dims, Grid, Dartboard] {
            let plan = Plan::new(
                None,
                &ExperimentFile {
                    experiment: Some(name),
                    ..Default::default()
                },
            )
            .unwrap();
            let resolved = plan.resolved();
            let jobs = plan.jobs(Path::new("out"));
            for job in &jobs {
                let same = ExperimentFile {
                    panel: resolved.panel,
                    n_s: resolved.n_s,
                    ..job.config.clone()
                };
                assert_eq!(same, resolved, "{name:?}");
                let text = job.config.to_toml("# header\n").unwrap();
                let again = LoadedFile::parse(Path::new("r.toml"), text).unwrap();
                assert_eq!(again.values, job.config);
                let replan = Plan::new(Some(&again), &ExperimentFile::default()).unwrap();
                assert_eq!(replan.resolved(), job.config, "{name:?}");
            }
        }
    }

    #[test]
    fn teacher_keys_are_checked_against_their_ranges_each_other_and_the_methods() {
        let cases = [
            (
                "methods = [\"random\"]\nfit_rate = 300\n",
                "e.toml:3: fit_rate applies only when methods lists alp-gmm",
            ),
            (
                "methods = [\"monotonic-progress\"]\nrandom_share = 0.5\n",
                "e.toml:3: random_share applies only when methods lists absolute-progress or alp-gmm",
            ),
            (
                "ema_slow = 0.01\n",
                "e.toml:2: ema_slow applies only when methods lists absolute-progress",
            ),
            (
                "methods = [\"alp-gmm\"]\nrandom_share = 1.5\n",
                "e.toml:3: random_share must be a number in 0..=1 (the share of contexts drawn uniformly), got 1.5",
            ),
            (
                "methods = [\"alp-gmm\"]\nfit_rate = 99\n",
                "e.toml:3: fit_rate must be an integer in 10 * max_components (10 unless set) ..=100000 (10 points per component of the largest mixture), got 99",
            ),
            (
                "methods = [\"alp-gmm\"]\nmax_components = 3\nfit_rate = 29\n",
                "e.toml:4: fit_rate must be",
            ),
            ("methods = [\"alp-gmm\"]\nfit_rate = 100001\n", "got 100001"),
            (
                "methods = [\"alp-gmm\"]\nmax_components = 21\n",
                "e.toml:3: max_components must be an integer in 2..=20, got 21",
            ),
            ("methods = [\"alp-gmm\"]\nmax_components = 1\n", "got 1"),
            (
                "methods = [\"random\"]\nzeta = 0.5\n",
                "e.toml:3: zeta applies only when methods lists self-paced",
            ),
            (
                "methods = [\"self-paced\"]\nzeta = 0.0\n",
                "e.toml:3: zeta must be a number in (0, 100] (alpha KL(q || target) as a share of the returns' standard deviation), got 0.0",
            ),
            (
                "methods = [\"self-paced\"]\nalpha_offset = -1\n",
                "e.toml:3: alpha_offset must be an integer in 0..=1000000",
            ),
            (
                "methods = [\"alp-gmm\"]\nsnap = 1\n",
                "e.toml:3: snap must be true or false, got 1",
            ),
            (
                "retire = \"yes\"\n",
                "e.toml:2: retire must be true or false, got \"yes\"",
            ),
            (
                "methods = [\"absolute-progress\"]\nema_fast = 0.04\n",
                "e.toml:3: ema_fast must be a number in (0, 1], above ema_slow (0.05 unless set), got 0.04",
            ),
            (
                "methods = [\"absolute-progress\"]\nema_slow = 0.2\n",
                "e.toml:3: ema_slow must be a number in (0, 1), below ema_fast (0.1 unless set), got 0.2",
            ),
            (
                "methods = [\"absolute-progress\"]\nema_fast = 1.5\nema_slow = 0.5\n",
                "got 1.5",
            ),
            ("methods = [\"absolute-progress\"]\nema_slow = 0.0\n", "got 0.0"),
            ("methods = [\"absolute-progress\"]\nema_fast = nan\n", "got nan"),
        ];
        for (keys, expected) in cases {
            let text = format!("experiment = \"function\"\n{keys}");
            let message = error(&text);
            let found = if expected.starts_with("e.toml:") {
                message.starts_with(expected)
            } else {
                message.starts_with("e.toml:") && message.ends_with(expected)
            };
            assert!(found, "{text:?}: {message}");
        }
        // The bounds themselves are accepted.
        for keys in [
            "methods = [\"alp-gmm\", \"absolute-progress\"]\nrandom_share = 0.0\nema_fast = 1.0\nmax_components = 2\nfit_rate = 20\n",
            "methods = [\"alp-gmm\"]\nrandom_share = 1.0\nmax_components = 20\nfit_rate = 100000\n",
            "methods = [\"absolute-progress\"]\nema_fast = 0.3\nema_slow = 0.29\n",
        ] {
            let text = format!("experiment = \"function\"\n{keys}");
            let file = LoadedFile::parse(Path::new("e.toml"), text.clone()).unwrap();
            assert!(Plan::new(Some(&file), &ExperimentFile::default()).is_ok(), "{text}");
        }
        let cli = ExperimentFile {
            experiment: Some(Grid),
            fit_rate: Some(300),
            ..Default::default()
        };
        let message = Plan::new(None, &cli).err().unwrap().to_string();
        assert_eq!(message, "--fit-rate applies only when methods lists alp-gmm");
    }

    /// The teachers run with the values of their keys (else their defaults), the summary records
    /// them, and the resolved file reads them back.
    #[test]
    fn teachers_run_with_their_keys_and_resolve_to_them() {
        use acps_learner::SelectorConfig as S;
        let every = ExperimentFile {
            experiment: Some(Function),
            methods: Some(vec![
                Method::AbsoluteProgress,
                Method::AlpGmm,
                Method::Diversity,
                Method::SelfPaced,
            ]),
            retire: Some(true),
            random_share: Some(0.3),
            ema_fast: Some(0.4),
            ema_slow: Some(0.2),
            fit_rate: Some(120),
            max_components: Some(4),
            snap: Some(true),
            zeta: Some(2.5),
            alpha_offset: Some(7),
            ..Default::default()
        };
        let plan = Plan::new(None, &every).unwrap();
        let job = plan.jobs(Path::new("out")).swap_remove(0);
        let [
            S::AbsoluteProgress(progress),
            S::AlpGmm { config, snap },
            S::Bandit(bandit),
            S::SelfPaced(paced),
        ] = job.experiment.methods.as_slice()
        else {
            panic!("{:?}", job.experiment.methods)
        };
        assert_eq!(
            (progress.rates.fast, progress.rates.slow, progress.random_share),
            (0.4, 0.2, 0.3)
        );
        assert!(progress.retire.is_some() && bandit.retire.is_some());
        assert_eq!(
            (config.fit_rate, config.max_components, config.random_share, *snap),
            (120, 4, 0.3, true)
        );
        assert_eq!((paced.zeta, paced.offset), (2.5, 7));
        let resolved = plan.resolved();
        assert_eq!(
            ExperimentFile {
                n_theta: None,
                first_visit: None,
                memory: None,
                initial_sigma: None,
                epsilon: None,
                xi: None,
                runs: None,
                episodes: None,
                seed: None,
                in_flight: None,
                ..resolved.clone()
            },
            every
        );
        let text = resolved.to_toml("").unwrap();
        let again = LoadedFile::parse(Path::new("r.toml"), text).unwrap();
        assert_eq!(
            Plan::new(Some(&again), &ExperimentFile::default()).unwrap().resolved(),
            resolved
        );
        // Unset, the paper's methods do not retire, and nothing of the teachers is written.
        let paper = Plan::new(
            None,
            &ExperimentFile {
                experiment: Some(Grid),
                ..Default::default()
            },
        )
        .unwrap();
        let resolved = paper.resolved();
        assert_eq!(resolved.retire, Some(false));
        assert_eq!(
            (resolved.random_share, resolved.fit_rate, resolved.snap),
            (None, None, None)
        );
        for job in paper.jobs(Path::new("out")) {
            assert!(job.experiment.settings["retire"].is_null());
            for method in &job.experiment.methods {
                assert!(!matches!(method, S::Bandit(b) if b.retire.is_some()));
            }
        }
    }
}
