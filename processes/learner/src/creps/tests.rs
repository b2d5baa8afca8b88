use std::sync::Arc;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::*;

fn linspace(a: f64, b: f64, n: usize) -> Vec<f64> {
    (0..n).map(|i| a + (b - a) * i as f64 / (n - 1) as f64).collect()
}

fn new_error(config: CRepsConfig, context_dim: usize, theta0: &[f64], n_tasks: usize) -> String {
    CReps::new(config, context_dim, theta0, n_tasks)
        .unwrap_err()
        .to_string()
}

#[test]
fn config_errors_name_the_field_and_range() {
    let with = |change: fn(&mut CRepsConfig)| {
        let mut config = CRepsConfig::default();
        change(&mut config);
        new_error(config, 1, &[0.0], 10)
    };
    assert_eq!(with(|c| c.epsilon = -1.0), "epsilon must be finite and > 0, got -1");
    assert_eq!(with(|c| c.eta_min = 0.0), "eta_min must be within [1e-8, 1e0], got 0e0");
    assert_eq!(with(|c| c.ridge = -1e-4), "ridge must be finite and >= 0, got -0.0001");
    assert_eq!(with(|c| c.update_every = 0), "update_every must be >= 1, got 0");
    assert_eq!(
        with(|c| c.memory = MemoryConfig::SlidingWindow { capacity: 0 }),
        "capacity must be >= 1, got 0"
    );
    assert_eq!(
        with(|c| c.memory = MemoryConfig::BestPerTask { per_task: 0 }),
        "per_task must be >= 1, got 0"
    );
    assert_eq!(
        with(|c| c.initial_sigma = f64::INFINITY),
        "initial_sigma must be finite and > 0, got inf"
    );
    let defaults = CRepsConfig::default;
    assert_eq!(new_error(defaults(), 1, &[0.0], 0), "n_tasks must be >= 1, got 0");
    assert_eq!(
        new_error(defaults(), 1, &[], 1),
        "theta0 length (n_theta) must be >= 1, got 0"
    );
    assert_eq!(
        new_error(defaults(), 1, &[0.0, f64::NAN], 1),
        "theta0 must be finite, got NaN at index 1"
    );
    assert_eq!(
        new_error(defaults(), 0, &[0.0], 1),
        "context_dim must be >= 1 for the Affine feature map, got 0"
    );
    let polar = CRepsConfig {
        features: FeatureMap::PolarQuadratic,
        ..defaults()
    };
    assert!(new_error(polar, 1, &[0.0], 1).contains("exactly 2"));
}

#[test]
fn initial_policy_has_mean_theta0_everywhere() {
    for features in [FeatureMap::Affine, FeatureMap::Quadratic, FeatureMap::PolarQuadratic] {
        let config = CRepsConfig {
            features,
            initial_sigma: 0.02,
            ..CRepsConfig::default()
        };
        let creps = CReps::new(config, 2, &[1.5, -2.0, 3.0], 4).unwrap();
        for context in [[-3.0, -4.0], [0.5, 2.0]] {
            assert_eq!(creps.greedy(&context), [1.5, -2.0, 3.0]);
        }
        assert_eq!(creps.policy().covariance(), &(DMatrix::identity(3, 3) * 0.02));
    }
    let custom = CustomFeatures {
        function: Arc::new(|s: &[f64]| vec![s[0], s[1]]),
        dim: 2,
        constant: None,
    };
    let config = CRepsConfig {
        features: FeatureMap::Custom(custom),
        ..CRepsConfig::default()
    };
    assert!(CReps::new(config.clone(), 2, &[1.0], 1).is_err());
    let creps = CReps::new(config, 2, &[0.0], 1).unwrap();
    assert_eq!(creps.greedy(&[0.3, 0.4]), [0.0]);
}

/// Runs BOLeRo's test_contextual.py setting (defaults, reward -(theta_0 - s_0)^2, contexts
/// linspace(-1, 1, 10) cycled, 300 evaluations) and returns the greedy policy's mean reward
/// over 101 contexts.
fn contextual_greedy_reward(seed: u64) -> f64 {
    let contexts = linspace(-1.0, 1.0, 10);
    let mut creps = CReps::new(CRepsConfig::default(), 1, &[0.0], contexts.len()).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut updates = 0;
    for i in 0..300 {
        let task = i % contexts.len();
        let context = [contexts[task]];
        let theta = creps.sample(&context, &mut rng);
        let reward = -(theta[0] - context[0]).powi(2);
        if let Some(report) = creps.record(task, &context, &theta, reward) {
            assert_eq!(report.rejected, None, "{report:?}");
            assert!(report.optimality <= 1e-10 && report.iterations >= 1, "{report:?}");
            assert_eq!(report.samples, (25 * (updates + 1)).min(100));
            updates += 1;
        }
    }
    assert_eq!(updates, 12);
    let test_contexts = linspace(-1.0, 1.0, 101);
    test_contexts
        .iter()
        .map(|&s| -(creps.greedy(&[s])[0] - s).powi(2))
        .sum::<f64>()
        / test_contexts.len() as f64
}

/// The notes' robust form of BOLeRo's assertion: the replication had the greedy mean reward
/// above -1e-5 in 100 of 100 seeds; we require 9 of 10.
#[test]
fn learns_bolero_contextual_problem() {
    let rewards: Vec<f64> = (0..10).map(contextual_greedy_reward).collect();
    let good = rewards.iter().filter(|&&r| r > -1e-5).count();
    assert!(good >= 9, "greedy mean rewards {rewards:?}");
}

#[test]
fn same_seed_gives_the_same_bits() {
    let run = || {
        let config = CRepsConfig {
            features: FeatureMap::Quadratic,
            memory: MemoryConfig::BestPerTask { per_task: 4 },
            update_every: 10,
            ..CRepsConfig::default()
        };
        let mut creps = CReps::new(config, 2, &[0.1, 0.2, 0.3], 5).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(42);
        let mut thetas = Vec::new();
        for i in 0..60 {
            let context = [i as f64 / 60.0, 1.0 - i as f64 / 30.0];
            let theta = creps.sample(&context, &mut rng);
            let reward = -theta.iter().map(|t| (t - context[0]).powi(2)).sum::<f64>();
            creps.record(i % 5, &context, &theta, reward);
            thetas.extend(theta.iter().map(|t| t.to_bits()));
        }
        let policy = creps.policy();
        let bits = |m: &DMatrix<f64>| m.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        (thetas, bits(policy.weights()), bits(policy.covariance()))
    };
    assert_eq!(run(), run());
}

#[test]
fn non_finite_rollouts_are_dropped() {
    let config = CRepsConfig {
        update_every: 2,
        ..CRepsConfig::default()
    };
    let mut creps = CReps::new(config, 1, &[0.0], 1).unwrap();
    assert!(creps.record(0, &[0.5], &[1.0], 0.0).is_none());
    assert!(creps.record(0, &[0.5], &[1.0], f64::NAN).is_none());
    assert!(creps.record(0, &[0.5], &[f64::INFINITY], 0.0).is_none());
    assert_eq!((creps.memory_len(), creps.dropped()), (1, 2));
    // The dropped rollouts did not count: the second stored one triggers the update.
    assert!(creps.record(0, &[0.2], &[0.0], -1.0).is_some());
}

/// Two ways an update fails after the dual succeeded; both keep the old policy.
#[test]
fn rejected_updates_keep_the_old_policy() {
    // Every theta is 1e200: the squared residuals overflow, so Sigma is not finite.
    let mut creps = CReps::new(CRepsConfig::default(), 1, &[0.0], 2).unwrap();
    let before = creps.policy().clone();
    let mut reports = Vec::new();
    for i in 0..25 {
        let context = [i as f64 / 25.0];
        reports.extend(creps.record(i % 2, &context, &[1e200], -(i as f64)));
    }
    assert_eq!(reports.len(), 1);
    assert_eq!(reports[0].rejected, Some(Rejection::CovarianceNotFinite));
    // The report describes the policy kept: Sigma = I.
    assert_eq!((reports[0].trace_sigma, reports[0].logdet_sigma), (1.0, 0.0));
    assert_eq!(creps.policy(), &before);

    // A single sample: (sum d)^2 - sum d^2 = 0, the covariance normaliser divides by zero.
    let config = CRepsConfig {
        update_every: 1,
        ..CRepsConfig::default()
    };
    let mut creps = CReps::new(config, 1, &[0.0], 1).unwrap();
    let report = creps.record(0, &[0.5], &[1.0], -1.0).unwrap();
    assert_eq!(report.rejected, Some(Rejection::TooFewSamples));
    assert_eq!(creps.policy(), &before);
}

/// The per-task memory is capped at `per_task` samples per task, and the update uses it all.
#[test]
fn best_per_task_memory_bounds_the_update() {
    let config = CRepsConfig {
        memory: MemoryConfig::BestPerTask { per_task: 3 },
        update_every: 10,
        ..CRepsConfig::default()
    };
    let mut creps = CReps::new(config, 1, &[0.0], 4).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut sizes = Vec::new();
    for i in 0..40 {
        let context = [i as f64 / 40.0];
        let theta = creps.sample(&context, &mut rng);
        // Only tasks 0 and 1 are practised.
        if let Some(report) = creps.record(i % 2, &context, &theta, -theta[0].abs()) {
            sizes.push(report.samples);
        }
    }
    assert_eq!(sizes, [6, 6, 6, 6]);
}

/// `Batch` and `update` refuse inconsistent or non-finite rollouts and bad settings with errors
/// that name the argument and both sides or the range.
#[test]
fn bad_batches_and_settings_are_errors_naming_the_argument() {
    let policy = LinearGaussianPolicy::new(DMatrix::zeros(2, 1), DMatrix::identity(1, 1)).unwrap();
    let message = |result: Result<Batch, BatchCreateError>| result.unwrap_err().to_string();
    let rows = |n| DMatrix::from_element(n, 1, 0.5);
    assert_eq!(
        message(Batch::new(DMatrix::zeros(3, 2), rows(3), vec![0.0; 2])),
        "the number of feature rows (3) must equal the number of returns (2)"
    );
    assert_eq!(
        message(Batch::new(DMatrix::zeros(2, 2), rows(3), vec![0.0; 2])),
        "the number of theta rows (3) must equal the number of returns (2)"
    );
    assert_eq!(
        message(Batch::new(DMatrix::zeros(0, 2), rows(0), vec![])),
        BatchCreateError::NoSamples.to_string()
    );
    let mut thetas = rows(2);
    thetas[(1, 0)] = f64::INFINITY;
    assert_eq!(
        message(Batch::new(DMatrix::zeros(2, 2), thetas, vec![0.0; 2])),
        "thetas must be finite, got inf at index 1"
    );
    assert_eq!(
        message(Batch::new(DMatrix::zeros(2, 2), rows(2), vec![0.0, f64::NAN])),
        "returns must be finite, got NaN at index 1"
    );

    let contexts = |rows: &[&[f64]]| rows.iter().map(|r| r.to_vec()).collect::<Vec<_>>();
    let from = |c: &[Vec<f64>], t: &[Vec<f64>], r: &[f64]| message(Batch::from_contexts(&FeatureMap::Affine, c, t, r));
    let thetas = vec![vec![0.1], vec![0.2]];
    assert_eq!(
        from(&contexts(&[&[0.0], &[0.5, 1.0]]), &thetas, &[0.0, 1.0]),
        "a context's length (2) must equal the first context's (1)"
    );
    assert_eq!(
        from(&contexts(&[&[0.0], &[0.5]]), &[vec![0.1], vec![0.2, 0.3]], &[0.0, 1.0]),
        "a theta's length (2) must equal the first theta's (1)"
    );
    assert_eq!(
        from(&contexts(&[&[0.0], &[0.5], &[1.0]]), &thetas, &[0.0, 1.0]),
        "the number of contexts (3) must equal the number of thetas (2)"
    );
    assert_eq!(
        from(&contexts(&[&[0.0], &[f64::NAN]]), &thetas, &[0.0, 1.0]),
        "contexts must be finite, got NaN at index 0"
    );
    assert!(from(&[vec![], vec![]], &thetas, &[0.0, 1.0]).contains("context_dim must be >= 1"));

    // A batch that does not fit the policy, and settings out of range.
    let batch = Batch::from_contexts(&FeatureMap::Affine, &contexts(&[&[0.0], &[0.5]]), &thetas, &[0.0, 1.0]).unwrap();
    let wide = LinearGaussianPolicy::new(DMatrix::zeros(2, 2), DMatrix::identity(2, 2)).unwrap();
    let update_error = |policy: &LinearGaussianPolicy, settings: UpdateSettings| {
        update(policy, &batch, &settings).unwrap_err().to_string()
    };
    assert_eq!(
        update_error(&wide, UpdateSettings::default()),
        "the number of theta columns (1) must equal the policy's n_theta (2)"
    );
    let with = |change: fn(&mut UpdateSettings)| {
        let mut settings = UpdateSettings::default();
        change(&mut settings);
        update_error(&policy, settings)
    };
    assert_eq!(with(|s| s.epsilon = 0.0), "epsilon must be finite and > 0, got 0");
    assert_eq!(with(|s| s.ridge = f64::NAN), "ridge must be finite and >= 0, got NaN");
    assert_eq!(
        with(|s| s.eta_min = 1e-9),
        "eta_min must be within [1e-8, 1e0], got 1e-9"
    );
    assert_eq!(
        with(|s| s.dual.tolerance = 1.0),
        "tolerance must be within [1e-14, 1e-3], got 1e0"
    );
    // The same batch with good settings updates.
    assert!(update(&policy, &batch, &UpdateSettings::default()).is_ok());
}

/// What a forged state says is wrong, and how it was forged.
type Forgery = (&'static str, fn(&mut CRepsState));

#[test]
fn a_state_holding_what_no_learner_saves_is_refused_by_name() {
    let config = CRepsConfig {
        update_every: 10,
        ..CRepsConfig::default()
    };
    let mut creps = CReps::new(config.clone(), 1, &[0.1, 0.2], 1).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for i in 0..25 {
        let context = [i as f64 / 25.0];
        let theta = creps.sample(&context, &mut rng);
        creps.record(0, &context, &theta, -(theta[0] - context[0]).powi(2));
    }
    let saved = creps.state();
    let forgeries: [Forgery; 4] = [
        ("W", |s| s.weights[(0, 1)] = f64::NAN),
        ("the covariance", |s| s.covariance[(0, 0)] = f64::NEG_INFINITY),
        ("the covariance and its sampling factor", |s| {
            s.covariance[(1, 1)] = 1e300
        }),
        ("a remembered rollout", |s| match &mut s.memory {
            Memory::Window { samples, .. } => samples[0].reward = f64::NAN,
            Memory::PerTask { .. } => unreachable!("the default memory is a window"),
        }),
    ];
    for (what, forge) in forgeries {
        let mut state = saved.clone();
        forge(&mut state);
        let mut fresh = CReps::new(config.clone(), 1, &[0.1, 0.2], 1).unwrap();
        let before = fresh.state();
        let error = fresh.restore(state).unwrap_err().to_string();
        assert_eq!(
            error,
            format!("C-REPS state: {what} holds values no learner could have saved (not finite, or not consistent)")
        );
        assert_eq!(fresh.state(), before, "{what}");
    }
    let mut fresh = CReps::new(config, 1, &[0.1, 0.2], 1).unwrap();
    fresh.restore(saved.clone()).unwrap();
    assert_eq!(fresh.state(), saved);
}
