//! Cost of the learner's two hot operations at the PA-10 scale: one C-REPS update (N = 300
//! samples, 21 parameters, 6 polar-quadratic features) and one D-UCB step over K = 81 arms.
//! The learner must stay far below the time of the rollouts it serves.

use acps_learner::creps::{CReps, CRepsConfig, DEFAULT_ETA_MIN, FeatureMap, MemoryConfig};
use acps_learner::selection::{BanditSelector, Choice, ContextSelector, DUcbConfig, FirstVisit, IntrinsicReward};
use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;

const N_THETA: usize = 21;
const SAMPLES: usize = 300;

/// A C-REPS learner whose memory holds 299 samples of a throwing-like problem, so the next
/// `record` runs an update on 300.
fn creps_before_update(rng: &mut ChaCha8Rng) -> (CReps, Vec<f64>, Vec<f64>, f64) {
    let config = CRepsConfig {
        epsilon: 0.5,
        eta_min: DEFAULT_ETA_MIN,
        ridge: 1e-4,
        update_every: SAMPLES,
        memory: MemoryConfig::SlidingWindow { capacity: SAMPLES },
        features: FeatureMap::PolarQuadratic,
        initial_sigma: 0.02,
    };
    let mut creps = CReps::new(config, 2, &[0.0; N_THETA], 25).unwrap();
    let sample = |creps: &CReps, rng: &mut ChaCha8Rng| {
        let context = vec![rng.random_range(-5.0..-3.0), rng.random_range(-5.0..-3.0)];
        let theta = creps.sample(&context, rng);
        let reward = -theta.iter().zip(&context).map(|(t, s)| (t - s).powi(2)).sum::<f64>();
        (context, theta, reward)
    };
    for _ in 0..SAMPLES - 1 {
        let (context, theta, reward) = sample(&creps, rng);
        assert!(creps.record(0, &context, &theta, reward).is_none());
    }
    let (context, theta, reward) = sample(&creps, rng);
    (creps, context, theta, reward)
}

fn creps_update(c: &mut Criterion) {
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    c.bench_function("creps_update_n300_theta21_phi6", |b| {
        b.iter_batched(
            || creps_before_update(&mut rng),
            |(mut creps, context, theta, reward)| black_box(creps.record(0, &context, &theta, reward)),
            BatchSize::SmallInput,
        )
    });
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
