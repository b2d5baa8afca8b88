//! How the learner wakes its workers.
//!
//! A heartbeat: every worker is woken at least once per [`TICK`], so a waiting worker that hears
//! nothing for longer knows the learner is stalled or gone, and only then lists the run's nodes
//! to find out which (docs/FLEET.md#oversubscription).

use acps_wire::ipc::{self, IpcError, TICK};
use iceoryx2::port::notifier::Notifier;
use std::time::{Duration, Instant};

/// The learner's notifier of the `to-workers` service.
pub struct Waker {
    notifier: Notifier<iceoryx2::prelude::ipc::Service>,
    /// When every worker was last woken.
    all_woken: Instant,
}

impl Waker {
    /// A waker over the run's `to-workers` service.
    pub fn new(services: &ipc::Services) -> Result<Self, IpcError> {
        let notifier = services
            .to_workers
            .notifier_builder()
            .create()
            .map_err(|e| IpcError::new("creating the learner's notifier", e))?;
        Ok(Self {
            notifier,
            all_woken: Instant::now(),
        })
    }

    /// Wake every worker.
    pub fn wake_all(&mut self) -> Result<(), IpcError> {
        self.notifier
            .notify()
            .map_err(|e| IpcError::new("waking the workers", e))?;
        self.all_woken = Instant::now();
        Ok(())
    }

    /// Wake every worker if none was woken for a tick: the heartbeat.
    pub fn heartbeat(&mut self) -> Result<(), IpcError> {
        if self.all_woken.elapsed() >= TICK {
            self.wake_all()?;
        }
        Ok(())
    }

    /// How long the learner may wait before the next heartbeat is due.
    pub fn until_heartbeat(&self) -> Duration {
        TICK.saturating_sub(self.all_woken.elapsed())
    }
}
