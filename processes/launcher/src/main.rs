//! `acps`: the command line of Active Contextual Policy Search.

use acps::bench::BenchEvent;
use acps::checkpoints::Checkpoints;
use acps::config::{self, ExperimentFile, Job, LoadedFile, Plan};
use acps::experiment::{Experiment, Summary};
use acps::progress::Progress;
use acps::workers::ModelFactory;
use acps_fleet::Fleet;
use acps_wire::ipc::{self, RunName};
use acps_worker::{WorkerExit, WorkerOptions};
use anyhow::{Context, bail};
use clap::{Parser, Subcommand};
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
    /// More log lines on stderr: -v info, -vv debug (e.g. rejected C-REPS updates), -vvv
    /// trace. The ACPS_LOG variable takes tracing filter directives instead (e.g.
    /// ACPS_LOG=acps_learner=debug); IOX2_LOG_LEVEL sets iceoryx2's own log (default error).
    #[arg(long, short, action = clap::ArgAction::Count, global = true)]
    verbose: u8,
}

/// Log to stderr at the level -v asks for, or as ACPS_LOG says; warnings by default.
fn init_logging(verbose: u8) {
    let level = match verbose {
        0 => "warn",
        1 => "info",
        2 => "debug",
        _ => "trace",
    };
    let filter = tracing_subscriber::EnvFilter::try_from_env("ACPS_LOG")
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(level));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .init();
    ipc::quiet_iceoryx2_log();
}

#[derive(Subcommand)]
enum Command {
    /// The main job with its defaults: the PA-10 learns to throw at the grid problem's 25
    /// targets (paper Section 5.2.3) through a fleet of simulator workers (rapier3d physics),
    /// choosing targets with D-UCB and monotonic progress. Shows the test error falling and
    /// writes DIR (default runs/learn). The same as `acps run grid --sim rapier --method
    /// monotonic-progress --runs 4 --episodes 10000 --in-flight 8 --out runs/learn`.
    Learn(LearnArgs),
    /// Run one of the paper's experiments in this process, for several methods x seeds in
    /// parallel, and write DIR/summary.json, the plots and DIR/config.toml. Name the experiment
    /// (`acps experiment grid --runs 5`) or give an experiment file (`acps experiment --config
    /// experiments/grid-fig8.toml`).
    Experiment(ExperimentArgs),
    /// Run an experiment through a worker fleet: this process is the learner and serves tasks
    /// over iceoryx2 shared memory to worker processes it starts. Writes the same DIR/summary.json
    /// as `acps experiment` with the same --in-flight and --seed.
    Run(RunArgs),
    /// Serve the learner of a running fleet (`acps run ... --run NAME`) as one more worker.
    Worker(WorkerArgs),
    /// Measure rollouts per second in-process and through fleets of 1 ..= cores workers, for a
    /// trivial environment (the transport's cost) and the analytic and rapier PA-10, in
    /// interleaved rounds; print a table and write DIR/bench.json, bench.svg and bench.png.
    Bench(BenchArgs),
    /// Replay a learned policy from a run directory greedily (its mean, exploration off) at
    /// --target points or at the problem's test contexts, printing the landing point, error and
    /// reward of every throw (the return of every context for the contextual function).
    Evaluate(EvaluateArgs),
}

#[derive(clap::Args)]
struct EvaluateArgs {
    /// A run directory written by `acps experiment` or `acps run` (or one of its
    /// policies/METHOD-runR.json files).
    dir: PathBuf,
    /// The method whose policy to replay (default: the first by name).
    #[arg(long)]
    method: Option<String>,
    /// The run whose policy to replay (default 0).
    #[arg(long)]
    run: Option<usize>,
    /// A target X,Y to throw at (repeatable; default: the problem's test contexts).
    #[arg(long, value_name = "X,Y", allow_hyphen_values = true, value_parser = acps::evaluate::parse_target)]
    target: Vec<Vec<f64>>,
    /// Draw the side view of the first throw into FILE (.svg or .png).
    #[arg(long, value_name = "FILE")]
    render: Option<PathBuf>,
}

#[derive(clap::Args)]
struct LearnArgs {
    /// Worker processes (default: the number of cores).
    #[arg(long)]
    workers: Option<usize>,
    /// Independent learning runs (seeds 0 .. runs - 1), for the SEM band of the curve.
    #[arg(long, default_value_t = 4)]
    runs: usize,
    /// Training episodes (throws) per run.
    #[arg(long, default_value_t = 10_000)]
    episodes: u64,
    /// How throws are simulated.
    #[arg(long, value_enum, default_value = "rapier")]
    sim: config::SimName,
    /// Output directory.
    #[arg(long, default_value = "runs/learn")]
    out: PathBuf,
    /// The run's name, for workers started by hand to join (default: grid-PID).
    #[arg(long)]
    run: Option<String>,
    /// No progress line.
    #[arg(long, short)]
    quiet: bool,
}

impl LearnArgs {
    /// The `acps run` this stands for.
    fn run_args(self) -> RunArgs {
        let settings = ExperimentFile {
            experiment: Some(config::ExperimentName::Grid),
            sim: Some(self.sim),
            runs: Some(self.runs),
            episodes: Some(self.episodes),
            in_flight: Some(8),
            methods: Some(vec![acps_learner::Method::MonotonicProgress]),
            ..ExperimentFile::default()
        };
        RunArgs {
            experiment: ExperimentArgs {
                config: None,
                settings,
                save_config: None,
                out: Some(self.out),
                checkpoint_every: DEFAULT_CHECKPOINT_EVERY,
                resume: None,
                quiet: self.quiet,
            },
            workers: self.workers,
            worker_in_flight: DEFAULT_WORKER_IN_FLIGHT,
            worker_nice: WorkerNiceArg { worker_nice: None },
            run: self.run,
        }
    }
}

#[derive(clap::Args)]
struct BenchArgs {
    /// Output directory.
    #[arg(long, default_value = "runs/bench")]
    out: PathBuf,
    /// Largest fleet (default: the number of cores).
    #[arg(long)]
    max_workers: Option<usize>,
    /// Tasks each worker keeps in flight, asked for or queued (1..=128; at most 8 of rollouts
    /// slower than a batch's 800 us, which travel alone).
    #[arg(long, default_value_t = 128)]
    worker_in_flight: usize,
    /// Multiplies the work per measurement (1: a few seconds per row and round; the default
    /// bench takes about a minute on 2 cores).
    #[arg(long, default_value_t = 1.0)]
    scale: f64,
    /// Times every mode is measured, interleaved (1..=100): rows report the median round, and
    /// the table the range of the ratio over rounds.
    #[arg(long, default_value_t = 3)]
    rounds: usize,
    /// Environments to measure, comma separated.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "trivial,analytic,rapier")]
    env: Vec<acps::bench::BenchEnv>,
    #[command(flatten)]
    worker_nice: WorkerNiceArg,
}

/// `--worker-nice` of `acps run` and `acps bench`.
#[derive(clap::Args)]
struct WorkerNiceArg {
    /// Niceness of the started workers (0..=19; default: 10 when the workers and the learner
    /// outnumber the cores, else 0). The learner gates every worker, so it should get a core as
    /// soon as it wakes; 0 keeps the workers at full priority next to other programs.
    #[arg(long, value_parser = clap::value_parser!(u8).range(0..=acps_fleet::processes::MAX_NICE as i64))]
    worker_nice: Option<u8>,
}

#[derive(clap::Args)]
struct RunArgs {
    #[command(flatten)]
    experiment: ExperimentArgs,
    /// Worker processes to start (default: the number of cores).
    #[arg(long)]
    workers: Option<usize>,
    /// Tasks each started worker keeps in flight, asked for or queued (1..=128; at most 8 of
    /// rollouts slower than a batch's 800 us, which travel alone).
    #[arg(long, default_value_t = DEFAULT_WORKER_IN_FLIGHT)]
    worker_in_flight: usize,
    #[command(flatten)]
    worker_nice: WorkerNiceArg,
    /// The run's name (letters, digits and '-'): its shared-memory prefix, and how workers
    /// started by hand join it (default: EXPERIMENT-PID).
    #[arg(long)]
    run: Option<String>,
}

#[derive(clap::Args)]
struct WorkerArgs {
    /// The run to join (the learner's --run) [default: the ACPS_RUN environment variable, which
    /// a learner sets for the workers it starts].
    #[arg(long)]
    run: Option<String>,
    /// Tasks kept in flight, asked for or queued (1..=128): more hides the wake-up latency
    /// between processes; cheap rollouts travel in batches of up to half of them, and at most 8
    /// of rollouts slower than a batch's 800 us, which travel alone, are in flight.
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
    /// Lower this worker's priority to niceness N (0..=19), so that a learner sharing its
    /// cores gets the CPU first; a worker already at N or above keeps its niceness.
    #[arg(long, value_name = "N", default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=acps_fleet::processes::MAX_NICE as i64))]
    nice: u8,
    /// Print nothing unless something goes wrong.
    #[arg(long, short)]
    quiet: bool,
}

#[derive(clap::Args)]
struct ExperimentArgs {
    /// Read the experiment from an experiment file (one per paper figure in experiments/); options
    /// given as well override the file's values.
    #[arg(long, short, value_name = "FILE")]
    config: Option<PathBuf>,
    #[command(flatten)]
    settings: ExperimentFile,
    /// Write the resolved experiment file (every setting, defaults filled in) to FILE and exit
    /// without running; `--config FILE` runs it. Every run also writes DIR/config.toml.
    #[arg(long, value_name = "FILE")]
    save_config: Option<PathBuf>,
    /// Output directory [default: runs/NAME, or runs/STEM for --config STEM.toml].
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write each (method, run) job's checkpoint to DIR/checkpoints after every N learning
    /// rounds (C-REPS updates; evaluations for the toy model, which has no policy) and when the
    /// job ends; 0: no checkpoints. A run started without --resume removes old checkpoints there.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_CHECKPOINT_EVERY)]
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

/// Default of `acps run --worker-in-flight`.
const DEFAULT_WORKER_IN_FLIGHT: usize = 4;
/// Default of `--checkpoint-every`.
const DEFAULT_CHECKPOINT_EVERY: u64 = 10;

fn main() -> ExitCode {
    let cli = Cli::parse();
    init_logging(cli.verbose);
    match run(cli) {
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
    use acps_fleet::FleetError;
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
        Command::Learn(args) => fleet(args.run_args()),
        Command::Run(args) => fleet(args),
        Command::Worker(args) => worker(args),
        Command::Bench(args) => bench(args),
        Command::Evaluate(args) => evaluate(args),
    }
}

/// The experiments `args` ask for, checked, with their output directories and resolved files;
/// `None` when `--save-config` wrote the resolved file instead.
fn jobs(args: &ExperimentArgs) -> anyhow::Result<Option<Vec<Job>>> {
    let file = args.config.as_deref().map(LoadedFile::read).transpose()?;
    let plan = Plan::new(file.as_ref(), &args.settings)?;
    if let Some(path) = &args.save_config {
        plan.resolved().save_new(path)?;
        println!("{} -> {}", plan.name().name(), path.display());
        return Ok(None);
    }
    let out = match (&args.resume, &args.out) {
        (Some(resume), Some(out)) if resume != out => {
            bail!(
                "--resume {} and --out {} name different directories; --resume DIR continues the run whose output directory is DIR",
                resume.display(),
                out.display()
            )
        }
        (Some(dir), _) | (None, Some(dir)) => dir.clone(),
        (None, None) => config::default_out(args.config.as_deref(), plan.name()),
    };
    Ok(Some(plan.jobs(&out)))
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
fn check_resumable(args: &ExperimentArgs, jobs: &[Job]) -> anyhow::Result<()> {
    let Some(resume) = &args.resume else {
        return Ok(());
    };
    if !jobs.iter().any(|job| job.dir.join("checkpoints").is_dir()) {
        bail!(
            "nothing to resume in {}: it has no checkpoints directory (was the run started with this --out and --checkpoint-every > 0?)",
            resume.display()
        );
    }
    Ok(())
}

fn experiment(args: ExperimentArgs) -> anyhow::Result<()> {
    let Some(jobs) = jobs(&args)? else {
        return Ok(());
    };
    check_resumable(&args, &jobs)?;
    for Job {
        experiment,
        dir,
        config,
    } in jobs
    {
        let progress = Progress::new(&experiment.name, args.quiet);
        let summary = match checkpoints(&args, &dir) {
            Some(checkpoints) => experiment.run_with_checkpoints(&progress, &checkpoints),
            None => experiment.run(&progress),
        }
        .with_context(|| format!("experiment {}", experiment.name))?;
        progress.finish();
        write(&experiment, &summary, &dir, &config, args.quiet)?;
    }
    Ok(())
}

/// Refuse a per-worker window the task service cannot hold.
fn check_worker_in_flight(option: &str, value: usize) -> anyhow::Result<()> {
    if !(1..=ipc::MAX_IN_FLIGHT_PER_WORKER).contains(&value) {
        bail!("{option} must be in 1..={}, got {value}", ipc::MAX_IN_FLIGHT_PER_WORKER);
    }
    Ok(())
}

/// Run the experiments through a fleet: this process serves the learners, `--workers` worker
/// processes simulate. The fleet removes the run's shared memory when it ends, also on errors
/// and Ctrl-C.
fn fleet(args: RunArgs) -> anyhow::Result<()> {
    check_worker_in_flight("--worker-in-flight", args.worker_in_flight)?;
    let Some(jobs) = jobs(&args.experiment)? else {
        return Ok(());
    };
    check_resumable(&args.experiment, &jobs)?;
    let name = args
        .run
        .clone()
        .unwrap_or_else(|| format!("{}-{}", jobs[0].experiment.name, std::process::id()));
    let workers = args
        .workers
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    for Job {
        experiment,
        dir,
        config,
    } in &jobs
    {
        let mut builder = Fleet::builder(name.as_str())
            .identity(experiment.identity())
            .ctrl_c(true);
        if workers > 0 {
            builder = builder.spawn_workers(workers, acps::workers::command(args.worker_in_flight, workers));
            if let Some(nice) = args.worker_nice.worker_nice {
                builder = builder.worker_niceness(nice);
            }
        }
        let mut fleet = builder.start().with_context(|| format!("--run {name}"))?;
        let run = fleet.run().clone();
        if workers == 0 {
            eprintln!("run '{run}' waits for workers: start them with `acps worker --run {run}`");
        }
        let progress = Progress::new(&experiment.name, args.experiment.quiet);
        let checkpoints = checkpoints(&args.experiment, dir);
        let outcome = experiment.run_fleet(&mut fleet, checkpoints.as_ref(), |p| {
            progress.show(&p.learning, p.outcomes, Some(p.workers));
        });
        progress.finish();
        let (summary, report) = outcome.with_context(|| format!("experiment {} on run '{run}'", experiment.name))?;
        if !args.experiment.quiet {
            println!(
                "{} on {workers} workers: {} outcomes, {} re-issued, {} duplicates dropped, {} refused",
                experiment.name, report.outcomes, report.reissued, report.duplicates, report.refused
            );
        }
        write(experiment, &summary, dir, config, args.experiment.quiet)?;
    }
    Ok(())
}

fn bench(args: BenchArgs) -> anyhow::Result<()> {
    if !(args.scale.is_finite() && args.scale > 0.0) {
        bail!("--scale must be finite and > 0, got {}", args.scale);
    }
    check_worker_in_flight("--worker-in-flight", args.worker_in_flight)?;
    if !(1..=100).contains(&args.rounds) {
        bail!("--rounds must be in 1..=100, got {}", args.rounds);
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let options = acps::bench::BenchOptions {
        envs: args.env,
        max_workers: args.max_workers.unwrap_or(cores),
        worker_in_flight: args.worker_in_flight,
        worker_nice: args.worker_nice.worker_nice,
        scale: args.scale,
        rounds: args.rounds,
    };
    print!("{}", acps::bench::table(&[]));
    let bar = ProgressBar::new(0).with_style(
        ProgressStyle::with_template("[{bar:25}] {pos}/{len} measurements, {msg}, {elapsed}")
            .expect("a valid template")
            .progress_chars("=> "),
    );
    let rows = acps::bench::run(&options, |event| match event {
        BenchEvent::Measuring {
            env,
            mode,
            workers,
            round,
            index,
            total,
        } => {
            bar.set_length(total as u64);
            bar.set_position(index as u64);
            bar.set_message(format!("{env} {mode} {workers}, round {round}"));
        }
        BenchEvent::Row(row) => {
            let table = acps::bench::table(std::slice::from_ref(row));
            bar.suspend(|| print!("{}", table.lines().nth(1).map(|l| format!("{l}\n")).unwrap_or_default()));
        }
    })?;
    bar.finish_and_clear();
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let json = serde_json::to_string_pretty(&serde_json::json!({ "rows": rows }))?;
    let path = args.out.join("bench.json");
    std::fs::write(&path, json).with_context(|| format!("writing {}", path.display()))?;
    acps::plot::save_bench(&rows, &args.out)
        .map_err(|e| anyhow::anyhow!("drawing {}: {e}", args.out.join("bench.svg").display()))?;
    println!("-> {} and bench.svg / bench.png", path.display());
    Ok(())
}

fn worker(args: WorkerArgs) -> anyhow::Result<()> {
    // Before the Ctrl-C handler's thread exists: Linux sets a niceness per thread.
    acps_fleet::processes::lower_priority(args.nice)?;
    let run = match args.run {
        Some(name) => RunName::new(&name)?,
        None => RunName::from_env()?.with_context(|| {
            format!(
                "--run is missing: name the run to join (the learner's --run), or set {}",
                ipc::RUN_ENV
            )
        })?,
    };
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
    let report = acps_worker::serve(&run, &options, &mut ModelFactory::default(), &stop)
        .with_context(|| format!("joining run '{run}' (its learner: `acps run ... --run {run}`)"))?;
    if !args.quiet || report.exit == WorkerExit::LearnerGone {
        eprintln!(
            "worker {}: {:?} after {} rollouts",
            options.name, report.exit, report.rollouts
        );
    }
    Ok(())
}

fn evaluate(args: EvaluateArgs) -> anyhow::Result<()> {
    use acps::evaluate;
    use acps::records::{SavedPolicy, policy_file};
    let path = policy_file(&args.dir, args.method.as_deref(), args.run)?;
    let (saved, policy) = SavedPolicy::load(&path)?;
    evaluate::check_targets(&saved, &args.target)?;
    if let Some(file) = &args.render {
        evaluate::check_render(&saved, file)?;
    }
    let test_set = args.target.is_empty();
    let contexts = if test_set {
        saved.problem.test_contexts.clone()
    } else {
        args.target
    };
    let replay =
        evaluate::replay(&saved, &policy, &contexts).with_context(|| format!("replaying {}", path.display()))?;
    print!("{}", evaluate::report(&saved, &replay, test_set));
    if let Some(file) = args.render {
        let first = replay.throws.first().context("--render: there is no throw to draw")?;
        evaluate::render(&saved, first, &file)?;
        println!("-> {}", file.display());
    }
    Ok(())
}

fn write(
    experiment: &Experiment,
    summary: &Summary,
    dir: &Path,
    config: &ExperimentFile,
    quiet: bool,
) -> anyhow::Result<()> {
    summary
        .write(dir)
        .with_context(|| format!("writing {}", dir.join("summary.json").display()))?;
    config.write_resolved(dir)?;
    acps::records::write(summary, dir)?;
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
