//! `acps bench`: rollouts per second of three environments, measured in one run side by side:
//! in-process on one thread, in-process on all cores (rayon), and through a fleet of W worker
//! processes for W = 1 ..= cores. The trivial environment costs nothing, so its fleet rows
//! measure the transport; the analytic and rapier PA-10 throws show how close the fleet comes
//! to W times one thread (the ratio). With `--relay`, every fleet is measured again through an
//! `acps relay` on loopback that starts the W workers, as a host of workers on the network would.

use acps_experiments::checkpoints::{Checkpoints, Writer};
use acps_experiments::paper::{self, Sim};
use acps_experiments::run_dir::DEFAULT_CHECKPOINT_EVERY;
use acps_experiments::settings::ExperimentFile;
use acps_fleet::{Fleet, FleetError, FleetJob, FleetProgress, Learners};
use acps_learner::checkpoint::Stamp;
use acps_learner::creps::CRepsConfig;
use acps_learner::selection::RoundRobin;
use acps_learner::{Learner, LearnerConfig, Method, SearchConfig, run_in_process};
use acps_models::environment::TrivialEnvironment;
use acps_shared::Environment;
use acps_wire::ipc::RunName;
use anyhow::Context;
use rayon::prelude::*;
use std::time::Instant;

pub use acps_reports::bench::{LongRun, Row};

/// What a fleet row measures beyond the rate.
#[derive(Clone, Copy)]
struct FleetCost {
    learner_seconds: f64,
    startup_seconds: f64,
    /// The serving process's own CPU time during the serve.
    cpu_seconds: Option<f64>,
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
    /// One trivial learner through 1,000,000 episodes (times `--scale`) with records and
    /// checkpoints as `acps run` writes them: its CPU per episode at the start and the end, and
    /// its memory.
    LongRun,
}

/// What to measure.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    /// Environments to measure, in this order.
    pub envs: Vec<BenchEnv>,
    /// Largest fleet.
    pub max_workers: usize,
    /// Tasks each worker keeps in flight.
    pub worker_queue_depth: usize,
    /// Niceness of the workers (default: [`acps_fleet::processes::default_nice`]).
    pub worker_nice: Option<u8>,
    /// Multiplies the amount of work per row (1 = a few seconds per row).
    pub scale: f64,
    /// Times every mode is measured, interleaved, >= 1.
    pub rounds: usize,
    /// Also measure every fleet through a relay on loopback.
    pub relay: bool,
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
                let problem = environment.problem(Vec::new());
                let config = LearnerConfig {
                    seed: seed as u64,
                    episodes: episodes(60_000.0),
                    in_flight: IN_FLIGHT,
                    eval_every: u64::MAX,
                    search: Some(SearchConfig::CReps(CRepsConfig::batches(1.0, 1000))),
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
            let options = ExperimentFile {
                runs: Some(JOBS),
                episodes: Some(episodes(base)),
                in_flight: Some(IN_FLIGHT),
                methods: Some(vec![Method::MonotonicProgress]),
                ..Default::default()
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
        /// inprocess-1, inprocess-rayon, fleet or relay.
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
#[derive(Clone, Copy, PartialEq, Eq)]
enum Mode {
    /// In this process, one after another.
    Single,
    /// In this process, on rayon's threads.
    Rayon,
    /// Through a fleet of this many worker processes.
    Fleet(usize),
    /// Through a relay child, served over Zenoh on loopback, that starts this many workers.
    Relay(usize),
}

impl Mode {
    fn name(self) -> &'static str {
        match self {
            Mode::Single => "inprocess-1",
            Mode::Rayon => "inprocess-rayon",
            Mode::Fleet(_) => "fleet",
            Mode::Relay(_) => "relay",
        }
    }

    fn workers(self) -> usize {
        match self {
            Mode::Single => 1,
            Mode::Rayon => rayon::current_num_threads(),
            Mode::Fleet(workers) | Mode::Relay(workers) => workers,
        }
    }

    /// What the ratio compares with: the same round's rate of this mode, times this factor. A
    /// relay is compared with as many workers connected directly, the cost of the network hop.
    fn reference(self) -> (Mode, f64) {
        match self {
            Mode::Relay(workers) => (Mode::Fleet(workers), 1.0),
            mode => (Mode::Single, mode.workers() as f64),
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

/// CPU time, in clock ticks, that the whole machine, this process, and its reaped children (a
/// fleet's workers, a relay) had used, from Linux's /proc.
#[derive(Clone, Copy)]
struct CpuTicks {
    machine_busy: u64,
    machine_total: u64,
    /// This process: utime + stime.
    process: u64,
    /// Its reaped children: cutime + cstime.
    children: u64,
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
        let own: Vec<u64> = own_stat
            .rsplit_once(')')?
            .1
            .split_whitespace()
            .skip(11)
            .take(4)
            .map(|field| field.parse().ok())
            .collect::<Option<_>>()?;
        let [utime, stime, cutime, cstime] = own[..] else {
            return None;
        };
        Some(Self {
            machine_busy,
            machine_total: machine_busy + field(3) + field(4),
            process: utime + stime,
            children: cutime + cstime,
        })
    }

    /// Seconds of CPU this process alone used between `self` and `later`; `None` when less than
    /// a tick.
    fn process_seconds(self, later: Self) -> Option<f64> {
        // SAFETY: sysconf only reads its integer argument.
        let per_second = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
        let ticks = later.process.checked_sub(self.process).filter(|&t| t > 0)?;
        (per_second > 0).then(|| ticks as f64 / per_second as f64)
    }

    /// The share of the machine's CPU time between `self` and `later` that other processes used.
    fn others_share(self, later: Self) -> Option<f64> {
        let total = later.machine_total.checked_sub(self.machine_total)?;
        let busy = later.machine_busy.checked_sub(self.machine_busy)?;
        let own = (later.process + later.children).checked_sub(self.process + self.children)?;
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
/// Rounds interleave the modes (one thread, rayon, fleets, each followed by its relay, then
/// again), so that a slow spell of a shared machine hits every mode of a round alike. A row is
/// the round with the (lower) median rate; its ratio is the median over rounds of the round's
/// rate / (W x the same round's single-thread rate), a relay's / the same round's direct fleet.
pub fn run(options: &BenchOptions, mut report: impl FnMut(BenchEvent)) -> anyhow::Result<Vec<Row>> {
    let mut rows = Vec::new();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let fleets = options.max_workers.min(cores.max(1));
    // Every measurement of a round, in the order taken; the first is the single-thread one.
    let modes: Vec<Mode> = [Mode::Single, Mode::Rayon]
        .into_iter()
        .chain((1..=fleets).flat_map(|workers| {
            let relay = options.relay.then_some(Mode::Relay(workers));
            [Mode::Fleet(workers)].into_iter().chain(relay)
        }))
        .collect();
    let workloads: Vec<Workload> = options
        .envs
        .iter()
        .filter_map(|env| match env {
            BenchEnv::Trivial => Some(Workload::Trivial),
            BenchEnv::Analytic => Some(Workload::Throw(Sim::Analytic)),
            BenchEnv::Rapier => Some(Workload::Throw(Sim::Rapier)),
            BenchEnv::LongRun => None,
        })
        .collect();
    let total = workloads.len() * options.rounds * modes.len();
    let mut index = 0;
    for workload in workloads {
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
                    Mode::Fleet(_) | Mode::Relay(_) => fleet(workload, options, mode)?,
                };
                measurement.others_share = before.zip(CpuTicks::now()).and_then(|(a, b)| a.others_share(b));
                samples.push(measurement);
            }
        }
        for (&mode, samples) in modes.iter().zip(&measured) {
            let workers = mode.workers();
            let rates: Vec<f64> = samples.iter().map(Measurement::rate).collect();
            let (reference, factor) = mode.reference();
            let reference = &measured[modes.iter().position(|&m| m == reference).expect("measured")];
            let ratios: Vec<f64> = rates
                .iter()
                .zip(reference)
                .map(|(rate, of)| rate / (factor * of.rate()))
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
                learner_cpu_us_per_task: chosen
                    .fleet
                    .and_then(|f| f.cpu_seconds)
                    .map(|cpu| 1e6 * cpu / chosen.rollouts as f64),
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

/// The long-run row's episodes at `--scale` 1.
pub const LONG_RUN_EPISODES: f64 = 1_000_000.0;

/// Measure the long-run row: a trivial learner with one training and one test context, default
/// C-REPS (an update every 25 episodes) and an evaluation every 50, its records and a checkpoint
/// every [`DEFAULT_CHECKPOINT_EVERY`] updates written to a temporary directory as `acps run`
/// writes them; `report(done, episodes)` sees its progress.
pub fn long_run(scale: f64, mut report: impl FnMut(u64, u64)) -> anyhow::Result<LongRun> {
    let episodes = ((LONG_RUN_EPISODES * scale).round() as u64).max(1000);
    let dir = TempDir::new("long-run")?;
    let mut environment = TrivialEnvironment::new();
    let problem = environment.problem(vec![vec![0.0]]);
    let config = LearnerConfig {
        episodes,
        ..Default::default()
    };
    let selector = Box::new(RoundRobin::all(problem.training_contexts.clone())?);
    let mut learner = Learner::new(config, problem, selector)?;
    let checkpoint = dir.0.join("long-run.ckpt");
    let stamp = Stamp { identity: 0, job: 0 };
    let mut writer = Writer::open(checkpoint.clone(), stamp, DEFAULT_CHECKPOINT_EVERY, &learner, None)?;
    let window = episodes / 10;
    let early_episodes = episodes.min(50_000);
    // Thread CPU time when the run had consumed 0, window, episodes - window and all episodes.
    let marks = [0, window, episodes - window, episodes];
    let mut cpu = [0.0; 4];
    let mut early_rss_mib = 0.0;
    let start = Instant::now();
    cpu[0] = thread_cpu_seconds()?;
    let mut done = 0;
    while let Some(task) = learner.ask() {
        let outcome = environment.rollout(&task);
        learner
            .tell(outcome)
            .expect("the outcome answers a task just handed out");
        writer.after_tell(&mut learner, Some(&environment))?;
        let now = learner.progress().episodes;
        if now == done {
            continue;
        }
        done = now;
        if let Some(at) = marks[1..].iter().position(|&m| m == done) {
            cpu[at + 1] = thread_cpu_seconds()?;
        }
        if done == early_episodes {
            early_rss_mib = rss_mib()?;
        }
        if done.is_multiple_of(10_000) {
            report(done, episodes);
        }
    }
    let seconds = start.elapsed().as_secs_f64();
    let end_rss_mib = rss_mib()?;
    let size = |path: &std::path::Path| std::fs::metadata(path).map(|m| m.len());
    Ok(LongRun {
        episodes,
        checkpoint_every: DEFAULT_CHECKPOINT_EVERY,
        checkpoints: writer.checkpoints_written(),
        window,
        start_cpu_us: 1e6 * (cpu[1] - cpu[0]) / window as f64,
        end_cpu_us: 1e6 * (cpu[3] - cpu[2]) / window as f64,
        early_rss_mib,
        early_episodes,
        end_rss_mib,
        checkpoint_bytes: size(&checkpoint)?,
        record_bytes: size(&Checkpoints::records_file(&checkpoint))?,
        seconds,
    })
}

/// A directory of this process's that goes when dropped.
struct TempDir(std::path::PathBuf);

impl TempDir {
    fn new(name: &str) -> anyhow::Result<Self> {
        let dir = std::env::temp_dir().join(format!("acps-bench-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        Ok(Self(dir))
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// CPU time (user and system) this thread has used.
fn thread_cpu_seconds() -> anyhow::Result<f64> {
    let mut now = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes the timespec it is given and nothing else.
    let status = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut now) };
    anyhow::ensure!(
        status == 0,
        "the thread's CPU clock: {}",
        std::io::Error::last_os_error()
    );
    Ok(now.tv_sec as f64 + now.tv_nsec as f64 * 1e-9)
}

/// This process's resident memory, from Linux's /proc.
fn rss_mib() -> anyhow::Result<f64> {
    let status = std::fs::read_to_string("/proc/self/status").context("reading /proc/self/status")?;
    let kib: f64 = status
        .lines()
        .find_map(|line| line.strip_prefix("VmRSS:"))
        .and_then(|rest| rest.trim().trim_end_matches("kB").trim().parse().ok())
        .context("/proc/self/status has no VmRSS line")?;
    Ok(kib / 1024.0)
}

/// The long-run rows as a table.
pub fn long_run_table(runs: &[LongRun]) -> String {
    let mut text = format!(
        "{:<9} {:>10} {:>12} {:>12} {:>8} {:>15} {:>13} {:>8} {:>11} {:>12}
",
        "long run",
        "episodes",
        "start us/ep",
        "end us/ep",
        "growth",
        "RSS early MiB",
        "RSS end MiB",
        "growth",
        "checkpoint",
        "records MiB"
    );
    for run in runs {
        text += &format!(
            "{:<9} {:>10} {:>12.3} {:>12.3} {:>8.3} {:>15.1} {:>13.1} {:>8.3} {:>11} {:>12.1}
",
            "",
            run.episodes,
            run.start_cpu_us,
            run.end_cpu_us,
            run.cpu_growth(),
            run.early_rss_mib,
            run.end_rss_mib,
            run.rss_growth(),
            format!("{} B", run.checkpoint_bytes),
            run.record_bytes as f64 / (1024.0 * 1024.0)
        );
    }
    text
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

/// The jobs of `workload` served by a fleet of this process: to `Fleet(W)` worker processes it
/// starts, or (`Relay(W)`) to one `acps relay` child on loopback that starts the W workers.
fn fleet(workload: Workload, options: &BenchOptions, mode: Mode) -> anyhow::Result<Measurement> {
    let workers = mode.workers();
    let relayed = matches!(mode, Mode::Relay(_));
    let kind = if relayed { "relay-" } else { "" };
    let name = RunName::new(&format!(
        "bench-{}-{}-{kind}{workers}",
        std::process::id(),
        workload.name()
    ))?;
    let mut fleet_jobs = jobs(workload, options.scale)?
        .into_iter()
        .map(|j| FleetJob::new(j.learner))
        .collect::<Result<Vec<_>, _>>()?;
    let mut builder = Fleet::builder(name.clone()).identity(0x0bec_4000 + workers as u64);
    builder = if relayed {
        // The learner sees one peer: its clock starts with the relay's first request. On
        // loopback it shares the cores with the relay and its workers, so it polls only if
        // they leave it one (as a fleet of W + 1 workers would).
        builder.start_with(1).spin(acps_fleet::processes::spin(workers + 1))
    } else {
        builder
            .spawn_workers(
                workers,
                acps_experiments::workers::command(options.worker_queue_depth, workers),
            )
            // The clock starts with the whole fleet at work, not with its first worker.
            .start_with(workers)
    };
    if let Some(nice) = options.worker_nice {
        builder = builder.worker_niceness(nice);
    }
    let mut fleet = builder.start()?;
    let (mut listener, command) = if relayed {
        let (listener, command) = crate::hosts::relay_command(&name, options, workers)?;
        (Some(listener), Some(command))
    } else {
        (None, None)
    };
    let start = Instant::now();
    let mut relay = match command {
        Some(mut command) => Some(command.spawn().context("starting acps relay")?),
        None => None,
    };
    let stop = fleet.stop_flag();
    let mut exited = false;
    let cpu_before = CpuTicks::now();
    let served = fleet.serve_with(
        &mut Learners(&mut fleet_jobs),
        &mut |progress: &FleetProgress| {
            // Workers and relays leave only once the learner is done: one gone means a broken
            // fleet, which would also keep the fleet from starting.
            let gone = match relay.as_mut() {
                Some(child) => !matches!(child.try_wait(), Ok(None)),
                None => progress.started_running < workers,
            };
            if gone {
                exited = true;
                stop.store(true, std::sync::atomic::Ordering::Relaxed);
            }
        },
        listener.as_deref_mut().map(|l| l as &mut dyn acps_fleet::Remote),
    );
    let cpu_seconds = cpu_before.zip(CpuTicks::now()).and_then(|(a, b)| a.process_seconds(b));
    let total_seconds = start.elapsed().as_secs_f64();
    // The relay ends once the learner's token is gone with the listener; told to stop otherwise.
    drop(listener);
    if let Some(mut child) = relay {
        if served.is_err() {
            // SAFETY: kill only reads its integer arguments; the child is not reaped yet.
            unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGTERM) };
        }
        acps_fleet::processes::reap(std::slice::from_mut(&mut child));
        let status = child.try_wait().ok().flatten();
        if served.is_ok() && !status.is_some_and(|s| s.success()) {
            anyhow::bail!(
                "the relay of {workers} workers on {} ended with {status:?}",
                workload.name()
            );
        }
    }
    let context = || format!("{} of {workers} on {}", mode.name(), workload.name());
    let who = if relayed { "the relay" } else { "a worker" };
    let died = || format!("{}: {who} exited before the bench was done", context());
    let progress = match served {
        Err(FleetError::Interrupted) if exited => anyhow::bail!(died()),
        // The fleet itself may notice first that its only workers failed.
        Err(error @ FleetError::NoWorkers { failed: true, .. }) => {
            return Err(anyhow::Error::new(error).context(died()));
        }
        Err(error) if exited => return Err(anyhow::Error::new(error).context(died())),
        served => served.with_context(context)?,
    };
    Ok(Measurement {
        rollouts: progress.outcomes,
        seconds: progress.serving_seconds,
        fleet: Some(FleetCost {
            learner_seconds: progress.learner_seconds,
            startup_seconds: total_seconds - progress.serving_seconds,
            cpu_seconds,
        }),
        others_share: None,
    })
}

/// The rows as an aligned table.
pub fn table(rows: &[Row]) -> String {
    let mut text = format!(
        "{:<9} {:<16} {:>7} {:>14} {:>7} {:>13} {:>14} {:>11} {:>15} {:>7}\n",
        "env",
        "mode",
        "workers",
        "rollouts/s",
        "ratio",
        "ratio range",
        "learner share",
        "startup ms",
        "learner us/task",
        "others"
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
        let cpu = row
            .learner_cpu_us_per_task
            .map_or("-".to_string(), |us| format!("{us:.2}"));
        let others = row
            .others_share
            .map_or("-".to_string(), |s| format!("{:.0}%", 100.0 * s));
        text += &format!(
            "{:<9} {:<16} {:>7} {:>14.0} {:>7.2} {:>13} {:>14} {:>11} {:>15} {:>7}\n",
            row.env, row.mode, row.workers, row.rollouts_per_s, row.ratio, range, share, startup, cpu, others
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
            learner_cpu_us_per_task: None,
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
            process: 60,
            children: 40,
        };
        // 400 ticks of the machine's 800 busy, 300 of them ours (100 this process's): others
        // took 100 of 800.
        let after = CpuTicks {
            machine_busy: 1400,
            machine_total: 4800,
            process: 160,
            children: 240,
        };
        assert_eq!(before.others_share(after), Some(0.125));
        assert_eq!(after.others_share(before), None);
        let tick = 1.0 / unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
        assert_eq!(before.process_seconds(after), Some(100.0 * tick));
        assert_eq!(before.process_seconds(before), None, "less than a tick");
        let now = CpuTicks::now().expect("Linux has /proc/stat and /proc/self/stat");
        assert!(now.machine_total >= now.machine_busy && now.machine_busy > 0);
    }
}
