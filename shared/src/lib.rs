//! What every part of an acps run agrees on, whoever simulates it:
//!
//! - `problem`: [`Problem`], what the learner needs to know about a problem (its contexts,
//!   space, initial parameters and how evaluations are scored).
//! - `context_space`: [`ContextSpace`], the box or ball the contexts live in, and the [`nearest`]
//!   of a list of contexts.
//! - `task`: the [`Task`] a learner hands out, the [`Outcome`] a rollout returns, and the
//!   [`Environment`] trait of whatever performs rollouts.
//! - `seed`: how every random stream of a run is derived from its seed ([`derive_seed`]).
//! - `spec`: [`EnvironmentSpec`], what an environment is: the identity a problem is defined for,
//!   every task names and every worker declares ([`Serves`]).
//! - `fnv`: the stable hash ([`fnv1a`]) of identities and checksums.
#![warn(missing_docs)]

mod context_space;
mod fnv;
mod problem;
mod seed;
mod spec;
mod task;

pub use context_space::{ContextSpace, ContextSpaceCreateError, nearest, random_unit_vector};
pub use fnv::{FNV_OFFSET, fnv1a};
pub use problem::{EnvironmentMatchError, Problem, ScoreAggregate};
pub use seed::{Stream, derive_seed};
pub use spec::{EnvironmentSpec, MAX_NAME, Serves, SpecBuildError};
pub use task::{Environment, EnvironmentRestoreError, Outcome, OutcomeStatus, Task, TaskKind};
