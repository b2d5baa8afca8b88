//! The acps fleet: learner cores served to worker processes over iceoryx2 shared memory.
//!
//! - [`server`]: serves any number of [`acps_learner::Learner`] cores to the workers of a run,
//!   re-issuing the tasks of workers that die.
//! - [`processes`]: worker processes this program starts, and their scheduling priority.
//! - [`wake`]: how the learner wakes its workers.
#![warn(missing_docs)]

pub mod processes;
pub mod server;
pub mod wake;

pub use server::{FleetError, FleetJob, FleetProgress, ServeOptions, serve};
