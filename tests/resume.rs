//! Checkpoint and resume at the learner level: a learner restored from a checkpoint taken at any
//! point (before training, between tells, mid-window with P > 1 while tasks are out and outcomes
//! wait in the reorder buffer, after the end) finishes bit for bit as the uninterrupted run.

use acps_learner::ccmaes::CCmaesConfig;
use acps_learner::checkpoint::{self, Checkpoint, Stamp};
use acps_learner::creps::{CRepsConfig, FeatureMap, MemoryConfig};
use acps_learner::selection::{AbsoluteProgressConfig, AlpGmmConfig, EmaRates, RetireConfig, SelfPacedConfig};
use acps_learner::{
    BanditConfig, Learner, LearnerConfig, LearnerTellError, Method, SearchConfig, SelectorConfig, run_in_process,
};
use acps_models::contextual_function::ContextualFunction;
use acps_models::learning_model::{LearningModel, LearningModelConfig};
use acps_shared::{Environment, EnvironmentSpec, Outcome, Task};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use std::cell::Cell;

const STAMP: Stamp = Stamp { identity: 1, job: 0 };

/// The contextual function, failing every rollout of a task whose id is 5 mod 13 (so that
/// retries and failed episodes are part of the state).
struct Flaky(ContextualFunction);

impl Environment for Flaky {
    fn spec(&self) -> EnvironmentSpec {
        self.0.spec()
    }

    fn context_dim(&self) -> usize {
        self.0.context_dim()
    }

    fn param_dim(&self) -> usize {
        self.0.param_dim()
    }

    fn rollout(&mut self, task: &Task) -> Outcome {
        if task.id % 13 == 5 {
            Outcome::failed(task.id)
        } else {
            self.0.rollout(task)
        }
    }
}

/// A run to interrupt: a learner and its environment, built afresh for every attempt.
#[derive(Clone, Copy, Debug)]
enum Setup {
    /// The contextual function with `method` (retiring solved contexts when `retire`), a
    /// per-task memory when `per_task`.
    Function {
        method: Method,
        retire: bool,
        seed: u64,
        in_flight: usize,
        per_task: bool,
    },
    /// The contextual function as `Function`'s, learned by C-CMA-ES (generations of 20).
    CCmaes {
        method: Method,
        seed: u64,
        in_flight: usize,
    },
    /// The Section 4 model: no policy, and an environment that keeps state.
    Toy {
        method: Method,
        retire: bool,
        seed: u64,
        in_flight: usize,
    },
}

/// `method`'s selector for runs of a few hundred episodes: ALP-GMM fits every 50 (snapped to the
/// training contexts when `snap`), self-paced pulls towards its target after 4 updates, and retirement, when on, settles after 4 visits with a wide
/// band, so that contexts do retire within the run.
fn selector(method: Method, retire: bool, snap: bool) -> SelectorConfig {
    let retire = retire.then_some(RetireConfig {
        rates: EmaRates { fast: 0.5, slow: 0.25 },
        tolerance: 0.3,
        probe_every: 3,
    });
    match SelectorConfig::from(method) {
        SelectorConfig::AlpGmm { .. } => SelectorConfig::AlpGmm {
            config: AlpGmmConfig {
                fit_rate: 50,
                max_components: 4,
                ..AlpGmmConfig::default()
            },
            snap,
        },
        // The pull towards the target starts within the run's 12 updates.
        SelectorConfig::SelfPaced(_) => SelfPacedConfig {
            offset: 4,
            ..SelfPacedConfig::default()
        }
        .into(),
        SelectorConfig::Bandit(bandit) => BanditConfig { retire, ..bandit }.into(),
        SelectorConfig::AbsoluteProgress(_) => AbsoluteProgressConfig {
            retire,
            ..AbsoluteProgressConfig::default()
        }
        .into(),
        other => other,
    }
}

impl Setup {
    fn build(self) -> (Learner, Box<dyn Environment>) {
        match self {
            Setup::Function {
                method,
                retire,
                seed,
                in_flight,
                per_task,
            } => {
                let function = ContextualFunction::new(2, 6, seed).unwrap();
                let problem = function.grid_problem().unwrap();
                let selector = selector(method, retire, false).build(&problem).unwrap();
                let memory = if per_task {
                    MemoryConfig::BestPerTask { per_task: 3 }
                } else {
                    MemoryConfig::SlidingWindow { capacity: 50 }
                };
                let creps = CRepsConfig {
                    epsilon: 1.0,
                    update_every: 20,
                    memory,
                    features: FeatureMap::Quadratic,
                    ..CRepsConfig::default()
                };
                let config = LearnerConfig {
                    seed,
                    episodes: 240,
                    in_flight,
                    eval_every: 40,
                    search: Some(SearchConfig::CReps(creps)),
                };
                let environment = Flaky(function);
                (Learner::new(config, problem, selector).unwrap(), Box::new(environment))
            }
            Setup::CCmaes {
                method,
                seed,
                in_flight,
            } => {
                let function = ContextualFunction::new(2, 6, seed).unwrap();
                let problem = function.grid_problem().unwrap();
                let selector = selector(method, false, false).build(&problem).unwrap();
                let ccmaes = CCmaesConfig {
                    population: Some(20),
                    features: FeatureMap::Quadratic,
                    ..CCmaesConfig::default()
                };
                let config = LearnerConfig {
                    seed,
                    episodes: 240,
                    in_flight,
                    eval_every: 40,
                    search: Some(SearchConfig::CCmaes(ccmaes)),
                };
                (
                    Learner::new(config, problem, selector).unwrap(),
                    Box::new(Flaky(function)),
                )
            }
            Setup::Toy {
                method,
                retire,
                seed,
                in_flight,
            } => {
                let model = LearningModel::new(
                    LearningModelConfig {
                        sigma_r: 0.01,
                        sigma_b: 0.2,
                    },
                    seed,
                )
                .unwrap();
                let problem = model.problem();
                let selector = selector(method, retire, true).build(&problem).unwrap();
                let config = LearnerConfig {
                    seed,
                    episodes: 200,
                    in_flight,
                    eval_every: 10,
                    search: None,
                };
                (Learner::new(config, problem, selector).unwrap(), Box::new(model))
            }
        }
    }

    /// Whether tasks may be out, or told out of order, when the checkpoint is taken: not with
    /// an environment whose rollouts change it.
    fn stateless(self) -> bool {
        matches!(self, Setup::Function { .. } | Setup::CCmaes { .. })
    }
}

/// The bytes of a checkpoint of `learner`: every bit of its state.
fn bits(learner: &Learner, environment: &dyn Environment) -> Vec<u8> {
    checkpoint::encode(STAMP, &Checkpoint::take(learner, environment))
}

/// Drive `learner` for `tells` outcomes, then stop as if killed. Sequentially, or, `shuffled`,
/// by taking every task offered, performing them all and telling the outcomes in a shuffled
/// order, so that at the stop tasks are out and outcomes wait in the reorder buffer.
fn drive(learner: &mut Learner, environment: &mut dyn Environment, tells: usize, shuffled: Option<u64>) {
    let mut told = 0;
    let Some(order_seed) = shuffled else {
        while told < tells {
            let Some(task) = learner.ask() else { return };
            learner.tell(environment.rollout(&task)).unwrap();
            told += 1;
        }
        return;
    };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(order_seed);
    while told < tells {
        let mut outcomes: Vec<Outcome> = std::iter::from_fn(|| learner.ask())
            .map(|task| environment.rollout(&task))
            .collect();
        if outcomes.is_empty() {
            return;
        }
        outcomes.shuffle(&mut rng);
        for outcome in outcomes {
            if told == tells {
                return;
            }
            learner.tell(outcome).unwrap();
            told += 1;
        }
    }
}

/// Interrupt `setup` after each count of `cuts` in turn (each time checkpoint, encode, decode,
/// restore into a freshly built learner and environment), finish, and return the final bits.
fn interrupted(setup: Setup, cuts: &[usize], shuffled: Option<u64>) -> Vec<u8> {
    let (mut learner, mut environment) = setup.build();
    for &tells in cuts {
        drive(&mut learner, environment.as_mut(), tells, shuffled);
        let bytes = bits(&learner, environment.as_ref());
        let saved = checkpoint::decode(&bytes, STAMP).unwrap();
        (learner, environment) = setup.build();
        saved.apply(&mut learner, environment.as_mut()).unwrap();
        assert!(
            bits(&learner, environment.as_ref()) == bytes,
            "{setup:?}: restore is exact"
        );
    }
    run_in_process(&mut learner, environment.as_mut()).unwrap();
    bits(&learner, environment.as_ref())
}

fn uninterrupted(setup: Setup) -> Vec<u8> {
    let (mut learner, mut environment) = setup.build();
    run_in_process(&mut learner, environment.as_mut()).unwrap();
    assert!(learner.is_done());
    bits(&learner, environment.as_ref())
}

fn check(setup: Setup) {
    let reference = uninterrupted(setup);
    let cut_lists: [&[usize]; 6] = [&[0], &[1], &[57], &[130], &[3, 41, 90], &[10_000]];
    for cuts in cut_lists {
        assert!(
            interrupted(setup, cuts, None) == reference,
            "{setup:?} interrupted after {cuts:?} tells"
        );
        if setup.stateless() {
            for order_seed in [0, 1] {
                assert!(
                    interrupted(setup, cuts, Some(order_seed)) == reference,
                    "{setup:?} interrupted after {cuts:?} shuffled tells (order {order_seed})"
                );
            }
        }
    }
}

#[test]
fn resumed_function_runs_are_bit_identical_for_every_selector() {
    let methods = [
        (Method::MonotonicProgress, false),
        (Method::BestReward, false),
        (Method::OneStepProgress, false),
        (Method::RoundRobin, false),
        (Method::Corners, false),
        (Method::Random, false),
        (Method::RandomContinuous, false),
        (Method::SaggRiac, false),
        (Method::AbsoluteProgress, false),
        (Method::AlpGmm, false),
        (Method::SelfPaced, false),
        (Method::MonotonicProgress, true),
        (Method::AbsoluteProgress, true),
    ];
    for (method, retire) in methods {
        for (seed, in_flight) in [(0, 1), (1, 4)] {
            check(Setup::Function {
                method,
                retire,
                seed,
                in_flight,
                per_task: false,
            });
        }
    }
    // The per-task memory, mid-window.
    check(Setup::Function {
        method: Method::Diversity,
        retire: false,
        seed: 2,
        in_flight: 3,
        per_task: true,
    });
}

#[test]
fn resumed_c_cmaes_runs_are_bit_identical_for_every_selector_that_takes_it() {
    for method in Method::ALL.into_iter().filter(|&m| m != Method::SelfPaced) {
        for (seed, in_flight) in [(0, 1), (1, 4)] {
            check(Setup::CCmaes {
                method,
                seed,
                in_flight,
            });
        }
    }
    // Self-paced moves its contexts in C-REPS' joint dual, which C-CMA-ES does not have.
    let function = ContextualFunction::new(2, 6, 0).unwrap();
    let problem = function.grid_problem().unwrap();
    let config = LearnerConfig {
        search: Some(SearchConfig::CCmaes(CCmaesConfig::default())),
        ..LearnerConfig::default()
    };
    let error = Learner::with_selector(config, problem, &selector(Method::SelfPaced, false, false))
        .err()
        .expect("refused")
        .to_string();
    assert!(error.contains("C-CMA-ES does not have"), "{error}");
}

#[test]
fn resumed_toy_runs_are_bit_identical_with_the_model_state() {
    let methods = [
        (Method::MonotonicProgress, false),
        (Method::SaggRiac, false),
        (Method::Random, false),
        (Method::AbsoluteProgress, true),
        (Method::AlpGmm, false),
    ];
    for (method, retire) in methods {
        for (seed, in_flight) in [(0, 1), (3, 5)] {
            check(Setup::Toy {
                method,
                retire,
                seed,
                in_flight,
            });
        }
    }
}

/// The arms run 0 of `setup` chose.
fn arms(setup: Setup) -> Vec<Option<usize>> {
    let (mut learner, mut environment) = setup.build();
    run_in_process(&mut learner, environment.as_mut()).unwrap();
    learner.episodes().iter().map(|e| e.arm).collect()
}

/// The resumed runs above with retirement do retire contexts: their choices are not those of the
/// same selector without it. (Retirement changes nothing until a context retires.)
#[test]
fn the_resumed_retiring_runs_did_retire() {
    for method in [Method::MonotonicProgress, Method::AbsoluteProgress] {
        let setup = |retire| Setup::Function {
            method,
            retire,
            seed: 0,
            in_flight: 1,
            per_task: false,
        };
        assert_ne!(arms(setup(true)), arms(setup(false)), "{method}");
    }
    let toy = |retire| Setup::Toy {
        method: Method::AbsoluteProgress,
        retire,
        seed: 0,
        in_flight: 1,
    };
    assert_ne!(arms(toy(true)), arms(toy(false)));
}

#[test]
fn the_interrupted_runs_did_fail_retry_and_update() {
    // The reference runs above exercise retries, failed episodes and updates.
    let (mut learner, mut environment) = Setup::Function {
        method: Method::MonotonicProgress,
        retire: false,
        seed: 1,
        in_flight: 4,
        per_task: false,
    }
    .build();
    run_in_process(&mut learner, environment.as_mut()).unwrap();
    let stats = learner.stats();
    assert!(
        stats.retries > 0 && stats.failed_episodes > 0 && stats.updates > 0,
        "{stats:?}"
    );
}

/// Drive `setup` to its end, stopping each update at its first question of `stop`, then at
/// its second, ... until it asks no more (Ctrl-C at every step of a solve and a fit), going on
/// from the stopped learner itself or from its checkpoint, alternately; the final bits and the
/// number of updates stopped.
fn stopped_updates(setup: Setup) -> (Vec<u8>, usize) {
    let (mut learner, mut environment) = setup.build();
    let (mut stopped, mut in_a_row) = (0, 0);
    while let Some(task) = learner.ask() {
        let outcome = environment.rollout(&task);
        let before = bits(&learner, environment.as_ref());
        let (at, asked) = (in_a_row + 1, Cell::new(0));
        let stop = || {
            asked.set(asked.get() + 1);
            asked.get() >= at
        };
        let started_by = match learner.tell_until(outcome, &stop) {
            Ok(()) => {
                in_a_row = 0;
                continue;
            }
            Err(LearnerTellError::Interrupted { task_id }) => task_id,
            Err(other) => panic!("{setup:?}: {other}"),
        };
        (stopped, in_a_row) = (stopped + 1, in_a_row + 1);
        // As if the outcome had not come back: the checkpoint hands the task out again. (An
        // outcome that waited for a retried task's may start the update instead.)
        assert!(
            started_by != task.id || bits(&learner, environment.as_ref()) == before,
            "{setup:?}: update {stopped}, stopped at question {at}, left a trace"
        );
        if stopped % 2 == 0 {
            let saved = checkpoint::decode(&before, STAMP).unwrap();
            (learner, environment) = setup.build();
            saved.apply(&mut learner, environment.as_mut()).unwrap();
        }
    }
    (bits(&learner, environment.as_ref()), stopped)
}

#[test]
fn an_update_stopped_half_way_leaves_no_trace() {
    // C-REPS' plain update and self-paced's joint one (which moves its context distribution
    // too), each memory, one task out or four; and C-CMA-ES's. Every update stopped at each of
    // its questions, then run to its end: C-REPS' 12 at one per Newton step and per block of a
    // fit's columns; C-CMA-ES's 11 generations of 20 (failed rollouts do not count) at two.
    let function = |method, per_task, in_flight| Setup::Function {
        method,
        retire: false,
        seed: 2,
        in_flight,
        per_task,
    };
    for (setup, at_least) in [
        (function(Method::Random, false, 1), 12 * 5),
        (function(Method::Random, true, 4), 12 * 5),
        (function(Method::SelfPaced, false, 4), 12 * 5),
        (function(Method::SelfPaced, true, 1), 12 * 5),
        (
            Setup::CCmaes {
                method: Method::Random,
                seed: 2,
                in_flight: 4,
            },
            11 * 2,
        ),
    ] {
        let (bits, stopped) = stopped_updates(setup);
        assert!(stopped >= at_least, "{setup:?}: {stopped} updates stopped");
        assert!(
            bits == uninterrupted(setup),
            "{setup:?}: stopped updates changed the run"
        );
    }
}

#[test]
fn a_checkpoint_of_another_selector_or_window_is_refused() {
    let setup = |method, in_flight| Setup::Function {
        method,
        retire: false,
        seed: 0,
        in_flight,
        per_task: false,
    };
    let (mut learner, mut environment) = setup(Method::RoundRobin, 2).build();
    drive(&mut learner, environment.as_mut(), 30, None);
    let saved = Checkpoint::take(&learner, environment.as_ref());

    let (mut other, mut environment) = setup(Method::MonotonicProgress, 2).build();
    let error = saved.clone().apply(&mut other, environment.as_mut()).unwrap_err();
    assert_eq!(
        error.to_string(),
        "selector state: a round-robin state cannot restore a D-UCB selector"
    );
    let (mut other, mut environment) = setup(Method::RoundRobin, 3).build();
    let error = saved.apply(&mut other, environment.as_mut()).unwrap_err();
    assert_eq!(
        error.to_string(),
        "the checkpoint is of a learner with in_flight 2, this one has in_flight 3"
    );
    // A toy checkpoint (no policy, a model state) for a function learner.
    let toy = Setup::Toy {
        method: Method::RoundRobin,
        retire: false,
        seed: 0,
        in_flight: 2,
    };
    let (learner, environment) = toy.build();
    let saved = Checkpoint::take(&learner, environment.as_ref());
    let (mut other, mut environment) = setup(Method::RoundRobin, 2).build();
    let error = saved.apply(&mut other, environment.as_mut()).unwrap_err();
    assert!(error.to_string().contains("problem learning-model"), "{error}");
}
