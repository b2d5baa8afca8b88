//! Waking a server that waits on its iceoryx2 listener when a network message arrives.
//!
//! Zenoh delivers messages on its own threads, and iceoryx2's ports cannot move between threads,
//! so a pump thread owns a node of the run and a notifier of its `to-learner` event: the network
//! callbacks queue their message and ring a [`Bell`], which pokes the pump only while the server
//! sleeps; the pump notifies, once per burst. A server that is awake takes the message in on its
//! next pass: poking it then cost a thread wake-up and a notification for nothing.

use acps_wire::ipc::{self, IpcError, RunName};
use std::sync::mpsc;
use std::thread::JoinHandle;

/// Pokes the pump; cheap and callable from any thread.
#[derive(Clone)]
pub(crate) struct Poke(mpsc::Sender<()>);

impl Poke {
    pub(crate) fn poke(&self) {
        // A pump that ended wakes nobody, and needs not.
        let _ = self.0.send(());
    }
}

/// Whether the server sleeps, kept under the same lock as the queue the callbacks fill. The
/// default wakes nobody (no serve, or it ended).
#[derive(Default)]
pub(crate) struct Bell {
    poke: Option<Poke>,
    asleep: bool,
}

impl Bell {
    /// A bell that pokes through `poke`; the server counts as asleep until it looks.
    pub(crate) fn new(poke: Poke) -> Self {
        Self {
            poke: Some(poke),
            asleep: true,
        }
    }

    /// Something was queued: wake the server if it sleeps, once per sleep.
    pub(crate) fn ring(&mut self) {
        if std::mem::take(&mut self.asleep)
            && let Some(poke) = &self.poke
        {
            poke.poke();
        }
    }

    /// The server takes in what is queued: it needs no wake-up until it sleeps again.
    pub(crate) fn awake(&mut self) {
        self.asleep = false;
    }

    /// The server is about to sleep, with `queued` messages waiting: it may unless there are
    /// some (they rang while it was awake). Called under the queue's lock, so a message queued
    /// after it rings, and the notification waits for the server in its listener.
    pub(crate) fn may_sleep(&mut self, queued: usize) -> bool {
        self.asleep = queued == 0;
        self.asleep
    }
}

/// Why a pump did not start.
#[derive(Debug, thiserror::Error)]
pub enum PumpStartError {
    /// Its node of the run, the run's services or its notifier could not be made.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// The operating system refused the thread.
    #[error("starting the network's wake-up thread")]
    ThreadSpawn(#[source] std::io::Error),
    /// The thread ended (it panicked) before it said whether it started.
    #[error("starting the network's wake-up thread: it ended")]
    ThreadEnded,
}

/// The pump thread of one serve of `run`; stopped and joined when dropped.
pub(crate) struct Pump {
    poke: Option<mpsc::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl Pump {
    /// Start pumping wake-ups to `run`'s learner (or relay) as node `name`.
    pub(crate) fn start(run: &RunName, name: &str) -> Result<(Self, Poke), PumpStartError> {
        let (poke, pokes) = mpsc::channel::<()>();
        let (ready, started) = mpsc::channel();
        let run = run.clone();
        let name = name.to_string();
        let thread = std::thread::Builder::new()
            .name(name.clone())
            .spawn(move || {
                let opened =
                    ipc::node(&run, &name).and_then(|node| {
                        let services = ipc::open_services(&node)?;
                        let notifier = services.to_learner.notifier_builder().create().map_err(|source| {
                            IpcError::NotifierCreate {
                                owner: "the network",
                                source,
                            }
                        })?;
                        Ok((node, services, notifier))
                    });
                let (_node, _services, notifier) = match opened {
                    Ok(opened) => {
                        let _ = ready.send(Ok(()));
                        opened
                    }
                    Err(error) => {
                        let _ = ready.send(Err(error));
                        return;
                    }
                };
                while pokes.recv().is_ok() {
                    // One notification per burst of messages.
                    while pokes.try_recv().is_ok() {}
                    if let Err(error) = notifier.notify() {
                        tracing::warn!("waking the server after a network message: {error:?}");
                    }
                }
            })
            .map_err(PumpStartError::ThreadSpawn)?;
        match started.recv() {
            Ok(Ok(())) => {}
            Ok(Err(error)) => {
                let _ = thread.join();
                return Err(error.into());
            }
            Err(_) => return Err(PumpStartError::ThreadEnded),
        }
        Ok((
            Self {
                poke: Some(poke.clone()),
                thread: Some(thread),
            },
            Poke(poke),
        ))
    }
}

impl Drop for Pump {
    fn drop(&mut self) {
        // The thread ends once every sender is gone: this one here, the pokes held by network
        // callbacks when those are undeclared.
        self.poke = None;
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bell_pokes_once_per_sleep_and_keeps_the_server_up_when_messages_wait() {
        let (poke, pokes) = mpsc::channel();
        let mut bell = Bell::new(Poke(poke));
        let count = || pokes.try_iter().count();
        // Asleep until the server first looks: the first message wakes it, the next ones not.
        bell.ring();
        bell.ring();
        assert_eq!(count(), 1);
        // Awake: nothing pokes.
        bell.awake();
        bell.ring();
        assert_eq!(count(), 0);
        // A message came in while it was awake: it must not sleep, and is not poked.
        assert!(!bell.may_sleep(1));
        bell.ring();
        assert_eq!(count(), 0);
        // Nothing waits: it sleeps, and the next message wakes it once.
        assert!(bell.may_sleep(0));
        bell.ring();
        bell.ring();
        assert_eq!(count(), 1);
        // A default bell wakes nobody.
        let mut silent = Bell::default();
        assert!(silent.may_sleep(0));
        silent.ring();
        assert_eq!(count(), 0);
    }
}
