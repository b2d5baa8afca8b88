//! acps experiments as a library: what the `acps` command runs, for any Rust program.
//!
//! - [`settings`]: every setting of an experiment, declared once with its range ([`keys`]: what
//!   a key is and how it is refused); [`mod@file`]: experiment files as read and written;
//! - [`plan`]: a request checked into a [`plan::Plan`] of [`plan::Job`]s;
//! - [`problem_file`]: a `[problem]` table of the user's, simulated by their workers;
//! - [`paper`]: the paper's experiments (Sections 4 and 5) as [`experiment::Experiment`]s;
//! - [`experiment`]: the runner, in this process or through a worker fleet;
//! - [`checkpoints`]: the learners' checkpoints and resume;
//! - [`summary`] and [`records`]: `summary.json` and the run directory's tables and policies;
//! - [`run_dir`]: a run directory from an experiment file: plan, prepare, run, write;
//! - [`progress`]: the progress line; [`workers`]: the project's models as worker environments.
#![warn(missing_docs)]

pub mod checkpoints;
pub mod experiment;
pub mod file;
pub mod keys;
pub mod paper;
pub mod plan;
pub mod problem_file;
pub mod progress;
pub mod records;
mod regular;
pub mod run_dir;
pub mod settings;
pub mod summary;
pub mod workers;
