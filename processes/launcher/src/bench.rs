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
    /// The largest share of the machine's CPU time that other processes used during a round of
    /// this row (`None` where the system does not say, Linux's /proc only, or where every round
    /// was shorter than its counters' tick of 10 ms).
    pub others_share: Option<f64>,
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
    /// The share of the machine's CPU time other processes used meanwhile.
    others_share: Option<f64>,
}

/// CPU time, in clock ticks, that the whole machine and this process with its reaped children
/// (a fleet's workers) had used, from Linux's /proc.
#[derive(Clone, Copy)]
struct CpuTicks {
    machine_busy: u64,
    machine_total: u64,
    own: u64,
}

impl CpuTicks {
    fn now() -> Option<Self> {
        let stat = std::fs::read_to_string("/proc/stat").ok()?;
        // cpu user nice system idle iowait irq softirq steal ...
        let machine: Vec<u64> = stat
            .lines()
            .next()?
            .split_whitespace()
            .skip(1)
            .map(|field| field.parse().ok())
            .collect::<Option<_>>()?;
        let field = |i: usize| machine.get(i).copied().unwrap_or(0);
        let machine_busy = field(0) + field(1) + field(2) + field(5) + field(6) + field(7);
        let own_stat = std::fs::read_to_string("/proc/self/stat").ok()?;
        // After the command name in parentheses: utime, stime, cutime, cstime are the 12th to
        // 15th fields.
        let own: u64 = own_stat
            .rsplit_once(')')?
            .1
            .split_whitespace()
            .skip(11)
            .take(4)
            .map(|field| field.parse::<u64>().ok())
            .sum::<Option<u64>>()?;
        Some(Self {
            machine_busy,
            machine_total: machine_busy + field(3) + field(4),
            own,
        })
    }

    /// The share of the machine's CPU time between `self` and `later` that other processes used.
    fn others_share(self, later: Self) -> Option<f64> {
        let total = later.machine_total.checked_sub(self.machine_total)?;
        let busy = later.machine_busy.checked_sub(self.machine_busy)?;
        let own = later.own.checked_sub(self.own)?;
        (total > 0).then(|| (busy.saturating_sub(own) as f64 / total as f64).min(1.0))
    }
}

/// Above this share of the machine's CPU used by other processes, a bench warns that its ratios
/// measure the competition rather than the fleet.
pub const BUSY_SHARE: f64 = 0.1;

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
                let before = CpuTicks::now();
                let mut measurement = match mode {
                    Mode::Single => in_process(workload, options.scale, false)?,
                    Mode::Rayon => in_process(workload, options.scale, true)?,
                    // Returns once its workers are reaped, so their CPU time counts as ours.
                    Mode::Fleet(workers) => fleet(workload, options, workers)?,
                };
                measurement.others_share = before.zip(CpuTicks::now()).and_then(|(a, b)| a.others_share(b));
                samples.push(measurement);
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
                others_share: samples.iter().filter_map(|m| m.others_share).reduce(f64::max),
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
        others_share: None,
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
        others_share: None,
    })
}

/// The rows as an aligned table.
pub fn table(rows: &[Row]) -> String {
    let mut text = format!(
        "{:<9} {:<16} {:>7} {:>14} {:>7} {:>13} {:>14} {:>11} {:>7}\n",
        "env", "mode", "workers", "rollouts/s", "ratio", "ratio range", "learner share", "startup ms", "others"
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
        let others = row
            .others_share
            .map_or("-".to_string(), |s| format!("{:.0}%", 100.0 * s));
        text += &format!(
            "{:<9} {:<16} {:>7} {:>14.0} {:>7.2} {:>13} {:>14} {:>11} {:>7}\n",
            row.env, row.mode, row.workers, row.rollouts_per_s, row.ratio, range, share, startup, others
        );
    }
    text
}

/// What a reader should know before trusting the ratios of `rows`: whether other processes
/// competed for the CPU (their largest share in any round), or the single-thread rate of an
/// environment varied between rounds by more than a fifth; `None` when neither happened.
pub fn busy_warning(rows: &[Row]) -> Option<String> {
    let mut reasons = Vec::new();
    let busiest = rows.iter().filter_map(|r| r.others_share).reduce(f64::max);
    if let Some(share) = busiest.filter(|&s| s > BUSY_SHARE) {
        reasons.push(format!(
            "other processes used up to {:.0}% of the machine's CPU time during a measurement (column 'others')",
            100.0 * share
        ));
    }
    for row in rows
        .iter()
        .filter(|r| r.mode == Mode::Single.name() && r.round_rates.len() > 1)
    {
        let lowest = row.round_rates.iter().copied().fold(f64::INFINITY, f64::min);
        let highest = row.round_rates.iter().copied().fold(0.0, f64::max);
        if highest > 1.2 * lowest {
            reasons.push(format!(
                "the {} single-thread rate varied by {:.0}% between rounds",
                row.env,
                100.0 * (highest / lowest - 1.0)
            ));
        }
    }
    (!reasons.is_empty()).then(|| {
        format!(
            "warning: the machine was busy: {}. Ratios below 1 then show the competition for the cores, not a slow fleet; measure again on an idle machine.",
            reasons.join("; ")
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(mode: Mode, rates: &[f64], others: Option<f64>) -> Row {
        Row {
            env: "analytic",
            mode: mode.name(),
            workers: 1,
            rollouts_per_s: rates[0],
            ratio: 1.0,
            learner_share: None,
            startup_seconds: None,
            rollouts: 1,
            seconds: 1.0,
            round_rates: rates.to_vec(),
            round_ratios: vec![1.0; rates.len()],
            others_share: others,
        }
    }

    #[test]
    fn a_busy_machine_is_named_and_a_quiet_one_is_not() {
        let quiet = [
            row(Mode::Single, &[100.0, 110.0], Some(0.05)),
            row(Mode::Fleet(2), &[10.0], Some(0.1)),
        ];
        assert_eq!(busy_warning(&quiet), None);
        let competed = [
            row(Mode::Single, &[100.0, 101.0], Some(0.02)),
            row(Mode::Fleet(2), &[10.0], Some(0.35)),
        ];
        let warning = busy_warning(&competed).unwrap();
        assert!(warning.contains("up to 35% of the machine's CPU time"), "{warning}");
        // Without /proc, the spread of the single-thread rate still tells.
        let spread = [row(Mode::Single, &[100.0, 130.0, 90.0], None)];
        let warning = busy_warning(&spread).unwrap();
        assert!(
            warning.contains("analytic single-thread rate varied by 44%"),
            "{warning}"
        );
    }

    #[test]
    fn the_others_share_leaves_out_this_process_and_its_children() {
        let before = CpuTicks {
            machine_busy: 1000,
            machine_total: 4000,
            own: 100,
        };
        // 400 ticks of the machine's 800 busy, 300 of them ours: others took 100 of 800.
        let after = CpuTicks {
            machine_busy: 1400,
            machine_total: 4800,
            own: 400,
        };
        assert_eq!(before.others_share(after), Some(0.125));
        assert_eq!(after.others_share(before), None);
        let now = CpuTicks::now().expect("Linux has /proc/stat and /proc/self/stat");
        assert!(now.machine_total >= now.machine_busy && now.machine_busy > 0);
    }
}
