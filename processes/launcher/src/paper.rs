//! The paper's in-process experiments: Section 4 (`toy`, Fig. 2 and 3), Section 5.1.2
//! (`function`, Fig. 4 and 5) and Section 5.1.3 (`dims`, Fig. 6). Every setting the paper leaves
//! open is recorded in the summary's `settings` and explained in docs/EXPERIMENTS.md.

use crate::experiment::{Experiment, Instance};
use acps_learner::creps::{CRepsConfig, FeatureMap, MemoryConfig};
use acps_learner::selection::{DUcbConfig, FirstVisit, SaggRiacConfig};
use acps_learner::{LearnerConfig, Method, SelectorConfig};
use acps_models::contextual_function::{ContextualFunction, DEFAULT_N_THETA};
use acps_models::learning_model::{LearningModel, LearningModelConfig};
use serde_json::json;

/// Choices shared by every experiment command.
#[derive(Debug, Clone)]
pub struct Options {
    /// Runs per method (default: the paper's 20).
    pub runs: usize,
    /// Override of the experiment's number of training episodes.
    pub episodes: Option<u64>,
    /// Seed of run 0.
    pub seed: u64,
    /// Training tasks in flight.
    pub in_flight: usize,
    /// Only these methods (default: the methods of the paper's figure).
    pub methods: Option<Vec<Method>>,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            runs: 20,
            episodes: None,
            seed: 0,
            in_flight: 1,
            methods: None,
        }
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
pub fn toy(model: LearningModelConfig, options: &Options) -> Experiment {
    let default_methods = [
        Method::RoundRobin,
        Method::BestReward,
        Method::Diversity,
        Method::OneStepProgress,
        Method::MonotonicProgress,
        Method::SaggRiac,
    ];
    let methods = selected(options, &default_methods)
        .into_iter()
        .map(|method| {
            let b = if matches!(method, Method::BestReward | Method::Diversity) {
                1.0
            } else {
                0.25
            };
            selector(
                method,
                DUcbConfig {
                    gamma: 0.95,
                    xi: 1e-8,
                    b,
                },
            )
        })
        .collect();
    let episodes = options.episodes.unwrap_or(1000);
    Experiment {
        name: "toy".into(),
        methods,
        runs: options.runs,
        base_seed: options.seed,
        learner: LearnerConfig {
            seed: options.seed,
            episodes,
            in_flight: options.in_flight,
            eval_every: 10,
            creps: None,
        },
        instance: Box::new(move |seed| {
            let environment = LearningModel::new(model, seed).expect("panel noise levels are valid");
            Instance {
                problem: LearningModel::problem(),
                optimal_score: Some(environment.optimal_performance()),
                environment: Box::new(environment),
            }
        }),
        selection_window: episodes as usize,
        settings: json!({
            "model": { "sigma_r": model.sigma_r, "sigma_b": model.sigma_b, "contexts": 10 },
            "ducb": { "gamma": 0.95, "xi": 1e-8, "b_best_reward_diversity": 1.0, "b_progress": 0.25 },
            "first_visit": "initial-return",
            "sagg_riac": SaggRiacConfig::default(),
            "eval_every": 10,
        }),
    }
}

/// Section 5.1.2 (Fig. 4 and 5): 25 grid contexts, C-REPS epsilon 2.0 over the last 50 rollouts,
/// an update every 25, quadratic features, W = 0 and Sigma = I; D-UCB B 1, gamma 0.99, xi 1e-8;
/// evaluation every 50 rollouts on 100 test contexts.
pub fn function(options: &Options) -> Experiment {
    let default_methods = [
        Method::BestReward,
        Method::Diversity,
        Method::OneStepProgress,
        Method::MonotonicProgress,
        Method::Corners,
        Method::Random,
    ];
    let creps = CRepsConfig {
        epsilon: 2.0,
        eta_min: 1e-8,
        ridge: 1e-4,
        update_every: 25,
        memory: MemoryConfig::SlidingWindow { capacity: 50 },
        features: FeatureMap::Quadratic,
        initial_sigma: 1.0,
    };
    contextual_function_experiment(
        "function",
        options,
        &default_methods,
        2500,
        50,
        creps,
        Box::new(|seed| ContextualFunction::grid_problem(DEFAULT_N_THETA, seed)),
        2,
        250,
    )
}

/// Section 5.1.3 (Fig. 6) for `n_s` context dimensions: C-REPS epsilon 1.0 over the last
/// 25 n_s^2 rollouts, an update every 13 n_s^2; D-UCB with monotonic progress.
pub fn dims(n_s: usize, options: &Options) -> Experiment {
    let default_methods = [Method::MonotonicProgress, Method::Random, Method::RandomContinuous];
    let n2 = n_s * n_s;
    let creps = CRepsConfig {
        epsilon: 1.0,
        eta_min: 1e-8,
        ridge: 1e-4,
        update_every: 13 * n2,
        memory: MemoryConfig::SlidingWindow { capacity: 25 * n2 },
        features: FeatureMap::Quadratic,
        initial_sigma: 1.0,
    };
    contextual_function_experiment(
        "dims",
        options,
        &default_methods,
        5000,
        100,
        creps,
        Box::new(move |seed| ContextualFunction::shell_problem(n_s, DEFAULT_N_THETA, seed)),
        n_s,
        250,
    )
}

#[allow(clippy::too_many_arguments)]
fn contextual_function_experiment(
    name: &str,
    options: &Options,
    default_methods: &[Method],
    default_episodes: u64,
    eval_every: u64,
    creps: CRepsConfig,
    problem: Box<dyn Fn(u64) -> acps_shared::Problem + Send + Sync>,
    n_s: usize,
    selection_window: usize,
) -> Experiment {
    let ducb = DUcbConfig {
        gamma: 0.99,
        xi: 1e-8,
        b: 1.0,
    };
    let settings = json!({
        "n_s": n_s,
        "n_theta": DEFAULT_N_THETA,
        "creps": {
            "epsilon": creps.epsilon, "eta_min": creps.eta_min, "ridge": creps.ridge,
            "update_every": creps.update_every, "memory": creps.memory, "features": format!("{:?}", creps.features),
            "initial_sigma": creps.initial_sigma, "initial_mean": "0",
        },
        "ducb": ducb,
        "first_visit": "initial-return",
        "eval_every": eval_every,
    });
    Experiment {
        name: name.into(),
        methods: selected(options, default_methods)
            .into_iter()
            .map(|m| selector(m, ducb.clone()))
            .collect(),
        runs: options.runs,
        base_seed: options.seed,
        learner: LearnerConfig {
            seed: options.seed,
            episodes: options.episodes.unwrap_or(default_episodes),
            in_flight: options.in_flight,
            eval_every,
            creps: Some(creps),
        },
        instance: Box::new(move |seed| Instance {
            problem: problem(seed),
            environment: Box::new(ContextualFunction::new(n_s, DEFAULT_N_THETA, seed).expect("n_theta > n_s")),
            optimal_score: None,
        }),
        selection_window,
        settings,
    }
}

fn selected(options: &Options, defaults: &[Method]) -> Vec<Method> {
    options.methods.clone().unwrap_or_else(|| defaults.to_vec())
}

fn selector(method: Method, ducb: DUcbConfig) -> SelectorConfig {
    SelectorConfig {
        method,
        ducb,
        first_visit: FirstVisit::InitialReturn,
        sagg_riac: SaggRiacConfig::default(),
    }
}
