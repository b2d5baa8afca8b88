//! `acps bench`: rollouts per second of three environments, measured in one run side by side:
//! in-process on one thread, in-process on all cores (rayon), and through a fleet of W worker
//! processes for W = 1 ..= cores. The trivial environment costs nothing, so its fleet rows
//! measure the transport; the analytic and rapier PA-10 throws show how close the fleet comes
//! to W times one thread (the ratio).

use crate::paper::{self, Options, Sim};
use acps_fleet::{Fleet, FleetError, FleetJob, FleetProgress};
use acps_learner::creps::{CRepsConfig, DEFAULT_ETA_MIN, FeatureMap, MemoryConfig};
use acps_learner::selection::RoundRobin;
use acps_learner::{Learner, LearnerConfig, Method, run_in_process};
use acps_models::environment::TrivialEnvironment;
use acps_shared::{ContextSpace, Environment, Problem, ScoreAggregate};
use anyhow::Context;
use rayon::prelude::*;
use serde::Serialize;
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
    /// Rollouts (training and evaluation) per second of wall time, the median over rounds; a
    /// fleet's from the moment all its workers asked for tasks.
    pub rollouts_per_s: f64,
    /// Median over rounds of the round's rate / (workers x its single-thread rate).
    pub ratio: f64,
    /// Share of the fleet's serving time (median round) spent inside the learner cores.
    pub learner_share: Option<f64>,
    /// Fleet only: seconds (median round) from starting the worker processes until every one
    /// has asked for tasks, which the rate leaves out (in-process rows build their environments
    /// before the clock starts, too).
    pub startup_seconds: Option<f64>,
    /// Rollouts performed in the median round.
    pub rollouts: u64,
    /// Wall time in seconds of the median round (a fleet's from its start, as for the rate).
    pub seconds: f64,
    /// Every round's rate, in order.
    pub round_rates: Vec<f64>,
    /// Every round's ratio, in order.
    pub round_ratios: Vec<f64>,
}

impl Row {
    /// The lowest and highest ratio over the rounds, when there were several.
    pub fn ratio_range(&self) -> Option<(f64, f64)> {
        (self.round_ratios.len() > 1).then(|| {
            let lowest = self.round_ratios.iter().copied().fold(f64::INFINITY, f64::min);
            let highest = self.round_ratios.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            (lowest, highest)
        })
    }
}

/// What a fleet row measures beyond the rate.
#[derive(Clone, Copy)]
struct FleetCost {
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
    /// Niceness of the workers (default: [`acps_fleet::processes::default_nice`]).
    pub worker_nice: Option<u8>,
    /// Multiplies the amount of work per row (1 = a few seconds per row).
    pub scale: f64,
    /// Times every mode is measured, interleaved, >= 1.
    pub rounds: usize,
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

/// Learners kept busy at once: many jobs with a wide window keep every worker fed. 8 x 64 tasks
/// leave ready ones in the learner while two workers hold 128 each (the default
/// `--worker-in-flight`): three batches of 32 analytic throws in reserve (2.4 ms) outlast most
/// runs of C-REPS updates, during which the learner answers no one.
const JOBS: usize = 8;
const IN_FLIGHT: usize = 64;

struct Job {
    learner: Learner,
    environment: Box<dyn Environment>,
}

fn jobs(workload: Workload, scale: f64) -> anyhow::Result<Vec<Job>> {
    let episodes = |base: f64| ((base * scale).round() as u64).max(1);
    match workload {
        Workload::Trivial => (0..JOBS)
            .map(|seed| {
                // One context, one parameter, no evaluation: the learner's cost stays small so
                // that the fleet rows measure the transport.
                let environment = TrivialEnvironment::new();
                let problem = Problem {
                    name: "trivial".into(),
                    training_contexts: vec![vec![0.0]],
                    test_contexts: Vec::new(),
                    space: ContextSpace::new_box(vec![-1.0], vec![1.0]).expect("a valid box"),
                    theta0: vec![1.0],
                    score: ScoreAggregate::Mean,
                    metric: "none".into(),
                    environment: environment.spec(),
                };
                let creps = CRepsConfig {
                    epsilon: 1.0,
                    eta_min: DEFAULT_ETA_MIN,
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
                    environment: Box::new(environment),
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
                        learner: job.learner,
                        environment: job.environment.context("the grid's jobs have an environment")?,
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

/// What [`run`] reports while it works.
pub enum BenchEvent<'a> {
    /// A measurement starts: `index` of `total` in the whole bench.
    Measuring {
        /// The environment.
        env: &'static str,
        /// inprocess-1, inprocess-rayon or fleet.
        mode: &'static str,
        /// Worker processes, threads or 1.
        workers: usize,
        /// The round, from 1.
        round: usize,
        /// Measurements done before this one.
        index: usize,
        /// Measurements in the whole bench.
        total: usize,
    },
    /// A row is final (after its environment's last round).
    Row(&'a Row),
}

/// How a row runs its jobs.
#[derive(Clone, Copy)]
enum Mode {
    /// In this process, one after another.
    Single,
    /// In this process, on rayon's threads.
    Rayon,
    /// Through a fleet of this many worker processes.
    Fleet(usize),
}

impl Mode {
    fn name(self) -> &'static str {
        match self {
            Mode::Single => "inprocess-1",
            Mode::Rayon => "inprocess-rayon",
            Mode::Fleet(_) => "fleet",
        }
    }

    fn workers(self) -> usize {
        match self {
            Mode::Single => 1,
            Mode::Rayon => rayon::current_num_threads(),
            Mode::Fleet(workers) => workers,
        }
    }
}

/// One round's measurement of one mode.
#[derive(Clone, Copy)]
struct Measurement {
    rollouts: u64,
    seconds: f64,
    fleet: Option<FleetCost>,
}

impl Measurement {
    fn rate(&self) -> f64 {
        self.rollouts as f64 / self.seconds
    }
}

/// The lower median: an element of `values` (a measured round, not a mean of two).
fn lower_median(values: &[f64]) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    sorted[(sorted.len() - 1) / 2]
}

/// Measure every row; `report` sees each measurement start and each row once it is final.
///
/// Rounds interleave the modes (one thread, rayon, fleets, then again), so that a slow spell
/// of a shared machine hits every mode of a round alike. A row is the round with the (lower)
/// median rate; its ratio is the median over rounds of the round's rate / (W x the same
/// round's single-thread rate).
pub fn run(options: &BenchOptions, mut report: impl FnMut(BenchEvent)) -> anyhow::Result<Vec<Row>> {
    let mut rows = Vec::new();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let fleets = options.max_workers.min(cores.max(1));
    // Every measurement of a round, in the order taken; the first is the single-thread one.
    let modes: Vec<Mode> = [Mode::Single, Mode::Rayon]
        .into_iter()
        .chain((1..=fleets).map(Mode::Fleet))
        .collect();
    let total = options.envs.len() * options.rounds * modes.len();
    let mut index = 0;
    for workload in options.envs.iter().map(|env| match env {
        BenchEnv::Trivial => Workload::Trivial,
        BenchEnv::Analytic => Workload::Throw(Sim::Analytic),
        BenchEnv::Rapier => Workload::Throw(Sim::Rapier),
    }) {
        let mut measured: Vec<Vec<Measurement>> = vec![Vec::new(); modes.len()];
        for round in 1..=options.rounds {
            for (&mode, samples) in modes.iter().zip(&mut measured) {
                report(BenchEvent::Measuring {
                    env: workload.name(),
                    mode: mode.name(),
                    workers: mode.workers(),
                    round,
                    index,
                    total,
                });
                index += 1;
                samples.push(match mode {
                    Mode::Single => in_process(workload, options.scale, false)?,
                    Mode::Rayon => in_process(workload, options.scale, true)?,
                    Mode::Fleet(workers) => fleet(workload, options, workers)?,
                });
            }
        }
        let single_rates: Vec<f64> = measured[0].iter().map(Measurement::rate).collect();
        for (&mode, samples) in modes.iter().zip(&measured) {
            let workers = mode.workers();
            let rates: Vec<f64> = samples.iter().map(Measurement::rate).collect();
            let ratios: Vec<f64> = rates
                .iter()
                .zip(&single_rates)
                .map(|(rate, single)| rate / (workers as f64 * single))
                .collect();
            let median = lower_median(&rates);
            let chosen = samples[rates
                .iter()
                .position(|&rate| rate == median)
                .expect("the median is a rate")];
            let row = Row {
                env: workload.name(),
                mode: mode.name(),
                workers,
                rollouts_per_s: median,
                ratio: lower_median(&ratios),
                learner_share: chosen.fleet.map(|f| f.learner_seconds / chosen.seconds),
                startup_seconds: chosen.fleet.map(|f| f.startup_seconds),
                rollouts: chosen.rollouts,
                seconds: chosen.seconds,
                round_rates: rates,
                round_ratios: ratios,
            };
            report(BenchEvent::Row(&row));
            rows.push(row);
        }
    }
    Ok(rows)
}

/// The jobs of `workload` run in this process, one after another or (`parallel`) by rayon.
fn in_process(workload: Workload, scale: f64, parallel: bool) -> anyhow::Result<Measurement> {
    let mut jobs = jobs(workload, scale)?;
    let start = Instant::now();
    let run = |job: &mut Job| run_in_process(&mut job.learner, job.environment.as_mut());
    if parallel {
        jobs.par_iter_mut().try_for_each(run)?;
    } else {
        jobs.iter_mut().try_for_each(run)?;
    }
    Ok(Measurement {
        seconds: start.elapsed().as_secs_f64(),
        rollouts: jobs.iter().map(|j| consumed(&j.learner)).sum(),
        fleet: None,
    })
}

/// The jobs of `workload` served to a fleet of `workers` processes started for it.
fn fleet(workload: Workload, options: &BenchOptions, workers: usize) -> anyhow::Result<Measurement> {
    let name = format!("bench-{}-{}-{workers}", std::process::id(), workload.name());
    let mut fleet_jobs = jobs(workload, options.scale)?
        .into_iter()
        .map(|j| FleetJob::new(j.learner))
        .collect::<Result<Vec<_>, _>>()?;
    let mut builder = Fleet::builder(name)
        .identity(0x0bec_4000 + workers as u64)
        .spawn_workers(workers, crate::workers::command(options.worker_in_flight, workers))
        // The clock starts with the whole fleet at work, not with its first worker.
        .start_with(workers);
    if let Some(nice) = options.worker_nice {
        builder = builder.worker_niceness(nice);
    }
    let mut fleet = builder.start()?;
    let stop = fleet.stop_flag();
    let mut worker_died = false;
    let start = Instant::now();
    let served = fleet.serve(&mut fleet_jobs, &mut |progress: &FleetProgress| {
        // Workers leave only once the learner is done: one gone means a broken fleet, which
        // would also keep the fleet from starting.
        if progress.started_running < workers {
            worker_died = true;
            stop.store(true, std::sync::atomic::Ordering::Relaxed);
        }
    });
    let total_seconds = start.elapsed().as_secs_f64();
    let context = || format!("fleet of {workers} on {}", workload.name());
    let died = || format!("{}: a worker exited before the bench was done", context());
    let progress = match served {
        Err(FleetError::Interrupted) if worker_died => anyhow::bail!(died()),
        Err(error) if worker_died => return Err(anyhow::Error::new(error).context(died())),
        served => served.with_context(context)?,
    };
    Ok(Measurement {
        rollouts: progress.outcomes,
        seconds: progress.serving_seconds,
        fleet: Some(FleetCost {
            learner_seconds: progress.learner_seconds,
            startup_seconds: total_seconds - progress.serving_seconds,
        }),
    })
}

/// The rows as an aligned table.
pub fn table(rows: &[Row]) -> String {
    let mut text = format!(
        "{:<9} {:<16} {:>7} {:>14} {:>7} {:>13} {:>14} {:>11}\n",
        "env", "mode", "workers", "rollouts/s", "ratio", "ratio range", "learner share", "startup ms"
    );
    for row in rows {
        let share = row
            .learner_share
            .map_or("-".to_string(), |s| format!("{:.1}%", 100.0 * s));
        let startup = row
            .startup_seconds
            .map_or("-".to_string(), |s| format!("{:.0}", 1000.0 * s));
        let range = row
            .ratio_range()
            .map_or("-".to_string(), |(lowest, highest)| format!("{lowest:.2}-{highest:.2}"));
        text += &format!(
            "{:<9} {:<16} {:>7} {:>14.0} {:>7.2} {:>13} {:>14} {:>11}\n",
            row.env, row.mode, row.workers, row.rollouts_per_s, row.ratio, range, share, startup
        );
    }
    text
}
