use super::*;
use crate::creps::FeatureMap;
use nalgebra::SymmetricEigen;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// BOLeRo's contextual sphere (`benchmarks/ccmaes/objective.py`): `-||theta + G s||^2` with
/// `G ~ N(0, 1)^(n_theta x n_s)` and contexts uniform in [1, 2)^n_s; the optimum 0 lies at
/// `theta = -G s`, which an affine policy can represent.
struct Sphere {
    g: DMatrix<f64>,
}

impl Sphere {
    fn new(n_theta: usize, n_s: usize, rng: &mut ChaCha8Rng) -> Self {
        Self {
            g: DMatrix::from_fn(n_theta, n_s, |_, _| rng.sample(StandardNormal)),
        }
    }

    fn reward(&self, theta: &[f64], s: &[f64]) -> f64 {
        let x = DVector::from_column_slice(theta) + &self.g * DVector::from_column_slice(s);
        -x.norm_squared()
    }
}

/// Trains on the sphere for `episodes`, calling `each` after every update, and returns the
/// learner and the mean greedy reward over 30 fixed test contexts.
fn train_on_sphere(
    config: CCmaesConfig,
    n_theta: usize,
    n_s: usize,
    episodes: usize,
    seed: u64,
    mut each: impl FnMut(&CCmaes, &CCmaesReport),
) -> (CCmaes, f64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let sphere = Sphere::new(n_theta, n_s, &mut rng);
    let theta0: Vec<f64> = (0..n_theta).map(|_| rng.sample(StandardNormal)).collect();
    let mut learner = CCmaes::new(config, n_s, &theta0).unwrap();
    for _ in 0..episodes {
        let s: Vec<f64> = (0..n_s).map(|_| rng.random_range(1.0..2.0)).collect();
        let theta = learner.sample(&s, &mut rng);
        if let Some(report) = learner.record(&s, &theta, sphere.reward(&theta, &s)) {
            each(&learner, &report);
        }
    }
    let mut test = ChaCha8Rng::seed_from_u64(u64::MAX);
    let tests: Vec<Vec<f64>> = (0..30)
        .map(|_| (0..n_s).map(|_| test.random_range(1.0..2.0)).collect())
        .collect();
    let score = tests.iter().map(|s| sphere.reward(&learner.greedy(s), s)).sum::<f64>() / 30.0;
    (learner, score)
}

#[test]
fn it_converges_on_the_contextual_sphere_for_every_seed() {
    for seed in 0..4 {
        let (_, score) = train_on_sphere(CCmaesConfig::default(), 10, 2, 6000, seed, |_, _| {});
        assert!(score > -1e-6, "seed {seed}: {score}");
    }
}

#[test]
fn it_is_at_least_as_good_as_bolero_on_its_sphere_benchmark() {
    // BOLeRo's C-CMA-ES on its benchmark (20 parameters, 2-D context, 50 rollouts per update,
    // 20 seeds; ../shared/notes/ccmaes.md): median -1.61 after 2,500 episodes, -5.3e-6 after
    // 10,000. Seeds 100..105 are used nowhere else.
    let config = CCmaesConfig {
        population: Some(50),
        ..CCmaesConfig::default()
    };
    let mut at_2500 = Vec::new();
    let mut at_10000 = Vec::new();
    for seed in 100..105 {
        at_2500.push(train_on_sphere(config.clone(), 20, 2, 2500, seed, |_, _| {}).1);
        at_10000.push(train_on_sphere(config.clone(), 20, 2, 10_000, seed, |_, _| {}).1);
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (early, late) = (median(&mut at_2500), median(&mut at_10000));
    assert!(early > -1.61, "median after 2,500 episodes {early} ({at_2500:?})");
    assert!(late > -5.3e-6, "median after 10,000 episodes {late} ({at_10000:?})");
}

#[test]
fn the_shape_stays_positive_definite_and_sigma_shrinks_as_it_converges() {
    let mut sigmas = Vec::new();
    let (learner, _) = train_on_sphere(CCmaesConfig::default(), 10, 2, 6000, 7, |learner, report| {
        assert_eq!(report.rejected, None);
        let eigen = SymmetricEigen::new(learner.shape().clone());
        assert!(eigen.eigenvalues.min() > 0.0, "{}", eigen.eigenvalues);
        assert!(report.condition.is_finite() && report.condition >= 1.0);
        sigmas.push(report.sigma);
    });
    assert!(sigmas.last().unwrap() < &(1e-3 * sigmas[0]), "{sigmas:?}");
    assert!(learner.policy().covariance().trace() < 1e-6);
}

#[test]
fn a_population_whose_default_rates_leave_the_old_shape_no_weight_still_learns() {
    // Hansen's c_mu is 1 - c_1 from a population of about 4 (n + 2)^2 = 784 here: C is then the
    // best half's steps alone, positive definite as they span the 10 parameters.
    let config = CCmaesConfig {
        population: Some(2000),
        ..CCmaesConfig::default()
    };
    let mut conditions = Vec::new();
    let (_, score) = train_on_sphere(config.clone(), 10, 2, 20 * 2000, 5, |learner, report| {
        let eigen = SymmetricEigen::new(learner.shape().clone());
        assert!(eigen.eigenvalues.min() > 0.0, "{}", eigen.eigenvalues);
        conditions.push(report.condition);
    });
    let (_, first) = train_on_sphere(config, 10, 2, 2000, 5, |_, _| {});
    assert!(
        score > 1e-3 * first,
        "cost {} after one generation, {} after 20",
        -first,
        -score
    );
    assert_eq!(conditions.len(), 20);
}

#[test]
fn sigma_grows_on_a_slope() {
    // A linear return: every step along -theta_0 is better, so the path lengthens and sigma
    // grows, as CMA-ES's does.
    let mut learner = CCmaes::new(CCmaesConfig::default(), 1, &[0.0; 5]).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let sigma0 = learner.sigma();
    for _ in 0..40 * learner.population() {
        let s = [rng.random_range(0.0..1.0)];
        let theta = learner.sample(&s, &mut rng);
        learner.record(&s, &theta, -theta[0]);
    }
    assert!(learner.sigma() > 10.0 * sigma0, "{} -> {}", sigma0, learner.sigma());
}

/// Runs `generations` on the sphere with returns mapped by `transform` and returns the state.
fn state_after(transform: impl Fn(f64) -> f64, generations: usize) -> CCmaesState {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let sphere = Sphere::new(6, 2, &mut rng);
    let mut learner = CCmaes::new(CCmaesConfig::default(), 2, &[0.5; 6]).unwrap();
    for _ in 0..generations * learner.population() {
        let s = [rng.random_range(1.0..2.0), rng.random_range(1.0..2.0)];
        let theta = learner.sample(&s, &mut rng);
        learner.record(&s, &theta, transform(sphere.reward(&theta, &s)));
    }
    learner.state()
}

#[test]
fn updates_are_invariant_to_a_positive_scaling_and_a_shift_of_the_returns() {
    // Only the ranks of the advantages reach the update, so the whole run is the same, bit for
    // bit, as long as rounding in the standardisation swaps no ranks.
    let plain = state_after(|r| r, 30);
    assert_eq!(state_after(|r| 1e4 * r - 3e5, 30), plain);
    assert_eq!(state_after(|r| 0.01 * r + 7.0, 30), plain);
    assert_ne!(state_after(|r| -r, 30), plain, "a negative scaling reverses the ranks");
}

#[test]
fn restore_continues_bit_for_bit_mid_generation() {
    let run = |restore_at: Option<usize>| {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let sphere = Sphere::new(4, 1, &mut rng);
        let mut learner = CCmaes::new(CCmaesConfig::default(), 1, &[0.0; 4]).unwrap();
        for episode in 0..400 {
            if Some(episode) == restore_at {
                let state = learner.state();
                learner = CCmaes::new(CCmaesConfig::default(), 1, &[0.0; 4]).unwrap();
                learner.restore(state).unwrap();
            }
            let s = [rng.random_range(1.0..2.0)];
            let theta = learner.sample(&s, &mut rng);
            learner.record(&s, &theta, sphere.reward(&theta, &s));
        }
        learner.state()
    };
    let straight = run(None);
    assert_eq!(run(Some(123)), straight);
    assert_eq!(run(Some(7 * CCmaesConfig::default().population(4, 1))), straight);
}

#[test]
fn a_state_of_other_dimensions_is_refused_by_name() {
    let state = CCmaes::new(CCmaesConfig::default(), 1, &[0.0; 4]).unwrap().state();
    let mut other = CCmaes::new(CCmaesConfig::default(), 1, &[0.0; 5]).unwrap();
    let before = other.state();
    let error = other.restore(state).unwrap_err().to_string();
    assert!(error.contains("W is 2 x 4, this learner's is 2 x 5"), "{error}");
    assert_eq!(other.state(), before);
    // The rollouts of a generation under way were recorded with a quadratic baseline (3
    // features of a 1-D context), this learner's is affine (2).
    let mut quadratic = CCmaes::new(CCmaesConfig::default(), 1, &[0.0; 4]).unwrap();
    quadratic.record(&[0.5], &[0.0; 4], 1.0);
    let affine = CCmaesConfig {
        baseline: FeatureMap::Affine,
        ..CCmaesConfig::default()
    };
    let mut other = CCmaes::new(affine, 1, &[0.0; 4]).unwrap();
    let error = other.restore(quadratic.state()).unwrap_err().to_string();
    assert!(
        error.contains(
            "a rollout's feature, baseline feature and theta lengths is 2, 3 and 4, this learner's is 2, 2 and 4"
        ),
        "{error}"
    );
}

#[test]
fn non_finite_rollouts_are_dropped_and_do_not_count_towards_a_generation() {
    let mut learner = CCmaes::new(CCmaesConfig::default(), 1, &[0.0; 3]).unwrap();
    let lambda = learner.population();
    assert!(learner.record(&[0.5], &[0.0; 3], f64::NAN).is_none());
    assert!(learner.record(&[f64::INFINITY], &[0.0; 3], 1.0).is_none());
    assert_eq!(learner.dropped(), 2);
    let reports: Vec<_> = (0..lambda)
        .filter_map(|i| learner.record(&[i as f64 / lambda as f64], &[i as f64, 0.0, 0.0], i as f64))
        .collect();
    assert_eq!(reports.len(), 1);
    assert_eq!(reports[0].samples, lambda);
}

#[test]
fn settings_out_of_range_are_refused_with_the_key_the_value_and_the_range() {
    let refused = |config: CCmaesConfig| CCmaes::new(config, 2, &[0.0; 20]).unwrap_err().to_string();
    let error = refused(CCmaesConfig {
        population: Some(5),
        ..CCmaesConfig::default()
    });
    assert!(
        error.contains("population must be >= 7") && error.contains("got 5"),
        "{error}"
    );
    let error = refused(CCmaesConfig {
        rates: Rates {
            c_mu: Some(-0.1),
            ..Rates::default()
        },
        ..CCmaesConfig::default()
    });
    assert!(
        error.contains("rates.c_mu") && error.contains("-1e-1") && error.contains("[0e0, 1e0]"),
        "{error}"
    );
    let error = refused(CCmaesConfig {
        rates: Rates {
            c_1: Some(0.5),
            c_mu: Some(0.5),
            ..Rates::default()
        },
        population: Some(40),
        ..CCmaesConfig::default()
    });
    assert!(
        error.contains(
            "c_1 + c_mu must be < 1, or 1 when the best half of a generation (mu = 20) outnumbers the 20 parameters"
        ) && error.contains("got 0.5 + 0.5"),
        "{error}"
    );
    let error = refused(CCmaesConfig {
        rates: Rates {
            c_1: Some(0.5),
            c_mu: Some(0.6),
            ..Rates::default()
        },
        population: Some(1000),
        ..CCmaesConfig::default()
    });
    assert!(error.contains("got 0.5 + 0.6"), "{error}");
    let error = refused(CCmaesConfig {
        initial_sigma: 0.0,
        ..CCmaesConfig::default()
    });
    assert!(error.contains("initial_sigma must be finite and > 0, got 0"), "{error}");
    let error = refused(CCmaesConfig {
        rates: Rates {
            d_sigma: Some(f64::INFINITY),
            ..Rates::default()
        },
        ..CCmaesConfig::default()
    });
    assert!(error.contains("rates.d_sigma"), "{error}");
    // The smallest population that works is accepted.
    assert!(
        CCmaes::new(
            CCmaesConfig {
                population: Some(7),
                ..CCmaesConfig::default()
            },
            2,
            &[0.0; 20]
        )
        .is_ok()
    );
}

#[test]
fn the_default_population_is_the_originals() {
    let config = CCmaesConfig::default();
    // 4 + floor(3 ln(n_theta + n_s)) (1 + 2 n_s) for the original's affine features ...
    assert_eq!(config.population(10, 2), 4 + 7 * 5);
    assert_eq!(config.population(20, 1), 4 + 9 * 3);
    // ... and 2 n_phi - 1 in its place for others: 10 quadratic features of a 3-D context.
    let quadratic = CCmaesConfig {
        features: FeatureMap::Quadratic,
        ..CCmaesConfig::default()
    };
    assert_eq!(quadratic.population(10, 3), 4 + 7 * 19);
    let learner = CCmaes::new(config, 2, &[0.0; 10]).unwrap();
    assert_eq!(learner.population(), 39);
    let mu_eff = learner.strategy.mu_eff;
    assert!(mu_eff > 1.0 && mu_eff < 19.0, "{mu_eff}");
    assert!((learner.strategy.weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
}

#[test]
fn the_policy_snapshot_describes_the_learned_policy() {
    let (learner, _) = train_on_sphere(CCmaesConfig::default(), 4, 1, 500, 2, |_, _| {});
    let snapshot = learner.snapshot().unwrap();
    assert_eq!((snapshot.features.as_str(), snapshot.context_dim), ("affine", 1));
    let restored = snapshot.restore(4).unwrap();
    assert_eq!(restored.greedy(&[1.5]), learner.greedy(&[1.5]));
    let custom = CCmaesConfig {
        features: FeatureMap::Quadratic,
        ..CCmaesConfig::default()
    };
    assert_eq!(
        CCmaes::new(custom, 1, &[0.0; 4]).unwrap().snapshot().unwrap().features,
        "quadratic"
    );
}

#[test]
fn a_generation_in_one_context_keeps_what_it_cannot_see_of_the_others() {
    // theta = 2 s is learned over s in [0, 1]; then a whole generation practises s = 0.2 only.
    // Its rollouts determine the mean at 0.2 alone: the policy elsewhere must stay what it was,
    // not be pulled towards 0 where the generation says nothing.
    let mut learner = CCmaes::new(CCmaesConfig::default(), 1, &[0.0, 0.0]).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let reward = |theta: &[f64], s: f64| -(theta[0] - 2.0 * s).powi(2) - (theta[1] + s).powi(2);
    for _ in 0..200 * learner.population() {
        let s = rng.random_range(0.0..1.0);
        let theta = learner.sample(&[s], &mut rng);
        learner.record(&[s], &theta, reward(&theta, s));
    }
    let before = learner.greedy(&[0.9]);
    assert!(
        (before[0] - 1.8).abs() < 1e-3 && (before[1] + 0.9).abs() < 1e-3,
        "{before:?}"
    );
    for _ in 0..learner.population() {
        let theta = learner.sample(&[0.2], &mut rng);
        learner.record(&[0.2], &theta, reward(&theta, 0.2));
    }
    let after = learner.greedy(&[0.9]);
    assert!(
        (after[0] - 1.8).abs() < 1e-2 && (after[1] + 0.9).abs() < 1e-2,
        "{before:?} -> {after:?}"
    );
}

/// What a forged state says is wrong, and how it was forged.
type Forgery = (&'static str, fn(&mut CCmaesState));

#[test]
fn a_state_holding_what_no_learner_saves_is_refused_by_name() {
    let mut rng = ChaCha8Rng::seed_from_u64(6);
    let sphere = Sphere::new(4, 1, &mut rng);
    let mut learner = CCmaes::new(CCmaesConfig::default(), 1, &[0.0; 4]).unwrap();
    for _ in 0..40 {
        let s = [rng.random_range(1.0..2.0)];
        let theta = learner.sample(&s, &mut rng);
        learner.record(&s, &theta, sphere.reward(&theta, &s));
    }
    let saved = learner.state();
    // Each forgery is what a checkpoint with its checksum recomputed could carry.
    let forgeries: [Forgery; 6] = [
        ("sigma", |s| s.sigma = f64::NAN),
        ("sigma", |s| s.sigma = -1.0),
        ("an evolution path", |s| s.p_c[0] = f64::INFINITY),
        ("a rollout of the generation", |s| s.rollouts[0].reward = f64::NAN),
        ("C", |s| s.shape[(1, 1)] = f64::NAN),
        ("the covariance and its sampling factor", |s| s.shape[(1, 1)] = 1e300),
    ];
    for (what, forge) in forgeries {
        let mut state = saved.clone();
        forge(&mut state);
        let mut fresh = CCmaes::new(CCmaesConfig::default(), 1, &[0.0; 4]).unwrap();
        let before = fresh.state();
        let error = fresh.restore(state).unwrap_err().to_string();
        assert_eq!(
            error,
            format!(
                "C-CMA-ES state: {what} holds values no learner could have saved (not finite, out of range, or not consistent)"
            )
        );
        assert_eq!(fresh.state(), before, "{what}");
    }
    let mut fresh = CCmaes::new(CCmaesConfig::default(), 1, &[0.0; 4]).unwrap();
    fresh.restore(saved.clone()).unwrap();
    assert_eq!(fresh.state(), saved);
}
