//! How the learner wakes its workers.
//!
//! - **Only the answered ones.** One notify of the `to-workers` service wakes every worker
//!   listening to it: with more workers than ready tasks (W = 128 on 2 cores), nearly all of them
//!   for nothing, W wake-ups and W sends per answer. So an answered worker is woken through its
//!   own listener.
//! - **A heartbeat:** every worker is woken at least once per [`TICK`], so a waiting worker that
//!   hears nothing for longer knows the learner is stalled or gone, and only then lists the run's
//!   nodes to find out which.
//!
//! See docs/FLEET.md#oversubscription.

use acps_wire::ipc::{self, IpcError, TICK, TaskService};
use iceoryx2::identifiers::UniqueClientId;
use iceoryx2::port::notifier::{ListenerKey, Notifier, NotifierNotifyError};
use iceoryx2::prelude::{CallbackProgression, PortFactory as _};
use std::collections::HashMap;
use std::time::{Duration, Instant};

/// The learner's notifier of the `to-workers` service.
pub struct Waker {
    notifier: Notifier<iceoryx2::prelude::ipc::Service>,
    /// When every worker was last woken.
    all_woken: Instant,
    /// Workers answered since they were last woken, by their task client.
    answered: Vec<UniqueClientId>,
    /// The listener of each worker's node, by its task client.
    listeners: HashMap<UniqueClientId, ListenerKey>,
}

impl Waker {
    /// A waker over the run's `to-workers` service.
    pub fn new(services: &ipc::Services) -> Result<Self, IpcError> {
        let notifier = services
            .to_workers
            .notifier_builder()
            .create()
            .map_err(|source| IpcError::NotifierCreate {
                owner: "the learner",
                source,
            })?;
        Ok(Self {
            notifier,
            all_woken: Instant::now(),
            answered: Vec::new(),
            listeners: HashMap::new(),
        })
    }

    /// `client` was answered: wake it with the next [`Waker::wake_answered`].
    pub fn answered(&mut self, client: UniqueClientId) {
        if !self.answered.contains(&client) {
            self.answered.push(client);
        }
    }

    /// Wake the workers answered since the last call, each alone.
    pub fn wake_answered(&mut self, tasks: &TaskService) -> Result<(), IpcError> {
        let mut answered = std::mem::take(&mut self.answered);
        for client in answered.drain(..) {
            if !self.listeners.contains_key(&client) {
                self.learn_listeners(tasks);
            }
            // A client without a listener (a hand-made one) polls for its answers.
            let Some(key) = self.listeners.get(&client) else {
                continue;
            };
            match self.notifier.notify_single_listener(key) {
                Ok(()) => {}
                // Its listener is gone, and the worker with it.
                Err(NotifierNotifyError::InvalidListenerKey) => {
                    self.listeners.remove(&client);
                }
                Err(source) => {
                    return Err(IpcError::NotifierNotify {
                        whom: "a worker",
                        source,
                    });
                }
            }
        }
        self.answered = answered;
        Ok(())
    }

    /// Map every task client to the listener of its node (a worker has one of each). Both lists
    /// are read from shared memory, no files.
    fn learn_listeners(&mut self, tasks: &TaskService) {
        let mut by_node = HashMap::new();
        self.notifier.for_each_listener(|listener, details| {
            by_node.insert(details.node_id, listener.listener_key());
            CallbackProgression::Continue
        });
        self.listeners.clear();
        tasks.dynamic_config().list_clients(|client| {
            if let Some(key) = by_node.get(&client.node_id) {
                self.listeners.insert(client.client_id, *key);
            }
            CallbackProgression::Continue
        });
    }

    /// Wake every worker.
    pub fn wake_all(&mut self) -> Result<(), IpcError> {
        self.notifier.notify().map_err(|source| IpcError::NotifierNotify {
            whom: "the workers",
            source,
        })?;
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
