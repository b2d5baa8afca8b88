//! Cost of one PA-10 throw, from the learner's 21 offsets to the landing point, single thread:
//! the analytic backend (two DMP rollouts, forward kinematics and Jacobian at release,
//! closed-form flight) and the rapier3d multibody arm tracking the same trajectory.

use acps_models::environment::{self, Sim};
use acps_models::robot::Robot;
use acps_models::throw::{PARAMS, Simulator, SpeedLimits, Targets, ThrowDesign, ThrowPolicy, ThrowingEnvironment};
use acps_shared::{Environment, Task, TaskKind};
use criterion::{Criterion, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use std::hint::black_box;

/// Tasks near theta_0, like the learner's exploration (std 0.14 = sqrt(0.02)).
fn tasks() -> Vec<Task> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    (0..64)
        .map(|id| Task {
            id,
            kind: TaskKind::Train,
            seed: id,
            context: vec![-4.0, -4.0],
            theta: (0..PARAMS).map(|_| rng.random_range(-0.2..0.2)).collect(),
        })
        .collect()
}

fn analytic(c: &mut Criterion) {
    let tasks = tasks();
    // 0.5 s: only the end points, as `acps experiment` samples for the analytic backend.
    for control_dt in [0.5, 0.01] {
        let policy = ThrowPolicy::new(ThrowDesign::pa10(), control_dt).unwrap();
        let mut env = ThrowingEnvironment::new(
            Robot::pa10(),
            policy,
            Simulator::Analytic,
            Targets::Grid,
            SpeedLimits::Ignore,
        );
        let mut i = 0;
        c.bench_function(&format!("throw_analytic_control_dt_{}ms", control_dt * 1000.0), |b| {
            b.iter(|| {
                i = (i + 1) % tasks.len();
                black_box(env.rollout(&tasks[i]))
            })
        });
    }
}

fn rapier(c: &mut Criterion) {
    let tasks = tasks();
    // The rapier environment exactly as the experiments and the workers build it.
    let mut env = environment::grid(Sim::Rapier).unwrap();
    let mut i = 0;
    c.bench_function("throw_rapier_default", |b| {
        b.iter(|| {
            i = (i + 1) % tasks.len();
            black_box(env.rollout(&tasks[i]))
        })
    });
}

criterion_group!(benches, analytic, rapier);
criterion_main!(benches);
