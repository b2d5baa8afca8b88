//! What each `acps` command does.

use crate::bench::BenchEvent;
use crate::cli::{self, BenchArgs, Command, EvaluateArgs, ExperimentArgs, RunArgs, StartedWorkers, WorkerArgs};
use acps_experiments::checkpoints::Checkpoints;
use acps_experiments::experiment::RunError;
use acps_experiments::file::LoadedFile;
use acps_experiments::plan::{Job, Plan};
use acps_experiments::run_dir::{self, RunDir, RunDirError, RunReport};
use acps_experiments::summary::Summary;
use acps_experiments::workers::ModelFactory;
use acps_fleet::{Fleet, FleetBuilder, FleetError};
use acps_shared::Serves;
use acps_wire::ipc::{self, RunName};
use acps_wire::wire;
use acps_worker::{WorkerExit, WorkerOptions};
use anyhow::{Context, bail};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// `error` and its causes, `: `-separated as `{error:#}` prints them, but without a cause whose
/// words the message before it already ends with (an error that shows its source's text and
/// also gives it as its source would otherwise say its reason twice).
pub(crate) fn described(error: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in error.chain() {
        let cause = cause.to_string();
        if text.is_empty() {
            text = cause;
        } else if !text.ends_with(&cause) {
            text = format!("{text}: {cause}");
        }
    }
    text
}

/// How a run that wrote checkpoints ended early: stopped by Ctrl-C, or failed. Its message
/// carries the exact command that continues the run, when its checkpoints allow it.
#[derive(Debug, thiserror::Error)]
pub enum Stopped {
    /// Ctrl-C (SIGINT, SIGTERM or SIGHUP).
    #[error(
        "interrupted; {}{}",
        if *fleet { "the run's workers were stopped and its shared memory removed; " } else { "" },
        continue_hint(resume.as_deref())
    )]
    Interrupted {
        /// The command that continues the run (`None`: it wrote no checkpoints).
        resume: Option<String>,
        /// Whether the run served a fleet.
        fleet: bool,
    },
    /// The reader of this command's output closed it: nothing more to say.
    #[error("the output was closed")]
    Closed,
    /// Ctrl-C of a relay: its workers were stopped; the learner hands their tasks to others.
    #[error(
        "interrupted; this host's workers were stopped and its shared memory removed; the learner hands their tasks to other hosts"
    )]
    // Made by `acps relay`, which only a build with the `hosts` feature carries out.
    #[cfg_attr(not(feature = "hosts"), allow(dead_code))]
    RelayInterrupted,
    /// Any other error, after which the checkpoints written so far continue the run.
    #[error("{}\n{}", described(error), continue_hint(Some(resume)))]
    Failed {
        /// What went wrong.
        error: anyhow::Error,
        /// The command that continues the run.
        resume: String,
    },
}

/// The run `--run` names, if it names one.
pub(crate) fn run_name(arg: Option<&str>) -> anyhow::Result<Option<RunName>> {
    arg.map(|name| RunName::new(name).with_context(|| format!("--run {name}")))
        .transpose()
}

/// Write `text` to stdout. A reader that closed it (`acps protocol | head`) ends the command
/// quietly ([`Stopped::Closed`]) instead of a panic of `print!`.
pub(crate) fn out(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    match stdout.write_all(text.as_bytes()).and_then(|()| stdout.flush()) {
        Err(error) if error.kind() == std::io::ErrorKind::BrokenPipe => Err(Stopped::Closed.into()),
        written => Ok(written.context("writing to standard output")?),
    }
}

fn continue_hint(resume: Option<&str>) -> String {
    match resume {
        Some(command) => format!("the checkpoints written so far continue the run with\n  {command}"),
        None => "the run wrote no checkpoints (--checkpoint-every 0) and cannot be continued".into(),
    }
}

/// The command line this process was started with, with `--resume DIR` in place of any
/// `--resume` it had: the exact command that continues the run writing into `dir`.
fn continue_command(dir: &Path) -> String {
    resumed(crate::command_line().iter().cloned(), dir)
}

/// The command `args` (the program first) with `--resume dir` in place of any `--resume`, as a
/// shell reads it.
fn resumed(mut args: impl Iterator<Item = String>, dir: &Path) -> String {
    let mut command: Vec<String> = args.next().into_iter().collect();
    let mut args = args.peekable();
    while let Some(arg) = args.next() {
        if arg == "--resume" {
            // `acps learn --resume` may stand without its value.
            args.next_if(|value| !value.starts_with('-'));
        } else if !arg.starts_with("--resume=") {
            command.push(arg);
        }
    }
    command.extend(["--resume".to_string(), dir.display().to_string()]);
    command
        .iter()
        .map(|arg| shell_quoted(arg))
        .collect::<Vec<_>>()
        .join(" ")
}

/// `arg` as a POSIX shell reads it back: bare when it holds no special characters, else in
/// single quotes.
fn shell_quoted(arg: &str) -> String {
    let plain = |c: char| c.is_ascii_alphanumeric() || "-_./,:=@%+".contains(c);
    if !arg.is_empty() && arg.chars().all(plain) {
        arg.to_string()
    } else {
        format!("'{}'", arg.replace('\'', r"'\''"))
    }
}

/// `error` of a job of the run whose output directory is `out`, as the user should read it:
/// with the command that continues the run when the job keeps checkpoints.
fn stopped(
    error: impl Into<anyhow::Error>,
    checkpoints: Option<&Checkpoints>,
    out: &Path,
    fleet: bool,
) -> anyhow::Error {
    let error = error.into();
    let checkpoints = checkpoints.filter(|c| c.every > 0);
    let resume = checkpoints.map(|_| continue_command(out));
    if interrupted(&error) {
        return Stopped::Interrupted { resume, fleet }.into();
    }
    // A fleet can fail half-way (its workers gone or silent); other errors happen before the
    // run starts or concern the checkpoints themselves. Workers the learner refused would be
    // refused again by the same run resumed, and workers that never connected would hang it
    // again: they, or the problem, must change first.
    let fleet_failed = run_errors(&error).any(|e| {
        matches!(e, RunError::Fleet(_))
            && !matches!(
                e,
                RunError::Fleet(FleetError::NoWorkers { refused: Some(_), .. } | FleetError::NeverConnected { .. })
            )
    });
    match resume {
        Some(resume) if fleet_failed && checkpoints.is_some_and(|c| c.dir.is_dir()) => {
            Stopped::Failed { error, resume }.into()
        }
        _ => error,
    }
}

/// The experiments' own errors in `error`'s chain, also inside a run directory's.
fn run_errors(error: &anyhow::Error) -> impl Iterator<Item = &RunError> {
    error.chain().filter_map(|e| {
        e.downcast_ref::<RunError>()
            .or_else(|| e.downcast_ref::<RunDirError>().and_then(RunDirError::run_error))
    })
}

/// True when `error` is a run stopped by Ctrl-C.
fn interrupted(error: &anyhow::Error) -> bool {
    run_errors(error).any(|e| matches!(e, RunError::Fleet(FleetError::Interrupted) | RunError::Interrupted))
        || error
            .chain()
            .any(|e| matches!(e.downcast_ref::<FleetError>(), Some(FleetError::Interrupted)))
}

/// The run directory `args` ask for, checked (its settings, memory, methods and what it resumes
/// from); `None` when `--save-config` wrote the resolved file instead.
fn run_dir(args: &ExperimentArgs) -> anyhow::Result<Option<RunDir>> {
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
        (resume, out) => resume.as_ref().or(out.as_ref()).cloned(),
    };
    let run = RunDir {
        progress_every: Duration::from_secs_f64(args.progress_every),
        max_failed_share: args.max_failed_share,
        replace: args.force,
        ..RunDir::of(&plan, args.config.as_deref(), out)?
    };
    Ok(Some(run.checkpointing(args.checkpoint_every, args.resume.is_some())?))
}

/// The pictures of a run directory.
fn pictures(summary: &Summary, dir: &Path) -> Result<(), Box<dyn std::error::Error>> {
    acps_reports::plot::write_all(summary, dir)
}

/// Set by the Ctrl-C handler of `acps experiment`.
static STOP: AtomicBool = AtomicBool::new(false);

pub(crate) fn experiment(args: ExperimentArgs) -> anyhow::Result<()> {
    let Some(run) = run_dir(&args)? else {
        return Ok(());
    };
    for job in &run.jobs {
        job.experiment.check_in_process()?;
    }
    run.prepare()?;
    ctrlc::set_handler(|| STOP.store(true, Ordering::Relaxed)).context("installing the Ctrl-C handler")?;
    let checkpoints = run.checkpoints(&run.out);
    run.in_process(args.quiet, &STOP, &pictures)
        .map_err(|e| stopped(e, checkpoints.as_ref(), &run.out, false))?;
    Ok(())
}

/// Run the experiments through a fleet: this process serves the learners, `--workers` worker
/// processes simulate. The fleet removes the run's shared memory when it ends, also on errors
/// and Ctrl-C.
pub(crate) fn fleet(args: RunArgs) -> anyhow::Result<()> {
    // Before the output directory is made.
    let run = run_name(args.run.as_deref())?;
    let hosts = crate::hosts::plan(&args.net, &args.listen)?;
    let Some(planned) = run_dir(&args.experiment)? else {
        return Ok(());
    };
    let (out, jobs) = (&planned.out, &planned.jobs);
    args.started.check()?;
    if let Some(job) = jobs.iter().find(|job| job.experiment.user_problem.is_some())
        && args.started.worker_command.is_none()
        && args.started.workers != Some(0)
    {
        bail!(
            "problem '{}' needs your workers: --worker-command CMD or --workers 0",
            job.experiment.name
        );
    }
    let created = planned.prepare()?;
    let name = match run {
        Some(run) => run,
        None => {
            // Run names take letters, digits and '-' only; problem names also '_' and '.'.
            let experiment = jobs[0].experiment.name.replace(['_', '.'], "-");
            let name = format!("{experiment}-{}", std::process::id());
            match RunName::new(&name) {
                Ok(run) => run,
                Err(error) => {
                    for dir in &created {
                        let _ = std::fs::remove_dir_all(dir);
                    }
                    return Err(anyhow::Error::new(error).context(format!("--run {name}")));
                }
            }
        }
    };
    let workers = args.started.count();
    // Once, for every experiment of the run: relays stay connected from one to the next.
    let mut listener = match hosts
        .map(|plan| plan.open(&args.net, &name, out, args.experiment.quiet))
        .transpose()
    {
        Ok(listener) => listener,
        Err(error) => {
            for dir in &created {
                let _ = std::fs::remove_dir_all(dir);
            }
            return Err(error);
        }
    };
    for (index, Job { experiment, dir, .. }) in jobs.iter().enumerate() {
        let builder = Fleet::builder(name.clone())
            .identity(experiment.identity())
            .ctrl_c(true);
        let mut fleet = match args.started.spawn(builder).start() {
            Ok(fleet) => fleet,
            Err(error) => {
                // Refused before anything ran (the run is taken, say): leave no empty directory.
                if index == 0 {
                    for dir in &created {
                        let _ = std::fs::remove_dir_all(dir);
                    }
                }
                return Err(anyhow::Error::new(error).context(format!("--run {name}")));
            }
        };
        let run = fleet.run().clone();
        if workers == 0 && listener.is_none() {
            match &experiment.user_problem {
                None => eprintln!("run '{run}' waits for workers: start them with `acps worker --run {run}`"),
                Some(_) => {
                    let environment = (experiment.instance)(experiment.base_seed).problem.environment;
                    eprintln!(
                        "run '{run}' waits for your workers: start each with {}={run} in its environment (`{}={run} CMD`); they must declare {}",
                        ipc::RUN_ENV,
                        ipc::RUN_ENV,
                        wire::serves_shown(&Serves::One(environment))
                    );
                }
            }
        }
        let progress = experiment.progress(args.experiment.quiet, planned.progress_every);
        let checkpoints = planned.checkpoints(dir);
        let remote = listener.as_deref_mut().map(|l| l as &mut dyn acps_fleet::Remote);
        let outcome = experiment.run_fleet(&mut fleet, checkpoints.as_ref(), remote, |p| {
            progress.show(&p.learning, p.outcomes, Some(p.workers));
        });
        match &outcome {
            Ok((summary, _)) => progress.finish(summary),
            Err(_) => progress.abandon(),
        }
        let (summary, fleet_progress) = outcome
            .with_context(|| format!("experiment {} on run '{run}'", experiment.name))
            .map_err(|e| stopped(e, checkpoints.as_ref(), out, true))?;
        let report =
            RunReport::of(&progress, &summary, Some(&fleet_progress), planned.resume).with_relays(listener.is_some());
        run_dir::write(experiment, &summary, &report, dir, args.experiment.quiet, &pictures)?;
        run_dir::check_failures(experiment, &summary, dir, planned.max_failed_share)?;
    }
    Ok(())
}

pub(crate) fn bench(args: BenchArgs) -> anyhow::Result<()> {
    run_dir::output_dir(&args.out)?;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let options = crate::bench::BenchOptions {
        envs: args.env,
        max_workers: args.max_workers.unwrap_or(cores.min(ipc::MAX_WORKERS)),
        worker_queue_depth: {
            args.deprecated.warn();
            args.deprecated.or(args.worker_queue_depth)
        },
        worker_nice: args.worker_nice.worker_nice,
        scale: args.scale,
        rounds: args.rounds,
        relay: args.relay,
    };
    if options.relay {
        crate::hosts::available("acps bench --relay")?;
    }
    let long_run = options.envs.contains(&crate::bench::BenchEnv::LongRun);
    let throughput = options.envs.len() > usize::from(long_run);
    if throughput {
        print!("{}", crate::bench::table(&[]));
    }
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
    let mut long_runs = Vec::new();
    if long_run {
        bar.suspend(|| print!("{}", crate::bench::long_run_table(&[])));
        for round in 1..=options.rounds {
            let run = crate::bench::long_run(options.scale, |done, episodes| {
                bar.set_message(format!("long run, round {round}: {done} of {episodes} episodes"));
                bar.tick();
            })?;
            let table = crate::bench::long_run_table(std::slice::from_ref(&run));
            bar.suspend(|| print!("{}", table.lines().nth(1).map(|l| format!("{l}\n")).unwrap_or_default()));
            long_runs.push(run);
        }
    }
    bar.finish_and_clear();
    let json = serde_json::to_string_pretty(&serde_json::json!({ "rows": rows, "long_run": long_runs }))?;
    let path = args.out.join("bench.json");
    std::fs::write(&path, json).with_context(|| format!("writing {}", path.display()))?;
    if throughput {
        acps_reports::plot::save_bench(&rows, &args.out)
            .map_err(|e| anyhow::anyhow!("drawing {}: {e}", args.out.join("bench.svg").display()))?;
        println!("-> {} and bench.svg / bench.png", path.display());
    } else {
        println!("-> {}", path.display());
    }
    if let Some(warning) = crate::bench::busy_warning(&rows) {
        eprintln!("{warning}");
    }
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
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed)).context("installing the Ctrl-C handler")?;
    let options = WorkerOptions {
        queue_depth: cli::deprecated("--in-flight", "--queue-depth", args.in_flight).unwrap_or(args.queue_depth),
        name,
        startup_timeout: Duration::from_secs_f64(args.startup_timeout),
        spin: Duration::from_micros(args.spin_us),
        // It builds whichever model a task names, of whatever sizes, and simulates one task at
        // a time.
        sizes: None,
        batches: false,
    };
    let report = acps_worker::serve(&run, &options, &mut ModelFactory::default(), &stop)
        .with_context(|| format!("joining run '{run}' (its learner: `acps run ... --run {run}`)"))?;
    // A quiet worker speaks up when its learner vanished, unless Ctrl-C (which a shell sends
    // to the learner and its workers alike) stopped it too: the learner says what happened.
    let gone = report.exit == WorkerExit::LearnerGone && !stop.load(Ordering::Relaxed);
    if !args.quiet || gone {
        eprintln!(
            "worker {}: {:?} after {} rollouts",
            options.name, report.exit, report.rollouts
        );
    }
    Ok(())
}

impl StartedWorkers {
    /// Refuse a --worker-command that starts nothing. Also warns, once, of a deprecated option.
    pub(crate) fn check(&self) -> anyhow::Result<()> {
        self.deprecated.warn();
        if let Some(command) = &self.worker_command {
            if command.trim().is_empty() {
                bail!("--worker-command must be a command that starts your worker, got {command:?}");
            }
            if self.workers == Some(0) {
                bail!("--worker-command starts --workers W >= 1 copies of CMD; with --workers 0 it would start none");
            }
        }
        Ok(())
    }

    /// How many workers to start: --workers, or the cores (at most a fleet's most).
    pub(crate) fn count(&self) -> usize {
        self.workers.unwrap_or_else(|| {
            std::thread::available_parallelism()
                .map_or(1, |n| n.get())
                .min(ipc::MAX_WORKERS)
        })
    }

    /// `builder`, starting these workers.
    pub(crate) fn spawn(&self, mut builder: FleetBuilder) -> FleetBuilder {
        let workers = self.count();
        if workers > 0 {
            builder = match &self.worker_command {
                Some(command) => {
                    builder.spawn_workers(workers, acps_experiments::workers::user_command(command.clone()))
                }
                None => builder.spawn_workers(
                    workers,
                    acps_experiments::workers::command(self.deprecated.or(self.worker_queue_depth), workers),
                ),
            };
            if let Some(nice) = self.worker_nice.worker_nice {
                builder = builder.worker_niceness(nice);
            }
            builder = builder.worker_startup(Duration::from_secs_f64(self.worker_startup_timeout));
        }
        builder
    }
}

pub(crate) fn evaluate(args: EvaluateArgs) -> anyhow::Result<()> {
    use crate::evaluate;
    use acps_experiments::records::{SavedPolicy, policy_file};
    let path = policy_file(&args.dir, args.method.as_deref(), args.run)?;
    let (saved, policy) = SavedPolicy::load(&path)?;
    if path != args.dir {
        saved.check_name(&path)?;
    }
    evaluate::check_simulated(&saved, &path)?;
    let mut environment = evaluate::rebuild(&saved, &path)?;
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
    let replay = evaluate::replay(&saved, &policy, environment.as_mut(), &contexts)
        .with_context(|| format!("replaying {}", path.display()))?;
    out(&evaluate::report(&saved, &replay, test_set))?;
    if let Some(file) = args.render {
        let first = replay.throws.first().context("--render: there is no throw to draw")?;
        evaluate::render(&saved, first, &file)?;
        println!("-> {}", file.display());
    }
    Ok(())
}

/// Carry out `command`.
pub(crate) fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Experiment(args) => experiment(args),
        Command::Learn(args) => fleet(args.run_args()),
        Command::Run(args) => fleet(args),
        Command::Worker(args) => worker(args),
        Command::Relay(args) => crate::hosts::relay(args),
        Command::Bench(args) => bench(args),
        Command::Evaluate(args) => evaluate(args),
        Command::Compare(args) => {
            let report = acps_reports::compare::run(
                &args.dir,
                &args.with,
                args.baseline.as_deref(),
                args.levels.as_deref(),
                match (args.json, args.wide) {
                    (true, _) => acps_reports::compare::Layout::Json,
                    (false, true) => acps_reports::compare::Layout::Wide,
                    (false, false) => acps_reports::compare::Layout::Long,
                },
            )?;
            out(&report)
        }
        Command::Protocol => out(&(serde_json::to_string_pretty(&acps_wire::layout::describe())? + "\n")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_error_that_shows_its_source_says_its_reason_once() {
        #[derive(Debug, thiserror::Error)]
        #[error("checkpoint x.ckpt: {source}")]
        struct Shows {
            source: std::io::Error,
        }
        let error = anyhow::Error::new(Shows {
            source: std::io::Error::other("not a regular file but a FIFO"),
        })
        .context("experiment bowl");
        assert_eq!(format!("{error:#}").matches("FIFO").count(), 2);
        assert_eq!(
            described(&error),
            "experiment bowl: checkpoint x.ckpt: not a regular file but a FIFO"
        );
        // Causes the message does not show yet are kept.
        let error = anyhow::anyhow!("gone").context("reading x").context("experiment bowl");
        assert_eq!(described(&error), "experiment bowl: reading x: gone");
    }

    #[test]
    fn the_continuing_command_is_the_started_one_with_resume_in_place() {
        let cases: [(&[&str], &str); 5] = [
            (&["acps", "learn"], "acps learn --resume runs/x"),
            (&["acps", "learn", "--resume", "-q"], "acps learn -q --resume runs/x"),
            (
                &["acps", "experiment", "toy", "--resume=runs/x", "--runs", "3"],
                "acps experiment toy --runs 3 --resume runs/x",
            ),
            (
                &["acps", "run", "--resume", "runs/x", "--config", "a b.toml"],
                "acps run --config 'a b.toml' --resume runs/x",
            ),
            (
                &[
                    "/opt/acps",
                    "run",
                    "--worker-command",
                    "python -c 'print(1)'",
                    "--workers",
                    "2",
                ],
                r"/opt/acps run --worker-command 'python -c '\''print(1)'\''' --workers 2 --resume runs/x",
            ),
        ];
        for (args, expected) in cases {
            let args = args.iter().map(|a| a.to_string());
            assert_eq!(resumed(args, Path::new("runs/x")), expected);
        }
    }
}
