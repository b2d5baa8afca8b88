//! Waking a server that waits on its iceoryx2 listener when a network message arrives.
//!
//! Zenoh delivers messages on its own threads, and iceoryx2's ports cannot move between threads,
//! so a pump thread owns a node of the run and a notifier of its `to-learner` event: the network
//! callbacks queue their message and poke the pump, which notifies, once per burst.

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

/// The pump thread of one serve of `run`; stopped and joined when dropped.
pub(crate) struct Pump {
    poke: Option<mpsc::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl Pump {
    /// Start pumping wake-ups to `run`'s learner (or relay) as node `name`.
    pub(crate) fn start(run: &RunName, name: &str) -> Result<(Self, Poke), IpcError> {
        let (poke, pokes) = mpsc::channel::<()>();
        let (ready, started) = mpsc::channel();
        let run = run.clone();
        let name = name.to_string();
        let thread = std::thread::Builder::new()
            .name(name.clone())
            .spawn(move || {
                let opened = ipc::node(&run, &name).and_then(|node| {
                    let services = ipc::open_services(&node)?;
                    let notifier = services
                        .to_learner
                        .notifier_builder()
                        .create()
                        .map_err(|e| IpcError::new("creating the network's notifier", e))?;
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
            .map_err(|e| IpcError::new("starting the network's wake-up thread", e))?;
        match started.recv() {
            Ok(Ok(())) => {}
            Ok(Err(error)) => {
                let _ = thread.join();
                return Err(error);
            }
            Err(_) => return Err(IpcError::new("starting the network's wake-up thread", "it ended")),
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
