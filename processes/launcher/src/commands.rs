//! What each `acps` command does.

use crate::bench::BenchEvent;
use crate::checkpoints::Checkpoints;
use crate::cli::{BenchArgs, EvaluateArgs, ExperimentArgs, NetArgs, RelayArgs, RunArgs, StartedWorkers, WorkerArgs};
use crate::config::{self, Job, LoadedFile, Plan};
use crate::experiment::{Experiment, Summary};
use crate::progress::{Progress, ScoreFormat};
use crate::workers::ModelFactory;
use acps_fleet::{Fleet, FleetBuilder, FleetProgress};
use acps_relay::{Listener, NetOptions, RelayOptions};
use acps_wire::ipc::{self, RunName};
use acps_worker::{WorkerExit, WorkerOptions};
use anyhow::{Context, bail};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

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
    /// Ctrl-C of a relay: its workers were stopped; the learner hands their tasks to others.
    #[error(
        "interrupted; this host's workers were stopped and its shared memory removed; the learner hands their tasks to other hosts"
    )]
    RelayInterrupted,
    /// Any other error, after which the checkpoints written so far continue the run.
    #[error("{error:#}\n{}", continue_hint(Some(resume)))]
    Failed {
        /// What went wrong.
        error: anyhow::Error,
        /// The command that continues the run.
        resume: String,
    },
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
    resumed(std::env::args_os().map(|a| a.to_string_lossy().into_owned()), dir)
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
    // A fleet can fail half-way (its workers gone, refused or silent); other errors happen
    // before the run starts or concern the checkpoints themselves.
    let fleet_failed = error.chain().any(|e| {
        matches!(
            e.downcast_ref::<crate::experiment::RunError>(),
            Some(crate::experiment::RunError::Fleet(_))
        )
    });
    match resume {
        Some(resume) if fleet_failed && checkpoints.is_some_and(|c| c.dir.is_dir()) => {
            Stopped::Failed { error, resume }.into()
        }
        _ => error,
    }
}

/// True when `error` is a run stopped by Ctrl-C.
fn interrupted(error: &anyhow::Error) -> bool {
    use crate::experiment::RunError;
    use acps_fleet::FleetError;
    error.chain().any(|e| {
        matches!(
            e.downcast_ref::<RunError>(),
            Some(RunError::Fleet(FleetError::Interrupted) | RunError::Interrupted)
        ) || matches!(e.downcast_ref::<FleetError>(), Some(FleetError::Interrupted))
    })
}

/// The run's output directory and the experiments `args` ask for, checked (their methods,
/// memory and what they resume from), with their own directories (the run's, or one per panel
/// in it) and resolved files; `None` when `--save-config` wrote the resolved file instead.
fn jobs(args: &ExperimentArgs) -> anyhow::Result<Option<(PathBuf, Vec<Job>)>> {
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
    let jobs = plan.jobs(&out);
    config::check_memory(&jobs)?;
    for job in &jobs {
        job.experiment.check_methods()?;
    }
    check_resumable(args, &jobs)?;
    Ok(Some((out, jobs)))
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

/// Make every job's output directory before anything is computed or started, and write its
/// resolved experiment file there: an output that cannot be written fails now, not after the
/// run. Returns the directories it created, the outermost of each path, for a run refused
/// before it started to take back.
fn prepare_outputs(jobs: &[Job]) -> anyhow::Result<Vec<PathBuf>> {
    let mut created = Vec::new();
    for job in jobs {
        let outermost = job
            .dir
            .ancestors()
            .take_while(|d| !d.as_os_str().is_empty() && !d.exists())
            .last();
        created.extend(outermost.map(Path::to_path_buf));
        output_dir(&job.dir)?;
        job.config.write_resolved(&job.dir)?;
    }
    Ok(created)
}

/// Create the output directory `dir` and make sure files can be written into it.
fn output_dir(dir: &Path) -> anyhow::Result<()> {
    if dir.exists() && !dir.is_dir() {
        bail!(
            "output directory {} exists and is not a directory: choose another --out",
            dir.display()
        );
    }
    let fail =
        |what: &str, e: std::io::Error| anyhow::anyhow!("output directory {}: cannot {what}: {e}", dir.display());
    std::fs::create_dir_all(dir).map_err(|e| fail("create it", e))?;
    let probe = dir.join(format!(".acps-probe-{}", std::process::id()));
    std::fs::write(&probe, b"").map_err(|e| fail("write into it", e))?;
    std::fs::remove_file(&probe).map_err(|e| fail("write into it", e))
}

/// Set by the Ctrl-C handler of `acps experiment`.
static STOP: AtomicBool = AtomicBool::new(false);

pub(crate) fn experiment(args: ExperimentArgs) -> anyhow::Result<()> {
    let Some((out, jobs)) = jobs(&args)? else {
        return Ok(());
    };
    for job in &jobs {
        job.experiment.check_in_process()?;
    }
    prepare_outputs(&jobs)?;
    ctrlc::set_handler(|| STOP.store(true, Ordering::Relaxed)).context("installing the Ctrl-C handler")?;
    for Job { experiment, dir, .. } in jobs {
        let progress = Progress::of(&experiment, args.quiet);
        let checkpoints = checkpoints(&args, &dir);
        let outcome = experiment.run_until(&progress, checkpoints.as_ref(), &STOP);
        match &outcome {
            Ok(summary) => progress.finish(summary),
            Err(_) => progress.abandon(),
        }
        let summary = outcome
            .with_context(|| format!("experiment {}", experiment.name))
            .map_err(|e| stopped(e, checkpoints.as_ref(), &out, false))?;
        write(&experiment, &summary, &dir, args.quiet)?;
    }
    Ok(())
}

/// Run the experiments through a fleet: this process serves the learners, `--workers` worker
/// processes simulate. The fleet removes the run's shared memory when it ends, also on errors
/// and Ctrl-C.
pub(crate) fn fleet(args: RunArgs) -> anyhow::Result<()> {
    // Before the output directory is made.
    let run = args
        .run
        .as_deref()
        .map(|name| RunName::new(name).with_context(|| format!("--run {name}")))
        .transpose()?;
    let net = net_options(&args.net, &args.listen, &[])?;
    let Some((out, jobs)) = jobs(&args.experiment)? else {
        return Ok(());
    };
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
    let created = prepare_outputs(&jobs)?;
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
    let mut listener = match &net {
        Some(net) => match Listener::open(&name, net) {
            Ok(listener) => Some(listener),
            Err(error) => {
                for dir in &created {
                    let _ = std::fs::remove_dir_all(dir);
                }
                return Err(anyhow::Error::new(error).context(format!("--listen {}", args.listen.join(" --listen "))));
            }
        },
        None => None,
    };
    if listener.is_some() && !args.experiment.quiet {
        eprintln!(
            "run '{name}' serves relays at {}: on each other host, `acps relay --connect ENDPOINT` with this host's address",
            args.listen.join(", ")
        );
    }
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
                        "run '{run}' waits for your workers: start each with {}={run} in its environment (`{}={run} CMD`); they must declare {environment}",
                        ipc::RUN_ENV,
                        ipc::RUN_ENV
                    );
                }
            }
        }
        let progress = Progress::of(experiment, args.experiment.quiet);
        let checkpoints = checkpoints(&args.experiment, dir);
        let remote = listener.as_mut().map(|l| l as &mut dyn acps_fleet::Remote);
        let outcome = experiment.run_fleet(&mut fleet, checkpoints.as_ref(), remote, |p| {
            progress.show(&p.learning, p.outcomes, Some(p.workers));
        });
        match &outcome {
            Ok((summary, _)) => progress.finish(summary),
            Err(_) => progress.abandon(),
        }
        let (summary, report) = outcome
            .with_context(|| format!("experiment {} on run '{run}'", experiment.name))
            .map_err(|e| stopped(e, checkpoints.as_ref(), &out, true))?;
        if !args.experiment.quiet {
            let relays = if listener.is_some() {
                " and relays of other hosts"
            } else {
                ""
            };
            println!(
                "{} on {workers} workers{relays}: {} outcomes, {} re-issued, {} duplicates dropped, {} refused",
                experiment.name, report.outcomes, report.reissued, report.duplicates, report.refused
            );
        }
        write(experiment, &summary, dir, args.experiment.quiet)?;
    }
    Ok(())
}

pub(crate) fn bench(args: BenchArgs) -> anyhow::Result<()> {
    output_dir(&args.out)?;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let options = crate::bench::BenchOptions {
        envs: args.env,
        max_workers: args.max_workers.unwrap_or(cores.min(ipc::MAX_WORKERS)),
        worker_in_flight: args.worker_in_flight,
        worker_nice: args.worker_nice.worker_nice,
        scale: args.scale,
        rounds: args.rounds,
        relay: args.relay,
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
    let json = serde_json::to_string_pretty(&serde_json::json!({ "rows": rows }))?;
    let path = args.out.join("bench.json");
    std::fs::write(&path, json).with_context(|| format!("writing {}", path.display()))?;
    crate::plot::save_bench(&rows, &args.out)
        .map_err(|e| anyhow::anyhow!("drawing {}: {e}", args.out.join("bench.svg").display()))?;
    println!("-> {} and bench.svg / bench.png", path.display());
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
        in_flight: args.in_flight,
        name,
        startup_timeout: Duration::from_secs_f64(args.startup_timeout),
        spin: Duration::from_micros(args.spin_us),
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

/// Serve this host's workers from a learner on another host.
pub(crate) fn relay(args: RelayArgs) -> anyhow::Result<()> {
    let Some(net) = net_options(&args.net, &[], &args.connect)? else {
        bail!("--connect ENDPOINT is missing: where the learner listens (its --listen)");
    };
    let run = args
        .run
        .as_deref()
        .map(|name| RunName::new(name).with_context(|| format!("--run {name}")))
        .transpose()?;
    args.started.check()?;
    let local = args
        .local_run
        .clone()
        .unwrap_or_else(|| format!("relay-{}", std::process::id()));
    let builder = Fleet::builder(RunName::new(&local).with_context(|| format!("--local-run {local}"))?).ctrl_c(true);
    let mut fleet = args
        .started
        .spawn(builder)
        .start()
        .with_context(|| format!("--local-run {local}"))?;
    if !args.quiet {
        eprintln!(
            "relay: this host's run is '{local}' (workers started by hand: `acps worker --run {local}`); asking {} for tasks",
            args.connect.join(", ")
        );
    }
    let options = RelayOptions {
        net,
        run,
        identity: 0,
        startup_timeout: Duration::from_secs_f64(args.startup_timeout),
        wait_for_learner: Duration::from_secs_f64(args.wait_for_learner),
        queue: args.queue,
    };
    let bar = (!args.quiet).then(|| {
        ProgressBar::new_spinner()
            .with_style(ProgressStyle::with_template("{spinner} relay: {msg}, {elapsed}").expect("a valid template"))
    });
    let mut observer = |progress: &FleetProgress| {
        if let Some(bar) = &bar {
            bar.set_message(format!(
                "{} outcomes from {} workers",
                progress.outcomes, progress.workers
            ));
            bar.tick();
        }
    };
    let served = acps_relay::relay::serve(&mut fleet, &options, &mut observer);
    if let Some(bar) = &bar {
        bar.finish_and_clear();
    }
    match served {
        Ok(report) => {
            if !args.quiet {
                eprintln!(
                    "relay: run '{}' is over: {} outcomes forwarded in {} serves",
                    report.run, report.outcomes, report.serves
                );
            }
            Ok(())
        }
        Err(acps_relay::RelayError::Fleet(acps_fleet::FleetError::Interrupted)) => {
            Err(Stopped::RelayInterrupted.into())
        }
        Err(error) => Err(anyhow::Error::new(error).context(format!("relay to {}", args.connect.join(", ")))),
    }
}

/// The network settings of a learner that listens on `listen` or a relay that connects to
/// `connect`; `None` when there is neither.
fn net_options(args: &NetArgs, listen: &[String], connect: &[String]) -> anyhow::Result<Option<NetOptions>> {
    if listen.is_empty() && connect.is_empty() {
        if args.zenoh_config.is_some() || args.lease.is_some() {
            bail!(
                "--zenoh-config and --lease set up the network of hosts, which only --listen (acps run) or --connect (acps relay) opens"
            );
        }
        return Ok(None);
    }
    let (flag, endpoints) = if listen.is_empty() {
        ("--connect", connect)
    } else {
        ("--listen", listen)
    };
    for endpoint in endpoints {
        acps_relay::net::check_endpoint(endpoint).with_context(|| format!("{flag} {endpoint}"))?;
    }
    if let Some(path) = &args.zenoh_config
        && !path.is_file()
    {
        bail!("--zenoh-config {}: not a readable file", path.display());
    }
    Ok(Some(NetOptions {
        listen: listen.to_vec(),
        connect: connect.to_vec(),
        lease: args
            .lease
            .map_or(acps_relay::net::DEFAULT_LEASE, Duration::from_secs_f64),
        config_file: args.zenoh_config.clone(),
    }))
}

impl StartedWorkers {
    /// Refuse a --worker-command that starts nothing.
    fn check(&self) -> anyhow::Result<()> {
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
    fn count(&self) -> usize {
        self.workers.unwrap_or_else(|| {
            std::thread::available_parallelism()
                .map_or(1, |n| n.get())
                .min(ipc::MAX_WORKERS)
        })
    }

    /// `builder`, starting these workers.
    fn spawn(&self, mut builder: FleetBuilder) -> FleetBuilder {
        let workers = self.count();
        if workers > 0 {
            builder = match &self.worker_command {
                Some(command) => builder.spawn_workers(workers, crate::workers::user_command(command.clone())),
                None => builder.spawn_workers(workers, crate::workers::command(self.worker_in_flight, workers)),
            };
            if let Some(nice) = self.worker_nice.worker_nice {
                builder = builder.worker_niceness(nice);
            }
        }
        builder
    }
}

pub(crate) fn evaluate(args: EvaluateArgs) -> anyhow::Result<()> {
    use crate::evaluate;
    use crate::records::{SavedPolicy, policy_file};
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
    print!("{}", evaluate::report(&saved, &replay, test_set));
    if let Some(file) = args.render {
        let first = replay.throws.first().context("--render: there is no throw to draw")?;
        evaluate::render(&saved, first, &file)?;
        println!("-> {}", file.display());
    }
    Ok(())
}

/// Write the run directory's results; its config.toml was written before the run.
fn write(experiment: &Experiment, summary: &Summary, dir: &Path, quiet: bool) -> anyhow::Result<()> {
    summary
        .write(dir)
        .with_context(|| format!("writing {}", dir.join("summary.json").display()))?;
    crate::records::write(summary, dir)?;
    crate::plot::write_all(summary, dir).map_err(|e| anyhow::anyhow!("plotting into {}: {e}", dir.display()))?;
    if !quiet {
        println!("{} -> {}", experiment.name, dir.join("summary.json").display());
        let score = ScoreFormat::of(experiment);
        for (method, result) in &summary.methods {
            let line = score.final_line(result.final_mean, result.final_sem, summary.runs);
            println!("  {method:>20}: {line}");
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

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
