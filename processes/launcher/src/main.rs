//! `acps`: the command line of Active Contextual Policy Search.

use acps::checkpoints::Checkpoints;
use acps::experiment::{Experiment, Summary, progress_bar};
use acps::paper::{self, Options, Overrides};
use acps_learner::Method;
use acps_learner::selection::FirstVisit;
use acps_shared::ipc::{self, RunName};
use acps_worker::{ModelFactory, WorkerExit, WorkerOptions};
use anyhow::{Context, bail};
use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

#[derive(Parser)]
#[command(
    name = "acps",
    version,
    about = "Active contextual policy search (Fabisch & Metzen, JMLR 2014): C-REPS learns one policy over task contexts while D-UCB chooses which context to practise next."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run one of the paper's experiments in this process, for several methods x seeds in
    /// parallel, and write DIR/summary.json.
    Experiment(ExperimentArgs),
    /// Run an experiment through a worker fleet: this process is the learner and serves tasks
    /// over iceoryx2 shared memory to worker processes it starts. Writes the same DIR/summary.json
    /// as `acps experiment` with the same --in-flight and --seed.
    Run(RunArgs),
    /// Serve the learner of a running fleet (`acps run ... --run NAME`) as one more worker.
    Worker(WorkerArgs),
    /// Measure rollouts per second in-process and through fleets of 1 ..= cores workers, for a
    /// trivial environment (the transport's cost) and the analytic and rapier PA-10; print a
    /// table and write DIR/bench.json.
    Bench(BenchArgs),
}

#[derive(clap::Args)]
struct BenchArgs {
    /// Output directory.
    #[arg(long, default_value = "runs/bench")]
    out: PathBuf,
    /// Largest fleet (default: the number of cores).
    #[arg(long)]
    max_workers: Option<usize>,
    /// Requests each worker keeps in flight (1..=64).
    #[arg(long, default_value_t = 16)]
    worker_in_flight: usize,
    /// Multiplies the work per row (1: a few seconds per row).
    #[arg(long, default_value_t = 1.0)]
    scale: f64,
}

#[derive(clap::Args)]
struct RunArgs {
    #[command(flatten)]
    experiment: ExperimentArgs,
    /// Worker processes to start (default: the number of cores).
    #[arg(long)]
    workers: Option<usize>,
    /// Requests each started worker keeps in flight (1..=64).
    #[arg(long, default_value_t = 4)]
    worker_in_flight: usize,
    /// The run's name: its shared-memory prefix, and how workers started by hand join it
    /// (default: EXPERIMENT-PID).
    #[arg(long)]
    run: Option<String>,
}

#[derive(clap::Args)]
struct WorkerArgs {
    /// The run to join (the learner's --run).
    #[arg(long)]
    run: String,
    /// Requests kept in flight (1..=64): more hides the wake-up latency between processes.
    #[arg(long, default_value_t = 4)]
    in_flight: usize,
    /// The worker's name in iceoryx2's node list (default: worker-PID).
    #[arg(long)]
    name: Option<String>,
    /// Seconds to wait for the run's learner to appear.
    #[arg(long, default_value_t = 30.0)]
    startup_timeout: f64,
    /// Microseconds to poll for an answer before blocking (0 when processes outnumber cores).
    #[arg(long, default_value_t = 0)]
    spin_us: u64,
    /// Print nothing unless something goes wrong.
    #[arg(long, short)]
    quiet: bool,
}

#[derive(Clone, Copy, ValueEnum)]
enum ExperimentName {
    /// Section 4's model of the learning process (Fig. 2 and 3).
    Toy,
    /// Section 5.1.2's contextual function on a 5x5 grid of contexts (Fig. 4 and 5).
    Function,
    /// Section 5.1.3: the contextual function for 1 to 4 context dimensions (Fig. 6).
    Dims,
    /// Section 5.2.3: the PA-10 throws at a 5x5 grid of targets, tested on a 4x4 grid (Fig. 8).
    Grid,
    /// Section 5.2.4: the PA-10 throws at the 81 fields of a dartboard on the ground (Fig. 10).
    Dartboard,
}

#[derive(Clone, Copy, ValueEnum)]
enum SimArg {
    /// Forward kinematics at release and closed-form flight (exact for perfect tracking).
    Analytic,
    /// The rapier3d multibody arm tracking the throw with joint motors (about 2 ms per throw).
    Rapier,
}

#[derive(clap::Args)]
struct ExperimentArgs {
    /// Which experiment.
    name: ExperimentName,
    /// Runs per method.
    #[arg(long, default_value_t = 20)]
    runs: usize,
    /// Training episodes per run (default: the paper's length: toy 1000, function 2500, dims 5000).
    #[arg(long)]
    episodes: Option<u64>,
    /// Seed of run 0; run r uses seed + r for the problem instance and the learner.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Training tasks in flight (P): task t is created after outcome t - P is consumed. 1 is the
    /// paper's sequential algorithm.
    #[arg(long, default_value_t = 1)]
    in_flight: usize,
    /// Run only this method (repeatable). Default: the methods of the paper's figure.
    #[arg(long = "method", value_name = "METHOD")]
    methods: Vec<String>,
    /// toy only: one panel of Fig. 2 (a: sigma_r 0, sigma_b 0; b: 0.01, 0; c: 0, 0.2; d: 0.01, 0.2)
    /// into DIR; without it all four go to DIR/a .. DIR/d.
    #[arg(long)]
    panel: Option<char>,
    /// dims only: one context dimension (1..=4) into DIR; without it all four go to DIR/ns-1 .. DIR/ns-4.
    #[arg(long)]
    n_s: Option<usize>,
    /// Number of low-level parameters n_theta of the contextual function (the paper does not say;
    /// default 20). Must exceed the context dimension.
    #[arg(long)]
    n_theta: Option<usize>,
    /// Baseline of a context's first visit for the progress heuristics: the initial greedy
    /// policy's return there (default), or none (the first visit scores 0).
    #[arg(long, value_enum)]
    first_visit: Option<FirstVisitArg>,
    /// C-REPS sample memory: the last N rollouts (default, as BOLeRo) or the paper's Section 5.2
    /// per-task memory of the best N/K rollouts.
    #[arg(long, value_enum)]
    memory: Option<MemoryArg>,
    /// Initial exploration covariance Sigma_0 = X I (default 1).
    #[arg(long, value_name = "X")]
    initial_sigma: Option<f64>,
    /// C-REPS KL bound epsilon (default: the experiment's).
    #[arg(long)]
    epsilon: Option<f64>,
    /// toy only: use the learning factors of the paper's Fig. 3 in every run instead of a random
    /// permutation per run.
    #[arg(long)]
    fig3_learning_factors: bool,
    /// D-UCB padding strength xi (default: the experiment's).
    #[arg(long)]
    xi: Option<f64>,
    /// grid and dartboard only: how throws are simulated.
    #[arg(long, value_enum, default_value = "analytic")]
    sim: SimArg,
    /// Output directory (default: runs/NAME).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write each (method, run) job's checkpoint to DIR/checkpoints after every N learning
    /// rounds (C-REPS updates; evaluations for the toy model, which has no policy) and when the
    /// job ends; 0: no checkpoints. A run started without --resume removes old checkpoints there.
    #[arg(long, value_name = "N", default_value_t = 10)]
    checkpoint_every: u64,
    /// Continue the run whose output directory is DIR from its checkpoints, after a crash, a
    /// kill or Ctrl-C; give the arguments the run was started with. The result is bit for bit
    /// that of an uninterrupted run.
    #[arg(long, value_name = "DIR")]
    resume: Option<PathBuf>,
    /// No progress bar.
    #[arg(long, short)]
    quiet: bool,
}

#[derive(Clone, Copy, ValueEnum)]
enum FirstVisitArg {
    InitialReturn,
    Zero,
    Optimistic,
}

#[derive(Clone, Copy, ValueEnum)]
enum MemoryArg {
    Window,
    BestPerTask,
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) if interrupted(&error) => {
            eprintln!(
                "interrupted; the run's workers were stopped and its shared memory removed (with checkpoints on, --resume DIR continues the run)"
            );
            ExitCode::from(130)
        }
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::from(2)
        }
    }
}

/// True when `error` is a fleet stopped by Ctrl-C.
fn interrupted(error: &anyhow::Error) -> bool {
    use acps::experiment::RunError;
    use acps_learner::fleet::FleetError;
    error.chain().any(|e| {
        matches!(
            e.downcast_ref::<RunError>(),
            Some(RunError::Fleet(FleetError::Interrupted))
        ) || matches!(e.downcast_ref::<FleetError>(), Some(FleetError::Interrupted))
    })
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Experiment(args) => experiment(args),
        Command::Run(args) => fleet(args),
        Command::Worker(args) => worker(args),
        Command::Bench(args) => bench(args),
    }
}

/// The experiments `args` name, with their output directories.
fn experiments(args: &ExperimentArgs) -> anyhow::Result<Vec<(Experiment, PathBuf)>> {
    if args.runs == 0 {
        bail!("--runs must be >= 1, got 0");
    }
    let methods = args
        .methods
        .iter()
        .map(|name| name.parse::<Method>())
        .collect::<Result<Vec<_>, _>>()
        .context("--method")?;
    if let Some(n_theta) = args.n_theta
        && n_theta <= 4
    {
        bail!("--n-theta must be > the context dimension (up to 4), got {n_theta}");
    }
    let options = Options {
        runs: args.runs,
        episodes: args.episodes,
        seed: args.seed,
        in_flight: args.in_flight,
        methods: (!methods.is_empty()).then_some(methods),
        overrides: Overrides {
            n_theta: args.n_theta,
            first_visit: args.first_visit.map(|f| match f {
                FirstVisitArg::InitialReturn => FirstVisit::InitialReturn,
                FirstVisitArg::Zero => FirstVisit::Zero,
                FirstVisitArg::Optimistic => FirstVisit::Optimistic,
            }),
            best_per_task: args.memory.map(|m| matches!(m, MemoryArg::BestPerTask)),
            initial_sigma: args.initial_sigma,
            xi: args.xi,
            epsilon: args.epsilon,
            learning_factors: args.fig3_learning_factors.then_some(paper::FIG3_LEARNING_FACTORS),
        },
    };
    let (name, default_dir) = match args.name {
        ExperimentName::Toy => ("toy", "runs/toy"),
        ExperimentName::Function => ("function", "runs/function"),
        ExperimentName::Dims => ("dims", "runs/dims"),
        ExperimentName::Grid => ("grid", "runs/grid"),
        ExperimentName::Dartboard => ("dartboard", "runs/dartboard"),
    };
    let sim = match args.sim {
        SimArg::Analytic => paper::Sim::Analytic,
        SimArg::Rapier => paper::Sim::Rapier,
    };
    let out = match (&args.resume, &args.out) {
        (Some(resume), Some(out)) if resume != out => {
            bail!(
                "--resume {} and --out {} name different directories; --resume DIR continues the run whose output directory is DIR",
                resume.display(),
                out.display()
            )
        }
        (Some(dir), _) | (None, Some(dir)) => dir.clone(),
        (None, None) => PathBuf::from(default_dir),
    };
    let jobs: Vec<(Experiment, PathBuf)> = match args.name {
        ExperimentName::Toy => {
            if args.n_s.is_some() {
                bail!("--n-s belongs to the dims experiment, not {name}");
            }
            let panels = match args.panel {
                Some(panel) => vec![(panel, out.clone())],
                None => "abcd".chars().map(|p| (p, out.join(p.to_string()))).collect(),
            };
            panels
                .into_iter()
                .map(|(panel, dir)| match paper::toy_panel(panel) {
                    Some(model) => Ok((paper::toy(model, &options), dir)),
                    None => bail!("--panel must be one of a, b, c, d; got '{panel}'"),
                })
                .collect::<anyhow::Result<_>>()?
        }
        ExperimentName::Function => {
            if args.panel.is_some() || args.n_s.is_some() {
                bail!("--panel and --n-s do not apply to the function experiment");
            }
            vec![(paper::function(&options), out.clone())]
        }
        ExperimentName::Dims => {
            if args.panel.is_some() {
                bail!("--panel belongs to the toy experiment, not {name}");
            }
            match args.n_s {
                Some(n_s @ 1..=4) => vec![(paper::dims(n_s, &options), out.clone())],
                Some(n_s) => bail!("--n-s must be in 1..=4, got {n_s}"),
                None => (1..=4)
                    .map(|n_s| (paper::dims(n_s, &options), out.join(format!("ns-{n_s}"))))
                    .collect(),
            }
        }
        ExperimentName::Grid | ExperimentName::Dartboard => {
            if args.panel.is_some() || args.n_s.is_some() {
                bail!("--panel and --n-s do not apply to the {name} experiment");
            }
            let experiment = match args.name {
                ExperimentName::Grid => paper::grid(sim, &options),
                _ => paper::dartboard(sim, &options),
            };
            vec![(experiment, out.clone())]
        }
    };
    Ok(jobs)
}

/// The checkpoints of the experiment that writes into `dir`, if it keeps or resumes any.
fn checkpoints(args: &ExperimentArgs, dir: &Path) -> Option<Checkpoints> {
    (args.checkpoint_every > 0 || args.resume.is_some()).then(|| Checkpoints {
        dir: dir.join("checkpoints"),
        every: args.checkpoint_every,
        resume: args.resume.is_some(),
    })
}

/// Refuse to resume where no run ever wrote checkpoints (a mistyped directory, or a run started
/// with --checkpoint-every 0).
fn check_resumable(args: &ExperimentArgs, experiments: &[(Experiment, PathBuf)]) -> anyhow::Result<()> {
    let Some(resume) = &args.resume else {
        return Ok(());
    };
    if !experiments.iter().any(|(_, dir)| dir.join("checkpoints").is_dir()) {
        bail!(
            "nothing to resume in {}: it has no checkpoints directory (was the run started with this --out and --checkpoint-every > 0?)",
            resume.display()
        );
    }
    Ok(())
}

fn experiment(args: ExperimentArgs) -> anyhow::Result<()> {
    let experiments = experiments(&args)?;
    check_resumable(&args, &experiments)?;
    for (experiment, dir) in experiments {
        let progress = progress_bar(args.quiet);
        let summary = match checkpoints(&args, &dir) {
            Some(checkpoints) => experiment
                .run_with_checkpoints(&progress, &checkpoints)
                .with_context(|| format!("experiment {}", experiment.name))?,
            None => experiment
                .run(&progress)
                .with_context(|| format!("experiment {}", experiment.name))?,
        };
        progress.finish_and_clear();
        write(&experiment, &summary, &dir, args.quiet)?;
    }
    Ok(())
}

/// Run the experiments through a fleet: this process serves the learners, `--workers` worker
/// processes simulate. Shared memory of the run is cleaned before and after, also on errors
/// and Ctrl-C.
/// Refuse a per-worker window the task service cannot hold.
fn check_worker_in_flight(option: &str, value: usize) -> anyhow::Result<()> {
    if !(1..=ipc::MAX_IN_FLIGHT_PER_WORKER).contains(&value) {
        bail!("{option} must be in 1..={}, got {value}", ipc::MAX_IN_FLIGHT_PER_WORKER);
    }
    Ok(())
}

fn fleet(args: RunArgs) -> anyhow::Result<()> {
    check_worker_in_flight("--worker-in-flight", args.worker_in_flight)?;
    let experiments = experiments(&args.experiment)?;
    check_resumable(&args.experiment, &experiments)?;
    let run = RunName::new(
        &args
            .run
            .clone()
            .unwrap_or_else(|| format!("{}-{}", experiments[0].0.name, std::process::id())),
    )?;
    // A crashed earlier run of the same name may have left resources behind; workers started by
    // hand may already be waiting, so only dead nodes are cleaned while anything is alive.
    clean_up(&run, false);
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed)).context("installing the Ctrl-C handler")?;
    let workers = args
        .workers
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let result = (|| -> anyhow::Result<()> {
        for (experiment, dir) in &experiments {
            let mut children = acps::workers::spawn(&run, workers, args.worker_in_flight)?;
            let progress = fleet_progress(args.experiment.quiet, experiment);
            let mut workers_lost = false;
            let checkpoints = checkpoints(&args.experiment, dir);
            let spin = acps::workers::spin(workers);
            let outcome = experiment.run_fleet(&run, spin, &stop, checkpoints.as_ref(), |p| {
                if acps::workers::all_exited(&mut children) {
                    workers_lost = true;
                    stop.store(true, Ordering::Relaxed);
                }
                progress.set_position(p.jobs_done as u64);
                let rate = p.outcomes as f64 / progress.elapsed().as_secs_f64().max(1e-3);
                progress.set_message(format!(
                    "{} workers, {} rollouts ({rate:.0}/s), {} re-issued",
                    p.workers, p.outcomes, p.reissued
                ));
            });
            progress.finish_and_clear();
            if workers_lost {
                bail!("all {workers} workers of run '{run}' exited before the run was done (see their messages above)");
            }
            let reaped = acps::workers::reap(&mut children);
            let (summary, report) =
                outcome.with_context(|| format!("experiment {} on run '{run}'", experiment.name))?;
            reaped?;
            if !args.experiment.quiet {
                println!(
                    "{} on {workers} workers: {} outcomes, {} re-issued, {} duplicates dropped, {} refused",
                    experiment.name, report.outcomes, report.reissued, report.duplicates, report.refused
                );
            }
            write(experiment, &summary, dir, args.experiment.quiet)?;
        }
        Ok(())
    })();
    clean_up(&run, true);
    result
}

/// Remove the run's shared memory, or, while nodes started elsewhere (workers started by hand,
/// embedding programs) are alive, only what dead nodes left: the last one out leaves a
/// management file that the next run of the same name removes. A node may appear at any moment
/// (a worker joining), which only means the files stay.
fn clean_up(run: &RunName, at_end: bool) {
    // Listing nodes can fail while one is being created or removed; then there is nothing
    // certain to remove, and the next start of the run looks again.
    let _ = ipc::clean_stale(run);
    let removed = ipc::live_nodes(run).is_ok_and(|alive| alive == 0) && ipc::remove_run_files(run).is_ok();
    if !removed && at_end {
        eprintln!("run '{run}': nodes started elsewhere are still alive; their shared memory stays until they exit");
    }
}

fn fleet_progress(quiet: bool, experiment: &Experiment) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new((experiment.methods.len() * experiment.runs) as u64);
    bar.set_style(
        ProgressStyle::with_template("{prefix} [{bar:30}] {pos}/{len} learners done, {msg}, {elapsed}")
            .expect("a valid template")
            .progress_chars("=> "),
    );
    bar.set_prefix(experiment.name.clone());
    bar
}

fn bench(args: BenchArgs) -> anyhow::Result<()> {
    if !(args.scale.is_finite() && args.scale > 0.0) {
        bail!("--scale must be finite and > 0, got {}", args.scale);
    }
    check_worker_in_flight("--worker-in-flight", args.worker_in_flight)?;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let options = acps::bench::BenchOptions {
        max_workers: args.max_workers.unwrap_or(cores),
        worker_in_flight: args.worker_in_flight,
        scale: args.scale,
    };
    println!(
        "{:<9} {:<16} {:>7} {:>14} {:>7} {:>14}",
        "env", "mode", "workers", "rollouts/s", "ratio", "learner share"
    );
    let rows = acps::bench::run(&options, |row| {
        let table = acps::bench::table(std::slice::from_ref(row));
        print!("{}", table.lines().nth(1).map(|l| format!("{l}\n")).unwrap_or_default());
    })?;
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let json = serde_json::to_string_pretty(&serde_json::json!({ "rows": rows }))?;
    let path = args.out.join("bench.json");
    std::fs::write(&path, json).with_context(|| format!("writing {}", path.display()))?;
    println!("-> {}", path.display());
    Ok(())
}

fn worker(args: WorkerArgs) -> anyhow::Result<()> {
    let run = RunName::new(&args.run)?;
    check_worker_in_flight("--in-flight", args.in_flight)?;
    if !(args.startup_timeout.is_finite() && args.startup_timeout >= 0.0) {
        bail!(
            "--startup-timeout must be finite and >= 0 seconds, got {}",
            args.startup_timeout
        );
    }
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed)).context("installing the Ctrl-C handler")?;
    let options = WorkerOptions {
        in_flight: args.in_flight,
        name: args.name.unwrap_or_else(|| format!("worker-{}", std::process::id())),
        startup_timeout: Duration::from_secs_f64(args.startup_timeout),
        spin: Duration::from_micros(args.spin_us),
    };
    let report = acps_worker::serve(&run, &options, &mut ModelFactory::default(), &stop)?;
    if !args.quiet || report.exit == WorkerExit::LearnerGone {
        eprintln!(
            "worker {}: {:?} after {} rollouts",
            options.name, report.exit, report.rollouts
        );
    }
    Ok(())
}

fn write(experiment: &Experiment, summary: &Summary, dir: &Path, quiet: bool) -> anyhow::Result<()> {
    summary
        .write(dir)
        .with_context(|| format!("writing {}", dir.join("summary.json").display()))?;
    acps::plot::write_all(summary, dir).map_err(|e| anyhow::anyhow!("plotting into {}: {e}", dir.display()))?;
    if !quiet {
        println!("{} -> {}", experiment.name, dir.join("summary.json").display());
        for (method, result) in &summary.methods {
            let fmt = |x: Option<f64>| x.map_or("n/a".to_string(), |x| format!("{x:.3}"));
            println!(
                "  {method:>20}: final {} +- {}",
                fmt(result.final_mean),
                fmt(result.final_sem)
            );
        }
    }
    Ok(())
}
