//! `acps bench`: rollouts per second of three environments, measured in one run side by side:
//! in-process on one thread, in-process on all cores (rayon), and through a fleet of W worker
//! processes for W = 1 ..= cores. The trivial environment costs nothing, so its fleet rows
//! measure the transport; the analytic and rapier PA-10 throws show how close the fleet comes
//! to W times one thread (the ratio).

use crate::paper::{self, Options, Sim};
use crate::workers;
use acps_learner::creps::{CRepsConfig, FeatureMap, MemoryConfig};
use acps_learner::fleet::{self, FleetJob};
use acps_learner::selection::RoundRobin;
use acps_learner::{Learner, LearnerConfig, Method, run_in_process};
use acps_models::environment::{self, TrivialEnvironment};
use acps_shared::ipc::{self, RunName};
use acps_shared::{ContextSpace, Environment, Problem, ScoreAggregate};
use anyhow::Context;
use rayon::prelude::*;
use serde::Serialize;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

/// One measurement.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// trivial, analytic or rapier.
    pub env: &'static str,
    /// inprocess-1, inprocess-rayon or fleet.
    pub mode: &'static str,
    /// Worker processes (fleet), threads (rayon) or 1.
    pub workers: usize,
    /// Rollouts (training and evaluation) per second of wall time; a fleet's from its first
    /// request on.
    pub rollouts_per_s: f64,
    /// rollouts_per_s / (workers x the single-thread rate).
    pub ratio: f64,
    /// Share of the fleet's serving time spent inside the learner cores.
    pub learner_share: Option<f64>,
    /// Fleet only: seconds from starting the worker processes to the first worker's first
    /// request, which the rate leaves out (in-process rows build their environments before
    /// the clock starts, too).
    pub startup_seconds: Option<f64>,
    /// Rollouts performed.
    pub rollouts: u64,
    /// Wall time in seconds (a fleet's from its first request on).
    pub seconds: f64,
}

/// What a fleet row measures beyond the rate.
#[derive(Clone, Copy)]
struct Fleet {
    learner_seconds: f64,
    startup_seconds: f64,
}

/// An environment the bench measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BenchEnv {
    /// Rollouts that cost nothing: the rows measure the transport.
    Trivial,
    /// The analytic PA-10 throw (tens of microseconds).
    Analytic,
    /// The rapier3d PA-10 throw (milliseconds).
    Rapier,
}

/// What to measure.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    /// Environments to measure, in this order.
    pub envs: Vec<BenchEnv>,
    /// Largest fleet.
    pub max_workers: usize,
    /// Tasks each worker keeps in flight.
    pub worker_in_flight: usize,
    /// Niceness of the workers (default: [`workers::default_nice`]).
    pub worker_nice: Option<u8>,
    /// Multiplies the amount of work per row (1 = a few seconds per row).
    pub scale: f64,
}

#[derive(Clone, Copy)]
enum Workload {
    Trivial,
    Throw(Sim),
}

impl Workload {
    fn name(self) -> &'static str {
        match self {
            Workload::Trivial => "trivial",
            Workload::Throw(sim) => paper::sim_name(sim),
        }
    }
}

/// Learners kept busy at once: many jobs with a wide window keep every worker fed. 8 x 32 tasks
/// leave ready ones in the learner while two workers hold 64 each (the default
/// `--worker-in-flight`), enough for batches of 32 analytic throws.
const JOBS: usize = 8;
const IN_FLIGHT: usize = 32;

struct Job {
    learner: Learner,
    spec: acps_shared::wire::EnvironmentSpec,
    environment: Box<dyn Environment>,
}

fn jobs(workload: Workload, scale: f64) -> anyhow::Result<Vec<Job>> {
    let episodes = |base: f64| ((base * scale).round() as u64).max(1);
    match workload {
        Workload::Trivial => (0..JOBS)
            .map(|seed| {
                // One context, one parameter, no evaluation: the learner's cost stays small so
                // that the fleet rows measure the transport.
                let problem = Problem {
                    name: "trivial".into(),
                    training_contexts: vec![vec![0.0]],
                    test_contexts: Vec::new(),
                    space: ContextSpace::new_box(vec![-1.0], vec![1.0]).expect("a valid box"),
                    theta0: vec![1.0],
                    score: ScoreAggregate::Mean,
                    metric: "none".into(),
                };
                let creps = CRepsConfig {
                    epsilon: 1.0,
                    eta_min: 1e-8,
                    ridge: 1e-4,
                    update_every: 1000,
                    memory: MemoryConfig::SlidingWindow { capacity: 1000 },
                    features: FeatureMap::Affine,
                    initial_sigma: 1.0,
                };
                let config = LearnerConfig {
                    seed: seed as u64,
                    episodes: episodes(60_000.0),
                    in_flight: IN_FLIGHT,
                    eval_every: u64::MAX,
                    creps: Some(creps),
                };
                let selector = Box::new(RoundRobin::all(problem.training_contexts.clone())?);
                Ok(Job {
                    learner: Learner::new(config, problem, selector)?,
                    spec: environment::trivial(),
                    environment: Box::new(TrivialEnvironment),
                })
            })
            .collect(),
        Workload::Throw(sim) => {
            let base = if sim == Sim::Rapier { 250.0 } else { 6000.0 };
            let options = Options {
                runs: JOBS,
                episodes: Some(episodes(base)),
                in_flight: IN_FLIGHT,
                methods: Some(vec![Method::MonotonicProgress]),
                ..Options::default()
            };
            paper::grid(sim, &options)
                .jobs()?
                .into_iter()
                .map(|job| {
                    Ok(Job {
                        spec: job.spec.context("grid jobs have specs")?,
                        learner: job.learner,
                        environment: job.environment,
                    })
                })
                .collect()
        }
    }
}

/// Outcomes a finished learner consumed.
fn consumed(learner: &Learner) -> u64 {
    let evaluations: usize = learner.evaluations().iter().map(|e| e.outcomes.len()).sum();
    learner.episodes().len() as u64 + evaluations as u64
}

/// Measure every row; `report` sees each row as it is measured.
pub fn run(options: &BenchOptions, mut report: impl FnMut(&Row)) -> anyhow::Result<Vec<Row>> {
    let mut rows = Vec::new();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    for workload in options.envs.iter().map(|env| match env {
        BenchEnv::Trivial => Workload::Trivial,
        BenchEnv::Analytic => Workload::Throw(Sim::Analytic),
        BenchEnv::Rapier => Workload::Throw(Sim::Rapier),
    }) {
        let mut measure =
            |mode: &'static str, workers: usize, rollouts: u64, seconds: f64, fleet: Option<Fleet>, single: f64| {
                let rate = rollouts as f64 / seconds;
                let row = Row {
                    env: workload.name(),
                    mode,
                    workers,
                    rollouts_per_s: rate,
                    ratio: if single > 0.0 {
                        rate / (workers as f64 * single)
                    } else {
                        1.0
                    },
                    learner_share: fleet.map(|f| f.learner_seconds / seconds),
                    startup_seconds: fleet.map(|f| f.startup_seconds),
                    rollouts,
                    seconds,
                };
                report(&row);
                rows.push(row);
                rate
            };
        let mut single_jobs = jobs(workload, options.scale)?;
        let start = Instant::now();
        for job in &mut single_jobs {
            run_in_process(&mut job.learner, job.environment.as_mut());
        }
        let total: u64 = single_jobs.iter().map(|j| consumed(&j.learner)).sum();
        let single = measure("inprocess-1", 1, total, start.elapsed().as_secs_f64(), None, 0.0);

        let mut parallel = jobs(workload, options.scale)?;
        let start = Instant::now();
        parallel
            .par_iter_mut()
            .for_each(|job| run_in_process(&mut job.learner, job.environment.as_mut()));
        let total: u64 = parallel.iter().map(|j| consumed(&j.learner)).sum();
        measure(
            "inprocess-rayon",
            rayon::current_num_threads(),
            total,
            start.elapsed().as_secs_f64(),
            None,
            single,
        );

        for workers in 1..=options.max_workers.min(cores.max(1)) {
            let run = RunName::new(&format!("bench-{}-{}-{workers}", std::process::id(), workload.name()))?;
            let mut fleet_jobs: Vec<FleetJob> = jobs(workload, options.scale)?
                .into_iter()
                .map(|j| FleetJob {
                    learner: j.learner,
                    environment: j.spec,
                })
                .collect();
            let nice = options.worker_nice.unwrap_or_else(|| workers::default_nice(workers));
            let mut children = workers::spawn(&run, workers, options.worker_in_flight, nice)?;
            let start = Instant::now();
            let stop = AtomicBool::new(false);
            let served = fleet::serve(
                &mut fleet_jobs,
                &run,
                0x0bec_4000 + workers as u64,
                workers::spin(workers),
                &stop,
                |_| {
                    if workers::all_exited(&mut children) {
                        stop.store(true, std::sync::atomic::Ordering::Relaxed);
                    }
                },
                |_, _| Ok(()),
            );
            let total_seconds = start.elapsed().as_secs_f64();
            let reaped = workers::reap(&mut children);
            let cleaned = ipc::remove_run_files(&run);
            let progress = served.with_context(|| format!("fleet of {workers} on {}", workload.name()))?;
            reaped?;
            cleaned?;
            let fleet = Fleet {
                learner_seconds: progress.learner_seconds,
                startup_seconds: total_seconds - progress.serving_seconds,
            };
            measure(
                "fleet",
                workers,
                progress.outcomes,
                progress.serving_seconds,
                Some(fleet),
                single,
            );
        }
    }
    Ok(rows)
}

/// The rows as an aligned table.
pub fn table(rows: &[Row]) -> String {
    let mut text = format!(
        "{:<9} {:<16} {:>7} {:>14} {:>7} {:>14} {:>11}\n",
        "env", "mode", "workers", "rollouts/s", "ratio", "learner share", "startup ms"
    );
    for row in rows {
        let share = row
            .learner_share
            .map_or("-".to_string(), |s| format!("{:.1}%", 100.0 * s));
        let startup = row
            .startup_seconds
            .map_or("-".to_string(), |s| format!("{:.0}", 1000.0 * s));
        text += &format!(
            "{:<9} {:<16} {:>7} {:>14.0} {:>7.2} {:>14} {:>11}\n",
            row.env, row.mode, row.workers, row.rollouts_per_s, row.ratio, share, startup
        );
    }
    text
}
