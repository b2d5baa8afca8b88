//! Cost of the learner's hot operations: one C-REPS update at the PA-10 scale (N = 300 samples,
//! 21 parameters, 6 polar-quadratic features, epsilon 0.5) and at the Section 5.1 scale (N = 50,
//! 20 parameters, 6 quadratic features, epsilon 2), and one D-UCB step over K = 81 arms. The
//! learner must stay far below the time of the rollouts it serves.
//!
//! Before measuring, the Newton steps per update of 200 seeded data sets of each scale are
//! printed.

use acps_learner::creps::{CReps, CRepsConfig, DEFAULT_ETA_MIN, FeatureMap, MemoryConfig};
use acps_learner::selection::{BanditSelector, Choice, ContextSelector, DUcbConfig, FirstVisit, IntrinsicReward};
use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;

/// A C-REPS learner whose memory holds all but one rollout of an update, and that rollout: the
/// next `record` runs an update.
type BeforeUpdate = (CReps, Vec<f64>, Vec<f64>, f64);

/// The PA-10 scale: targets in [-5, -3]^2, rewards `-||theta_0..2 - s||^2`.
fn throwing_before_update(rng: &mut ChaCha8Rng) -> BeforeUpdate {
    const SAMPLES: usize = 300;
    let config = CRepsConfig {
        epsilon: 0.5,
        eta_min: DEFAULT_ETA_MIN,
        ridge: 1e-4,
        update_every: SAMPLES,
        memory: MemoryConfig::SlidingWindow { capacity: SAMPLES },
        features: FeatureMap::PolarQuadratic,
        initial_sigma: 0.02,
    };
    let creps = CReps::new(config, 2, &[0.0; 21], 25).unwrap();
    fill(
        creps,
        SAMPLES,
        rng,
        |rng| vec![rng.random_range(-5.0..-3.0), rng.random_range(-5.0..-3.0)],
        |s, theta| -theta.iter().zip(s).map(|(t, s)| (t - s).powi(2)).sum::<f64>(),
    )
}

/// The Section 5.1 scale: grid contexts in [-1, 1]^2, the contextual function
/// `-||A theta - s|| ||s||^2 + sum s` with A uniform in [0, 1]^(2 x 20), Sigma_0 = I.
fn function_before_update(rng: &mut ChaCha8Rng) -> BeforeUpdate {
    const SAMPLES: usize = 50;
    let config = CRepsConfig {
        epsilon: 2.0,
        eta_min: DEFAULT_ETA_MIN,
        ridge: 1e-4,
        update_every: SAMPLES,
        memory: MemoryConfig::SlidingWindow { capacity: SAMPLES },
        features: FeatureMap::Quadratic,
        initial_sigma: 1.0,
    };
    let creps = CReps::new(config, 2, &[0.0; 20], 25).unwrap();
    let a: Vec<f64> = (0..40).map(|_| rng.random_range(0.0..1.0)).collect();
    let grid = [-1.0, -0.5, 0.0, 0.5, 1.0];
    fill(
        creps,
        SAMPLES,
        rng,
        |rng| vec![grid[rng.random_range(0..5)], grid[rng.random_range(0..5)]],
        move |s, theta| {
            let row = |r: usize| {
                a[20 * r..20 * r + 20]
                    .iter()
                    .zip(theta)
                    .map(|(a, t)| a * t)
                    .sum::<f64>()
            };
            let miss = (row(0) - s[0]).hypot(row(1) - s[1]);
            -miss * (s[0] * s[0] + s[1] * s[1]) + s[0] + s[1]
        },
    )
}

/// Records `samples - 1` rollouts of the initial policy and draws the last one.
fn fill(
    mut creps: CReps,
    samples: usize,
    rng: &mut ChaCha8Rng,
    context: impl Fn(&mut ChaCha8Rng) -> Vec<f64>,
    reward: impl Fn(&[f64], &[f64]) -> f64,
) -> BeforeUpdate {
    let draw = |creps: &CReps, rng: &mut ChaCha8Rng| {
        let s = context(rng);
        let theta = creps.sample(&s, rng);
        let r = reward(&s, &theta);
        (s, theta, r)
    };
    for _ in 0..samples - 1 {
        let (s, theta, r) = draw(&creps, rng);
        assert!(creps.record(0, &s, &theta, r).is_none());
    }
    let (s, theta, r) = draw(&creps, rng);
    (creps, s, theta, r)
}

type Scale = (&'static str, fn(&mut ChaCha8Rng) -> BeforeUpdate);

const SCALES: [Scale; 2] = [
    ("creps_update_n300_theta21_phi6", throwing_before_update),
    ("creps_update_n50_theta20_phi6", function_before_update),
];

fn creps_update(c: &mut Criterion) {
    for (name, before_update) in SCALES {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut steps: Vec<usize> = (0..200)
            .map(|_| {
                let (mut creps, s, theta, r) = before_update(&mut rng);
                creps.record(0, &s, &theta, r).unwrap().iterations
            })
            .collect();
        steps.sort_unstable();
        eprintln!(
            "{name}: Newton steps per update over 200 data sets: median {}, 90th percentile {}, max {}",
            steps[100], steps[180], steps[199]
        );
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        c.bench_function(name, |b| {
            b.iter_batched(
                || before_update(&mut rng),
                |(mut creps, s, theta, r)| black_box(creps.record(0, &s, &theta, r)),
                BatchSize::SmallInput,
            )
        });
    }
}

fn ducb_step(c: &mut Criterion) {
    let contexts: Vec<Vec<f64>> = (0..81).map(|i| vec![i as f64]).collect();
    let ducb = DUcbConfig {
        gamma: 0.99,
        xi: 1e-9,
        b: 10_000.0,
    };
    let mut selector = BanditSelector::new(
        contexts,
        ducb,
        IntrinsicReward::MonotonicProgress,
        FirstVisit::InitialReturn,
    )
    .unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let mut reward_rng = ChaCha8Rng::seed_from_u64(1);
    c.bench_function("ducb_step_k81_choose_and_observe", |b| {
        b.iter(|| {
            let choice: Choice = selector.choose(&mut rng);
            selector.observe(&choice, -reward_rng.random::<f64>() * 1e4);
            black_box(choice.arm)
        })
    });
}

criterion_group!(benches, creps_update, ducb_step);
criterion_main!(benches);
