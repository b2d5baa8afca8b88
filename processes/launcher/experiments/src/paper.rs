//! The paper's in-process experiments: Section 4 (`toy`, Fig. 2 and 3), Section 5.1.2
//! (`function`, Fig. 4 and 5), Section 5.1.3 (`dims`, Fig. 6) and Section 5.2 (`grid`, Fig. 8;
//! `dartboard`, Fig. 10). Every setting the paper leaves open is recorded in the summary's
//! `settings` and explained in docs/CHOICES.md.

use crate::experiment::{Experiment, Instance, InstanceFactory};
use crate::settings::{DEFAULT_IN_FLIGHT, DEFAULT_RUNS, ExperimentFile, LearnerName, Memory};
use crate::summary::{RunResult, mean};
use acps_learner::ccmaes::CCmaesConfig;
use acps_learner::creps::{CRepsConfig, MemoryConfig};
use acps_learner::selection::{
    AbsoluteProgressConfig, AlpGmmConfig, DUcbConfig, EmaRates, FirstVisit, RetireConfig, SaggRiacConfig,
    SelfPacedConfig,
};
use acps_learner::{BanditConfig, LearnerConfig, Method, SearchConfig, SelectorConfig};
use acps_models::benchmark::{ContextualBenchmark, Objective};
use acps_models::contextual_function::{ContextualFunction, DEFAULT_N_THETA};
use acps_models::environment;
use acps_models::learning_model::{CONTEXTS, LearningModel, LearningModelConfig};
use acps_models::rapier_sim::RapierConfig;
use acps_models::robot::Robot;
use acps_models::targets::{Category, Field};
use acps_models::throw::{INITIAL_LANDING, SpeedLimits, dartboard_problem, grid_problem};
use acps_shared::{Environment, Problem};
use serde_json::json;
use std::collections::BTreeMap;

/// The learning factors of the paper's Fig. 3 (context 3 learns fastest, its neighbour 4 hardly
/// at all), as read off the figure; they equal numpy's `RandomState(0).permutation` of
/// {0.1^2, ..., 1.0^2}.
pub const FIG3_LEARNING_FACTORS: [f64; CONTEXTS] = [0.09, 0.81, 0.25, 1.0, 0.04, 0.49, 0.64, 0.16, 0.01, 0.36];

/// The baseline of a context's first visit.
pub(crate) fn first_visit(s: &ExperimentFile) -> FirstVisit {
    s.first_visit.map_or(FirstVisit::InitialReturn, FirstVisit::from)
}

/// Retirement of solved contexts, when asked for.
fn retire(s: &ExperimentFile) -> Option<RetireConfig> {
    (s.retire == Some(true)).then(RetireConfig::default)
}

/// `preset`'s D-UCB with the run's gamma, xi and B.
pub(crate) fn ducb(preset: DUcbConfig, s: &ExperimentFile) -> DUcbConfig {
    DUcbConfig {
        gamma: s.gamma.unwrap_or(preset.gamma),
        xi: s.xi.unwrap_or(preset.xi),
        b: s.b.unwrap_or(preset.b),
    }
}

/// The learner of an experiment whose C-REPS would be `creps`: the run's seed, episodes (else
/// `episodes`), window and evaluation interval (else `eval_every`), and its policy search:
/// `creps`, or with `learner = "c-cmaes"` C-CMA-ES with C-REPS' features and initial
/// exploration.
pub(crate) fn learner(s: &ExperimentFile, episodes: u64, eval_every: u64, creps: Option<CRepsConfig>) -> LearnerConfig {
    LearnerConfig {
        seed: s.seed.unwrap_or(0),
        episodes: s.episodes.unwrap_or(episodes),
        in_flight: s.in_flight.unwrap_or(DEFAULT_IN_FLIGHT),
        eval_every: s.eval_every.unwrap_or(eval_every),
        search: creps.map(|creps| match s.learner.unwrap_or(LearnerName::CReps) {
            LearnerName::CReps => SearchConfig::CReps(creps),
            LearnerName::CCmaes => SearchConfig::CCmaes(CCmaesConfig {
                population: s.population,
                initial_sigma: creps.initial_sigma,
                features: creps.features,
                ..CCmaesConfig::default()
            }),
        }),
    }
}

/// The selected methods (else `defaults`), the D-UCB ones with `ducb(method)` and this run's
/// first-visit rule, every one with this run's settings of the teachers beyond the paper.
pub(crate) fn methods(
    s: &ExperimentFile,
    defaults: &[Method],
    ducb: impl Fn(Method) -> DUcbConfig,
) -> Vec<SelectorConfig> {
    let methods = s.methods.clone().unwrap_or_else(|| defaults.to_vec());
    methods
        .into_iter()
        .map(|method| match SelectorConfig::from(method) {
            SelectorConfig::Bandit(bandit) => SelectorConfig::Bandit(BanditConfig {
                ducb: ducb(method),
                first_visit: first_visit(s),
                retire: retire(s),
                ..bandit
            }),
            SelectorConfig::AbsoluteProgress(defaults) => SelectorConfig::AbsoluteProgress(AbsoluteProgressConfig {
                rates: EmaRates {
                    fast: s.ema_fast.unwrap_or(defaults.rates.fast),
                    slow: s.ema_slow.unwrap_or(defaults.rates.slow),
                },
                random_share: s.random_share.unwrap_or(defaults.random_share),
                retire: retire(s),
            }),
            SelectorConfig::AlpGmm { config: defaults, snap } => SelectorConfig::AlpGmm {
                config: AlpGmmConfig {
                    fit_rate: s.fit_rate.unwrap_or(defaults.fit_rate),
                    max_components: s.max_components.unwrap_or(defaults.max_components),
                    random_share: s.random_share.unwrap_or(defaults.random_share),
                },
                snap: s.snap.unwrap_or(snap),
            },
            SelectorConfig::SelfPaced(defaults) => SelectorConfig::SelfPaced(SelfPacedConfig {
                zeta: s.zeta.unwrap_or(defaults.zeta),
                offset: s.alpha_offset.unwrap_or(defaults.offset),
                ..defaults
            }),
            other => other,
        })
        .collect()
}

/// `settings` with the settings of the teachers beyond the paper: `retire` always (null when
/// off), `absolute_progress`, `alp_gmm` and `self_paced` when `methods` has them.
fn with_teachers(s: &ExperimentFile, mut settings: serde_json::Value, methods: &[SelectorConfig]) -> serde_json::Value {
    let map = settings
        .as_object_mut()
        .expect("an experiment's settings are an object");
    map.insert("retire".into(), json!(retire(s)));
    for method in methods {
        match method {
            SelectorConfig::AbsoluteProgress(config) => {
                map.insert("absolute_progress".into(), json!(config));
            }
            SelectorConfig::AlpGmm { config, snap } => {
                let mut recorded = json!(config);
                recorded["snap"] = json!(snap);
                map.insert("alp_gmm".into(), recorded);
            }
            SelectorConfig::SelfPaced(config) => {
                map.insert("self_paced".into(), json!(config));
            }
            _ => {}
        }
    }
    settings
}

/// An experiment of the run's settings `s` with nothing problem-specific: `methods` (recorded
/// in `settings` with the teachers' settings), the run's runs and seed, `learner` and
/// `instance`; selection ratios over the first 250 episodes, contexts from anywhere in the
/// space, no best policy, no detail, not a problem file's.
pub(crate) fn experiment(
    name: &str,
    s: &ExperimentFile,
    settings: serde_json::Value,
    methods: Vec<SelectorConfig>,
    learner: LearnerConfig,
    instance: InstanceFactory,
) -> Experiment {
    Experiment {
        name: name.into(),
        settings: with_teachers(s, settings, &methods),
        methods,
        runs: s.runs.unwrap_or(DEFAULT_RUNS),
        base_seed: learner.seed,
        learner,
        instance,
        selection_window: 250,
        detail: None,
        best_policy: false,
        user_problem: None,
        continuous_contexts: true,
    }
}

/// A panel of Fig. 2: its noise levels.
pub fn toy_panel(panel: char) -> Option<LearningModelConfig> {
    let (sigma_r, sigma_b) = match panel {
        'a' => (0.0, 0.0),
        'b' => (0.01, 0.0),
        'c' => (0.0, 0.2),
        'd' => (0.01, 0.2),
        _ => return None,
    };
    Some(LearningModelConfig { sigma_r, sigma_b })
}

/// Section 4, one panel of Fig. 2: D-UCB with gamma 0.95, xi 1e-8, B = 1 for best reward and
/// diversity and 0.25 for the progress heuristics; SAGG-RIAC with split threshold 8, window 10.
pub fn toy(model: LearningModelConfig, s: &ExperimentFile) -> Experiment {
    let defaults = [
        Method::RoundRobin,
        Method::BestReward,
        Method::Diversity,
        Method::OneStepProgress,
        Method::MonotonicProgress,
        Method::SaggRiac,
    ];
    let b = |method| match s.b {
        Some(b) => b,
        None if matches!(method, Method::BestReward | Method::Diversity) => 1.0,
        None => 0.25,
    };
    let preset = |method| DUcbConfig {
        gamma: 0.95,
        xi: 1e-8,
        b: b(method),
    };
    let learner = learner(s, 1000, 10, None);
    let episodes = learner.episodes;
    let learning_factors = (s.fig3_learning_factors == Some(true)).then_some(FIG3_LEARNING_FACTORS);
    let methods = methods(s, &defaults, |method| ducb(preset(method), s));
    let recorded = ducb(preset(Method::BestReward), s);
    let settings = json!({
        "model": { "sigma_r": model.sigma_r, "sigma_b": model.sigma_b, "contexts": CONTEXTS, "learning_factors": learning_factors.map_or("random permutation per run".to_string(), |w| format!("{w:?}")) },
        "ducb": { "gamma": recorded.gamma, "xi": recorded.xi, "b_best_reward_diversity": b(Method::BestReward), "b_progress": b(Method::MonotonicProgress) },
        "first_visit": first_visit(s),
        "sagg_riac": SaggRiacConfig::default(),
        "eval_every": learner.eval_every,
    });
    let instance: InstanceFactory = Box::new(move |seed| {
        let mut environment = LearningModel::new(model, seed).expect("panel noise levels are valid");
        if let Some(factors) = learning_factors {
            environment = environment
                .with_learning_factors(factors)
                .expect("the factors were validated");
        }
        Instance {
            problem: environment.problem(),
            optimal_score: Some(environment.optimal_performance()),
            environment: Some(Box::new(environment)),
            keeps_state: true,
        }
    });
    Experiment {
        selection_window: episodes as usize,
        // The model's contexts are the indices of its ten: it fails any other.
        continuous_contexts: false,
        ..experiment("toy", s, settings, methods, learner, instance)
    }
}

/// Section 5.1.2 (Fig. 4 and 5): 25 grid contexts, C-REPS epsilon 2.0 over the last 50 rollouts,
/// an update every 25, quadratic features, W = 0 and Sigma = I; D-UCB B 1, gamma 0.99, xi 1e-8;
/// evaluation every 50 rollouts on 100 test contexts.
pub fn function(s: &ExperimentFile) -> Experiment {
    let defaults = [
        Method::BestReward,
        Method::Diversity,
        Method::OneStepProgress,
        Method::MonotonicProgress,
        Method::Corners,
        Method::Random,
    ];
    let setting = FunctionSetting {
        creps: CRepsConfig::paper_function(),
        episodes: 2500,
        eval_every: 50,
    };
    function_experiment("function", 2, setting, &defaults, s, |function| {
        function
            .grid_problem()
            .expect("the function experiment's contexts are 2-D")
    })
}

/// Section 5.1.3 (Fig. 6) for `n_s` context dimensions: C-REPS epsilon 1.0 over the last
/// 25 n_s^2 rollouts, an update every 13 n_s^2; D-UCB with monotonic progress.
pub fn dims(n_s: usize, s: &ExperimentFile) -> Experiment {
    let defaults = [Method::MonotonicProgress, Method::Random, Method::RandomContinuous];
    let setting = FunctionSetting {
        creps: CRepsConfig::paper_dims(n_s),
        episodes: 5000,
        eval_every: 100,
    };
    function_experiment("dims", n_s, setting, &defaults, s, ContextualFunction::shell_problem)
}

/// The C-REPS setting and schedule of a Section 5.1 experiment.
struct FunctionSetting {
    creps: CRepsConfig,
    episodes: u64,
    eval_every: u64,
}

fn function_experiment(
    name: &str,
    n_s: usize,
    setting: FunctionSetting,
    defaults: &[Method],
    s: &ExperimentFile,
    problem: impl Fn(&ContextualFunction) -> Problem + Send + Sync + 'static,
) -> Experiment {
    let n_theta = s.n_theta.unwrap_or(DEFAULT_N_THETA);
    let capacity = match setting.creps.memory {
        MemoryConfig::SlidingWindow { capacity } => capacity,
        MemoryConfig::BestPerTask { .. } => unreachable!("Section 5.1's memories are windows"),
    };
    let creps = creps(setting.creps, s, Memory::Window, capacity, 25);
    let ducb = function_ducb(s);
    let learner = learner(s, setting.episodes, setting.eval_every, Some(creps));
    let settings = sized_settings((n_s, n_theta), &ducb, s, &learner, ("quadratic", "0"));
    let methods = methods(s, defaults, |_| ducb.clone());
    let instance: InstanceFactory = Box::new(move |seed| {
        let function = ContextualFunction::new(n_s, n_theta, seed).expect("the experiment's function is valid");
        stateless(problem(&function), Box::new(function))
    });
    experiment(name, s, settings, methods, learner, instance)
}

/// D-UCB of the functions (Section 5.1.2 and the benchmarks): gamma 0.99, xi 1e-8, B 1.
fn function_ducb(s: &ExperimentFile) -> DUcbConfig {
    ducb(
        DUcbConfig {
            gamma: 0.99,
            xi: 1e-8,
            b: 1.0,
        },
        s,
    )
}

/// The settings of a function experiment of `(n_s, n_theta)`: D-UCB's, the first visit, the
/// evaluation interval and the policy search's with its `(features, initial mean)`.
fn sized_settings(
    (n_s, n_theta): (usize, usize),
    ducb: &DUcbConfig,
    s: &ExperimentFile,
    learner: &LearnerConfig,
    (features, initial_mean): (&str, &str),
) -> serde_json::Value {
    with_search(
        json!({
            "n_s": n_s,
            "n_theta": n_theta,
            "ducb": ducb,
            "first_visit": first_visit(s),
            "eval_every": learner.eval_every,
        }),
        learner,
        features,
        initial_mean,
    )
}

/// BOLeRo's benchmark of C-CMA-ES against C-REPS (`benchmarks/ccmaes/`, the IJCAI 2017 paper's
/// Sec. 6.1): the contextual sphere (a 2-D context, 10,000 episodes) or Rosenbrock (a 1-D
/// context, 42,500), 20 parameters (or `n_theta`), contexts from [1, 2]^n_s; C-REPS as the benchmark runs it
/// (epsilon 1, an update every 50 rollouts on those 50, affine features, Sigma_0 = I, ridge
/// 1e-10); D-UCB as for the function; evaluation every 250 (sphere) or 500 (Rosenbrock)
/// episodes on 50 test contexts.
pub fn benchmark(objective: Objective, s: &ExperimentFile) -> Experiment {
    let n_theta = s.n_theta.unwrap_or(DEFAULT_N_THETA);
    let (n_s, episodes, eval_every) = match objective {
        Objective::Sphere => (2, 10_000, 250),
        Objective::Rosenbrock => (1, 42_500, 500),
    };
    let preset = CRepsConfig {
        ridge: 1e-10,
        ..CRepsConfig::batches(1.0, 50)
    };
    let creps = creps(preset, s, Memory::Window, 50, 5usize.pow(n_s as u32));
    let ducb = function_ducb(s);
    let learner = learner(s, episodes, eval_every, Some(creps));
    let settings = sized_settings(
        (n_s, n_theta),
        &ducb,
        s,
        &learner,
        ("affine", "theta0 ~ N(0, I), drawn per run"),
    );
    let methods = methods(s, &[Method::RandomContinuous, Method::MonotonicProgress], |_| {
        ducb.clone()
    });
    let instance: InstanceFactory = Box::new(move |seed| {
        let function =
            ContextualBenchmark::new(objective, n_s, n_theta, seed).expect("the benchmark's sizes are valid");
        stateless(function.problem(), Box::new(function))
    });
    experiment(objective.name(), s, settings, methods, learner, instance)
}

/// How throws are simulated.
pub use acps_models::environment::Sim;

/// The command-line name of a simulator.
pub fn sim_name(sim: Sim) -> &'static str {
    match sim {
        Sim::Analytic => "analytic",
        Sim::Rapier => "rapier",
    }
}

/// An instance of `problem` whose `environment`'s rollouts depend on the task only.
fn stateless(problem: Problem, environment: Box<dyn Environment>) -> Instance {
    Instance {
        problem,
        environment: Some(environment),
        optimal_score: None,
        keeps_state: false,
    }
}

/// `preset` with the run's epsilon, Sigma_0, ridge, update interval and memory: its kind (else
/// `memory`) of its size (else `size` rollouts; best-per-task keeps size/K of each of the
/// `tasks` training contexts).
pub(crate) fn creps(preset: CRepsConfig, s: &ExperimentFile, memory: Memory, size: usize, tasks: usize) -> CRepsConfig {
    let size = s.memory_size.unwrap_or(size);
    CRepsConfig {
        epsilon: s.epsilon.unwrap_or(preset.epsilon),
        initial_sigma: s.initial_sigma.unwrap_or(preset.initial_sigma),
        ridge: s.ridge.unwrap_or(preset.ridge),
        eta_min: s.eta_min.unwrap_or(preset.eta_min),
        update_every: s.update_every.unwrap_or(preset.update_every),
        memory: match s.memory.unwrap_or(memory) {
            Memory::Window => MemoryConfig::SlidingWindow { capacity: size },
            Memory::BestPerTask => MemoryConfig::best_per_task(size, tasks),
        },
        ..preset
    }
}

/// Section 5.2.2's C-REPS for K tasks ([`CRepsConfig::paper_throwing`]: epsilon 0.5, an update
/// every 50 trials on a memory of the best 300/K trials per task, polar-quadratic features,
/// Sigma_0 = 0.02 I), W = 0 around theta_0.
fn throwing_creps(tasks: usize, s: &ExperimentFile) -> CRepsConfig {
    creps(CRepsConfig::paper_throwing(tasks), s, Memory::BestPerTask, 300, tasks)
}

fn throwing_settings(sim: Sim, learner: &LearnerConfig, ducb: &DUcbConfig, s: &ExperimentFile) -> serde_json::Value {
    with_search(
        json!({
            "sim": sim_name(sim),
            "rapier": (sim == Sim::Rapier).then(RapierConfig::default),
            "robot": Robot::pa10().name,
            "theta": "offset on theta_0 = (g1, g1dot, g2dot), 21 values",
            "theta0_landing": INITIAL_LANDING,
            "speed_limits": SpeedLimits::Ignore,
            "ducb": ducb,
            "first_visit": first_visit(s),
            "eval_every": learner.eval_every,
        }),
        learner,
        "polar-quadratic",
        "theta_0 (offset 0)",
    )
}

/// Section 5.2.2's D-UCB: gamma 0.99, B 10,000, xi 1e-9.
fn throwing_ducb(s: &ExperimentFile) -> DUcbConfig {
    ducb(
        DUcbConfig {
            gamma: 0.99,
            xi: 1e-9,
            b: 10_000.0,
        },
        s,
    )
}

/// Section 5.2.3, the grid problem (Fig. 8): 25 training targets, 16 test targets, 10,000
/// episodes, D-UCB gamma 0.99, B 10,000, xi 1e-9; the summary names the best policy of all runs.
pub fn grid(sim: Sim, s: &ExperimentFile) -> Experiment {
    let defaults = [
        Method::BestReward,
        Method::Diversity,
        Method::OneStepProgress,
        Method::MonotonicProgress,
        Method::RoundRobin,
        Method::RandomContinuous,
    ];
    let ducb = throwing_ducb(s);
    let learner = learner(s, 10_000, 100, Some(throwing_creps(25, s)));
    let methods = methods(s, &defaults, |_| ducb.clone());
    let settings = throwing_settings(sim, &learner, &ducb, s);
    let instance: InstanceFactory = Box::new(move |_| {
        let environment = environment::grid(sim).expect("the shipped PA-10 throws");
        stateless(grid_problem(environment.spec()), Box::new(environment))
    });
    Experiment {
        best_policy: true,
        ..experiment("grid", s, settings, methods, learner, instance)
    }
}

/// Section 5.2.4, the dartboard problem (Fig. 10): 81 fields on a 1.4 m board centred on
/// theta_0's landing point, 50,000 episodes, monotonic progress.
pub fn dartboard(sim: Sim, s: &ExperimentFile) -> Experiment {
    let ducb = throwing_ducb(s);
    let learner = learner(s, 50_000, 1000, Some(throwing_creps(81, s)));
    let fields = environment::dartboard_fields();
    let methods = methods(s, &[Method::MonotonicProgress], |_| ducb.clone());
    let settings = throwing_settings(sim, &learner, &ducb, s);
    let instance: InstanceFactory = Box::new(move |_| {
        let fields = environment::dartboard_fields();
        let environment = environment::dartboard(sim).expect("the shipped PA-10 throws");
        stateless(
            dartboard_problem(&fields, fields[0].centre, environment.spec()),
            Box::new(environment),
        )
    });
    Experiment {
        selection_window: 10_000,
        detail: Some(Box::new(move |runs| dartboard_detail(&fields, runs))),
        // A throw at any point but a field's centre is a failed rollout (the fields are the contexts).
        continuous_contexts: false,
        ..experiment("dartboard", s, settings, methods, learner, instance)
    }
}

/// Hits per ring and error statistics of the final policies (mean over runs), and the average
/// number of selections per field of every ring over the selection window (Fig. 10 right).
fn dartboard_detail(fields: &[Field], runs: &[RunResult]) -> serde_json::Map<String, serde_json::Value> {
    let mut hits: BTreeMap<&str, f64> = Category::ALL.iter().map(|c| (c.name(), 0.0)).collect();
    let (mut means, mut medians, mut maxima) = (Vec::new(), Vec::new(), Vec::new());
    for run in runs {
        let mut errors = Vec::new();
        for (field, outcome) in fields.iter().zip(&run.final_outcomes) {
            let Some(outcome) = outcome.as_ref().filter(|o| o.is_ok()) else {
                continue;
            };
            let landing = [outcome.diagnostics[0], outcome.diagnostics[1]];
            if field.hit(landing) {
                *hits.get_mut(field.category.name()).expect("every category is counted") += 1.0 / runs.len() as f64;
            }
            errors.push(outcome.score);
        }
        if errors.is_empty() {
            continue;
        }
        errors.sort_by(f64::total_cmp);
        means.push(mean(&errors));
        medians.push(median(&errors));
        maxima.push(*errors.last().expect("not empty"));
    }
    let per_field = |category: Category| fields.iter().filter(|f| f.category == category).count() as f64;
    let window = runs.iter().map(|r| r.episodes.len()).min().unwrap_or(0).min(10_000);
    let selections: BTreeMap<&str, Vec<f64>> = Category::ALL
        .iter()
        .map(|&category| {
            let mut cumulative = Vec::new();
            let mut count = 0.0;
            for t in 0..window {
                count += runs
                    .iter()
                    .filter(|r| r.episodes[t].arm.is_some_and(|a| fields[a].category == category))
                    .count() as f64;
                if (t + 1) % 100 == 0 {
                    cumulative.push(count / runs.len() as f64 / per_field(category));
                }
            }
            (category.name(), cumulative)
        })
        .collect();
    let landings_run0: Vec<Option<[f64; 2]>> = runs[0]
        .final_outcomes
        .iter()
        .map(|o| {
            o.as_ref()
                .filter(|o| o.is_ok())
                .map(|o| [o.diagnostics[0], o.diagnostics[1]])
        })
        .collect();
    let mut detail = serde_json::Map::new();
    detail.insert("landings_run0".into(), json!(landings_run0));
    detail.insert("hits".into(), json!(hits));
    detail.insert("fields_hit".into(), json!(hits.values().sum::<f64>()));
    detail.insert(
        "error_cm".into(),
        json!({ "mean": mean_or_null(&means), "median": mean_or_null(&medians), "max": mean_or_null(&maxima) }),
    );
    detail.insert(
        "selections_per_field".into(),
        json!({ "every": 100, "episodes": window, "cumulative": selections }),
    );
    detail
}

/// `settings` with the policy search's under the key `creps` or `ccmaes` (the feature map is
/// named, as custom maps are not data; a C-CMA-ES population of null is the original's).
pub(crate) fn with_search(
    mut settings: serde_json::Value,
    learner: &LearnerConfig,
    features: &str,
    initial_mean: &str,
) -> serde_json::Value {
    let (key, value) = match learner.search.as_ref().expect("the experiment learns a policy") {
        SearchConfig::CReps(creps) => (
            "creps",
            json!({
                "epsilon": creps.epsilon, "eta_min": creps.eta_min, "ridge": creps.ridge,
                "update_every": creps.update_every, "memory": creps.memory, "features": features,
                "initial_sigma": creps.initial_sigma, "initial_mean": initial_mean,
            }),
        ),
        SearchConfig::CCmaes(ccmaes) => (
            "ccmaes",
            json!({
                "population": ccmaes.population, "ridge": ccmaes.ridge, "features": features,
                "baseline": "quadratic", "rates": "the original's",
                "initial_sigma": ccmaes.initial_sigma, "initial_mean": initial_mean,
            }),
        ),
    };
    settings[key] = value;
    settings
}

fn median(sorted: &[f64]) -> f64 {
    let n = sorted.len();
    if n % 2 == 1 {
        sorted[n / 2]
    } else {
        (sorted[n / 2 - 1] + sorted[n / 2]) / 2.0
    }
}

fn mean_or_null(values: &[f64]) -> Option<f64> {
    (!values.is_empty()).then(|| mean(values))
}
