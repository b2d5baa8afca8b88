//! The simulator worker of an acps fleet.
//!
//! A worker joins a run by name, keeps up to K requests in flight with the run's learner, and
//! answers each task it receives with the rollout's outcome, sent as its next request. It stops
//! when the learner says the run is over, when the learner disappears, when the caller's stop
//! flag is set, or when the learner refuses it (another build or another run).
//!
//! Embedding: call [`serve`] on any thread of your program with an [`EnvironmentFactory`] (for
//! example [`Single`] around your own [`Environment`]) and an `AtomicBool` to stop it.

use acps_shared::ipc::{self, IpcError, MAX_IN_FLIGHT_PER_WORKER, RunName, TICK};
use acps_shared::wire::{EnvironmentSpec, PROTOCOL_VERSION, Response, WireTask, WorkerMessage};
use acps_shared::{Environment, Outcome};
use iceoryx2::prelude::{CallbackProgression, PortFactory as _};
use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// How often a starting worker looks for the run's learner.
const JOIN_POLL: Duration = Duration::from_millis(2);

/// Where a worker gets the environment a task names.
pub trait EnvironmentFactory {
    /// The environment for `spec`, or why there is none.
    fn environment(&mut self, spec: &EnvironmentSpec) -> Result<&mut dyn Environment, String>;
}

/// Builds environments with `acps_models::environment::build` and keeps them for later tasks.
#[derive(Default)]
pub struct ModelFactory {
    cache: HashMap<EnvironmentSpec, Box<dyn Environment>>,
}

impl EnvironmentFactory for ModelFactory {
    fn environment(&mut self, spec: &EnvironmentSpec) -> Result<&mut dyn Environment, String> {
        if !self.cache.contains_key(spec) {
            let environment = acps_models::environment::build(spec).map_err(|e| e.to_string())?;
            self.cache.insert(*spec, environment);
        }
        Ok(self.cache.get_mut(spec).expect("inserted above").as_mut())
    }
}

/// One environment of your own, used for every task whatever its spec says.
pub struct Single<E: Environment>(pub E);

impl<E: Environment> EnvironmentFactory for Single<E> {
    fn environment(&mut self, _: &EnvironmentSpec) -> Result<&mut dyn Environment, String> {
        Ok(&mut self.0)
    }
}

/// How a worker behaves.
#[derive(Debug, Clone)]
pub struct WorkerOptions {
    /// Requests kept in flight, 1..=64: more hides the wake-up latency between processes.
    pub in_flight: usize,
    /// The worker's node name (shown by iceoryx2's tools).
    pub name: String,
    /// How long to wait for the run's learner to appear before giving up.
    pub startup_timeout: Duration,
    /// How long to poll (yielding the CPU) for an answer before blocking: saves the wake-up
    /// latency when every process has a core of its own; use zero when processes outnumber cores.
    pub spin: Duration,
}

impl Default for WorkerOptions {
    fn default() -> Self {
        Self {
            in_flight: 4,
            name: format!("worker-{}", std::process::id()),
            startup_timeout: Duration::from_secs(10),
            spin: Duration::ZERO,
        }
    }
}

/// Why a worker stopped.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum WorkerExit {
    /// The learner said the run is over.
    Finished,
    /// The learner disappeared (crashed or killed).
    LearnerGone,
    /// The caller's stop flag was set.
    Stopped,
}

/// What a worker did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WorkerReport {
    /// Why it stopped.
    pub exit: WorkerExit,
    /// Rollouts performed.
    pub rollouts: u64,
}

/// A worker that could not serve.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WorkerError {
    /// A bad option.
    #[error("worker option {field} must be {accepted}, got {got}")]
    Option {
        /// The option.
        field: &'static str,
        /// The accepted range.
        accepted: &'static str,
        /// The value.
        got: String,
    },
    /// iceoryx2 failed.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// No learner serves the run.
    #[error("no learner serves run '{run}' (waited {waited:?}); start it with `acps run ... --run {run}`")]
    NoLearner {
        /// The run.
        run: String,
        /// How long the worker waited.
        waited: Duration,
    },
    /// The learner refused this worker.
    #[error("the learner of run '{run}' refused this worker: {reason}")]
    Refused {
        /// The run.
        run: String,
        /// Why.
        reason: String,
    },
    /// A task named an environment the factory cannot provide.
    #[error("task {task_id} of job {job}: no environment: {reason}")]
    Environment {
        /// The job.
        job: u32,
        /// The task.
        task_id: u64,
        /// The factory's reason.
        reason: String,
    },
}

/// Whether the run's server (the learner) runs in a live node. Workers leave cleaning up dead
/// nodes to the learner: concurrent cleanups of one dead node can interrupt each other.
fn learner_alive(run: &RunName, services: &ipc::Services) -> Result<bool, IpcError> {
    let alive = ipc::alive_nodes(run)?;
    let mut serving = false;
    services.tasks.dynamic_config().list_servers(|server| {
        serving |= alive.contains(&server.node_id);
        CallbackProgression::Continue
    });
    Ok(serving)
}

/// Serve the learner of `run` until it finishes, disappears or `stop` is set.
pub fn serve(
    run: &RunName,
    options: &WorkerOptions,
    factory: &mut dyn EnvironmentFactory,
    stop: &AtomicBool,
) -> Result<WorkerReport, WorkerError> {
    if !(1..=MAX_IN_FLIGHT_PER_WORKER).contains(&options.in_flight) {
        return Err(WorkerError::Option {
            field: "in_flight",
            accepted: "in 1..=64",
            got: options.in_flight.to_string(),
        });
    }
    let node = ipc::node(run, &options.name)?;
    let services = ipc::open_services(&node)?;
    let started = Instant::now();
    while services.tasks.dynamic_config().number_of_servers() == 0 {
        if stop.load(Ordering::Relaxed) {
            return Ok(WorkerReport {
                exit: WorkerExit::Stopped,
                rollouts: 0,
            });
        }
        if started.elapsed() > options.startup_timeout {
            return Err(WorkerError::NoLearner {
                run: run.to_string(),
                waited: started.elapsed(),
            });
        }
        // Spawned workers usually start before the learner serves; a short poll lets them join
        // within a few milliseconds (a benchmark row lasts about a second).
        std::thread::sleep(JOIN_POLL);
    }
    tracing::info!("worker {} joins run '{run}'", options.name);
    let client = services
        .tasks
        .client_builder()
        .create()
        .map_err(|e| IpcError::new("creating the worker's client", e))?;
    let notifier = services
        .to_learner
        .notifier_builder()
        .create()
        .map_err(|e| IpcError::new("creating the worker's notifier", e))?;
    let listener = services
        .to_workers
        .listener_builder()
        .create()
        .map_err(|e| IpcError::new("creating the worker's listener", e))?;
    let send = |message: WorkerMessage| {
        client
            .send_copy(message)
            .map_err(|e| IpcError::new("sending a request", e))
    };
    // The learner's identity, learnt from its first answer; 0 asks to join whatever runs.
    let mut identity = 0u64;
    let mut pending: Vec<_> = (0..options.in_flight)
        .map(|_| send(WorkerMessage::hello(identity)).map(Some))
        .collect::<Result<_, _>>()?;
    notifier.notify().map_err(|e| IpcError::new("waking the learner", e))?;
    let mut rollouts = 0;
    let mut idle_since = None;
    // Tasks answered by the learner and not yet simulated, with the slot each frees.
    let mut queue = VecDeque::new();
    // Outcomes sent since the learner was last woken: waking it once per half window (rather
    // than per outcome) keeps it from preempting a worker thousands of times a second when
    // processes share cores, while the other half window keeps this worker busy meanwhile.
    let mut unannounced = 0;
    let wake_every = options.in_flight.div_ceil(2);
    loop {
        if stop.load(Ordering::Relaxed) {
            return Ok(WorkerReport {
                exit: WorkerExit::Stopped,
                rollouts,
            });
        }
        // Polling every slot costs about as much as a trivial rollout, so it waits until the
        // queue runs dry: answers that arrive meanwhile wait in their slots.
        let slots = if queue.is_empty() { pending.len() } else { 0 };
        for (index, slot) in pending.iter_mut().enumerate().take(slots) {
            let Some(request) = slot.as_ref() else { continue };
            let Some(response) = request
                .receive()
                .map_err(|e| IpcError::new("receiving a response", e))?
            else {
                continue;
            };
            let wire: WireTask = *response.payload();
            drop(response);
            // The answered request must be gone before the next one is sent: the service allows
            // only `in_flight` active requests per client.
            *slot = None;
            match wire.response() {
                Some(Response::Task) => queue.push_back((index, wire)),
                Some(Response::Stop) => {
                    return Ok(WorkerReport {
                        exit: WorkerExit::Finished,
                        rollouts,
                    });
                }
                Some(Response::Refused) | None => {
                    let reason = if wire.protocol != PROTOCOL_VERSION {
                        format!(
                            "protocol version {} here, {} at the learner (another build)",
                            PROTOCOL_VERSION, wire.protocol
                        )
                    } else {
                        format!(
                            "this worker belongs to run identity {identity:016x}, the learner runs {:016x}",
                            wire.run
                        )
                    };
                    return Err(WorkerError::Refused {
                        run: run.to_string(),
                        reason,
                    });
                }
            }
        }
        if let Some((index, wire)) = queue.pop_front() {
            if identity == 0 {
                identity = wire.run;
            }
            let task = wire.to_task();
            let environment = factory
                .environment(&wire.environment)
                .map_err(|reason| WorkerError::Environment {
                    job: wire.job,
                    task_id: task.id,
                    reason,
                })?;
            let outcome = environment.rollout(&task);
            rollouts += 1;
            // An outcome the wire cannot carry is reported as failed rather than cut.
            let message = WorkerMessage::with_outcome(identity, wire.job, &outcome)
                .or_else(|_| WorkerMessage::with_outcome(identity, wire.job, &Outcome::failed(task.id)))
                .expect("a failed outcome has no diagnostics");
            pending[index] = Some(send(message)?);
            unannounced += 1;
            if unannounced >= wake_every || queue.is_empty() {
                notifier.notify().map_err(|e| IpcError::new("waking the learner", e))?;
                unannounced = 0;
            }
            idle_since = None;
            continue;
        }
        let idle = *idle_since.get_or_insert_with(Instant::now);
        if idle.elapsed() < options.spin {
            std::thread::yield_now();
            continue;
        }
        idle_since = None;
        let woken = listener
            .timed_wait(|_| {}, TICK)
            .map_err(|e| IpcError::new("waiting for the learner", e))?;
        if woken == 0 && !learner_alive(run, &services)? {
            return Ok(WorkerReport {
                exit: WorkerExit::LearnerGone,
                rollouts,
            });
        }
    }
}
