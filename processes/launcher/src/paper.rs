//! The paper's in-process experiments: Section 4 (`toy`, Fig. 2 and 3), Section 5.1.2
//! (`function`, Fig. 4 and 5) and Section 5.1.3 (`dims`, Fig. 6). Every setting the paper leaves
//! open is recorded in the summary's `settings` and explained in docs/EXPERIMENTS.md.

use crate::experiment::{Experiment, Instance};
use acps_learner::creps::{CRepsConfig, FeatureMap, MemoryConfig};
use acps_learner::selection::{DUcbConfig, FirstVisit, SaggRiacConfig};
use acps_learner::{LearnerConfig, Method, SelectorConfig};
use acps_models::contextual_function::{ContextualFunction, DEFAULT_N_THETA};
use acps_models::learning_model::{CONTEXTS, LearningModel, LearningModelConfig};
use acps_shared::Problem;
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
    /// Settings the paper does not state, overriding the experiment's defaults.
    pub overrides: Overrides,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            runs: 20,
            episodes: None,
            seed: 0,
            in_flight: 1,
            methods: None,
            overrides: Overrides::default(),
        }
    }
}

/// Overrides of settings the paper leaves open or that are worth varying.
#[derive(Debug, Clone, Default)]
pub struct Overrides {
    /// Number of low-level parameters n_theta of the contextual function (must exceed n_s).
    pub n_theta: Option<usize>,
    /// Baseline of a context's first visit.
    pub first_visit: Option<FirstVisit>,
    /// True: the paper's Section 5.2 per-task memory of the best N/K rollouts instead of the
    /// sliding window of the last N.
    pub best_per_task: Option<bool>,
    /// Initial covariance Sigma_0 = initial_sigma I.
    pub initial_sigma: Option<f64>,
    /// D-UCB padding strength xi.
    pub xi: Option<f64>,
    /// C-REPS epsilon.
    pub epsilon: Option<f64>,
    /// Section 4 model: fixed learning factors instead of a random permutation per run.
    pub learning_factors: Option<[f64; CONTEXTS]>,
}

/// The learning factors of the paper's Fig. 3 (context 3 learns fastest, its neighbour 4 hardly
/// at all), as read off the figure; they equal numpy's `RandomState(0).permutation` of
/// {0.1^2, ..., 1.0^2}.
pub const FIG3_LEARNING_FACTORS: [f64; CONTEXTS] = [0.09, 0.81, 0.25, 1.0, 0.04, 0.49, 0.64, 0.16, 0.01, 0.36];

impl Options {
    fn first_visit(&self) -> FirstVisit {
        self.overrides.first_visit.unwrap_or(FirstVisit::InitialReturn)
    }

    fn methods(&self, defaults: &[Method], ducb: impl Fn(Method) -> DUcbConfig) -> Vec<SelectorConfig> {
        let methods = self.methods.clone().unwrap_or_else(|| defaults.to_vec());
        methods
            .into_iter()
            .map(|method| SelectorConfig {
                method,
                ducb: ducb(method),
                first_visit: self.first_visit(),
                sagg_riac: SaggRiacConfig::default(),
            })
            .collect()
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
    let defaults = [
        Method::RoundRobin,
        Method::BestReward,
        Method::Diversity,
        Method::OneStepProgress,
        Method::MonotonicProgress,
        Method::SaggRiac,
    ];
    let xi = options.overrides.xi.unwrap_or(1e-8);
    let b = |method| {
        if matches!(method, Method::BestReward | Method::Diversity) {
            1.0
        } else {
            0.25
        }
    };
    let episodes = options.episodes.unwrap_or(1000);
    let learning_factors = options.overrides.learning_factors;
    Experiment {
        name: "toy".into(),
        methods: options.methods(&defaults, |method| DUcbConfig {
            gamma: 0.95,
            xi,
            b: b(method),
        }),
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
            let mut environment = LearningModel::new(model, seed).expect("panel noise levels are valid");
            if let Some(factors) = learning_factors {
                environment = environment
                    .with_learning_factors(factors)
                    .expect("the factors were validated");
            }
            Instance {
                problem: LearningModel::problem(),
                optimal_score: Some(environment.optimal_performance()),
                environment: Box::new(environment),
            }
        }),
        selection_window: episodes as usize,
        settings: json!({
            "model": { "sigma_r": model.sigma_r, "sigma_b": model.sigma_b, "contexts": CONTEXTS, "learning_factors": learning_factors.map_or("random permutation per run".to_string(), |w| format!("{w:?}")) },
            "ducb": { "gamma": 0.95, "xi": xi, "b_best_reward_diversity": 1.0, "b_progress": 0.25 },
            "first_visit": options.first_visit(),
            "sagg_riac": SaggRiacConfig::default(),
            "eval_every": 10,
        }),
        detail: None,
    }
}

/// Section 5.1.2 (Fig. 4 and 5): 25 grid contexts, C-REPS epsilon 2.0 over the last 50 rollouts,
/// an update every 25, quadratic features, W = 0 and Sigma = I; D-UCB B 1, gamma 0.99, xi 1e-8;
/// evaluation every 50 rollouts on 100 test contexts.
pub fn function(options: &Options) -> Experiment {
    let defaults = [
        Method::BestReward,
        Method::Diversity,
        Method::OneStepProgress,
        Method::MonotonicProgress,
        Method::Corners,
        Method::Random,
    ];
    let setting = FunctionSetting {
        epsilon: 2.0,
        samples: 50,
        update_every: 25,
        episodes: 2500,
        eval_every: 50,
    };
    function_experiment("function", 2, setting, &defaults, options, |seed, n_theta| {
        ContextualFunction::grid_problem(n_theta, seed)
    })
}

/// Section 5.1.3 (Fig. 6) for `n_s` context dimensions: C-REPS epsilon 1.0 over the last
/// 25 n_s^2 rollouts, an update every 13 n_s^2; D-UCB with monotonic progress.
pub fn dims(n_s: usize, options: &Options) -> Experiment {
    let defaults = [Method::MonotonicProgress, Method::Random, Method::RandomContinuous];
    let n2 = n_s * n_s;
    let setting = FunctionSetting {
        epsilon: 1.0,
        samples: 25 * n2,
        update_every: 13 * n2,
        episodes: 5000,
        eval_every: 100,
    };
    function_experiment("dims", n_s, setting, &defaults, options, move |seed, n_theta| {
        ContextualFunction::shell_problem(n_s, n_theta, seed)
    })
}

/// The C-REPS schedule of a Section 5.1 experiment.
struct FunctionSetting {
    epsilon: f64,
    samples: usize,
    update_every: usize,
    episodes: u64,
    eval_every: u64,
}

fn function_experiment(
    name: &str,
    n_s: usize,
    setting: FunctionSetting,
    defaults: &[Method],
    options: &Options,
    problem: impl Fn(u64, usize) -> Problem + Send + Sync + 'static,
) -> Experiment {
    let overrides = &options.overrides;
    let n_theta = overrides.n_theta.unwrap_or(DEFAULT_N_THETA);
    let n_tasks = 25;
    let memory = if overrides.best_per_task == Some(true) {
        MemoryConfig::BestPerTask {
            per_task: (setting.samples / n_tasks).max(1),
        }
    } else {
        MemoryConfig::SlidingWindow {
            capacity: setting.samples,
        }
    };
    let creps = CRepsConfig {
        epsilon: overrides.epsilon.unwrap_or(setting.epsilon),
        eta_min: 1e-8,
        ridge: 1e-4,
        update_every: setting.update_every,
        memory,
        features: FeatureMap::Quadratic,
        initial_sigma: overrides.initial_sigma.unwrap_or(1.0),
    };
    let ducb = DUcbConfig {
        gamma: 0.99,
        xi: overrides.xi.unwrap_or(1e-8),
        b: 1.0,
    };
    let settings = json!({
        "n_s": n_s,
        "n_theta": n_theta,
        "creps": {
            "epsilon": creps.epsilon, "eta_min": creps.eta_min, "ridge": creps.ridge,
            "update_every": creps.update_every, "memory": creps.memory, "features": "quadratic",
            "initial_sigma": creps.initial_sigma, "initial_mean": "0",
        },
        "ducb": ducb,
        "first_visit": options.first_visit(),
        "eval_every": setting.eval_every,
    });
    Experiment {
        name: name.into(),
        methods: options.methods(defaults, |_| ducb.clone()),
        runs: options.runs,
        base_seed: options.seed,
        learner: LearnerConfig {
            seed: options.seed,
            episodes: options.episodes.unwrap_or(setting.episodes),
            in_flight: options.in_flight,
            eval_every: setting.eval_every,
            creps: Some(creps),
        },
        instance: Box::new(move |seed| Instance {
            problem: problem(seed, n_theta),
            environment: Box::new(ContextualFunction::new(n_s, n_theta, seed).expect("n_theta > n_s was checked")),
            optimal_score: None,
        }),
        selection_window: 250,
        settings,
        detail: None,
    }
}
