//! The ask/tell core: determinism, in-flight window, reordering, bad input.

use acps_learner::creps::{CRepsConfig, DEFAULT_ETA_MIN, FeatureMap, MemoryConfig};
use acps_learner::{Learner, LearnerConfig, LearnerTellError, Method, SearchConfig, SelectorConfig};
use acps_models::contextual_function::ContextualFunction;
use acps_shared::{Environment, Outcome, TaskKind};
use rand::SeedableRng;
use rand::seq::SliceRandom;

fn function_learner(method: Method, seed: u64, in_flight: usize, episodes: u64) -> (Learner, ContextualFunction) {
    let function = ContextualFunction::new(2, 6, seed).unwrap();
    let problem = function.grid_problem().unwrap();
    let selector = SelectorConfig::from(method).build(&problem).unwrap();
    let creps = CRepsConfig {
        epsilon: 1.0,
        eta_min: DEFAULT_ETA_MIN,
        ridge: 1e-4,
        update_every: 25,
        memory: MemoryConfig::SlidingWindow { capacity: 50 },
        features: FeatureMap::Quadratic,
        initial_sigma: 1.0,
    };
    let config = LearnerConfig {
        seed,
        episodes,
        in_flight,
        eval_every: 50,
        search: Some(SearchConfig::CReps(creps)),
    };
    (Learner::new(config, problem, selector).unwrap(), function)
}

/// Everything observable about a finished run, as bits.
fn fingerprint(learner: &Learner) -> Vec<u64> {
    let mut bits = Vec::new();
    for evaluation in learner.evaluations() {
        bits.push(evaluation.episode);
        bits.push(evaluation.score.unwrap().to_bits());
    }
    for episode in learner.episodes() {
        bits.push(episode.arm.map_or(u64::MAX, |a| a as u64));
        bits.push(episode.reward.to_bits());
    }
    bits
}

/// Drive a learner by handing out everything available, performing the rollouts, and telling the
/// outcomes back in an order shuffled by `order_seed`.
fn run_shuffled(learner: &mut Learner, environment: &mut ContextualFunction, order_seed: u64) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(order_seed);
    while !learner.is_done() {
        let mut outcomes: Vec<Outcome> = std::iter::from_fn(|| learner.ask())
            .map(|task| environment.rollout(&task))
            .collect();
        assert!(!outcomes.is_empty(), "the learner stalled");
        outcomes.shuffle(&mut rng);
        for outcome in outcomes {
            learner.tell(outcome).unwrap();
        }
    }
}

#[test]
fn same_seed_gives_the_same_bits() {
    for method in [Method::MonotonicProgress, Method::Random, Method::RandomContinuous] {
        let (mut a, mut env_a) = function_learner(method, 5, 1, 300);
        let (mut b, mut env_b) = function_learner(method, 5, 1, 300);
        acps_learner::run_in_process(&mut a, &mut env_a).unwrap();
        acps_learner::run_in_process(&mut b, &mut env_b).unwrap();
        assert_eq!(fingerprint(&a), fingerprint(&b), "{method}");
        let (mut c, mut env_c) = function_learner(method, 6, 1, 300);
        acps_learner::run_in_process(&mut c, &mut env_c).unwrap();
        assert_ne!(
            fingerprint(&a),
            fingerprint(&c),
            "{method}: another seed must change the run"
        );
    }
}

#[test]
fn outcome_order_does_not_change_the_run() {
    for in_flight in [1, 4, 16] {
        let (mut reference, mut env) = function_learner(Method::MonotonicProgress, 3, in_flight, 400);
        acps_learner::run_in_process(&mut reference, &mut env).unwrap();
        for order_seed in 0..3 {
            let (mut shuffled, mut env) = function_learner(Method::MonotonicProgress, 3, in_flight, 400);
            run_shuffled(&mut shuffled, &mut env, order_seed);
            assert_eq!(
                fingerprint(&reference),
                fingerprint(&shuffled),
                "P = {in_flight}, order {order_seed}"
            );
        }
    }
}

#[test]
fn the_window_holds_exactly_p_training_tasks() {
    for in_flight in [1, 3, 8] {
        let (mut learner, mut env) = function_learner(Method::Random, 1, in_flight, 100);
        let mut held = Vec::new();
        // Take everything offered without answering: exactly P training tasks come out.
        while let Some(task) = learner.ask() {
            held.push(task);
        }
        let training = held.iter().filter(|t| t.kind == TaskKind::Train).count();
        assert_eq!(training, in_flight);
        // Answering the first training task (and everything before it) releases exactly one more.
        let first_train = held.iter().position(|t| t.kind == TaskKind::Train).unwrap();
        for task in &held[..=first_train] {
            learner.tell(env.rollout(task)).unwrap();
        }
        let released: Vec<_> = std::iter::from_fn(|| learner.ask()).collect();
        assert_eq!(
            released.iter().filter(|t| t.kind == TaskKind::Train).count(),
            1,
            "P = {in_flight}"
        );
    }
}

#[test]
fn in_flight_one_matches_the_sequential_algorithm_and_larger_p_differs() {
    let (mut sequential, mut env) = function_learner(Method::MonotonicProgress, 2, 1, 300);
    acps_learner::run_in_process(&mut sequential, &mut env).unwrap();
    let (mut batched, mut env) = function_learner(Method::MonotonicProgress, 2, 8, 300);
    acps_learner::run_in_process(&mut batched, &mut env).unwrap();
    assert_eq!(sequential.episodes().len(), 300);
    assert_eq!(batched.episodes().len(), 300);
    assert_ne!(fingerprint(&sequential), fingerprint(&batched));
}

#[test]
fn failed_rollouts_never_reach_the_policy() {
    let (mut learner, mut env) = function_learner(Method::Random, 4, 1, 200);
    let mut failures = 0;
    while let Some(task) = learner.ask() {
        let outcome = if task.kind == TaskKind::Train && task.id % 7 == 0 {
            failures += 1;
            Outcome::new(task.id, f64::NAN, f64::NAN)
        } else {
            env.rollout(&task)
        };
        learner.tell(outcome).unwrap();
    }
    assert!(learner.is_done());
    // Every failing task was told twice: once, and once more after its retry.
    assert_eq!(2 * learner.stats().failed_episodes, failures);
    assert!(failures > 20);
    assert_eq!(learner.stats().rejected_updates, 0);
    assert!(
        learner
            .evaluations()
            .iter()
            .all(|e| e.score.is_some_and(f64::is_finite))
    );
    let policy = learner.policy().unwrap();
    assert!(policy.greedy(&[0.5, 0.5]).iter().all(|x| x.is_finite()));
}

#[test]
fn unknown_and_duplicate_outcomes_are_refused() {
    let (mut learner, mut env) = function_learner(Method::Random, 1, 2, 10);
    let first = learner.ask().unwrap();
    let second = learner.ask().unwrap();
    assert_eq!(
        learner.tell(Outcome::new(999, 0.0, 0.0)),
        Err(LearnerTellError::UnknownTask { task_id: 999 })
    );
    learner.tell(env.rollout(&second)).unwrap();
    assert_eq!(
        learner.tell(env.rollout(&second)),
        Err(LearnerTellError::Duplicate { task_id: second.id })
    );
    learner.tell(env.rollout(&first)).unwrap();
    // Consumed now: a late copy is unknown.
    assert_eq!(
        learner.tell(env.rollout(&first)),
        Err(LearnerTellError::UnknownTask { task_id: first.id })
    );
}

#[test]
fn reissued_tasks_come_out_again_unchanged() {
    let (mut learner, _) = function_learner(Method::Random, 1, 2, 10);
    let task = learner.ask().unwrap();
    assert!(learner.reissue(task.id));
    assert!(!learner.reissue(task.id), "already waiting in the outbox");
    let mut again = std::iter::from_fn(|| learner.ask()).filter(|t| t.id == task.id);
    assert_eq!(again.next(), Some(task));
    assert!(!learner.reissue(12345));
}

#[test]
fn bad_configs_are_refused_with_the_field_name() {
    let problem = ContextualFunction::new(2, 6, 0).unwrap().grid_problem().unwrap();
    let selector = || SelectorConfig::from(Method::Random).build(&problem).unwrap();
    let config = LearnerConfig {
        seed: 0,
        episodes: 10,
        in_flight: 0,
        eval_every: 5,
        search: None,
    };
    let error = Learner::new(config, problem.clone(), selector())
        .err()
        .unwrap()
        .to_string();
    assert!(error.contains("in_flight") && error.contains(">= 1"), "{error}");
    let config = LearnerConfig {
        seed: 0,
        episodes: 10,
        in_flight: 1,
        eval_every: 5,
        search: None,
    };
    let error = Learner::new(config, problem.clone(), selector())
        .err()
        .unwrap()
        .to_string();
    assert!(error.contains("no policy search"), "{error}");
}

#[test]
fn evaluations_keep_every_test_outcome_in_order() {
    let (mut learner, mut env) = function_learner(Method::Random, 2, 1, 100);
    acps_learner::run_in_process(&mut learner, &mut env).unwrap();
    let contexts = learner.problem().test_contexts.clone();
    for evaluation in learner.evaluations() {
        assert_eq!(evaluation.outcomes.len(), contexts.len());
        let scores: Vec<f64> = evaluation.outcomes.iter().map(|o| o.as_ref().unwrap().score).collect();
        // The function's score is the cost ||A theta - s|| ||s||^2, so it is 0 only at s = 0; and
        // the aggregate is ln(mean cost).
        let mean = scores.iter().sum::<f64>() / scores.len() as f64;
        assert!((evaluation.score.unwrap() - mean.ln()).abs() < 1e-12);
    }
    // Outcome i answers test context i: re-evaluating context 0 with the final greedy policy
    // reproduces the final evaluation's first score.
    let last = learner.evaluations().last().unwrap();
    let theta = learner.policy().unwrap().greedy(&contexts[0]);
    let (_, cost) = env.evaluate(&theta, &contexts[0]).unwrap();
    assert_eq!(cost, last.outcomes[0].as_ref().unwrap().score);
}

#[test]
fn a_failed_outcome_is_retried_once_then_consumed_as_failed() {
    // Transient failures: the first attempt of every 5th training task fails, the retry works.
    let (mut transient, mut env) = function_learner(Method::Random, 8, 1, 200);
    let (mut reference, mut env_reference) = function_learner(Method::Random, 8, 1, 200);
    acps_learner::run_in_process(&mut reference, &mut env_reference).unwrap();
    let mut attempts = std::collections::HashMap::new();
    while let Some(task) = transient.ask() {
        let attempt = attempts.entry(task.id).and_modify(|n| *n += 1).or_insert(1);
        let outcome = if task.kind == TaskKind::Train && task.id % 5 == 0 && *attempt == 1 {
            Outcome::failed(task.id)
        } else {
            env.rollout(&task)
        };
        transient.tell(outcome).unwrap();
    }
    assert!(transient.stats().retries > 20);
    assert_eq!(transient.stats().failed_episodes, 0);
    assert_eq!(
        fingerprint(&transient),
        fingerprint(&reference),
        "a retried success changes nothing"
    );
    // Permanent failures: retried once, then consumed as failed.
    let (mut permanent, mut env) = function_learner(Method::Random, 8, 1, 200);
    while let Some(task) = permanent.ask() {
        let outcome = if task.kind == TaskKind::Train && task.id % 5 == 0 {
            Outcome::failed(task.id)
        } else {
            env.rollout(&task)
        };
        permanent.tell(outcome).unwrap();
    }
    assert_eq!(permanent.stats().retries, permanent.stats().failed_episodes);
    assert!(permanent.stats().failed_episodes > 20);
}

#[test]
fn progress_reports_episodes_and_the_latest_complete_evaluation() {
    for seed in [1, 2, 3] {
        let (mut learner, mut environment) = function_learner(Method::MonotonicProgress, seed, 4, 200);
        let mut observed = Vec::new();
        let mut rollouts = 0u64;
        while let Some(task) = learner.ask() {
            learner.tell(environment.rollout(&task)).unwrap();
            rollouts += 1;
            if rollouts.is_multiple_of(37) || learner.is_done() {
                observed.push((learner.progress(), rollouts));
            }
        }
        // The rollouts are the training episodes, the evaluations and the first-visit baselines.
        let evaluation_rollouts: usize = learner.evaluations().iter().map(|e| e.outcomes.len()).sum();
        let baselines = learner.problem().training_contexts.len() as u64;
        assert_eq!(rollouts, 200 + evaluation_rollouts as u64 + baselines);
        let (last, _) = observed.last().unwrap();
        assert_eq!((last.episodes, last.total_episodes), (200, 200));
        assert_eq!(last.score, learner.evaluations().last().unwrap().score);
        assert!(observed.windows(2).all(|w| w[0].0.episodes <= w[1].0.episodes));
        // Mid-run, the score is that of an evaluation already scheduled at that point.
        let (middle, _) = observed[observed.len() / 2];
        let score = middle.score.expect("the first evaluation is done early");
        assert!(
            learner
                .evaluations()
                .iter()
                .any(|e| e.episode <= middle.episodes && e.score == Some(score))
        );
    }
}

#[test]
fn progress_of_several_learners_adds_episodes_and_averages_scores() {
    use acps_learner::LearningProgress;
    let part = |episodes, score: Option<f64>| LearningProgress {
        episodes,
        total_episodes: 100,
        score,
        scored: usize::from(score.is_some()),
    };
    let total = LearningProgress::combine([part(10, Some(1.0)), part(20, None), part(30, Some(4.0))]);
    assert_eq!((total.episodes, total.total_episodes, total.scored), (60, 300, 2));
    assert_eq!(total.score, Some(2.5));
    // Combining combined parts weighs them by the learners they average.
    let nested = LearningProgress::combine([total, part(0, Some(7.0))]);
    assert_eq!(nested.score, Some(4.0));
    assert_eq!(LearningProgress::combine([part(5, None)]).score, None);
}

#[test]
fn an_environment_other_than_the_problems_is_refused_before_any_rollout() {
    let (mut learner, _) = function_learner(Method::Random, 1, 1, 10);
    // The same function of another problem seed: another matrix A, another environment.
    let mut other = ContextualFunction::new(2, 6, 2).unwrap();
    let error = acps_learner::run_in_process(&mut learner, &mut other).unwrap_err();
    let message = error.to_string();
    assert!(
        message.contains(&learner.problem().environment.to_string()) && message.contains(&other.spec().to_string()),
        "{message}"
    );
    assert_eq!(learner.stats(), &Default::default(), "nothing was performed");
    assert!(learner.episodes().is_empty());
}

/// Self-paced (SPRL): every update moves the context distribution with the policy, within both KL
/// bounds; on the contextual function, whose value grows with s0 + s1 (its optimum is sum s), the
/// distribution first moves towards the corner (1, 1), where the returns are highest.
#[test]
fn self_paced_moves_its_contexts_towards_high_returns_within_both_bounds() {
    for seed in 0..3 {
        // 20 updates: all before the default offset, so alpha is 0 throughout.
        let (mut learner, mut function) = function_learner(Method::SelfPaced, seed, 1, 500);
        acps_learner::run_in_process(&mut learner, &mut function).unwrap();
        assert_eq!(learner.updates().len(), 20);
        for record in learner.updates() {
            let acps_learner::SearchReport::CReps(report) = &record.report else {
                panic!("self-paced runs C-REPS")
            };
            let context = report
                .context
                .as_ref()
                .expect("a paced update reports its context side");
            assert_eq!(report.rejected, None, "seed {seed}");
            assert_eq!(context.alpha, 0.0);
            assert!(report.kl <= report.epsilon + 1e-8 && context.kl <= report.epsilon + 1e-8);
            assert!(context.nu.is_some_and(|nu| nu >= 0.0));
        }
        let level = |episodes: &[acps_learner::Episode]| {
            episodes.iter().map(|e| e.context.iter().sum::<f64>()).sum::<f64>() / episodes.len() as f64
        };
        let episodes = learner.episodes();
        let (first, last) = (level(&episodes[..100]), level(&episodes[400..]));
        assert!(
            last > first + 0.5 && last > 1.0,
            "seed {seed}: mean s0 + s1 {first} -> {last}"
        );
    }
}

#[test]
fn self_paced_needs_a_policy() {
    use acps_models::learning_model::{LearningModel, LearningModelConfig};
    let noiseless = LearningModelConfig {
        sigma_r: 0.0,
        sigma_b: 0.0,
    };
    let model = LearningModel::new(noiseless, 0).unwrap();
    let problem = model.problem();
    let selector = SelectorConfig::from(Method::SelfPaced).build(&problem).unwrap();
    let config = LearnerConfig {
        search: None,
        ..LearnerConfig::default()
    };
    let error = Learner::new(config, problem, selector).err().unwrap().to_string();
    assert!(
        error.contains("no policy parameters") && error.contains("self-paced"),
        "{error}"
    );
}
