//! What every part of an acps run agrees on: the task a learner hands out, the outcome an
//! environment returns, what an environment is, the problem description, the space contexts live
//! in, and how seeds are derived.
#![warn(missing_docs)]

mod context_space;
mod fnv;
mod problem;
mod seed;
mod spec;
mod task;

pub use context_space::{ContextSpace, ContextSpaceError, random_unit_vector};
pub use fnv::{FNV_OFFSET, fnv1a};
pub use problem::{EnvironmentMatchError, Problem, ScoreAggregate};
pub use seed::{Stream, derive_seed};
pub use spec::{EnvironmentSpec, MAX_NAME, Serves, SpecBuildError};
pub use task::{Environment, Outcome, OutcomeStatus, Task, TaskKind};
