//! Cost of the learner's hot operations: one C-REPS update at the PA-10 scale (N = 300 samples,
//! 21 parameters, 6 polar-quadratic features, epsilon 0.5) and at the Section 5.1 scale (N = 50,
//! 20 parameters, 6 quadratic features, epsilon 2), and one step (choose and observe) of the
//! context selectors: D-UCB over K = 81 arms, with and without retirement, absolute progress over
//! K = 81, and ALP-GMM between its refits, with a refit measured on its own; self-paced's step, and
//! its update (the joint dual and both bounded fits) beside plain C-REPS' at the PA-10 scale. The
//! learner must stay far below the time of the rollouts it serves.
//!
//! One C-CMA-ES generation at the PA-10 scale, beside the C-REPS update.
//!
//! The learner's own cost per rollout (ask, tell, the C-REPS updates, no simulation), as in
//! `acps bench --env trivial`'s in-process rows, guards the transport's figures against
//! regressions of the core: 2000 trivial rollouts with P = 1 and P = 64, and with C-CMA-ES at P = 64.
//! The bowl problem's learner driven in batches of 1,024 is the Rust side of
//! `python/benches/ask_tell.py`: the difference is the Python boundary's cost per task.
//!
//! Before measuring, the Newton steps per update of 200 seeded data sets of each scale are
//! printed.

use acps_experiments::file::LoadedFile;
use acps_experiments::plan::Plan;
use acps_experiments::settings::ExperimentFile;
use acps_learner::ccmaes::{CCmaes, CCmaesConfig};
use acps_learner::creps::{CReps, CRepsConfig, DEFAULT_ETA_MIN, FeatureMap, MemoryConfig};
use acps_learner::selection::{
    AbsoluteProgress, AbsoluteProgressConfig, AlpGmm, AlpGmmConfig, BanditSelector, Choice, ContextSelector,
    DUcbConfig, FirstVisit, IntrinsicReward, RetireConfig, RoundRobin, SelfPaced, SelfPacedConfig,
};
use acps_learner::{Learner, LearnerConfig, SearchConfig, run_in_process};
use acps_models::environment::TrivialEnvironment;
use acps_shared::{ContextSpace, Outcome, Task};
use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;
use std::time::{Duration, Instant};

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

/// One choose and one observe of `selector`, the return drawn by `reward` from the choice.
fn step(
    selector: &mut dyn ContextSelector,
    rng: &mut ChaCha8Rng,
    reward_rng: &mut ChaCha8Rng,
    reward: &impl Fn(&Choice, &mut ChaCha8Rng) -> f64,
) -> Choice {
    let choice = selector.choose(rng);
    let r = reward(&choice, reward_rng);
    selector.observe(&choice, r);
    choice
}

/// The return of a choice, drawn with the given stream.
type Reward = fn(&Choice, &mut ChaCha8Rng) -> f64;

/// K = 81 arms whose returns have levels 100 apart and noise of 10, as on the dartboard (the
/// paper's largest K) with returns of a few thousand.
fn arm_levels(choice: &Choice, rng: &mut ChaCha8Rng) -> f64 {
    -100.0 * choice.arm.unwrap_or(0) as f64 - 10.0 * rng.random::<f64>()
}

fn selector_steps(c: &mut Criterion) {
    let contexts: Vec<Vec<f64>> = (0..81).map(|i| vec![i as f64]).collect();
    let ducb = DUcbConfig {
        gamma: 0.99,
        xi: 1e-9,
        b: 10_000.0,
    };
    let bandit = || {
        BanditSelector::new(
            contexts.clone(),
            ducb.clone(),
            IntrinsicReward::MonotonicProgress,
            FirstVisit::InitialReturn,
        )
        .unwrap()
    };
    let noise: Reward = |_, rng| -rng.random::<f64>() * 1e4;
    let retiring = bandit().with_retirement(RetireConfig::default()).unwrap();
    let progress = AbsoluteProgress::new(contexts.clone(), AbsoluteProgressConfig::default()).unwrap();
    let mut cases: [(&str, Box<dyn ContextSelector>, Reward); 3] = [
        ("ducb_step_k81_choose_and_observe", Box::new(bandit()), noise),
        (
            "ducb_retire_step_k81_choose_and_observe",
            Box::new(retiring),
            arm_levels,
        ),
        (
            "absolute_progress_step_k81_choose_and_observe",
            Box::new(progress),
            arm_levels,
        ),
    ];
    for (name, selector, reward) in &mut cases {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut reward_rng = ChaCha8Rng::seed_from_u64(1);
        // Past the initial sweep, with averages settled and (with retirement) contexts retired.
        for _ in 0..2000 {
            step(selector.as_mut(), &mut rng, &mut reward_rng, reward);
        }
        c.bench_function(name, |b| {
            b.iter(|| black_box(step(selector.as_mut(), &mut rng, &mut reward_rng, reward).arm))
        });
    }
}

/// ALP-GMM over the grid's target box [-5, -3]^2 with the original's parameters, after
/// `observations` steps on a return that changes with the context and over time.
fn alp_gmm_after(observations: usize) -> (AlpGmm, ChaCha8Rng, ChaCha8Rng) {
    let space = ContextSpace::new_box(vec![-5.0, -5.0], vec![-3.0, -3.0]).unwrap();
    let mut selector = AlpGmm::new(space, None, AlpGmmConfig::default()).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let mut reward_rng = ChaCha8Rng::seed_from_u64(1);
    for _ in 0..observations {
        let t = selector.observations();
        step(&mut selector, &mut rng, &mut reward_rng, &grid_return(t));
    }
    (selector, rng, reward_rng)
}

/// A return that improves over `t` observations, fastest in one corner of the box.
fn grid_return(t: u64) -> impl Fn(&Choice, &mut ChaCha8Rng) -> f64 {
    move |choice, rng| {
        let (x, y) = (choice.context[0] + 4.0, choice.context[1] + 4.0);
        let rate = 1e-3 * (1.0 + (3.0 * x).cos() * (2.0 * y).sin());
        -(x * x + y * y) * (-rate * t as f64).exp() - 0.01 * rng.random::<f64>()
    }
}

fn alp_gmm(c: &mut Criterion) {
    const HISTORY: usize = 10_000;
    let fit_rate = AlpGmmConfig::default().fit_rate;
    // 10,000 observations (the grid's length) make a fit due: one choice makes it.
    let (due, rng, reward_rng) = alp_gmm_after(HISTORY);
    c.bench_function("alp_gmm_refit_fit_rate250_k2to10", |b| {
        b.iter_batched(
            || (due.clone(), rng.clone()),
            |(mut selector, mut rng)| black_box(selector.choose(&mut rng)),
            BatchSize::SmallInput,
        )
    });
    let (mut fitted, mut rng, mut reward_rng) = (due, rng, reward_rng);
    step(&mut fitted, &mut rng, &mut reward_rng, &grid_return(HISTORY as u64));
    assert!(fitted.mixture().is_some());
    // Steps between two fits: start again from the fitted state before the next one falls due.
    c.bench_function("alp_gmm_step_history10000_choose_and_observe", |b| {
        b.iter_custom(|iterations| {
            let mut elapsed = Duration::ZERO;
            let mut done = 0;
            while done < iterations {
                let mut selector = fitted.clone();
                let steps = (iterations - done).min(fit_rate as u64 - 2);
                let reward = grid_return(HISTORY as u64);
                let start = Instant::now();
                for _ in 0..steps {
                    black_box(step(&mut selector, &mut rng, &mut reward_rng, &reward));
                }
                elapsed += start.elapsed();
                done += steps;
            }
            elapsed
        })
    });
}

/// One C-CMA-ES generation at the PA-10 scale (21 parameters, polar-quadratic features of 2-D
/// targets in [-5, -3]^2, the default population 4 + floor(3 ln 23) (2 * 6 - 1) = 103), beside
/// `creps_update_n300_theta21_phi6`: C-REPS updates every 50 rollouts on 300, C-CMA-ES every 103
/// on those 103.
fn ccmaes_update(c: &mut Criterion) {
    let config = CCmaesConfig {
        features: FeatureMap::PolarQuadratic,
        initial_sigma: 0.02,
        ..CCmaesConfig::default()
    };
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let before_update = |rng: &mut ChaCha8Rng| {
        let mut learner = CCmaes::new(config.clone(), 2, &[0.0; 21]).unwrap();
        let lambda = learner.population();
        let mut draw = |learner: &CCmaes| {
            let s = vec![rng.random_range(-5.0..-3.0), rng.random_range(-5.0..-3.0)];
            let theta = learner.sample(&s, rng);
            let r = -theta.iter().zip(&s).map(|(t, s)| (t - s).powi(2)).sum::<f64>();
            (s, theta, r)
        };
        for _ in 0..lambda - 1 {
            let (s, theta, r) = draw(&learner);
            assert!(learner.record(&s, &theta, r).is_none());
        }
        let last = draw(&learner);
        (learner, last)
    };
    c.bench_function("ccmaes_update_n103_theta21_phi6", |b| {
        b.iter_batched(
            || before_update(&mut rng),
            |(mut learner, (s, theta, r))| black_box(learner.record(&s, &theta, r)),
            BatchSize::SmallInput,
        )
    });
}

/// Self-paced over the grid's target box, pulled towards its target from the first update: one
/// PA-10-scale update that moves it with the policy (compare `creps_update_n300_theta21_phi6`),
/// and one step between updates.
fn self_paced(c: &mut Criterion) {
    let space = ContextSpace::new_box(vec![-5.0, -5.0], vec![-3.0, -3.0]).unwrap();
    let config = SelfPacedConfig {
        offset: 0,
        ..SelfPacedConfig::default()
    };
    let pacer = SelfPaced::new(space, config).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    c.bench_function("creps_update_paced_n300_theta21_phi6", |b| {
        b.iter_batched(
            || (throwing_before_update(&mut rng), pacer.clone()),
            |((mut creps, s, theta, r), mut pacer)| black_box(creps.record_paced(0, &s, &theta, r, Some(&mut pacer))),
            BatchSize::SmallInput,
        )
    });
    let mut selector = pacer;
    let mut reward_rng = ChaCha8Rng::seed_from_u64(1);
    c.bench_function("self_paced_step_choose_and_observe", |b| {
        b.iter(|| black_box(step(&mut selector, &mut rng, &mut reward_rng, &grid_return(0)).arm))
    });
}

/// A learner of `acps bench`'s trivial problem (one context, one parameter, no evaluation) for
/// 2000 episodes with P = `in_flight` and `search`.
fn trivial_learner(in_flight: usize, search: SearchConfig) -> Learner {
    let problem = TrivialEnvironment::new().problem(Vec::new());
    let config = LearnerConfig {
        episodes: 2000,
        in_flight,
        eval_every: u64::MAX,
        search: Some(search),
        ..Default::default()
    };
    let selector = Box::new(RoundRobin::all(problem.training_contexts.clone()).unwrap());
    Learner::new(config, problem, selector).unwrap()
}

/// The learner's cost per rollout: C-REPS as `acps bench` runs it (an update every 1000
/// rollouts on a window of 1000) at P = 1 and 64, and C-CMA-ES at its defaults (a generation
/// of 10 here) at P = 64.
fn learner_rollouts(c: &mut Criterion) {
    let creps = || SearchConfig::CReps(CRepsConfig::batches(1.0, 1000));
    let ccmaes = || SearchConfig::CCmaes(CCmaesConfig::default());
    let cases: [(&str, usize, &dyn Fn() -> SearchConfig); 3] = [
        ("learner_2000_trivial_rollouts_p1", 1, &creps),
        ("learner_2000_trivial_rollouts_p64", 64, &creps),
        ("learner_2000_trivial_rollouts_p64_ccmaes", 64, &ccmaes),
    ];
    for (name, in_flight, search) in cases {
        c.bench_function(name, |b| {
            b.iter_batched(
                || (trivial_learner(in_flight, search()), TrivialEnvironment::new()),
                |(mut learner, mut environment)| {
                    run_in_process(&mut learner, &mut environment).unwrap();
                    black_box(learner.stats().updates)
                },
                BatchSize::SmallInput,
            )
        });
    }
}

/// The learner of `experiments/bowl.toml`'s random method with a window of `in_flight` (as
/// `python/benches/ask_tell.py` builds it from Python), for `episodes` episodes.
fn bowl_learner(in_flight: usize, episodes: u64) -> Learner {
    let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../experiments/bowl.toml");
    let file = LoadedFile::read(&file).unwrap();
    let request = ExperimentFile {
        methods: Some(vec![acps_learner::Method::Random]),
        runs: Some(1),
        episodes: Some(episodes),
        in_flight: Some(in_flight),
        ..Default::default()
    };
    let plan = Plan::new(Some(&file), &request).unwrap();
    let experiment = plan.jobs(std::path::Path::new("")).remove(0).experiment;
    experiment
        .job(&experiment.methods[0], experiment.base_seed)
        .unwrap()
        .learner
}

/// The bowl's arithmetic (`processes/worker/examples/bowl.rs`).
fn bowl(task: &Task) -> Outcome {
    let (d, n) = (task.context.len(), task.theta.len());
    let total: f64 = task
        .theta
        .iter()
        .enumerate()
        .map(|(i, t)| (t - task.context[i % d] * (i + 1) as f64 / n as f64).powi(2))
        .sum();
    Outcome::new(task.id, -total, total.sqrt())
}

/// The Rust side of `python/benches/ask_tell.py`: the bowl learner with a window of 1,024
/// driven in Rust, ask every ready task then tell them all. Its time per task is what the
/// Python ask/tell costs without the Python boundary.
fn bowl_ask_tell(c: &mut Criterion) {
    let mut group = c.benchmark_group("bowl_ask_tell");
    group.sample_size(10);
    group.bench_function("bowl_20000_episodes_batches_of_1024", |b| {
        b.iter_batched(
            || bowl_learner(1024, 20_000),
            |mut learner| {
                let mut tasks = Vec::with_capacity(1024);
                while !learner.is_done() {
                    tasks.extend(std::iter::from_fn(|| learner.ask()));
                    for task in tasks.drain(..) {
                        learner.tell(bowl(&task)).unwrap();
                    }
                }
                black_box(learner.stats().updates)
            },
            BatchSize::LargeInput,
        )
    });
    group.finish();
}

criterion_group!(
    benches,
    creps_update,
    ccmaes_update,
    selector_steps,
    alp_gmm,
    self_paced,
    learner_rollouts,
    bowl_ask_tell
);
criterion_main!(benches);
