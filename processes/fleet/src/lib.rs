//! The acps fleet: learner cores served to worker processes over iceoryx2 shared memory.
//!
//! - [`Fleet`]: one run's lifecycle: its name and identity, cleanup of what dead runs left,
//!   the worker processes it starts, Ctrl-C, progress, and removal of its shared memory.
//! - [`server`]: how tasks go out and outcomes come back, many learner cores at once; the
//!   tasks of workers that die or hang are re-issued ([`Liveness`]).
//! - [`processes`]: the scheduling priority of worker processes.
//! - `wake` (internal): how the learner wakes its workers: only those it answered, all once per
//!   tick.
//!
//! Workers are `acps-worker`'s [`serve`](https://docs.rs/acps-worker) in any process; a
//! fleet's results are bit for bit those of the same learners driven in-process.
#![warn(missing_docs)]

mod fleet;
pub mod processes;
pub mod server;
mod wake;

/// The progress [`TaskSource::learning`] reports.
pub use acps_learner::{Interrupted, LearningProgress};
pub use acps_wire::ipc::{RunName, RunNameParseError, ServerError};
pub use acps_wire::secret::{RunSecret, SecretError};
pub use fleet::{Fleet, FleetBuilder, FleetStartError, RUN_ENV, SECRET_ENV};
pub use server::{
    FleetError, FleetJob, FleetJobBuildError, FleetProgress, ForwardError, ForwardingSource, Learners, Liveness,
    ObserveError, Observer, PeerId, Remote, RemoteEvent, RemoteServeError, ServeOptions, TaskSource,
};
