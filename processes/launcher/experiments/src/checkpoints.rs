//! Checkpoints of an experiment's jobs: one file per (method, run) job in DIR/checkpoints, in the
//! format of [`acps_learner::checkpoint`], written every N learning rounds and when the job ends.
//!
//! A fresh run removes the checkpoint files it finds there first; a resumed run loads every job's
//! file that exists (a finished job's holds its final state) and refuses files of another
//! experiment, so the resumed run ends exactly as an uninterrupted one would.

use acps_learner::Learner;
use acps_learner::checkpoint::{
    self, Checkpoint, CheckpointApplyError, CheckpointReadError, CheckpointWriteError, Stamp,
};
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

    /// Make the directory ready: for a fresh run, create it and remove old checkpoint files;
    /// for a resumed run, refuse checkpoint files that are not among `files` (this
    /// experiment's). A resumed run without the directory starts fresh.
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
            let is_checkpoint = name.ends_with(".ckpt");
            if !is_checkpoint && !name.ends_with(".ckpt.tmp") {
                continue;
            }
            if !self.resume {
                std::fs::remove_file(&path).map_err(dir_error)?;
            } else if is_checkpoint && !files.contains(&path) {
                return Err(CheckpointsError::Stray { path });
            }
        }
        if self.every > 0 {
            std::fs::create_dir_all(&self.dir).map_err(dir_error)?;
        }
        Ok(())
    }
}

/// Writes one job's checkpoints as it runs.
pub(crate) struct Writer {
    path: PathBuf,
    stamp: Stamp,
    every: u64,
    /// `rounds / every` at the last checkpoint.
    mark: u64,
    /// Whether the final checkpoint is written.
    finished: bool,
}

impl Writer {
    /// A writer for the job at `path` whose learner stands where it starts (fresh or restored).
    pub fn new(path: PathBuf, stamp: Stamp, every: u64, learner: &Learner) -> Self {
        Self {
            path,
            stamp,
            every,
            mark: learner.rounds().checked_div(every).unwrap_or(0),
            finished: learner.is_done(),
        }
    }

    /// Called after every outcome told to `learner`: writes a checkpoint when the learner has
    /// completed another `every` rounds, and once when it is done.
    pub fn after_tell(
        &mut self,
        learner: &Learner,
        environment: Option<&dyn Environment>,
    ) -> Result<(), CheckpointsError> {
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

    /// Write the checkpoint now (for example when the run is interrupted). A problem the
    /// user's workers simulate has no environment here, and so no environment state.
    pub fn write(&self, learner: &Learner, environment: Option<&dyn Environment>) -> Result<(), CheckpointsError> {
        let checkpoint = match environment {
            Some(environment) => Checkpoint::take(learner, environment),
            None => Checkpoint {
                learner: learner.snapshot(),
                environment: Vec::new(),
            },
        };
        Ok(checkpoint::write(&self.path, self.stamp, &checkpoint)?)
    }

    /// Whether checkpoints are written at all.
    pub fn enabled(&self) -> bool {
        self.every > 0
    }
}

/// Continue `learner` and `environment` (none for a problem the user's workers simulate, whose
/// checkpoints hold no environment state) from the checkpoint at `path`, if there is one.
/// Returns whether there was.
pub(crate) fn restore(
    path: &Path,
    stamp: Stamp,
    learner: &mut Learner,
    environment: Option<&mut Box<dyn Environment>>,
) -> Result<bool, CheckpointsError> {
    let Some(saved) = checkpoint::read(path, stamp)? else {
        return Ok(false);
    };
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
    Ok(true)
}
