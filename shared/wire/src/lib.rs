//! The acps wire: what crosses shared memory between a learner and its workers, and how both
//! sides open it.
//!
//! - [`wire`]: the fixed-size, `#[repr(C)]` payloads (tasks, outcomes, requests, answers), their
//!   capacities and the protocol version.
//! - [`layout`]: the payloads' layout as JSON, which workers in other languages are tested
//!   against (docs/PROTOCOL.md).
//! - [`ipc`]: run names, the iceoryx2 services every side opens with the same limits, and the
//!   removal of what dead processes left.
//! - [`secret`]: the run's secret, which every worker message carries and the learner checks.
#![warn(missing_docs)]

pub mod ipc;
pub mod layout;
pub mod secret;
pub mod wire;
