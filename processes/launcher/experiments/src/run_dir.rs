//! A run directory from an experiment file, without the command line: [`RunDir::plan`] checks
//! the request (its settings, memory, methods and what it resumes from), [`RunDir::prepare`]
//! makes the output directories and writes each resolved `config.toml` before anything runs, and
//! [`RunDir::in_process`] runs every experiment and writes `summary.json`, the tables, the
//! policies and (through the caller's [`Pictures`]) the pictures. `acps experiment` is this;
//! `acps run` drives the same jobs through a worker fleet.
//!
//! ```no_run
//! use acps_experiments::run_dir::RunDir;
//! use acps_experiments::settings::ExperimentFile;
//! use std::path::Path;
//! use std::sync::atomic::AtomicBool;
//!
//! let settings = ExperimentFile { runs: Some(2), ..Default::default() };
//! let run = RunDir::plan(Some(Path::new("experiments/function-fig4.toml")), &settings, Some("runs/mine".into()))?;
//! run.prepare()?;
//! let summaries = run.in_process(true, &AtomicBool::new(false), &|_, _| Ok(()))?;
//! println!("{}", summaries[0].methods["random"].final_mean.unwrap());
//! # Ok::<(), acps_experiments::run_dir::RunDirError>(())
//! ```

use crate::checkpoints::Checkpoints;
use crate::experiment::{Experiment, Perform, RunError};
use crate::file::LoadedFile;
use crate::keys::ConfigError;
use crate::plan::{self, Job, Plan};
use crate::progress::{Observer, PROGRESS_EVERY, Progress};
use crate::records::{self, RecordsError};
use crate::settings::ExperimentFile;
use crate::summary::{Failures, Summary};
use acps_fleet::FleetProgress;
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Duration;

/// Draws a summary's pictures into its run directory (acps-reports' `plot::write_all`, or
/// nothing).
pub type Pictures<'a> = &'a dyn Fn(&Summary, &Path) -> Result<(), Box<dyn std::error::Error>>;

/// A run directory that could not be planned, prepared, run or written.
#[derive(Debug, thiserror::Error)]
pub enum RunDirError {
    /// The experiment file or settings were refused.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// An experiment could not start or complete; `experiment` names it.
    #[error("experiment {experiment}")]
    Run {
        /// Its name.
        experiment: String,
        /// Why.
        #[source]
        source: Box<RunError>,
    },
    /// A method the experiment's environment cannot serve, or a problem only the user's
    /// workers simulate, asked to run in this process.
    #[error(transparent)]
    Refused(Box<RunError>),
    /// The tables or policies could not be written.
    #[error(transparent)]
    Records(#[from] RecordsError),
    /// Nothing to resume: no job's directory has checkpoints.
    #[error(
        "nothing to resume in {}: it has no checkpoints directory (was the run started with this --out and --checkpoint-every > 0?)",
        dir.display()
    )]
    NothingToResume {
        /// The run directory.
        dir: PathBuf,
    },
    /// The output directory holds a finished run (its summary), which a new run would replace.
    #[error(
        "{} holds a finished run (its summary.json): continue it with --resume, write this run elsewhere with --out, or replace it with --force",
        dir.display()
    )]
    Finished {
        /// The run directory.
        dir: PathBuf,
    },
    /// The output path exists and is not a directory.
    #[error("output directory {} exists and is not a directory: choose another --out", dir.display())]
    NotADirectory {
        /// The path.
        dir: PathBuf,
    },
    /// The output path is a symbolic link to nothing: a loop, or a target that does not exist
    /// (creating the directory would only say "File exists").
    #[error("output directory {} is a symbolic link that leads nowhere ({reason}): fix the link or choose another --out", dir.display())]
    DanglingLink {
        /// The path.
        dir: PathBuf,
        /// Why following it fails.
        reason: String,
    },
    /// The output directory cannot be made or written into, or a file in it written.
    #[error("output directory {}: cannot {action}", dir.display())]
    Output {
        /// The directory.
        dir: PathBuf,
        /// "create it" or "write into it".
        action: &'static str,
        /// The system's reason.
        #[source]
        source: std::io::Error,
    },
    /// `summary.json`, `run.json` or the summary lines on stdout could not be written.
    #[error("writing {}", path.display())]
    Summary {
        /// The file.
        path: PathBuf,
        /// The system's reason.
        #[source]
        source: std::io::Error,
    },
    /// A larger share of a method's rollouts failed than the run accepts; the run directory
    /// holds what was measured.
    #[error(
        "experiment {experiment}, {failures}: more than --max-failed-share {max_share} accepts; {} holds what was measured (a failed rollout is one whose reward or score is not a finite number, or that the environment reported as failed)",
        dir.display()
    )]
    TooManyFailed {
        /// The experiment.
        experiment: String,
        /// The first method beyond the share, with its counts.
        failures: Failures,
        /// The share accepted.
        max_share: f64,
        /// The run directory.
        dir: PathBuf,
    },
    /// The pictures could not be drawn.
    #[error("plotting into {}: {message}", dir.display())]
    Pictures {
        /// The run directory.
        dir: PathBuf,
        /// The plotting library's reason.
        message: String,
    },
}

impl RunDirError {
    /// The experiment's own error, when the run started and failed (or was stopped).
    pub fn run_error(&self) -> Option<&RunError> {
        match self {
            Self::Run { source, .. } | Self::Refused(source) => Some(source),
            _ => None,
        }
    }
}

/// A checked request with its output directory and jobs.
pub struct RunDir {
    /// The run's output directory.
    pub out: PathBuf,
    /// The experiments to run, each with its own directory (the run's, or one per panel or
    /// dimension in it) and resolved file.
    pub jobs: Vec<Job>,
    /// Write checkpoints after every this many learning rounds (0: none).
    pub checkpoint_every: u64,
    /// Continue every job from its checkpoints in `out`.
    pub resume: bool,
    /// When stderr is not a terminal, write the progress as a plain line this often.
    pub progress_every: Duration,
    /// Whether each experiment shows its progress line (unless quiet); off when an observer
    /// draws its own.
    pub progress_line: bool,
    /// Who else is told each experiment's progress.
    pub observer: Option<Observer>,
    /// The largest share of a method's rollouts (training and evaluation) that may fail before
    /// the run is an error ([`MAX_FAILED_SHARE`] unless set).
    pub max_failed_share: f64,
    /// Start afresh in a directory that holds a finished run, replacing its results; without
    /// it [`prepare`](Self::prepare) refuses ([`RunDirError::Finished`]).
    pub replace: bool,
}

/// Remove what a finished run wrote into `dir` (its summary, run report, tables, pictures and
/// policies); checkpoints, the experiment file and files of the user's stay.
fn remove_results(dir: &Path) -> std::io::Result<()> {
    // No directory yet, or something else in its place, which making it will name.
    if !dir.is_dir() {
        return Ok(());
    }
    let entries = std::fs::read_dir(dir)?;
    for entry in entries {
        let path = entry?.path();
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or_default();
        let result = matches!(name, "summary.json" | "run.json")
            || [".csv", ".png", ".svg"].iter().any(|end| name.ends_with(end));
        if name == crate::records::POLICY_DIR && path.is_dir() {
            std::fs::remove_dir_all(&path)?;
        } else if result && path.is_file() {
            std::fs::remove_file(&path)?;
        }
    }
    Ok(())
}

/// The share of a method's rollouts that may fail unless set: a quarter. Beyond it the test
/// means rest on too few rollouts, or the policy learnt from too few, to be read as results.
pub const MAX_FAILED_SHARE: f64 = 0.25;

impl RunDir {
    /// Check `settings` over the experiment file `config`, writing into `out` (default:
    /// `runs/STEM` for `config` STEM.toml, else `runs/NAME`); checkpoints every 10 learning
    /// rounds, no resume (see [`RunDir::checkpointing`]).
    pub fn plan(config: Option<&Path>, settings: &ExperimentFile, out: Option<PathBuf>) -> Result<Self, RunDirError> {
        let file = config.map(LoadedFile::read).transpose()?;
        let plan = Plan::new(file.as_ref(), settings)?;
        Self::of(&plan, config, out)
    }

    /// The run directory of a checked `plan` read from `config`.
    pub fn of(plan: &Plan, config: Option<&Path>, out: Option<PathBuf>) -> Result<Self, RunDirError> {
        let out = out.unwrap_or_else(|| plan::default_out(config, plan.name()));
        let jobs = plan.jobs(&out);
        plan::check_memory(&jobs)?;
        for job in &jobs {
            job.experiment
                .check_methods()
                .map_err(|e| RunDirError::Refused(Box::new(e)))?;
        }
        Ok(Self {
            out,
            jobs,
            checkpoint_every: DEFAULT_CHECKPOINT_EVERY,
            resume: false,
            progress_every: PROGRESS_EVERY,
            progress_line: true,
            observer: None,
            max_failed_share: MAX_FAILED_SHARE,
            replace: false,
        })
    }

    /// The same run writing checkpoints every `every` learning rounds (0: none) and, when
    /// `resume`, continuing every job from the checkpoints in its directory.
    pub fn checkpointing(mut self, every: u64, resume: bool) -> Result<Self, RunDirError> {
        self.checkpoint_every = every;
        // Where no run ever wrote checkpoints: a mistyped directory, or --checkpoint-every 0.
        if resume && !self.jobs.iter().any(|job| job.dir.join("checkpoints").is_dir()) {
            return Err(RunDirError::NothingToResume { dir: self.out });
        }
        self.resume = resume;
        Ok(self)
    }

    /// The checkpoints of the experiment that writes into `dir`, if it keeps or resumes any.
    pub fn checkpoints(&self, dir: &Path) -> Option<Checkpoints> {
        (self.checkpoint_every > 0 || self.resume).then(|| Checkpoints {
            dir: dir.join("checkpoints"),
            every: self.checkpoint_every,
            resume: self.resume,
        })
    }

    /// Make every job's output directory before anything is computed or started, and write its
    /// resolved experiment file there: an output that cannot be written fails now, not after the
    /// run. Returns the directories it created, the outermost of each path, for a run refused
    /// before it started to take back.
    ///
    /// A run that does not resume starts afresh: a directory that holds a finished run (its
    /// `summary.json`) is refused unless [`replace`](Self::replace), and the results of an
    /// earlier run there (summary, tables, pictures, policies) are removed, so that a directory
    /// holds a summary only when its run finished.
    pub fn prepare(&self) -> Result<Vec<PathBuf>, RunDirError> {
        if !self.resume {
            for job in &self.jobs {
                if job.dir.join("summary.json").exists() && !self.replace {
                    return Err(RunDirError::Finished { dir: job.dir.clone() });
                }
            }
            for job in &self.jobs {
                remove_results(&job.dir).map_err(|source| RunDirError::Summary {
                    path: job.dir.clone(),
                    source,
                })?;
            }
        }
        let mut created = Vec::new();
        for job in &self.jobs {
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

    /// Run every experiment in this process, one after another (each runs its (method, run)
    /// jobs in parallel), and write each one's directory; stop with [`RunError::Interrupted`]
    /// once `stop` is set, after every unfinished job wrote its checkpoint. Returns the
    /// summaries in the order of [`RunDir::jobs`].
    pub fn in_process(&self, quiet: bool, stop: &AtomicBool, pictures: Pictures) -> Result<Vec<Summary>, RunDirError> {
        for job in &self.jobs {
            job.experiment
                .check_in_process()
                .map_err(|e| RunDirError::Refused(Box::new(e)))?;
        }
        self.each(quiet, pictures, |experiment, progress, checkpoints| {
            experiment.run_until(progress, checkpoints, stop)
        })
    }

    /// Run every experiment in this thread, one after another, handing `perform` every task its
    /// jobs have ready at once ([`Experiment::run_batched`]: a vectorised simulator of the
    /// caller's, also for a problem file's problem), and write each one's directory. Stops
    /// with [`RunError::Interrupted`] once `stop` is set or `perform` returns `None`, after
    /// every unfinished job wrote its checkpoint.
    pub fn batched(
        &self,
        quiet: bool,
        stop: &AtomicBool,
        pictures: Pictures,
        perform: &mut Perform<'_>,
    ) -> Result<Vec<Summary>, RunDirError> {
        self.each(quiet, pictures, |experiment, progress, checkpoints| {
            experiment.run_batched(progress, checkpoints, stop, perform)
        })
    }

    /// Each experiment run by `run` with its progress line and checkpoints, its directory
    /// written and its failures checked.
    fn each(
        &self,
        quiet: bool,
        pictures: Pictures,
        mut run: impl FnMut(&Experiment, &Progress, Option<&Checkpoints>) -> Result<Summary, RunError>,
    ) -> Result<Vec<Summary>, RunDirError> {
        let mut summaries = Vec::with_capacity(self.jobs.len());
        for Job { experiment, dir, .. } in &self.jobs {
            let progress = experiment
                .progress(quiet || !self.progress_line, self.progress_every)
                .observed(self.observer.clone());
            let checkpoints = self.checkpoints(dir);
            let outcome = run(experiment, &progress, checkpoints.as_ref());
            match &outcome {
                Ok(summary) => progress.finish(summary),
                Err(_) => progress.abandon(),
            }
            let summary = outcome.map_err(|source| RunDirError::Run {
                experiment: experiment.name.clone(),
                source: Box::new(source),
            })?;
            let report = RunReport::of(&progress, &summary, None, self.resume);
            write(experiment, &summary, &report, dir, quiet, pictures)?;
            check_failures(experiment, &summary, dir, self.max_failed_share)?;
            summaries.push(summary);
        }
        Ok(summaries)
    }
}

/// `--checkpoint-every`'s default: learning rounds between two checkpoints.
pub const DEFAULT_CHECKPOINT_EVERY: u64 = 10;

/// Create the output directory `dir` and make sure files can be written into it.
pub fn output_dir(dir: &Path) -> Result<(), RunDirError> {
    if std::fs::symlink_metadata(dir).is_ok_and(|link| link.file_type().is_symlink())
        && let Err(error) = std::fs::metadata(dir)
    {
        return Err(RunDirError::DanglingLink {
            dir: dir.to_path_buf(),
            reason: error.to_string(),
        });
    }
    if dir.exists() && !dir.is_dir() {
        return Err(RunDirError::NotADirectory { dir: dir.to_path_buf() });
    }
    let fail = |action, source| RunDirError::Output {
        dir: dir.to_path_buf(),
        action,
        source,
    };
    std::fs::create_dir_all(dir).map_err(|e| fail("create it", e))?;
    let probe = dir.join(format!(".acps-probe-{}", std::process::id()));
    std::fs::write(&probe, b"").map_err(|e| fail("write into it", e))?;
    std::fs::remove_file(&probe).map_err(|e| fail("write into it", e))
}

/// What a run did in this process, which `summary.json` cannot say: it must be the same bytes
/// after a resume, while these figures depend on the machine, the workers and the moment. Written
/// to `DIR/run.json` and as the run's first final line.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunReport {
    /// `in-process` or `fleet`.
    pub mode: &'static str,
    /// Whether the run continued from checkpoints (then the counts below are this process's
    /// part of it).
    pub resumed: bool,
    /// Training episodes of all jobs together.
    pub episodes: u64,
    /// Rollouts (training, evaluation and first-visit baselines) this process consumed.
    pub rollouts: u64,
    /// Wall-clock seconds from the experiment's start in this process to its last outcome (a
    /// fleet's workers' start-up included).
    pub seconds: f64,
    /// `rollouts / seconds`.
    pub rollouts_per_s: f64,
    /// A fleet's most workers connected at once (those behind relays included); in-process, the
    /// threads that ran the jobs.
    pub workers: usize,
    /// Whether the run served relays of other hosts (`--listen`).
    pub relays: bool,
    /// `rollouts_per_s / workers`.
    pub rollouts_per_s_per_worker: f64,
    /// Failed training rollouts of all jobs (after their retry), as in `summary.json`.
    pub failed_training: u64,
    /// Failed evaluation rollouts of all jobs, as in `summary.json`.
    pub failed_evaluation: u64,
    /// Fleet only: tasks handed out again because their worker died or fell silent.
    pub reissued: Option<u64>,
    /// Fleet only: outcomes dropped because their task had been answered (a re-issued task
    /// answered twice).
    pub duplicates: Option<u64>,
    /// Fleet only: requests refused (another build, run or environment).
    pub refused: Option<u64>,
    /// Fleet only: outcomes dropped because they came from a worker that never held their task.
    pub foreign: Option<u64>,
}

impl RunReport {
    /// The report of a run that showed `progress` and ended with `summary`: on a fleet whose
    /// last progress was `fleet`, or in this process (`None`); `resumed` from checkpoints.
    pub fn of(progress: &Progress, summary: &Summary, fleet: Option<&FleetProgress>, resumed: bool) -> Self {
        let (rollouts, seconds) = progress.done();
        let jobs = summary.runs * summary.methods.len();
        let workers = match fleet {
            Some(fleet) => fleet.most_workers,
            None => rayon::current_num_threads().min(jobs),
        };
        let rollouts = fleet.map_or(rollouts, |f| f.outcomes);
        let rollouts_per_s = rollouts as f64 / seconds.max(1e-9);
        let sum = |count: fn(&crate::summary::MethodSummary) -> u64| summary.methods.values().map(count).sum();
        Self {
            mode: if fleet.is_some() { "fleet" } else { "in-process" },
            resumed,
            episodes: summary.training_episodes * jobs as u64,
            rollouts,
            seconds,
            rollouts_per_s,
            workers,
            relays: false,
            rollouts_per_s_per_worker: rollouts_per_s / workers.max(1) as f64,
            failed_training: sum(|m| m.failed_episodes),
            failed_evaluation: sum(|m| m.failed_evaluation_rollouts),
            reissued: fleet.map(|f| f.reissued),
            duplicates: fleet.map(|f| f.duplicates),
            refused: fleet.map(|f| f.refused),
            foreign: fleet.map(|f| f.foreign),
        }
    }

    /// The same report of a run that served relays of other hosts.
    pub fn with_relays(self, relays: bool) -> Self {
        Self { relays, ..self }
    }

    /// The final line of experiment `name`.
    pub fn line(&self, name: &str) -> String {
        let relays = if self.relays { " and relays of other hosts" } else { "" };
        let plural = if self.workers == 1 { "" } else { "s" };
        let unit = if self.mode == "fleet" { "worker" } else { "thread" };
        let resumed = if self.resumed {
            " (resumed: this process's part)"
        } else {
            ""
        };
        let mut line = format!(
            "{name} on {} {unit}{plural}{relays}: {} episodes, {} rollouts{resumed} in {:.1} s ({:.0}/s, {:.0}/s per {unit})",
            self.workers,
            self.episodes,
            self.rollouts,
            self.seconds,
            self.rollouts_per_s,
            self.rollouts_per_s_per_worker
        );
        if let (Some(reissued), Some(duplicates), Some(refused)) = (self.reissued, self.duplicates, self.refused) {
            line += &format!(", {reissued} re-issued, {duplicates} duplicates dropped, {refused} refused");
        }
        if let Some(foreign) = self.foreign.filter(|&n| n > 0) {
            line += &format!(", {foreign} outcomes from workers without their task dropped");
        }
        line += &format!(
            ", {} failed ({} training, {} evaluation)",
            self.failed_training + self.failed_evaluation,
            self.failed_training,
            self.failed_evaluation
        );
        line
    }
}

/// Write the run directory's results (its config.toml was written before the run) with the
/// run's `report` in `run.json` and, unless `quiet`, say what the run did, where the results
/// are and the final scores.
pub fn write(
    experiment: &Experiment,
    summary: &Summary,
    report: &RunReport,
    dir: &Path,
    quiet: bool,
    pictures: Pictures,
) -> Result<(), RunDirError> {
    summary.write(dir).map_err(|source| RunDirError::Summary {
        path: dir.join("summary.json"),
        source,
    })?;
    let run_json = dir.join("run.json");
    let json = serde_json::to_string_pretty(report).expect("a run report always serialises");
    std::fs::write(&run_json, json).map_err(|source| RunDirError::Summary { path: run_json, source })?;
    records::write(summary, dir)?;
    pictures(summary, dir).map_err(|e| RunDirError::Pictures {
        dir: dir.to_path_buf(),
        message: e.to_string(),
    })?;
    if !quiet {
        for failures in summary.failures() {
            eprintln!("warning: experiment {}, {failures}", experiment.name);
        }
        let mut lines = format!(
            "{}\n{} -> {}\n",
            report.line(&experiment.name),
            experiment.name,
            dir.join("summary.json").display()
        );
        let score = experiment.score_format();
        for (method, result) in &summary.methods {
            let line = score.final_line(result.final_mean, result.final_sem, summary.runs);
            lines.push_str(&format!("  {method:>20}: {line}\n"));
        }
        // The run directory is the record; a reader that closed the output (`acps run ... |
        // head -1`) misses only these lines, and the run still succeeds.
        let mut stdout = std::io::stdout().lock();
        match stdout.write_all(lines.as_bytes()).and_then(|()| stdout.flush()) {
            Err(error) if error.kind() == std::io::ErrorKind::BrokenPipe => {}
            written => written.map_err(|source| RunDirError::Summary {
                path: PathBuf::from("<stdout>"),
                source,
            })?,
        }
    }
    Ok(())
}

/// Refuse a run in which more than `max_share` of a method's rollouts failed, once its
/// directory is written.
pub fn check_failures(
    experiment: &Experiment,
    summary: &Summary,
    dir: &Path,
    max_share: f64,
) -> Result<(), RunDirError> {
    match summary.failures().into_iter().find(|f| f.share() > max_share) {
        Some(failures) => Err(RunDirError::TooManyFailed {
            experiment: experiment.name.clone(),
            failures,
            max_share,
            dir: dir.to_path_buf(),
        }),
        None => Ok(()),
    }
}
