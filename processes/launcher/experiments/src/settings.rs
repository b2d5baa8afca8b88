//! Every setting of an experiment, declared once.
//!
//! A setting is one entry of the `settings!` table below: its name (the TOML key; the option is
//! `--name-with-dashes`), type, default, accepted range with its reason, where it applies, which
//! methods take it, how its value is checked and how it is read back from the experiment it
//! built. From that entry come the field of [`ExperimentFile`] (parsed from files by serde and
//! from the command line by clap), its `--help` line, its range check and error message, the
//! merge of options over a file, the resolved `config.toml` and the accepted-ranges table of
//! docs/CHOICES.md ([`accepted_ranges`]). Adding a setting is one entry here plus its use where
//! an experiment is built ([`crate::paper`], [`crate::plan`]).

use crate::experiment::Experiment;
pub use crate::keys::ExperimentName;
use crate::keys::{ALL, ANY_METHOD, FILE, Invalid, Key, Kind, PAPER, Problem, WITH_CREPS, out_of_range};
use crate::problem_file::{PROBLEM_KEYS, ProblemFile};
use acps_learner::ccmaes::CCmaesConfig;
use acps_learner::creps::{CRepsConfig, ETA_MIN_RANGE, MemoryConfig};
use acps_learner::selection::{AlpGmmConfig, EmaRates, FirstVisit};
use acps_learner::{Method, SearchConfig, SelectorConfig};
use acps_wire::ipc;
use acps_wire::wire::MAX_THETA;
use serde::{Deserialize, Serialize};

/// Training tasks in flight at most: what a full fleet holds (every worker's every request).
pub const MAX_IN_FLIGHT: usize = ipc::MAX_WORKERS * ipc::MAX_IN_FLIGHT_PER_WORKER;

/// The largest integer TOML holds (a signed 64-bit integer).
const TOML_MAX: u64 = i64::MAX as u64;

/// Most runs per method: statistical repetitions (the paper uses 20); each is a learner held in
/// memory at once (docs/CHOICES.md, "Accepted ranges").
pub const MAX_RUNS: usize = 1000;

/// Most training episodes per run: every episode is recorded in memory while the run lasts.
pub const MAX_EPISODES: u64 = 10_000_000;

/// Runs per method unless set: the paper's 20.
pub const DEFAULT_RUNS: usize = 20;

/// Training tasks in flight unless set: the paper's sequential algorithm.
pub const DEFAULT_IN_FLIGHT: usize = 1;

/// Most rollouts a C-REPS update weighs, or between two updates: the dual's cost grows with the
/// samples, and an update that waits longer learns from rollouts of a policy long gone.
const MAX_SAMPLES: usize = 100_000;

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

impl From<FirstVisitName> for FirstVisit {
    fn from(name: FirstVisitName) -> Self {
        match name {
            FirstVisitName::InitialReturn => FirstVisit::InitialReturn,
            FirstVisitName::Zero => FirstVisit::Zero,
            FirstVisitName::Optimistic => FirstVisit::Optimistic,
        }
    }
}

impl From<FirstVisit> for FirstVisitName {
    fn from(rule: FirstVisit) -> Self {
        match rule {
            FirstVisit::InitialReturn => FirstVisitName::InitialReturn,
            FirstVisit::Zero => FirstVisitName::Zero,
            FirstVisit::Optimistic => FirstVisitName::Optimistic,
        }
    }
}

/// The upper-level learner.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum LearnerName {
    /// C-REPS, the paper's.
    CReps,
    /// Contextual CMA-ES (Abdolmaleki et al. 2017).
    CCmaes,
}

impl LearnerName {
    /// The learner `search` runs.
    pub fn of(search: &SearchConfig) -> Self {
        match search {
            SearchConfig::CReps(_) => LearnerName::CReps,
            SearchConfig::CCmaes(_) => LearnerName::CCmaes,
        }
    }

    /// Its name in files and options.
    pub fn name(self) -> &'static str {
        match self {
            LearnerName::CReps => "c-reps",
            LearnerName::CCmaes => "c-cmaes",
        }
    }

    /// The learner of an experiment whose summary recorded `settings`: C-CMA-ES when they have
    /// its settings (`ccmaes`, which the paper experiments' `with_search` writes), else C-REPS (also for a problem
    /// without a policy, which has neither).
    pub fn recorded(settings: &serde_json::Value) -> Self {
        if settings.get("ccmaes").is_some() {
            LearnerName::CCmaes
        } else {
            LearnerName::CReps
        }
    }
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

/// What a resolved setting is read back from: the experiment a request built, so that the
/// resolved file cannot drift from what runs.
pub(crate) struct Resolving<'a> {
    /// The experiment.
    pub(crate) experiment: &'a Experiment,
    /// The request it was built from.
    pub(crate) request: &'a ExperimentFile,
    /// Which of the paper's experiments (`None`: a problem file's).
    pub(crate) paper: Option<ExperimentName>,
    /// The toy panel this experiment is.
    pub(crate) panel: Option<char>,
    /// The dims dimension this experiment is.
    pub(crate) n_s: Option<usize>,
}

impl Resolving<'_> {
    fn creps(&self) -> Option<&CRepsConfig> {
        match self.experiment.learner.search.as_ref()? {
            SearchConfig::CReps(c) => Some(c),
            SearchConfig::CCmaes(_) => None,
        }
    }

    /// The C-CMA-ES settings with the problem's n_theta and n_s.
    fn ccmaes(&self) -> Option<(&CCmaesConfig, usize, usize)> {
        match self.experiment.learner.search.as_ref()? {
            SearchConfig::CCmaes(c) => {
                let problem = (self.experiment.instance)(self.experiment.base_seed).problem;
                Some((c, problem.theta0.len(), problem.context_dim()))
            }
            SearchConfig::CReps(_) => None,
        }
    }

    /// The settings the summary records.
    fn recorded(&self) -> &serde_json::Value {
        &self.experiment.settings
    }

    /// The rollouts an update weighs: the window's, or the best-per-task memory's over all
    /// training contexts.
    fn memory_size(&self) -> Option<usize> {
        Some(match self.creps()?.memory {
            MemoryConfig::SlidingWindow { capacity } => capacity,
            MemoryConfig::BestPerTask { per_task } => {
                let instance = (self.experiment.instance)(self.experiment.base_seed);
                per_task * instance.problem.training_contexts.len()
            }
        })
    }
}

/// A setting's value as an error message shows it.
trait Shown {
    fn shown(&self) -> String;
}

impl Shown for usize {
    fn shown(&self) -> String {
        self.to_string()
    }
}

impl Shown for u64 {
    fn shown(&self) -> String {
        self.to_string()
    }
}

impl Shown for f64 {
    /// Debug writes 1e300 as such, where Display spells out 301 digits.
    fn shown(&self) -> String {
        format!("{self:?}")
    }
}

impl Shown for char {
    fn shown(&self) -> String {
        format!("'{self}'")
    }
}

impl Shown for Vec<Method> {
    fn shown(&self) -> String {
        let names: Vec<&str> = self.iter().map(|m| m.name()).collect();
        format!("{names:?}")
    }
}

macro_rules! shown_by_serde {
    ($($ty:ty),*) => {$(
        impl Shown for $ty {
            fn shown(&self) -> String {
                serde_json::to_string(self).expect("a plain value serialises")
            }
        }
    )*};
}
shown_by_serde!(bool, ExperimentName, SimName, FirstVisitName, Memory, LearnerName);

/// The settings table: see the module's documentation. Every entry:
///
/// ```text
/// /// What it sets (the first line of its --help).
/// name: Type {
///     arg: (clap's attributes of its option),
///     default: "its default, as --help and docs/CHOICES.md say it",
///     accepted: "what it accepts, as errors say it",
///     why: "why that range, for docs/CHOICES.md",
///     applies: where it applies (crate::keys),
///     methods: the methods that take it (crate::keys::ANY_METHOD: all),
///     learner: the one learner that takes it (None: either),
///     check: |value, settings| whether the value is accepted,
///     resolved: |resolving| the value the built experiment runs with,
/// },
/// ```
macro_rules! settings {
    ($(
        $(#[doc = $doc:literal])+
        $name:ident: $ty:ty {
            arg: ($($arg:tt)*),
            default: $default:literal,
            accepted: $accepted:literal,
            why: $why:literal,
            applies: $applies:expr,
            methods: $methods:expr,
            learner: $learner:expr,
            check: $check:expr,
            resolved: $resolved:expr $(,)?
        }
    ),* $(,)?) => {
        /// Everything that defines a run, as an experiment file or as command-line options.
        /// Every key is optional except `experiment` (or, in a file, a `[problem]` table
        /// instead); an unset key takes the experiment's default, and a resolved file
        /// (`DIR/config.toml`) sets every key that applies to its experiment.
        #[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, clap::Args)]
        #[serde(deny_unknown_fields)]
        pub struct ExperimentFile {
            $(
                $(#[doc = $doc])+
                #[arg($($arg)*, help = help(stringify!($name)))]
                #[serde(default, skip_serializing_if = "Option::is_none")]
                pub $name: Option<$ty>,
            )*
            /// Files only: a problem of your own, simulated by your workers, instead of
            /// `experiment`.
            #[arg(skip)]
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub problem: Option<ProblemFile>,
        }

        /// Every key of [`ExperimentFile`] but the `[problem]` table's, in file order.
        pub const SETTINGS: &[Key] = &[$(
            Key {
                name: stringify!($name),
                doc: concat!($($doc),+),
                default: $default,
                accepted: $accepted,
                why: $why,
                applies: $applies,
                methods: $methods,
                learner: $learner,
            },
        )*];

        impl ExperimentFile {
            /// `self`'s set values over `base`'s.
            pub fn over(&self, base: ExperimentFile) -> ExperimentFile {
                ExperimentFile {
                    $($name: self.$name.clone().or(base.$name),)*
                    problem: self.problem.clone().or(base.problem),
                }
            }

            /// Every set value in its range (a value bounded by another key is checked against
            /// that key's value, or its default when unset).
            fn check_ranges(&self) -> Result<(), Invalid> {
                $(
                    if let Some(value) = &self.$name {
                        let accepted: fn(&$ty, &ExperimentFile) -> bool = $check;
                        if !accepted(value, self) {
                            return Err(out_of_range(stringify!($name), value.shown()));
                        }
                    }
                )*
                Ok(())
            }

            /// Every setting of `resolving`'s experiment, read back from what it runs.
            pub(crate) fn resolved(resolving: &Resolving) -> ExperimentFile {
                ExperimentFile {
                    $($name: {
                        let read: fn(&Resolving) -> Option<$ty> = $resolved;
                        read(resolving)
                    },)*
                    problem: None,
                }
            }
        }
    };
}

settings! {
    /// Which experiment (or give an experiment file with --config).
    experiment: ExperimentName {
        arg: (value_name = "NAME", required_unless_present = "config", conflicts_with = "config"),
        default: "none: name one, or give a file with a [problem] table",
        accepted: "one of toy, function, dims, grid, dartboard, sphere, rosenbrock (or, in a file, a [problem] table of your own)",
        why: "",
        applies: PAPER,
        methods: ANY_METHOD,
        learner: None,
        check: |_, _| true,
        resolved: |r| r.paper,
    },
    /// toy only: one panel of Fig. 2 (a: sigma_r 0, sigma_b 0; b: 0.01, 0; c: 0, 0.2; d: 0.01,
    /// 0.2) into DIR; without it all four go to DIR/a .. DIR/d.
    panel: char {
        arg: (long),
        default: "all four",
        accepted: "one of a, b, c, d",
        why: "the four panels of the paper's Fig. 2",
        applies: &[Kind::Paper(ExperimentName::Toy)],
        methods: ANY_METHOD,
        learner: None,
        check: |panel, _| ('a'..='d').contains(panel),
        resolved: |r| r.panel,
    },
    /// dims only: one context dimension into DIR; without it all four go to DIR/ns-1 ..
    /// DIR/ns-4.
    n_s: usize {
        arg: (long, allow_hyphen_values = true, value_parser = parse_option::<usize>("n_s")),
        default: "all four",
        accepted: "an integer in 1..=4",
        why: "the paper's Fig. 6 dimensions",
        applies: &[Kind::Paper(ExperimentName::Dims)],
        methods: ANY_METHOD,
        learner: None,
        check: |n_s, _| (1..=4).contains(n_s),
        resolved: |r| r.n_s,
    },
    /// grid and dartboard only: how throws are simulated.
    sim: SimName {
        arg: (long, value_enum),
        default: "analytic",
        accepted: "analytic or rapier",
        why: "",
        applies: &[Kind::Paper(ExperimentName::Grid), Kind::Paper(ExperimentName::Dartboard)],
        methods: ANY_METHOD,
        learner: None,
        check: |_, _| true,
        resolved: |r| matches!(r.paper, Some(ExperimentName::Grid | ExperimentName::Dartboard))
            .then(|| r.request.sim.unwrap_or(SimName::Analytic)),
    },
    /// Runs per method.
    runs: usize {
        arg: (long, allow_hyphen_values = true, value_parser = parse_option::<usize>("runs")),
        default: "20",
        accepted: "an integer in 1..=1000 (repetitions with seeds seed ..= seed + runs - 1, all in memory at once)",
        why: "statistical repetitions (the paper: 20). The SEM falls as 1/sqrt(runs), so 1000 runs put it at 3% of the runs' spread, finer than a figure shows; every run of every method is a learner in memory at once",
        applies: ALL,
        methods: ANY_METHOD,
        learner: None,
        check: |runs, _| (1..=MAX_RUNS).contains(runs),
        resolved: |r| Some(r.experiment.runs),
    },
    /// Training episodes per run.
    episodes: u64 {
        arg: (long, allow_hyphen_values = true, value_parser = parse_option::<u64>("episodes")),
        default: "the paper's: toy 1000, function 2500, dims 5000, grid 10000, dartboard 50000; BOLeRo's: sphere 10000, rosenbrock 42500; a problem file's 2500",
        accepted: "an integer in 1..=10000000 (training episodes per run, each kept in memory: about 300 bytes per episode and run)",
        why: "the paper's longest run is 50,000 (dartboard). Every episode stays in memory until the run is written (about 300 bytes per episode and run, so 10 million hold about 3 GB per run) and every method's run 0 is written to `selections.csv` (about 60 bytes per episode); an analytic throw run of 10 million episodes takes minutes",
        applies: ALL,
        methods: ANY_METHOD,
        learner: None,
        check: |episodes, _| (1..=MAX_EPISODES).contains(episodes),
        resolved: |r| Some(r.experiment.learner.episodes),
    },
    /// Seed of run 0; run r uses seed + r for the problem instance and the learner.
    seed: u64 {
        arg: (long, allow_hyphen_values = true, value_parser = parse_option::<u64>("seed")),
        default: "0",
        accepted: "an integer in 0..=2^63-1 - (runs - 1) (run r uses seed + r)",
        why: "run r uses seed + r, and the resolved `config.toml` must hold it: TOML's integers are signed 64-bit",
        applies: ALL,
        methods: ANY_METHOD,
        learner: None,
        check: |seed, s| {
            let runs = s.runs.unwrap_or(DEFAULT_RUNS) as u64;
            seed.checked_add(runs.saturating_sub(1)).is_some_and(|last| last <= TOML_MAX)
        },
        resolved: |r| Some(r.experiment.base_seed),
    },
    /// Training tasks in flight, the learner's window P: task t is created after outcome t - P
    /// is consumed; 1 is the paper's sequential algorithm.
    in_flight: usize {
        arg: (long, allow_hyphen_values = true, value_parser = parse_option::<usize>("in_flight")),
        default: "1",
        accepted: "an integer in 1..=16384 (what a full fleet holds)",
        why: "what a full fleet holds: 128 workers x 128 tasks",
        applies: ALL,
        methods: ANY_METHOD,
        learner: None,
        check: |in_flight, _| (1..=MAX_IN_FLIGHT).contains(in_flight),
        resolved: |r| Some(r.experiment.learner.in_flight),
    },
    /// Run only this method (repeatable; absolute-progress, alp-gmm and self-paced are beyond
    /// the paper).
    methods: Vec<Method> {
        arg: (long = "method", value_name = "METHOD"),
        default: "the methods of the paper's figure; a problem file's monotonic-progress and random",
        accepted: "a non-empty list of distinct methods: round-robin, random, random-continuous, corners, best-reward, diversity, one-step-progress, monotonic-progress, sagg-riac, absolute-progress, alp-gmm, self-paced",
        why: "",
        applies: ALL,
        methods: ANY_METHOD,
        learner: None,
        check: |methods, _| {
            !methods.is_empty() && methods.iter().enumerate().all(|(i, m)| !methods[..i].contains(m))
        },
        resolved: |r| Some(r.experiment.methods.iter().map(SelectorConfig::method).collect()),
    },
    /// function, dims, sphere and rosenbrock only: number of low-level parameters n_theta of
    /// the contextual function (the paper does not say) or of BOLeRo's benchmark function.
    n_theta: usize {
        arg: (long, allow_hyphen_values = true, value_parser = parse_option::<usize>("n_theta")),
        default: "20",
        accepted: "an integer in 5..=64 (more than the largest context dimension, at most what a task carries)",
        why: "above the largest n_s (A must have rank n_s), at most the 64 parameters a task carries",
        applies: &[
            Kind::Paper(ExperimentName::Function),
            Kind::Paper(ExperimentName::Dims),
            Kind::Paper(ExperimentName::Sphere),
            Kind::Paper(ExperimentName::Rosenbrock),
        ],
        methods: ANY_METHOD,
        learner: None,
        check: |n_theta, _| (5..=MAX_THETA).contains(n_theta),
        resolved: |r| r.recorded()["n_theta"].as_u64().map(|n| n as usize),
    },
    /// Baseline of a context's first visit for the progress heuristics.
    first_visit: FirstVisitName {
        arg: (long, value_enum),
        default: "initial-return",
        accepted: "one of initial-return, zero, optimistic",
        why: "",
        applies: ALL,
        methods: ANY_METHOD,
        learner: None,
        check: |_, _| true,
        resolved: |r| {
            let rule: FirstVisit = serde_json::from_value(r.recorded()["first_visit"].clone())
                .expect("every experiment records its first-visit rule");
            Some(rule.into())
        },
    },
    /// Not toy: the upper-level policy search: C-REPS (the paper's) or contextual CMA-ES
    /// (Abdolmaleki et al. 2017).
    learner: LearnerName {
        arg: (long, value_enum),
        default: "c-reps",
        accepted: "c-reps or c-cmaes",
        why: "",
        applies: WITH_CREPS,
        methods: ANY_METHOD,
        learner: None,
        check: |_, _| true,
        resolved: |r| r.experiment.learner.search.as_ref().map(LearnerName::of),
    },
    /// Not toy, learner c-cmaes: rollouts per generation (lambda); the best half of each
    /// weighs in its update.
    population: usize {
        arg: (long, value_name = "N", allow_hyphen_values = true, value_parser = parse_option::<usize>("population")),
        default: "4 + floor(3 ln(n_theta + n_s)) (2 n_phi - 1): the original's (1 + 2 n_s) for affine features, 103 for the grid's and the function's 6",
        accepted: "an integer in 2..=100000 (rollouts per C-CMA-ES generation, and at least what its regressions need: 2 n_phi, and more than the baseline's features)",
        why: "the mean's regression weighs the best half of a generation and needs as many rollouts as it has features; the upper bound is C-REPS' memory's, for the same reason (an update that waits longer learns from a policy long gone)",
        applies: WITH_CREPS,
        methods: ANY_METHOD,
        learner: Some(LearnerName::CCmaes),
        check: |n, _| (2..=MAX_SAMPLES).contains(n),
        resolved: |r| r.ccmaes().map(|(c, n_theta, n_s)| c.population(n_theta, n_s)),
    },
    /// Not toy: C-REPS sample memory.
    memory: Memory {
        arg: (long, value_enum),
        default: "window for function, dims, sphere and rosenbrock, best-per-task for grid and dartboard (as in the paper) and for problem files",
        accepted: "window or best-per-task",
        why: "",
        applies: WITH_CREPS,
        methods: ANY_METHOD,
        learner: Some(LearnerName::CReps),
        check: |_, _| true,
        resolved: |r| r.creps().map(|c| match c.memory {
            MemoryConfig::SlidingWindow { .. } => Memory::Window,
            MemoryConfig::BestPerTask { .. } => Memory::BestPerTask,
        }),
    },
    /// Not toy: the rollouts each C-REPS update weighs (BOLeRo's samples per update): the
    /// window's N, or with best-per-task N in all, the best N/K of each of the K training
    /// contexts.
    memory_size: usize {
        arg: (long, value_name = "N", allow_hyphen_values = true, value_parser = parse_option::<usize>("memory_size")),
        default: "function 50, dims 25 n_s^2, grid and dartboard 300, sphere and rosenbrock 50, problem files 100",
        accepted: "an integer in 2..=100000 (the rollouts each C-REPS update weighs)",
        why: "a weighting of one rollout is no weighting; the dual's cost grows with N (about 0.1 ms per 300 samples at the PA-10's scale) and a memory far larger than the rollouts between updates learns from policies long gone. With best-per-task, N below K keeps the best one per context; the resolved file says N/K x K",
        applies: WITH_CREPS,
        methods: ANY_METHOD,
        learner: Some(LearnerName::CReps),
        check: |n, _| (2..=MAX_SAMPLES).contains(n),
        resolved: |r| r.memory_size(),
    },
    /// Not toy: rollouts between two C-REPS updates (BOLeRo's train_freq).
    update_every: usize {
        arg: (long, value_name = "N", allow_hyphen_values = true, value_parser = parse_option::<usize>("update_every")),
        default: "function 25, dims 13 n_s^2, grid and dartboard 50, sphere and rosenbrock 50, problem files 25",
        accepted: "an integer in 1..=100000 (rollouts between two C-REPS updates)",
        why: "1 updates after every rollout (the sequential algorithm at its finest); an update that waits beyond 100,000 rollouts learns nothing in any run acps holds in memory",
        applies: WITH_CREPS,
        methods: ANY_METHOD,
        learner: Some(LearnerName::CReps),
        check: |n, _| (1..=MAX_SAMPLES).contains(n),
        resolved: |r| r.creps().map(|c| c.update_every),
    },
    /// Not toy: initial exploration covariance Sigma_0 = X I.
    initial_sigma: f64 {
        arg: (long, value_name = "X", allow_hyphen_values = true, value_parser = parse_option::<f64>("initial_sigma")),
        default: "1 for function, dims, sphere, rosenbrock and problem files, 0.02 for grid and dartboard",
        accepted: "a number in 1e-12..=1e12 (a variance in the parameters' units: standard deviations 1e-6 to 1e6)",
        why: "a variance in the parameters' units: standard deviations 1e-6 ..= 1e6, twelve orders of magnitude around the paper's 0.14 and 1. The C-REPS update is invariant to the returns' units but not to theta's: beyond, rescale the parameters",
        applies: WITH_CREPS,
        methods: ANY_METHOD,
        learner: None,
        check: |x, _| (1e-12..=1e12).contains(x),
        resolved: |r| r.creps().map(|c| c.initial_sigma),
    },
    /// Not toy: C-REPS KL bound epsilon.
    epsilon: f64 {
        arg: (long, allow_hyphen_values = true, value_parser = parse_option::<f64>("epsilon")),
        default: "function 2, dims 1, grid and dartboard 0.5, sphere and rosenbrock 1, problem files 2",
        accepted: "a number in 1e-4..=10 (C-REPS's KL bound in nats)",
        why: "the weights' KL from uniform is at most epsilon, and for small epsilon a weighted mean then moves at most about sqrt(2 epsilon) standard deviations of the samples per update: at 1e-4 that is 0.014, so a 10,000-episode run with an update every 25 rollouts moves its policy at most about 6 standard deviations; below, it barely learns. No weighting of N samples is further than ln N from uniform, and acps' memories hold 50 to 400 samples (ln 400 = 6.0): above, the bound does not bind and the update takes the best samples (greedy); 10 keeps every binding value",
        applies: WITH_CREPS,
        methods: ANY_METHOD,
        learner: Some(LearnerName::CReps),
        check: |x, _| (1e-4..=10.0).contains(x),
        resolved: |r| r.creps().map(|c| c.epsilon),
    },
    /// Not toy: ridge lambda of C-REPS's weighted regression of the policy.
    ridge: f64 {
        arg: (long, value_name = "LAMBDA", allow_hyphen_values = true, value_parser = parse_option::<f64>("ridge")),
        default: "1e-4 (the paper's and BOLeRo's), 1e-10 for sphere and rosenbrock (BOLeRo's benchmark)",
        accepted: "a number in 0..=1e6 (added to the diagonal of the weighted features' Gram matrix)",
        why: "0 is plain weighted least squares, singular when fewer samples than features carry weight; the weights sum to 1, so for features of order 1 the Gram matrix is of order 1, and a ridge of 1e6 already holds the policy's mean at zero",
        applies: WITH_CREPS,
        methods: ANY_METHOD,
        learner: Some(LearnerName::CReps),
        check: |x, _| (0.0..=1e6).contains(x),
        resolved: |r| r.creps().map(|c| c.ridge),
    },
    /// Not toy: C-REPS's floor of the dual's temperature eta, relative to the returns' standard
    /// deviation in each update.
    eta_min: f64 {
        arg: (long, allow_hyphen_values = true, value_parser = parse_option::<f64>("eta_min")),
        default: "1e-5",
        accepted: "a number in 1e-8..=1 (relative to the standard deviation of the returns)",
        why: "below 1e-8 the log-weights carry less than 7 significant digits; above 1 the floor overrides the KL bound for any epsilon above about 0.5 (the paper suggests 1e-6..1e-4 in reward units)",
        applies: WITH_CREPS,
        methods: ANY_METHOD,
        learner: Some(LearnerName::CReps),
        check: |x, _| (ETA_MIN_RANGE.0..=ETA_MIN_RANGE.1).contains(x),
        resolved: |r| r.creps().map(|c| c.eta_min),
    },
    /// D-UCB padding strength xi.
    xi: f64 {
        arg: (long, allow_hyphen_values = true, value_parser = parse_option::<f64>("xi")),
        default: "1e-8, grid and dartboard 1e-9, problem files 1e-2",
        accepted: "a number in 0..=1e6 (D-UCB's exploration bonus is 2 B sqrt(xi ln n / N_i))",
        why: "D-UCB's bonus is 2 B sqrt(xi ln n / N_i) ([DUCB-PARAMETERS.md](DUCB-PARAMETERS.md)). 0 is no bonus (greedy on the discounted means), the paper uses 1e-8 and 1e-9, the library 1e-2; at 1e6 the bonus is 2000 B sqrt(ln n / N_i), far beyond the spread of the means (intrinsic rewards lie within B), so D-UCB already chooses by counts alone",
        applies: ALL,
        methods: ANY_METHOD,
        learner: None,
        check: |x, _| (0.0..=1e6).contains(x),
        resolved: |r| r.recorded()["ducb"]["xi"].as_f64(),
    },
    /// D-UCB's bound B of the intrinsic rewards, which scales its exploration bonus.
    b: f64 {
        arg: (long, allow_hyphen_values = true, value_parser = parse_option::<f64>("b")),
        default: "toy 1 (best-reward, diversity) and 0.25 (progress), function and dims 1, grid and dartboard 10000, problem files 1",
        accepted: "a number in 1e-12..=1e12 (the largest intrinsic reward, in the returns' units)",
        why: "B should bound the intrinsic rewards, which are in the returns' units (DUCB-PARAMETERS.md says how to choose it); the range spans twelve orders of magnitude either side of 1, like initial_sigma's",
        applies: ALL,
        methods: ANY_METHOD,
        learner: None,
        check: |x, _| (1e-12..=1e12).contains(x),
        resolved: |r| {
            let ducb = &r.recorded()["ducb"];
            match (ducb["b_best_reward_diversity"].as_f64(), ducb["b_progress"].as_f64()) {
                // Section 4's two bounds: one setting only when they are one value.
                (Some(best), Some(progress)) => (best == progress).then_some(best),
                _ => ducb["b"].as_f64(),
            }
        },
    },
    /// D-UCB's discount gamma of past rewards.
    gamma: f64 {
        arg: (long, allow_hyphen_values = true, value_parser = parse_option::<f64>("gamma")),
        default: "toy 0.95, else 0.99",
        accepted: "a number in (0, 1] (D-UCB's discount: 1 never forgets)",
        why: "a discount: 1 is plain UCB, and a reward's weight halves after ln 0.5 / ln gamma choices (69 at 0.99, 14 at 0.95); 0 would forget everything at once",
        applies: ALL,
        methods: ANY_METHOD,
        learner: None,
        check: |x, _| *x > 0.0 && *x <= 1.0,
        resolved: |r| r.recorded()["ducb"]["gamma"].as_f64(),
    },
    /// Training episodes between two evaluations of the greedy policy on the test contexts (and
    /// one after the last episode).
    eval_every: u64 {
        arg: (long, value_name = "N", allow_hyphen_values = true, value_parser = parse_option::<u64>("eval_every")),
        default: "toy 10, function 50, dims 100, grid 100, dartboard 1000, sphere 250, rosenbrock 500, problem files 50 (at most the episodes)",
        accepted: "an integer in 1..=10000000 (training episodes between two evaluations)",
        why: "every evaluation runs every test context once and is kept in memory: 1 evaluates after every episode, and no run is longer than 10 million episodes",
        applies: ALL,
        methods: ANY_METHOD,
        learner: None,
        check: |n, _| (1..=MAX_EPISODES).contains(n),
        resolved: |r| Some(r.experiment.learner.eval_every),
    },
    /// D-UCB methods and absolute-progress: retire a context whose return has reached a
    /// plateau, probe it every 10th choice and bring it back when its return falls (beyond the
    /// paper; docs/CHOICES.md).
    retire: bool {
        arg: (long, num_args = 0..=1, require_equals = true, default_missing_value = "true", value_name = "BOOL"),
        default: "false",
        accepted: "true or false",
        why: "",
        applies: ALL,
        methods: ANY_METHOD,
        learner: None,
        check: |_, _| true,
        resolved: |r| Some(r.recorded()["retire"].is_object()),
    },
    /// absolute-progress and alp-gmm: share of contexts drawn uniformly.
    random_share: f64 {
        arg: (long, value_name = "SHARE", allow_hyphen_values = true, value_parser = parse_option::<f64>("random_share")),
        default: "0.2",
        accepted: "a number in 0..=1 (the share of contexts drawn uniformly)",
        why: "a probability: 0 is progress alone, 1 uniform alone",
        applies: ALL,
        methods: &[Method::AbsoluteProgress, Method::AlpGmm],
        learner: None,
        check: |x, _| (0.0..=1.0).contains(x),
        resolved: |r| {
            let recorded = r.recorded();
            recorded["absolute_progress"]["random_share"]
                .as_f64()
                .or(recorded["alp_gmm"]["random_share"].as_f64())
        },
    },
    /// absolute-progress: rate of the fast moving average of a context's return.
    ema_fast: f64 {
        arg: (long, value_name = "RATE", allow_hyphen_values = true, value_parser = parse_option::<f64>("ema_fast")),
        default: "0.1",
        accepted: "a number in (0, 1], above ema_slow (0.05 unless set)",
        why: "the rate of a moving average: 1 is the last return itself, 0 never moves; the slow one must be slower, or progress is 0",
        applies: ALL,
        methods: &[Method::AbsoluteProgress],
        learner: None,
        check: |fast, s| *fast > s.ema_slow.unwrap_or(EmaRates::default().slow) && *fast <= 1.0,
        resolved: |r| r.recorded()["absolute_progress"]["rates"]["fast"].as_f64(),
    },
    /// absolute-progress: rate of the slow moving average.
    ema_slow: f64 {
        arg: (long, value_name = "RATE", allow_hyphen_values = true, value_parser = parse_option::<f64>("ema_slow")),
        default: "0.05",
        accepted: "a number in (0, 1), below ema_fast (0.1 unless set)",
        why: "as ema_fast's, and below it",
        applies: ALL,
        methods: &[Method::AbsoluteProgress],
        learner: None,
        check: |slow, s| *slow > 0.0 && *slow < s.ema_fast.unwrap_or(EmaRates::default().fast) && *slow < 1.0,
        resolved: |r| r.recorded()["absolute_progress"]["rates"]["slow"].as_f64(),
    },
    /// alp-gmm: contexts between two fits of its Gaussian mixture, and the points each fit
    /// uses.
    fit_rate: usize {
        arg: (long, value_name = "N", allow_hyphen_values = true, value_parser = parse_option::<usize>("fit_rate")),
        default: "250",
        accepted: "an integer in 10 * max_components (10 unless set) ..=100000 (10 points per component of the largest mixture)",
        why: "at least 10 points per component of the largest mixture, so each covariance (up to 9 x 9 for 8 context dimensions and the ALP) rests on enough points; a fit's cost grows with its points (3.2 ms for 250), so 100,000 already takes seconds per fit",
        applies: ALL,
        methods: &[Method::AlpGmm],
        learner: None,
        check: |fit_rate, s| {
            let components = s.max_components.unwrap_or(AlpGmmConfig::default().max_components);
            (AlpGmmConfig::POINTS_PER_COMPONENT * components..=AlpGmmConfig::MAX_FIT_RATE).contains(fit_rate)
        },
        resolved: |r| r.recorded()["alp_gmm"]["fit_rate"].as_u64().map(|n| n as usize),
    },
    /// alp-gmm: mixtures of 2 ..= N components are fitted and compared by AIC.
    max_components: usize {
        arg: (long, value_name = "N", allow_hyphen_values = true, value_parser = parse_option::<usize>("max_components")),
        default: "10",
        accepted: "an integer in 2..=20",
        why: "the original fits 2 ..= 10; AIC seldom wants more, and every k is one more EM per fit",
        applies: ALL,
        methods: &[Method::AlpGmm],
        learner: None,
        check: |n, _| AlpGmmConfig::MAX_COMPONENTS.contains(n),
        resolved: |r| r.recorded()["alp_gmm"]["max_components"].as_u64().map(|n| n as usize),
    },
    /// alp-gmm: replace every context by the nearest training context, for an experiment that
    /// takes only those (toy).
    snap: bool {
        arg: (long, num_args = 0..=1, require_equals = true, default_missing_value = "true", value_name = "BOOL"),
        default: "false",
        accepted: "true or false",
        why: "",
        applies: ALL,
        methods: &[Method::AlpGmm],
        learner: None,
        check: |_, _| true,
        resolved: |r| r.recorded()["alp_gmm"]["snap"].as_bool(),
    },
    /// self-paced: alpha KL(q || target) as a share of the returns' standard deviation.
    zeta: f64 {
        arg: (long, value_name = "SHARE", allow_hyphen_values = true, value_parser = parse_option::<f64>("zeta")),
        default: "8",
        accepted: "a number in (0, 100] (alpha KL(q || target) as a share of the returns' standard deviation)",
        why: "a share of the returns' spread: 0 never pulls towards the target, and at 100 the pull outweighs any return",
        applies: ALL,
        methods: &[Method::SelfPaced],
        learner: None,
        check: |x, _| *x > 0.0 && *x <= 100.0,
        resolved: |r| r.recorded()["self_paced"]["zeta"].as_f64(),
    },
    /// self-paced: C-REPS updates before its context distribution is pulled towards the target.
    alpha_offset: usize {
        arg: (long, value_name = "N", allow_hyphen_values = true, value_parser = parse_option::<usize>("alpha_offset")),
        default: "60",
        accepted: "an integer in 0..=1000000 (C-REPS updates before the pull towards the target)",
        why: "a count of updates; no run holds more than a million",
        applies: ALL,
        methods: &[Method::SelfPaced],
        learner: None,
        check: |n, _| *n <= 1_000_000,
        resolved: |r| r.recorded()["self_paced"]["offset"].as_u64().map(|n| n as usize),
    },
    /// toy only: use the learning factors of the paper's Fig. 3 in every run instead of a
    /// random permutation per run.
    fig3_learning_factors: bool {
        arg: (long, num_args = 0..=1, require_equals = true, default_missing_value = "true", value_name = "BOOL"),
        default: "false",
        accepted: "true or false",
        why: "",
        applies: &[Kind::Paper(ExperimentName::Toy)],
        methods: ANY_METHOD,
        learner: None,
        check: |_, _| true,
        resolved: |r| (r.paper == Some(ExperimentName::Toy))
            .then(|| r.request.fig3_learning_factors == Some(true)),
    },
}

/// The key of `problem`, a table of its own.
const PROBLEM: Key = Key {
    name: "problem",
    doc: "a problem of your own, simulated by your workers, instead of experiment",
    default: "none",
    accepted: "a table describing a problem of your own (README, \"Your own problem\")",
    why: "",
    applies: FILE,
    methods: ANY_METHOD,
    learner: None,
};

/// Every key: the settings, `problem` and the keys of its table.
pub fn keys() -> impl Iterator<Item = &'static Key> {
    SETTINGS.iter().chain([&PROBLEM]).chain(PROBLEM_KEYS)
}

/// The key called `name`.
pub(crate) fn key(name: &str) -> &'static Key {
    keys()
        .find(|k| k.name == name)
        .expect("every field of ExperimentFile and ProblemFile is a key (tested)")
}

/// The `--help` line of setting `name`: what it sets, what it accepts and its default.
fn help(name: &str) -> String {
    let key = key(name);
    let doc = key.doc.trim().trim_end_matches('.');
    format!("{doc}: {} [default: {}]", key.accepted, key.default)
}

/// The value parser of the option of key `name`: a value that is not a `T` (a negative count, a
/// word) is refused with what the key accepts, like an out-of-range one by the checks.
pub fn parse_option<T: std::str::FromStr>(
    name: &'static str,
) -> impl Fn(&str) -> Result<T, String> + Clone + Send + Sync + 'static {
    move |text: &str| text.parse().map_err(|_| format!("must be {}", key(name).accepted))
}

/// The accepted-ranges table of docs/CHOICES.md: one row per setting with a reason.
pub fn accepted_ranges() -> String {
    let mut table = String::from("| setting | accepted | default | why |\n|---|---|---|---|\n");
    for key in SETTINGS.iter().filter(|k| !k.why.is_empty()) {
        table += &format!(
            "| `{}` | {} | {} | {} |\n",
            key.name, key.accepted, key.default, key.why
        );
    }
    table
}

impl ExperimentFile {
    /// The keys that are set.
    pub(crate) fn set_keys(&self) -> Vec<String> {
        // Unset keys are skipped when serialising; JSON, unlike TOML, holds every u64 and f64.
        match serde_json::to_value(self) {
            Ok(serde_json::Value::Object(map)) => map.keys().cloned().collect(),
            _ => unreachable!("a struct of plain values serialises to an object"),
        }
    }

    /// What the file describes: one of the paper's experiments or a `[problem]` table.
    pub(crate) fn kind(&self) -> Result<Kind, Invalid> {
        match (self.experiment, &self.problem) {
            (Some(name), None) => Ok(Kind::Paper(name)),
            (None, Some(_)) => Ok(Kind::File),
            (Some(_), Some(_)) => Err(Invalid::conflict("problem", "experiment")),
            (None, None) => Err(Invalid::missing("experiment")),
        }
    }

    /// Only keys that apply to the experiment and its methods, every value in its range.
    pub(crate) fn check(&self) -> Result<Kind, Invalid> {
        let kind = self.kind()?;
        let listed = self.methods.as_deref().unwrap_or_default();
        let learner = self.learner.unwrap_or(LearnerName::CReps);
        for set in self.set_keys() {
            let key = key(&set);
            if !key.applies.contains(&kind) {
                return Err(Invalid {
                    key: key.name,
                    problem: Problem::NotApplicable(kind),
                });
            }
            if !key.methods.is_empty() && !key.methods.iter().any(|m| listed.contains(m)) {
                return Err(Invalid {
                    key: key.name,
                    problem: Problem::NoMethod(key.methods),
                });
            }
            if let Some(only) = key.learner.filter(|&only| only != learner) {
                return Err(Invalid {
                    key: key.name,
                    problem: Problem::OtherLearner { only, chosen: learner },
                });
            }
        }
        self.check_ranges()?;
        Ok(kind)
    }
}
