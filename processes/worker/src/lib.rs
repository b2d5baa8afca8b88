//! The simulator worker of an acps fleet.
//!
//! A worker joins a run by name, keeps up to K tasks in flight with the run's learner (asked
//! for, queued or not yet reported), and sends the outcomes of the tasks it performed with its
//! next request for tasks; cheap rollouts travel in batches. It stops
//! when the learner says the run is over, when the learner disappears, when the caller's stop
//! flag is set, or when the learner refuses it (another build or another run, or an environment
//! no job of the run needs).
//!
//! Every request declares the environments the worker serves ([`EnvironmentFactory::serves`]),
//! and the worker checks every task: one that needs another environment than the one its
//! factory provides stops it with an error naming both, and the learner hands the task to
//! another worker once this one is gone.
//!
//! Embedding: call [`serve`] on any thread of your program with an [`EnvironmentFactory`] (for
//! example [`Single`] around your own [`Environment`]) and an `AtomicBool` to stop it.
#![warn(missing_docs)]

use acps_shared::{Environment, EnvironmentSpec, Outcome, Serves, Task};
use acps_wire::ipc::{self, IpcError, MAX_ASKING_REQUESTS, MAX_IN_FLIGHT_PER_WORKER, PendingTasks, TICK};
/// A run's name, which a worker joins by; [`RunName::from_env`] reads the one a fleet gives the
/// worker processes it starts.
pub use acps_wire::ipc::{RunName, RunNameParseError};
/// A run's secret, and where a worker finds it.
pub use acps_wire::secret::{RunSecret, SECRET_ENV, SecretError, SecretOrigin};
pub use acps_wire::wire::Sizes;
use acps_wire::wire::{
    self, Answer, CapacityError, MAX_BATCH, PROTOCOL_VERSION, Refusal, Response, WireEnvironment, WireOutcome,
    WireTask, WorkerMessage,
};
use iceoryx2::port::listener::ListenerWaitError;
use iceoryx2::prelude::{CallbackProgression, PortFactory as _};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// How often a starting worker looks for the run's learner.
const JOIN_POLL: Duration = Duration::from_millis(2);

/// Where a worker gets the environment a task names.
pub trait EnvironmentFactory {
    /// The environments this factory provides, declared to the learner with every request.
    fn serves(&self) -> Serves;

    /// The environment for `spec`, or why there is none. The worker refuses the task when the
    /// environment's own spec is not `spec`.
    fn environment(&mut self, spec: &EnvironmentSpec) -> Result<&mut dyn Environment, EnvironmentProvideError>;
}

/// Why an [`EnvironmentFactory`] provides no environment for a spec: the factory's own error
/// (building a simulator can fail in as many ways as there are simulators), or a spec a task
/// carried that does not decode.
#[derive(Debug, thiserror::Error)]
#[error(transparent)]
pub struct EnvironmentProvideError(Box<dyn std::error::Error + Send + Sync>);

impl EnvironmentProvideError {
    /// The factory's `error`.
    pub fn new(error: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> Self {
        Self(error.into())
    }
}

/// One environment of your own: the worker serves its spec and refuses tasks of any other.
pub struct Single<E: Environment>(pub E);

impl<E: Environment> EnvironmentFactory for Single<E> {
    fn serves(&self) -> Serves {
        Serves::One(self.0.spec())
    }

    fn environment(&mut self, _: &EnvironmentSpec) -> Result<&mut dyn Environment, EnvironmentProvideError> {
        Ok(&mut self.0)
    }
}

/// How a worker behaves.
#[derive(Debug, Clone)]
pub struct WorkerOptions {
    /// The worker's queue: tasks kept asked for, queued or not yet reported, 1..=128. More
    /// hides the wake-up latency between processes. Cheap rollouts travel in batches of up to
    /// half of them; at most 8 requests ask for tasks at once, so rollouts that travel alone
    /// (slower than a batch's 800 us) keep at most 8 in flight. Not the learner's window
    /// (`LearnerConfig::in_flight`), which decides the results.
    pub queue_depth: usize,
    /// The worker's node name (shown by iceoryx2's tools): [`ipc::WORKER_NAMES`].
    pub name: String,
    /// How long to wait for the run's learner to appear before giving up.
    pub startup_timeout: Duration,
    /// How long to poll (yielding the CPU) for an answer before blocking: saves the wake-up
    /// latency when every process has a core of its own; use zero when processes outnumber cores.
    pub spin: Duration,
    /// The lengths of contexts and parameters this worker's simulator takes, if it says: the
    /// learner then refuses it at once, naming both sides, when its jobs carry others (without,
    /// a worker of other sizes fails every rollout).
    pub sizes: Option<Sizes>,
    /// Hand the environment every queued task of one environment at once, through
    /// [`Environment::rollout_batch`] (a vectorised simulator), instead of one per
    /// [`Environment::rollout`]: at most 64 (one request's outcomes) and at most `queue_depth`.
    /// Off by default: one by one, outcomes go back while later tasks are simulated.
    pub batches: bool,
}

pub use acps_wire::ipc::DEFAULT_QUEUE_DEPTH;

impl Default for WorkerOptions {
    fn default() -> Self {
        Self {
            queue_depth: DEFAULT_QUEUE_DEPTH,
            name: format!("worker-{}", std::process::id()),
            startup_timeout: Duration::from_secs(10),
            spin: Duration::ZERO,
            sizes: None,
            batches: false,
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
#[derive(Debug, thiserror::Error)]
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
    #[error("no learner serves run '{run}' (waited {waited:?})")]
    NoLearner {
        /// The run.
        run: RunName,
        /// How long the worker waited.
        waited: Duration,
    },
    /// The learner refused this worker.
    #[error("the learner of run '{run}' refused this worker: {reason}")]
    Refused {
        /// The run.
        run: RunName,
        /// Why, naming both sides' protocol versions, run identities or environments.
        reason: String,
    },
    /// The run's secret could not be read: its file is not one this user's learner wrote, or
    /// [`SECRET_ENV`] holds no secret.
    #[error(transparent)]
    Secret(Box<SecretError>),
    /// The environment returned an outcome the wire cannot carry (too many diagnostics).
    #[error("task {task_id} of job {job}: the outcome cannot be sent: {capacity}")]
    OutcomeTooLarge {
        /// The job.
        job: u32,
        /// The task.
        task_id: u64,
        /// What exceeds which capacity.
        capacity: CapacityError,
    },
    /// An environment's [`Environment::rollout_batch`] did not return one outcome per task in
    /// the tasks' order: the outcomes cannot be matched to their tasks.
    #[error("a batch of job {job}: {reason}; the worker stops, and the learner hands its tasks to another worker")]
    Batch {
        /// The job of the batch's first task.
        job: u32,
        /// What is wrong.
        reason: String,
    },
    /// A task needs another environment than the one the factory provided for it (for example
    /// one the learner's build configures differently).
    #[error(
        "task {task_id} of job {job} needs environment {needed}, this worker's is {provided}; it stops, and the learner hands the task to another worker"
    )]
    TaskRefused {
        /// The job.
        job: u32,
        /// The task.
        task_id: u64,
        /// The environment the task needs (boxed, as errors are rare and results stay small).
        needed: Box<EnvironmentSpec>,
        /// The environment the factory provided.
        provided: Box<EnvironmentSpec>,
    },
    /// A task named an environment the factory cannot provide.
    #[error("task {task_id} of job {job}: no environment")]
    Environment {
        /// The job.
        job: u32,
        /// The task.
        task_id: u64,
        /// The factory's reason.
        #[source]
        reason: EnvironmentProvideError,
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

/// Whether the learner lives, asked cheaply unless `list`: the id of the learner's node holds the
/// PID of its process, and /proc tells in one small file read whether that still runs. Listing
/// the run's nodes ([`learner_alive`]) reads every node's files, 7-10 ms at 129 nodes; it
/// decides when the PID's process is gone, and when `list` (a PID may be reused, or belong to
/// another PID namespace).
fn learner_lives(run: &RunName, services: &ipc::Services, list: bool) -> Result<bool, IpcError> {
    if !list && learner_process_runs(services) {
        return Ok(true);
    }
    learner_alive(run, services)
}

/// Whether the process that created the server's node (the learner) runs.
fn learner_process_runs(services: &ipc::Services) -> bool {
    let mut runs = false;
    services.tasks.dynamic_config().list_servers(|server| {
        runs |= server
            .node_id
            .pid::<iceoryx2::prelude::ipc::Service>()
            .is_ok_and(|pid| ipc::process_runs(pid.value()));
        CallbackProgression::Continue
    });
    runs
}

/// Serve the learner of `run` until it finishes, disappears or `stop` is set.
pub fn serve(
    run: &RunName,
    options: &WorkerOptions,
    factory: &mut dyn EnvironmentFactory,
    stop: &AtomicBool,
) -> Result<WorkerReport, WorkerError> {
    if !(1..=MAX_IN_FLIGHT_PER_WORKER).contains(&options.queue_depth) {
        return Err(WorkerError::Option {
            field: "queue_depth",
            accepted: "in 1..=128",
            got: options.queue_depth.to_string(),
        });
    }
    ipc::check_worker_name(&options.name).map_err(|e| WorkerError::Option {
        field: "name",
        accepted: ipc::WORKER_NAMES,
        got: e.got,
    })?;
    let node = ipc::worker_node(run, &options.name)?;
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
            let waited = started.elapsed();
            drop(services);
            drop(node);
            // No learner came: this worker may have created the run's files, and nobody else
            // would remove them before the next fleet starts.
            if ipc::live_nodes(run).is_ok_and(|alive| alive == 0) {
                let _ = ipc::remove_run_files(run);
            }
            return Err(WorkerError::NoLearner {
                run: run.clone(),
                waited,
            });
        }
        // Spawned workers usually start before the learner serves; a short poll lets them join
        // within a few milliseconds (a benchmark row lasts about a second).
        std::thread::sleep(JOIN_POLL);
    }
    let (secret, origin) = find_secret(run, options, started, stop)?;
    tracing::info!("worker {} joins run '{run}'", options.name);
    let client = services
        .tasks
        .client_builder()
        .create()
        .map_err(IpcError::ClientCreate)?;
    let notifier = services
        .to_learner
        .notifier_builder()
        .create()
        .map_err(|source| IpcError::NotifierCreate {
            owner: "the worker",
            source,
        })?;
    let listener = services
        .to_workers
        .listener_builder()
        .create()
        .map_err(|source| IpcError::ListenerCreate {
            owner: "the worker",
            source,
        })?;
    // The learner's identity, learnt from its first answer; 0 asks to join whatever runs.
    let mut identity = 0u64;
    let serves = factory.serves();
    // Requests in flight, each with the number of tasks it asks for; `None` is a free slot. The
    // first `asking` slots ask for tasks, the last one only delivers outcomes.
    let asking = options.queue_depth.min(MAX_ASKING_REQUESTS);
    let mut slots: Vec<Option<(PendingTasks, usize)>> = (0..=asking).map(|_| None).collect();
    // Tasks answered by the learner and not yet simulated.
    let mut queue: VecDeque<WireTask> = VecDeque::new();
    // Outcomes not yet sent. Each request starts from one made once: making it looks up the
    // environment's settings text, which is no work for every request.
    let template = {
        let mut message = WorkerMessage::request(0, 1, serves);
        if let Some(secret) = secret {
            message = message.carrying(secret);
        }
        match options.sizes {
            Some(sizes) => message.declaring(sizes),
            None => message,
        }
    };
    let fresh_outbox = |identity| {
        let mut message = template;
        message.run = identity;
        message
    };
    let mut outbox = fresh_outbox(identity);
    let mut batching = Batching::new(options.queue_depth);
    // Told to the learner, which then waits for this worker at least a few times as long.
    let mut slowest = Duration::ZERO;
    let mut rollouts = 0;
    // The environment the last task needed, once its spec was read and the factory's environment
    // found to be it: tasks of one environment follow each other, and reading and checking the
    // spec again for each would cost a tenth of a trivial rollout.
    let mut checked: Option<(WireEnvironment, EnvironmentSpec)> = None;
    let mut idle_since = None;
    let mut silence = Silence::default();
    // Requests sent since the learner was last woken.
    let mut unannounced = false;
    loop {
        if stop.load(Ordering::Relaxed) {
            return Ok(WorkerReport {
                exit: WorkerExit::Stopped,
                rollouts,
            });
        }
        // Send what `next_request` says, until it says nothing.
        let mut sent = false;
        loop {
            let asked: usize = slots.iter().flatten().map(|(_, want)| want).sum();
            let Some((slot, want)) = next_request(Budget {
                queue_depth: options.queue_depth,
                queued: queue.len(),
                asked,
                outbox: outbox.count as usize,
                batch: batching.size(),
                free_asking: slots[..asking].iter().position(Option::is_none),
                delivery_free: slots[asking].is_none(),
            }) else {
                break;
            };
            outbox.run = identity;
            outbox.want = want as u32;
            outbox.observe_rollout(slowest);
            let request = client.send_copy(outbox).map_err(IpcError::RequestSend)?;
            // The delivery slot is the last, after the asking ones.
            slots[slot.unwrap_or(asking)] = Some((request, want));
            outbox = fresh_outbox(identity);
            sent = true;
        }
        unannounced |= sent;
        let outbox_full = outbox.count as usize >= MAX_BATCH;
        if unannounced && wakes_learner(queue.len(), batching.size(), outbox_full) {
            notifier.notify().map_err(|source| IpcError::NotifierNotify {
                whom: "the learner",
                source,
            })?;
            unannounced = false;
        }
        // Polling every slot costs about as much as a trivial rollout, so it waits until the
        // queue runs dry (or outcomes cannot go out): answers that arrive meanwhile wait in
        // their slots.
        if queue.is_empty() || outbox_full {
            for slot in slots.iter_mut() {
                let Some((request, _)) = slot.as_ref() else { continue };
                let Some(response) = request.receive().map_err(IpcError::ResponseReceive)? else {
                    continue;
                };
                let answer = *response.user_header();
                match answer.response() {
                    Some(Response::Task) => {
                        if identity == 0 {
                            identity = answer.run;
                        }
                        queue.extend(response.payload());
                    }
                    Some(Response::Stop) => {
                        return Ok(WorkerReport {
                            exit: WorkerExit::Finished,
                            rollouts,
                        });
                    }
                    Some(Response::Refused) | None => {
                        return Err(WorkerError::Refused {
                            run: run.clone(),
                            reason: refusal_reason(&answer, identity, &serves, options.sizes, &origin),
                        });
                    }
                }
                // The answered request must be gone before the next one is sent: the service
                // allows only `queue_depth` active requests per client.
                drop(response);
                *slot = None;
            }
        }
        let next = if outbox_full { None } else { queue.pop_front() };
        if let Some(wire) = next {
            let task = wire.to_task();
            let no_environment = |reason| WorkerError::Environment {
                job: wire.job,
                task_id: task.id,
                reason,
            };
            let known = checked
                .filter(|(seen, _)| *seen == wire.environment)
                .map(|(_, spec)| spec);
            let spec = match known {
                Some(spec) => spec,
                None => EnvironmentSpec::try_from(wire.environment)
                    .map_err(|e| no_environment(EnvironmentProvideError::new(e)))?,
            };
            let environment = factory.environment(&spec).map_err(no_environment)?;
            if known.is_none() {
                let provided = environment.spec();
                if provided != spec {
                    return Err(WorkerError::TaskRefused {
                        job: wire.job,
                        task_id: task.id,
                        needed: Box::new(spec),
                        provided: Box::new(provided),
                    });
                }
                checked = Some((wire.environment, spec));
            }
            let started = Instant::now();
            if options.batches {
                // The queued tasks of the same environment that the outbox has room for go
                // with this one, in one call.
                let room = MAX_BATCH - outbox.count as usize;
                let mut batch = vec![wire];
                while batch.len() < room && queue.front().is_some_and(|next| next.environment == wire.environment) {
                    batch.push(queue.pop_front().expect("a front task"));
                }
                let tasks: Vec<Task> = std::iter::once(task)
                    .chain(batch[1..].iter().map(WireTask::to_task))
                    .collect();
                let outcomes = environment.rollout_batch(&tasks);
                if let Some(reason) = batched_wrongly(&tasks, &outcomes) {
                    return Err(WorkerError::Batch { job: wire.job, reason });
                }
                let took = started.elapsed();
                batching.observe(took / batch.len() as u32);
                slowest = slowest.max(took);
                rollouts += batch.len() as u64;
                for (wire, outcome) in batch.iter().zip(&outcomes) {
                    deliver(&mut outbox, wire, outcome)?;
                }
            } else {
                let outcome = environment.rollout(&task);
                let took = started.elapsed();
                batching.observe(took);
                slowest = slowest.max(took);
                rollouts += 1;
                deliver(&mut outbox, &wire, &outcome)?;
            }
            idle_since = None;
            // A task came from a live learner.
            silence.heard();
            continue;
        }
        let idle = *idle_since.get_or_insert_with(Instant::now);
        if idle.elapsed() < options.spin {
            std::thread::yield_now();
            continue;
        }
        idle_since = None;
        let woken = match listener.timed_wait(|_| {}, TICK) {
            Ok(woken) => woken,
            // A signal, also a pause and resume (SIGSTOP, SIGCONT): only `stop` ends the worker.
            Err(ListenerWaitError::InterruptSignal) => 0,
            Err(source) => {
                return Err(IpcError::ListenerWait {
                    whom: "the learner",
                    source,
                }
                .into());
            }
        };
        if woken > 0 {
            silence.heard();
        } else if silence.look_due() {
            if !learner_lives(run, &services, silence.lists())? {
                return Ok(WorkerReport {
                    exit: WorkerExit::LearnerGone,
                    rollouts,
                });
            }
            silence.looked();
        }
    }
}

/// Put the `outcome` of `wire`'s task into `outbox`. An outcome the wire cannot carry stops
/// the worker: reported as failed, it would read as the environment's failure and change the
/// run's result.
fn deliver(outbox: &mut WorkerMessage, wire: &WireTask, outcome: &Outcome) -> Result<(), WorkerError> {
    let wire_outcome = WireOutcome::new(wire.job, outcome).map_err(|capacity| WorkerError::OutcomeTooLarge {
        job: wire.job,
        task_id: wire.task_id,
        capacity,
    })?;
    outbox
        .push(wire_outcome)
        .expect("a full outbox stops the simulation until it is sent");
    Ok(())
}

/// Why the outcomes of a batch are not one per task in the tasks' order, if they are not.
fn batched_wrongly(tasks: &[Task], outcomes: &[Outcome]) -> Option<String> {
    if outcomes.len() != tasks.len() {
        return Some(format!(
            "rollout_batch returned {} outcomes for {} tasks",
            outcomes.len(),
            tasks.len()
        ));
    }
    tasks
        .iter()
        .zip(outcomes)
        .find(|(task, outcome)| task.id != outcome.task_id)
        .map(|(task, outcome)| {
            format!(
                "rollout_batch returned the outcome of task {} where task {}'s belongs",
                outcome.task_id, task.id
            )
        })
}

/// The run's secret for this worker ([`RunSecret::for_worker`]), and where it came from. The
/// learner writes its file just after it starts serving, so a worker started by hand that found
/// the learner a moment earlier looks again for a little while before it goes on without one
/// (then the learner refuses it, and the refusal says where it looked).
fn find_secret(
    run: &RunName,
    options: &WorkerOptions,
    started: Instant,
    stop: &AtomicBool,
) -> Result<(Option<RunSecret>, SecretOrigin), WorkerError> {
    const PUBLISHED_WITHIN: Duration = Duration::from_secs(1);
    let looking = Instant::now();
    loop {
        let found = RunSecret::for_worker(run).map_err(|error| WorkerError::Secret(Box::new(error)))?;
        let waited_enough = looking.elapsed() >= PUBLISHED_WITHIN || started.elapsed() >= options.startup_timeout;
        if found.0.is_some() || waited_enough || stop.load(Ordering::Relaxed) {
            return Ok(found);
        }
        std::thread::sleep(JOIN_POLL);
    }
}

/// Why the learner's `answer` refused this worker (of run `identity`, 0 before it learnt one,
/// serving `serves` of `sizes`, with the secret from `origin`), naming both sides.
fn refusal_reason(
    answer: &Answer,
    identity: u64,
    serves: &Serves,
    sizes: Option<Sizes>,
    origin: &SecretOrigin,
) -> String {
    if answer.protocol != PROTOCOL_VERSION {
        return format!(
            "protocol version {} here, {} at the learner (another build)",
            PROTOCOL_VERSION, answer.protocol
        );
    }
    match answer.refusal() {
        Some(Refusal::Secret) => format!(
            "its messages do not carry the run's secret: {origin}; a worker started by hand reads the file the learner writes, or takes the secret in {SECRET_ENV}"
        ),
        Some(Refusal::Environment) => {
            format!(
                "this worker serves {}; the run's jobs need {}",
                wire::serves_shown(serves),
                answer.needs()
            )
        }
        Some(Refusal::Sizes) => match sizes {
            Some(sizes) => format!(
                "this worker serves {sizes}; the run's jobs need {}",
                answer.needed_sizes()
            ),
            None => format!("the run's jobs need {}", answer.needed_sizes()),
        },
        _ => format!(
            "this worker belongs to run identity {identity:016x}, the learner runs {:016x}",
            answer.run
        ),
    }
}

/// How long a waiting worker hears nothing from the learner before it looks whether the learner
/// still lives ([`learner_lives`]). Idle workers looked on every silent tick by listing the run's
/// nodes: at W = 128 that took more CPU than 2 cores have, and starved the learner
/// (docs/FLEET.md#oversubscription). A live learner wakes every worker at least once per tick;
/// so a worker looks only after [`Silence::FIRST_LOOK`] silent waits in a row, and at a learner
/// found alive but silent (paused, or starved itself) again after twice as many, up to
/// [`Silence::LAST_LOOK`]. Every [`Silence::LIST_EVERY`]th look lists the run's nodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Silence {
    /// Waits that timed out since the learner was last heard or looked at.
    waits: u32,
    /// Timed-out waits after which the next look is due.
    look_after: u32,
    /// Looks since the learner was last heard.
    looks: u32,
}

impl Default for Silence {
    fn default() -> Self {
        Self {
            waits: 0,
            look_after: Self::FIRST_LOOK,
            looks: 0,
        }
    }
}

impl Silence {
    /// Two ticks: one heartbeat may come late.
    const FIRST_LOOK: u32 = 2;
    /// 32 ticks (1.6 s) between looks at a learner that stays silent.
    const LAST_LOOK: u32 = 32;
    /// The 8th look of a silence (after 8 s) lists the nodes, and every 8th after it (13 s).
    const LIST_EVERY: u32 = 8;

    /// The learner woke this worker.
    fn heard(&mut self) {
        *self = Self::default();
    }

    /// A wait timed out; true when the learner should be looked at now.
    fn look_due(&mut self) -> bool {
        self.waits += 1;
        self.waits >= self.look_after
    }

    /// Whether the due look lists the run's nodes rather than trust the learner's PID.
    fn lists(&self) -> bool {
        self.looks % Self::LIST_EVERY == Self::LIST_EVERY - 1
    }

    /// The look found the learner alive.
    fn looked(&mut self) {
        self.waits = 0;
        self.looks += 1;
        self.look_after = (2 * self.look_after).min(Self::LAST_LOOK);
    }
}

/// What a worker holds when it decides on its next request.
#[derive(Debug, Clone, Copy)]
struct Budget {
    /// Most tasks it keeps asked for or queued.
    queue_depth: usize,
    /// Tasks queued, not yet simulated.
    queued: usize,
    /// Tasks its pending requests asked for.
    asked: usize,
    /// Outcomes in its outbox.
    outbox: usize,
    /// Tasks per request ([`Batching::size`]).
    batch: usize,
    /// Its first free asking slot, if any.
    free_asking: Option<usize>,
    /// Whether its delivery slot (outcomes alone) is free.
    delivery_free: bool,
}

/// The request a worker sends next, if any: the asking slot it takes (`None`: the delivery
/// slot) and the tasks it asks for. Tasks queued, unsent or asked for stay within the queue
/// depth. The outbox goes out when it holds a batch or nothing else is left to simulate, and
/// asks for as many tasks as the budget then allows; a worker with room for a batch (or with
/// nothing at all) asks for more. Outcomes never wait for tasks: when every asking slot is
/// taken they go out alone in the delivery slot, which the learner answers at once (its asking
/// requests may wait for tasks that need these very outcomes). A worker with both kinds of
/// slot taken stops simulating once its outbox is full, until an answer frees one. The cases
/// of `decisions.json` hold for this and for the Python worker's `_next_request`.
fn next_request(budget: Budget) -> Option<(Option<usize>, usize)> {
    let Budget {
        queue_depth,
        queued,
        asked,
        outbox,
        batch,
        free_asking,
        delivery_free,
    } = budget;
    // Saturating: a learner that answered with more tasks than asked for cannot make the
    // budget underflow.
    let room = queue_depth.saturating_sub(queued + asked);
    let flush = outbox > 0 && (outbox >= batch || queued == 0);
    let top_up = outbox == 0 && (room >= batch || (asked == 0 && queued == 0));
    if !(flush || top_up) || room == 0 {
        return None;
    }
    match free_asking {
        Some(slot) => Some((Some(slot), room.min(batch))),
        None if flush && delivery_free => Some((None, 0)),
        None => None,
    }
}

/// Whether a worker with `queued` tasks left wakes the learner for the requests it sent. At
/// W = cores the learner has no core of its own, so every wake-up preempts a worker. A worker
/// therefore wakes it only once it could run dry before the learner next looks (fewer than two
/// batches queued) or is about to stop simulating (`outbox_full`); until then the learner reads
/// its requests when it wakes for this or another worker. A worker waits only in those two
/// states, so it never sleeps on requests the learner was not told of.
fn wakes_learner(queued: usize, batch: usize, outbox_full: bool) -> bool {
    queued < 2 * batch || outbox_full
}

/// How much simulation one request should carry: enough to pay for the message and the
/// wake-ups it may cost, little enough that outcomes return promptly, since the learner creates
/// new tasks only from outcomes. At W = cores a request that wakes the learner preempts a
/// worker: 800 us (32 analytic PA-10 throws) halved those switches and beat 400 us, given the
/// tasks in flight to fill such batches (docs/FLEET.md#throughput).
const BATCH_TIME: Duration = Duration::from_micros(800);

/// Tasks per request, from the measured rollout time: 1 until a rollout has been timed (and
/// for rollouts longer than [`BATCH_TIME`]), at most half the budget so that a second request
/// is in flight while a batch is simulated, and at most [`MAX_BATCH`].
struct Batching {
    largest: usize,
    mean_seconds: Option<f64>,
}

impl Batching {
    fn new(in_flight: usize) -> Self {
        Self {
            largest: (in_flight / 2).clamp(1, MAX_BATCH),
            mean_seconds: None,
        }
    }

    fn observe(&mut self, rollout: Duration) {
        let seconds = rollout.as_secs_f64();
        self.mean_seconds = Some(self.mean_seconds.map_or(seconds, |mean| 0.9 * mean + 0.1 * seconds));
    }

    fn size(&self) -> usize {
        self.mean_seconds.map_or(1, |mean| {
            let fits = (BATCH_TIME.as_secs_f64() / mean.max(1e-9)).floor();
            (fits.min(self.largest as f64) as usize).max(1)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cases of `decisions.json`, which the Python worker's tests read too.
    #[derive(serde::Deserialize)]
    struct Decisions {
        requests: Cases<RequestCase>,
        wakes_learner: Cases<WakeCase>,
        batch_size: Cases<BatchCase>,
        silence: SilenceCase,
    }

    #[derive(serde::Deserialize)]
    struct Cases<T> {
        cases: Vec<T>,
    }

    #[derive(serde::Deserialize)]
    struct RequestCase {
        name: String,
        queue_depth: usize,
        batch: usize,
        queued: usize,
        outbox: usize,
        slots: Vec<Option<usize>>,
        delivery: Option<usize>,
        sent: Vec<(usize, usize)>,
    }

    #[derive(serde::Deserialize)]
    struct WakeCase {
        queued: usize,
        batch: usize,
        outbox_full: bool,
        wakes: bool,
    }

    #[derive(serde::Deserialize)]
    struct BatchCase {
        queue_depth: usize,
        rollouts_ns: Vec<u64>,
        size: usize,
    }

    #[derive(serde::Deserialize)]
    struct SilenceCase {
        waits: u32,
        looks: Vec<(u32, bool)>,
    }

    #[test]
    fn the_worker_loop_follows_the_shared_decision_table() {
        let table: Decisions = serde_json::from_str(include_str!("../decisions.json")).expect("decisions.json parses");
        for case in &table.requests.cases {
            assert_eq!(case.slots.len(), MAX_ASKING_REQUESTS, "{}", case.name);
            let (mut slots, mut delivery, mut outbox) = (case.slots.clone(), case.delivery, case.outbox);
            let mut sent = Vec::new();
            while let Some((slot, want)) = next_request(Budget {
                queue_depth: case.queue_depth,
                queued: case.queued,
                asked: slots.iter().flatten().chain(&delivery).sum(),
                outbox,
                batch: case.batch,
                free_asking: slots.iter().position(Option::is_none),
                delivery_free: delivery.is_none(),
            }) {
                match slot {
                    Some(slot) => slots[slot] = Some(want),
                    None => delivery = Some(want),
                }
                sent.push((slot.unwrap_or(MAX_ASKING_REQUESTS), want));
                outbox = 0;
            }
            assert_eq!(sent, case.sent, "{}", case.name);
        }
        for case in &table.wakes_learner.cases {
            assert_eq!(
                wakes_learner(case.queued, case.batch, case.outbox_full),
                case.wakes,
                "{} queued, batch {}, outbox full {}",
                case.queued,
                case.batch,
                case.outbox_full
            );
        }
        for case in &table.batch_size.cases {
            let mut batching = Batching::new(case.queue_depth);
            for &ns in &case.rollouts_ns {
                batching.observe(Duration::from_nanos(ns));
            }
            assert_eq!(
                batching.size(),
                case.size,
                "{} after {:?}",
                case.queue_depth,
                case.rollouts_ns
            );
        }
        let mut silence = Silence::default();
        let mut looks = Vec::new();
        for wait in 1..=table.silence.waits {
            if silence.look_due() {
                looks.push((wait, silence.lists()));
                silence.looked();
            }
        }
        assert_eq!(looks, table.silence.looks);
    }

    #[test]
    fn a_worker_wakes_the_learner_only_when_it_could_run_dry() {
        // 128 analytic throws in flight, batches of 32.
        assert!(
            !wakes_learner(96, 32, false),
            "three batches left: the learner may sleep"
        );
        assert!(!wakes_learner(64, 32, false), "two batches left");
        assert!(wakes_learner(63, 32, false), "less than two batches left");
        assert!(wakes_learner(0, 32, false), "about to wait for tasks");
        assert!(wakes_learner(96, 32, true), "about to stop simulating");
        // Rapier throws travel alone.
        assert!(!wakes_learner(2, 1, false));
        assert!(wakes_learner(1, 1, false), "one throw left");
    }

    #[test]
    fn a_silent_learner_is_looked_at_after_two_silent_waits_then_ever_more_rarely() {
        let mut silence = Silence::default();
        // The silent waits at which the next `waits` looks, and whether each lists the nodes.
        let looks = |silence: &mut Silence, waits: u32| {
            let mut looks = Vec::new();
            for wait in 1..=waits {
                if silence.look_due() {
                    looks.push((wait, silence.lists()));
                    silence.looked();
                }
            }
            looks
        };
        assert!(!silence.look_due(), "one late heartbeat is no reason to look");
        assert!(silence.look_due());
        assert!(!silence.lists(), "the first look trusts the PID");
        silence.looked();
        // Then after 4, 8, 16 and every 32 silent waits; the 8th look lists the nodes.
        let after: Vec<(u32, bool)> = looks(&mut silence, 4 + 8 + 16 + 32 * 12);
        let waits: Vec<u32> = after.iter().map(|(wait, _)| *wait).collect();
        assert_eq!(&waits[..5], [4, 12, 28, 60, 92]);
        let listing: Vec<usize> = after
            .iter()
            .enumerate()
            .filter(|(_, (_, l))| *l)
            .map(|(i, _)| i + 2)
            .collect();
        assert_eq!(listing, [8, 16], "the looks that list, counted from the first");
        silence.heard();
        assert_eq!(silence, Silence::default(), "a heartbeat starts over");
    }

    #[test]
    fn batches_follow_the_rollout_time_within_half_the_budget() {
        let batch = |in_flight: usize, rollout: Option<Duration>| {
            let mut batching = Batching::new(in_flight);
            if let Some(rollout) = rollout {
                batching.observe(rollout);
            }
            batching.size()
        };
        assert_eq!(batch(16, None), 1, "an untimed rollout travels alone");
        assert_eq!(
            batch(16, Some(Duration::from_millis(2))),
            1,
            "a rapier throw is worth a message"
        );
        assert_eq!(
            batch(16, Some(Duration::from_micros(25))),
            8,
            "half the budget of 25 us rollouts"
        );
        assert_eq!(
            batch(64, Some(Duration::from_micros(25))),
            32,
            "800 us of 25 us rollouts"
        );
        assert_eq!(batch(64, Some(Duration::from_micros(40))), 20);
        assert_eq!(batch(64, Some(Duration::from_nanos(100))), 32, "half the budget");
        assert_eq!(batch(128, Some(Duration::from_nanos(100))), MAX_BATCH);
        assert_eq!(batch(3, Some(Duration::from_nanos(100))), 1, "half of 3 is 1");
        let mut batching = Batching::new(16);
        batching.observe(Duration::from_micros(25));
        for _ in 0..50 {
            batching.observe(Duration::from_millis(1));
        }
        assert_eq!(batching.size(), 1, "the mean follows slower rollouts");
    }
}
