//! What each `acps` command does.

use crate::bench::BenchEvent;
use crate::checkpoints::Checkpoints;
use crate::cli::{BenchArgs, EvaluateArgs, ExperimentArgs, RunArgs, WorkerArgs};
use crate::config::{self, ExperimentFile, Job, LoadedFile, Plan};
use crate::experiment::{Experiment, Summary};
use crate::progress::Progress;
use crate::workers::ModelFactory;
use acps_fleet::Fleet;
use acps_wire::ipc::{self, RunName};
use acps_worker::{WorkerExit, WorkerOptions};
use anyhow::{Context, bail};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// True when `error` is a fleet stopped by Ctrl-C.
pub fn interrupted(error: &anyhow::Error) -> bool {
    use crate::experiment::RunError;
    use acps_fleet::FleetError;
    error.chain().any(|e| {
        matches!(
            e.downcast_ref::<RunError>(),
            Some(RunError::Fleet(FleetError::Interrupted))
        ) || matches!(e.downcast_ref::<FleetError>(), Some(FleetError::Interrupted))
    })
}

/// The experiments `args` ask for, checked, with their output directories and resolved files;
/// `None` when `--save-config` wrote the resolved file instead.
fn jobs(args: &ExperimentArgs) -> anyhow::Result<Option<Vec<Job>>> {
    let file = args.config.as_deref().map(LoadedFile::read).transpose()?;
    let plan = Plan::new(file.as_ref(), &args.settings)?;
    if let Some(path) = &args.save_config {
        plan.resolved().save_new(path)?;
        println!("{} -> {}", plan.name(), path.display());
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

pub(crate) fn experiment(args: ExperimentArgs) -> anyhow::Result<()> {
    let Some(jobs) = jobs(&args)? else {
        return Ok(());
    };
    for job in &jobs {
        job.experiment.check_in_process()?;
    }
    check_resumable(&args, &jobs)?;
    for Job {
        experiment,
        dir,
        config,
    } in jobs
    {
        let progress = Progress::of(&experiment, args.quiet);
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
pub(crate) fn fleet(args: RunArgs) -> anyhow::Result<()> {
    check_worker_in_flight("--worker-in-flight", args.worker_in_flight)?;
    let Some(jobs) = jobs(&args.experiment)? else {
        return Ok(());
    };
    if let Some(command) = &args.worker_command {
        if command.trim().is_empty() {
            bail!("--worker-command must be a command that starts your worker, got {command:?}");
        }
        if args.workers == Some(0) {
            bail!("--worker-command starts --workers W >= 1 copies of CMD; with --workers 0 it would start none");
        }
    }
    if let Some(job) = jobs.iter().find(|job| job.experiment.user_problem.is_some())
        && args.worker_command.is_none()
        && args.workers != Some(0)
    {
        bail!(
            "problem '{}' needs your workers: --worker-command CMD or --workers 0",
            job.experiment.name
        );
    }
    check_resumable(&args.experiment, &jobs)?;
    let name = args.run.clone().unwrap_or_else(|| {
        // Run names take letters, digits and '-' only; problem names also '_' and '.'.
        let experiment = jobs[0].experiment.name.replace(['_', '.'], "-");
        format!("{experiment}-{}", std::process::id())
    });
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
            builder = match &args.worker_command {
                Some(command) => builder.spawn_workers(workers, crate::workers::user_command(command.clone())),
                None => builder.spawn_workers(workers, crate::workers::command(args.worker_in_flight, workers)),
            };
            if let Some(nice) = args.worker_nice.worker_nice {
                builder = builder.worker_niceness(nice);
            }
        }
        let mut fleet = builder.start().with_context(|| format!("--run {name}"))?;
        let run = fleet.run().clone();
        if workers == 0 {
            match &experiment.user_problem {
                None => eprintln!("run '{run}' waits for workers: start them with `acps worker --run {run}`"),
                Some(_) => {
                    let environment = (experiment.instance)(experiment.base_seed).problem.environment;
                    eprintln!(
                        "run '{run}' waits for your workers: start each with {}={run} in its environment (`{}={run} CMD`); they must declare {environment}",
                        ipc::RUN_ENV,
                        ipc::RUN_ENV
                    );
                }
            }
        }
        let progress = Progress::of(experiment, args.experiment.quiet);
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

pub(crate) fn bench(args: BenchArgs) -> anyhow::Result<()> {
    if !(args.scale.is_finite() && args.scale > 0.0) {
        bail!("--scale must be finite and > 0, got {}", args.scale);
    }
    check_worker_in_flight("--worker-in-flight", args.worker_in_flight)?;
    if !(1..=100).contains(&args.rounds) {
        bail!("--rounds must be in 1..=100, got {}", args.rounds);
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let options = crate::bench::BenchOptions {
        envs: args.env,
        max_workers: args.max_workers.unwrap_or(cores),
        worker_in_flight: args.worker_in_flight,
        worker_nice: args.worker_nice.worker_nice,
        scale: args.scale,
        rounds: args.rounds,
    };
    print!("{}", crate::bench::table(&[]));
    let bar = ProgressBar::new(0).with_style(
        ProgressStyle::with_template("[{bar:25}] {pos}/{len} measurements, {msg}, {elapsed}")
            .expect("a valid template")
            .progress_chars("=> "),
    );
    let rows = crate::bench::run(&options, |event| match event {
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
            let table = crate::bench::table(std::slice::from_ref(row));
            bar.suspend(|| print!("{}", table.lines().nth(1).map(|l| format!("{l}\n")).unwrap_or_default()));
        }
    })?;
    bar.finish_and_clear();
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let json = serde_json::to_string_pretty(&serde_json::json!({ "rows": rows }))?;
    let path = args.out.join("bench.json");
    std::fs::write(&path, json).with_context(|| format!("writing {}", path.display()))?;
    crate::plot::save_bench(&rows, &args.out)
        .map_err(|e| anyhow::anyhow!("drawing {}: {e}", args.out.join("bench.svg").display()))?;
    println!("-> {} and bench.svg / bench.png", path.display());
    Ok(())
}

pub(crate) fn worker(args: WorkerArgs) -> anyhow::Result<()> {
    // Before the Ctrl-C handler's thread exists: Linux sets a niceness per thread.
    acps_fleet::processes::lower_priority(args.nice)?;
    let run = match args.run {
        Some(name) => RunName::new(&name).with_context(|| format!("--run {name}"))?,
        None => RunName::from_env().context(ipc::RUN_ENV)?.with_context(|| {
            format!(
                "--run is missing: name the run to join (the learner's --run), or set {}",
                ipc::RUN_ENV
            )
        })?,
    };
    let name = args.name.unwrap_or_else(|| format!("worker-{}", std::process::id()));
    ipc::check_worker_name(&name).map_err(|e| anyhow::anyhow!("--name {e}"))?;
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
        name,
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

pub(crate) fn evaluate(args: EvaluateArgs) -> anyhow::Result<()> {
    use crate::evaluate;
    use crate::records::{SavedPolicy, policy_file};
    let path = policy_file(&args.dir, args.method.as_deref(), args.run)?;
    let (saved, policy) = SavedPolicy::load(&path)?;
    evaluate::check_simulated(&saved, &path)?;
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
    crate::records::write(summary, dir)?;
    crate::plot::write_all(summary, dir).map_err(|e| anyhow::anyhow!("plotting into {}: {e}", dir.display()))?;
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
