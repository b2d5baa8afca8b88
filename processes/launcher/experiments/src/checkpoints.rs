//! Checkpoints of an experiment's jobs: two files per (method, run) job in DIR/checkpoints, in
//! the formats of [`acps_learner::checkpoint`]:
//! - `METHOD-run-R.records`, the job's record file: its learner's records (episodes, updates,
//!   evaluations), appended as they are made, so that the learner holds only its state;
//! - `METHOD-run-R.ckpt`, the checkpoint: that state and where the record file ended, written
//!   every N learning rounds and when the job ends. Its cost does not grow with the run.
//!
//! A fresh run removes the files it finds there first; a resumed run loads every job's
//! checkpoint that exists (a finished job's holds its final state), cuts its record file back to
//! where the checkpoint says it ended, and refuses files of another experiment, so the resumed
//! run ends exactly as an uninterrupted one would.

use acps_learner::checkpoint::journal::{self, JournalError, JournalMark, JournalWriter, Record};
use acps_learner::checkpoint::{
    self, Checkpoint, CheckpointApplyError, CheckpointReadError, CheckpointWriteError, Stamp,
};
use acps_learner::{Learner, RecordCounts, Records};
use acps_shared::{Environment, EnvironmentRestoreError};
use std::path::{Path, PathBuf};

/// Where a run keeps its checkpoints, how often it writes them, and whether it starts from them.
#[derive(Debug, Clone)]
pub struct Checkpoints {
    /// The directory of the checkpoint files (DIR/checkpoints).
    pub dir: PathBuf,
    /// Write a job's checkpoint after every `every` learning rounds ([`Learner::rounds`]: C-REPS
    /// updates, or evaluations for a problem without a policy) and when it ends; 0: never.
    pub every: u64,
    /// Continue every job from its checkpoint, if it has one.
    pub resume: bool,
}

/// A checkpoint directory that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointsError {
    /// A checkpoint file could not be written.
    #[error(transparent)]
    Write(#[from] CheckpointWriteError),
    /// A checkpoint file could not be read, or is not one of this job.
    #[error(transparent)]
    Read(#[from] CheckpointReadError),
    /// A checkpoint file does not fit the job it was read for.
    #[error("checkpoint {}: {source}", path.display())]
    Apply {
        /// The file.
        path: PathBuf,
        /// Why the job refused it.
        source: CheckpointApplyError,
    },
    /// A record file could not be written, or does not reach or match its checkpoint's mark.
    #[error(transparent)]
    Journal(#[from] JournalError),
    /// A checkpoint whose record file's mark is missing or does not fit its learner.
    #[error("checkpoint {}: {reason}", path.display())]
    RecordMark {
        /// The checkpoint file.
        path: PathBuf,
        /// What does not fit.
        reason: String,
    },
    /// The directory could not be created, listed or cleaned.
    #[error("checkpoint directory {}: {source}", path.display())]
    Dir {
        /// The directory.
        path: PathBuf,
        /// What failed.
        source: std::io::Error,
    },
    /// A file in the directory that is no job's of this experiment.
    #[error(
        "checkpoint {} belongs to no job of this experiment (was the run started with other --method or --runs?); resume with the arguments the run was started with, or use another directory",
        path.display()
    )]
    Stray {
        /// The file.
        path: PathBuf,
    },
}

impl Checkpoints {
    /// The checkpoint file of `method`'s run `run`.
    pub fn file(&self, method: &str, run: usize) -> PathBuf {
        self.dir.join(format!("{method}-run-{run}.ckpt"))
    }

    /// The record file that goes with the checkpoint file `checkpoint`.
    pub fn records_file(checkpoint: &Path) -> PathBuf {
        checkpoint.with_extension("records")
    }

    /// Make the directory ready: for a fresh run, create it and remove old checkpoint and record
    /// files; for a resumed run, refuse checkpoint and record files that are not among `files`'
    /// (this experiment's checkpoints). A resumed run without the directory starts fresh.
    pub(crate) fn prepare(&self, files: &[PathBuf]) -> Result<(), CheckpointsError> {
        let dir_error = |source| CheckpointsError::Dir {
            path: self.dir.clone(),
            source,
        };
        let entries = match std::fs::read_dir(&self.dir) {
            Ok(entries) => entries.collect::<Result<Vec<_>, _>>().map_err(dir_error)?,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
            Err(e) => return Err(dir_error(e)),
        };
        for entry in entries {
            let path = entry.path();
            let name = entry.file_name().to_string_lossy().into_owned();
            let ours = if name.ends_with(".ckpt") {
                files.contains(&path)
            } else if name.ends_with(".records") {
                files.iter().any(|file| Self::records_file(file) == path)
            } else if name.ends_with(".ckpt.tmp") {
                true
            } else {
                continue;
            };
            if !self.resume {
                std::fs::remove_file(&path).map_err(dir_error)?;
            } else if !ours {
                return Err(CheckpointsError::Stray { path });
            }
        }
        std::fs::create_dir_all(&self.dir).map_err(dir_error)
    }
}

/// Writes one job's records and checkpoints as it runs: what [`Experiment`](crate::experiment::Experiment)
/// does for each of its jobs, for a loop of your own (`acps bench`'s long run is one).
///
/// ```
/// use acps_experiments::checkpoints::Writer;
/// use acps_learner::checkpoint::Stamp;
/// use acps_learner::{Learner, LearnerConfig, SelectorConfig};
/// use acps_models::contextual_function::ContextualFunction;
/// use acps_shared::Environment;
///
/// let mut environment = ContextualFunction::new(2, 4, 0)?;
/// let problem = environment.grid_problem()?;
/// let config = LearnerConfig { episodes: 200, ..Default::default() };
/// let mut learner = Learner::with_selector(config, problem, &SelectorConfig::default())?;
/// let dir = std::env::temp_dir().join(format!("acps-doc-writer-{}", std::process::id()));
/// std::fs::create_dir_all(&dir)?;
/// let stamp = Stamp { identity: 1, job: 0 };
/// let mut writer = Writer::open(dir.join("job.ckpt"), stamp, 10, &learner, None)?;
/// while let Some(task) = learner.ask() {
///     learner.tell(environment.rollout(&task))?;
///     writer.after_tell(&mut learner, Some(&environment))?; // records out, checkpoint when due
/// }
/// let records = writer.finish(&mut learner)?;
/// assert_eq!(records.episodes.len(), 200);
/// # std::fs::remove_dir_all(&dir)?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct Writer {
    path: PathBuf,
    stamp: Stamp,
    every: u64,
    /// `rounds / every` at the last checkpoint.
    mark: u64,
    /// Checkpoints written.
    written: u64,
    /// Whether the final checkpoint is written.
    finished: bool,
    journal: JournalWriter,
}

impl Writer {
    /// A writer for the job whose checkpoint is `path` and whose learner stands where it starts:
    /// fresh (`resumed` is `None`; a new record file), or restored from a checkpoint whose
    /// record file ended at `resumed` (the file is cut back to that mark). The record file is the
    /// checkpoint's path with the extension `records`.
    pub fn open(
        path: PathBuf,
        stamp: Stamp,
        every: u64,
        learner: &Learner,
        resumed: Option<JournalMark>,
    ) -> Result<Self, CheckpointsError> {
        let records = Checkpoints::records_file(&path);
        let journal = match resumed {
            None => JournalWriter::create(&records, stamp)?,
            Some(mark) if mark.records != learner.records_taken() => {
                return Err(CheckpointsError::RecordMark {
                    reason: format!(
                        "its record file mark counts {} but its learner took {}",
                        counts(mark.records),
                        counts(learner.records_taken())
                    ),
                    path,
                });
            }
            Some(mark) => JournalWriter::resume(&records, stamp, &mark)?,
        };
        Ok(Self {
            path,
            stamp,
            every,
            mark: learner.rounds().checked_div(every).unwrap_or(0),
            written: 0,
            finished: learner.is_done(),
            journal,
        })
    }

    /// Called after every outcome told to `learner`: appends its new records, and writes a
    /// checkpoint when the learner has completed another `every` rounds, and once when it is done.
    pub fn after_tell(
        &mut self,
        learner: &mut Learner,
        environment: Option<&dyn Environment>,
    ) -> Result<(), CheckpointsError> {
        self.journal.append(&learner.take_records())?;
        if self.every == 0 || self.finished {
            return Ok(());
        }
        let mark = learner.rounds() / self.every;
        if learner.is_done() || mark > self.mark {
            self.write(learner, environment)?;
            self.mark = mark;
            self.finished = learner.is_done();
        }
        Ok(())
    }

    /// Write the checkpoint now (for example when the run is interrupted), after the record
    /// file. A problem the user's workers simulate has no environment here, and so no
    /// environment state.
    pub fn write(
        &mut self,
        learner: &mut Learner,
        environment: Option<&dyn Environment>,
    ) -> Result<(), CheckpointsError> {
        self.journal.append(&learner.take_records())?;
        let records = Some(self.journal.flush()?);
        let checkpoint = Checkpoint {
            learner: learner.snapshot(),
            environment: environment.map(Environment::save_state).unwrap_or_default(),
            records,
        };
        checkpoint::write(&self.path, self.stamp, &checkpoint)?;
        self.written += 1;
        Ok(())
    }

    /// Checkpoints this writer has written.
    pub fn checkpoints_written(&self) -> u64 {
        self.written
    }

    /// Whether checkpoints are written at all.
    pub fn enabled(&self) -> bool {
        self.every > 0
    }

    /// Every record of the finished job, read back from its record file; of the evaluations'
    /// outcomes, only the first's and the last's (where failures began, the final test
    /// rollouts): a long run's would hold every test rollout of the run.
    pub fn finish(mut self, learner: &mut Learner) -> Result<Records, CheckpointsError> {
        self.journal.append(&learner.take_records())?;
        let mark = self.journal.flush()?;
        let mut records = Records::default();
        journal::read_each(self.journal.path(), self.stamp, &mark, |record| match record {
            Record::Episode(episode) => records.episodes.push(episode),
            Record::Update(update) => records.updates.push(update),
            Record::Evaluation(evaluation) => {
                if let [_, .., last] = records.evaluations.as_mut_slice() {
                    last.outcomes = Vec::new();
                }
                records.evaluations.push(evaluation);
            }
        })?;
        Ok(records)
    }
}

fn counts(records: RecordCounts) -> String {
    format!(
        "{} episodes, {} updates and {} evaluations",
        records.episodes, records.updates, records.evaluations
    )
}

/// Continue `learner` and `environment` (none for a problem the user's workers simulate, whose
/// checkpoints hold no environment state) from the checkpoint at `path`, if there is one.
/// Returns where the checkpoint's record file ended, if there was a checkpoint; one that
/// records no record file (an experiment's always do) is refused.
pub(crate) fn restore(
    path: &Path,
    stamp: Stamp,
    learner: &mut Learner,
    environment: Option<&mut Box<dyn Environment>>,
) -> Result<Option<JournalMark>, CheckpointsError> {
    let Some(mut saved) = checkpoint::read(path, stamp)? else {
        return Ok(None);
    };
    let records = saved.records.take().ok_or_else(|| CheckpointsError::RecordMark {
        path: path.to_path_buf(),
        reason: "it records no record file".into(),
    })?;
    let applied = match environment {
        Some(environment) => saved.apply(learner, environment.as_mut()),
        None if !saved.environment.is_empty() => Err(EnvironmentRestoreError::Length {
            expected: 0,
            got: saved.environment.len(),
        }
        .into()),
        None => learner.restore(saved.learner).map_err(Into::into),
    };
    applied.map_err(|source| CheckpointsError::Apply {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(Some(records))
}
