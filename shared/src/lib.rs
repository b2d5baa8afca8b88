//! What every part of an acps run agrees on: the task a learner hands out, the outcome an
//! environment returns, the problem description, the space contexts live in, and how seeds are
//! derived.
#![warn(missing_docs)]

mod context_space;
mod problem;
mod seed;
mod spec;
mod task;

pub use context_space::{ContextSpace, ContextSpaceCreateError, random_unit_vector};
pub use problem::{Problem, ScoreAggregate};
pub use seed::{Stream, derive_seed};
pub use spec::EnvironmentSpec;
pub use task::{Environment, EnvironmentRestoreError, Outcome, OutcomeStatus, Task, TaskKind};
