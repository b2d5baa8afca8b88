//! Workers on other hosts: one learner, many machines, over Zenoh.
//!
//! A host's workers stay what they are (`acps worker`, embedded Rust workers, Python workers):
//! they talk iceoryx2 to a local process. On the learner's host that is the learner; on every
//! other host it is a **relay** ([`relay::serve`]), which serves them as their learner does and,
//! to the learner, is one Zenoh peer that asks for their tasks in batches and returns their
//! outcomes. The learner's [`Listener`] admits relays (protocol, build, run and identity checked,
//! refusals in words on both sides) and serves them beside its local workers through the same
//! fleet server, so the run's results are bit for bit those of an in-process run.
//!
//! - [`net`]: the keys, the messages and the Zenoh session settings (peer mode, only the given
//!   endpoints, no scouting, the lease; user/password from a Zenoh configuration file).
//! - [`Listener`]: the learner's side, a [`Remote`](acps_fleet::Remote) of its fleet.
//! - [`relay`]: the relay's side.
//!
//! Faults: a relay that dies is noticed within milliseconds (its liveliness token goes with its
//! connection); a frozen or cut-off one after the lease; a relay whose workers all hang after the
//! fleet's liveness deadline. Its tasks then go to other workers, and it is evicted: its late
//! outcomes are dropped, and it joins again as a new peer. A relay whose learner vanished waits
//! a bounded time for the run to come back (resumed), then exits.
//!
//! docs/HOSTS.md shows how to run one learner and relays on several hosts.
#![warn(missing_docs)]

mod listener;
pub mod net;
mod pump;
pub mod relay;

pub use listener::{ListenError, Listener};
pub use net::{NetError, NetOptions};
pub use pump::PumpStartError;
pub use relay::{RelayError, RelayOptions, RelayReport};
