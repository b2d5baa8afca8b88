//! Serving learners to a fleet of worker processes over iceoryx2 shared memory.
//!
//! The transport boundary: everything iceoryx2-specific on the learner side lives here; the
//! learner cores are driven through `ask`/`tell`/`reissue` only, exactly as in-process runs drive
//! them. Many cores (one per method x run) share the fleet; tasks are handed out round robin over
//! the cores that have one ready, so even P = 1 runs keep many workers busy, and every core's
//! trajectory stays the one it has in-process.
//!
//! Faults, looked for every tick (50 ms):
//! - A worker that died: once a worker holding tasks has been silent since its answer for a tick,
//!   or is no longer connected, the server asks iceoryx2 to clean up dead nodes, lists the live
//!   clients, and re-issues exactly the tasks held by clients that are gone.
//! - A worker that lives but says nothing (stopped, hung in a rollout): one that holds tasks and
//!   has sent nothing for its deadline ([`Liveness`]) is treated as dead for those tasks, which
//!   are re-issued; it gets no new tasks until it speaks again.
//! - No worker at all: with no connected worker and no started one on its way for
//!   [`Liveness::no_workers`], the run stops with [`FleetError::NoWorkers`].
//!
//! A late outcome of a re-issued task is recognised as a duplicate and dropped (or, arriving
//! first, accepted: the rollout is seeded, so both copies carry the same bits). Workers of
//! another build or run, and workers serving an environment no job needs, are refused; a worker
//! that serves one environment is handed only tasks of jobs that need it.

use crate::wake::Waker;
use acps_learner::{Learner, LearnerTellError, LearningProgress};
use acps_shared::{EnvironmentSpec, Serves, SpecBuildError};
use acps_wire::ipc::{self, IpcError, RunName, ServerError, TICK, TaskRequest, TaskServer, TaskService};
use acps_wire::wire::{
    Answer, CapacityError, PROTOCOL_VERSION, Refusal, Response, WireTask, WorkerMessage, check_task_sizes,
};
use iceoryx2::identifiers::UniqueClientId;
use iceoryx2::port::listener::ListenerWaitError;
use iceoryx2::prelude::{CallbackProgression, PortFactory as _};
use std::collections::{HashMap, HashSet, VecDeque};
use std::time::{Duration, Instant};

/// How long the server tells queued outcomes before it looks for requests again.
const TELL_BUDGET: Duration = Duration::from_micros(50);

/// A learner whose tasks the wire carries, ready to be served: its problem's environment is
/// what workers must serve to perform its tasks.
pub struct FleetJob {
    learner: Learner,
}

/// A learner a fleet cannot serve.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("problem '{problem}' cannot be served to workers: {capacity}")]
pub struct FleetJobBuildError {
    /// The learner's problem.
    pub problem: String,
    /// What its tasks would carry beyond the wire's capacity.
    pub capacity: CapacityError,
}

impl FleetJob {
    /// A job of `learner`, refused when its tasks' contexts or parameters exceed what the wire
    /// carries: before the run starts rather than when a task would be handed out.
    pub fn new(learner: Learner) -> Result<Self, FleetJobBuildError> {
        let problem = learner.problem();
        check_task_sizes(problem.context_dim(), problem.theta0.len()).map_err(|capacity| FleetJobBuildError {
            problem: problem.name.clone(),
            capacity,
        })?;
        Ok(Self { learner })
    }

    /// The learner core.
    pub fn learner(&self) -> &Learner {
        &self.learner
    }

    /// The learner core, once served.
    pub fn into_learner(self) -> Learner {
        self.learner
    }

    /// The environment the job's tasks need.
    fn environment(&self) -> &EnvironmentSpec {
        &self.learner.problem().environment
    }
}

/// Progress of a fleet run, reported every tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FleetProgress {
    /// Jobs finished.
    pub jobs_done: usize,
    /// Outcomes consumed (all kinds).
    pub outcomes: u64,
    /// Connected workers.
    pub workers: usize,
    /// Worker processes the fleet started that are still running (connected or not).
    pub started_running: usize,
    /// Tasks re-issued because their worker died.
    pub reissued: u64,
    /// Outcomes dropped as duplicates (a re-issued task answered twice).
    pub duplicates: u64,
    /// Requests refused (another build, run or environment).
    pub refused: u64,
    /// Requests that only delivered outcomes, because the worker's asking requests all waited.
    pub delivered: u64,
    /// Time spent inside the learner cores (`tell` and `ask`), in seconds.
    pub learner_seconds: f64,
    /// Seconds since the first task went out (see [`ServeOptions::start_with`]): the run's time
    /// without the workers' start-up.
    pub serving_seconds: f64,
    /// Training episodes and latest test scores of all jobs together.
    pub learning: LearningProgress,
}

/// A fleet run that could not complete.
#[derive(Debug, thiserror::Error)]
pub enum FleetError {
    /// iceoryx2 failed: creating the run's node, ports or services, or exchanging messages.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// A fleet that served before could not serve its run again: another learner took it
    /// ([`ServerError::Taken`]), or iceoryx2 failed.
    #[error(transparent)]
    Seat(#[from] ServerError),
    /// A task does not fit the wire (a job's checked sizes prevent it).
    #[error(transparent)]
    Capacity(#[from] CapacityError),
    /// The stop flag was set (Ctrl-C, or the caller's [`Fleet::stop_flag`](crate::Fleet::stop_flag)).
    #[error("interrupted")]
    Interrupted,
    /// No worker was connected and none was on its way for the grace period
    /// ([`Liveness::no_workers`]): every started worker exited, and no other joined.
    #[error(
        "no worker can go on with run '{run}': none connected for {waited:?}{started}",
        started = if *started > 0 { format!(", and all {started} started worker processes exited (see their messages above)") } else { String::new() }
    )]
    NoWorkers {
        /// The run.
        run: String,
        /// Worker processes the fleet started.
        started: usize,
        /// How long the run was without a worker.
        waited: Duration,
    },
    /// A worker process could not be started.
    #[error("starting worker process {program}: {error}")]
    Spawn {
        /// The program.
        program: String,
        /// The operating system's reason.
        error: String,
    },
    /// The observer's [`Observer::told`] failed (for example writing a checkpoint).
    #[error(transparent)]
    Observer(Box<dyn std::error::Error + Send + Sync>),
}

/// When the server gives up on workers. The defaults suit rollouts of up to a second or so:
/// a run whose rollouts are slower should raise [`silence`](Self::silence) above the first
/// rollout's duration, or that rollout runs twice (once; results do not change).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Liveness {
    /// A worker holding tasks that has sent nothing for this long, and for
    /// [`rollout_factor`](Self::rollout_factor) times the slowest rollout any worker has
    /// reported, is hung: its tasks are handed to others.
    pub silence: Duration,
    /// See [`silence`](Self::silence).
    pub rollout_factor: u32,
    /// Stop with [`FleetError::NoWorkers`] once no worker has been connected, and no started
    /// worker process has been running, for this long; `None`: wait for workers forever (for a
    /// fleet that starts none and waits for workers started by hand).
    pub no_workers: Option<Duration>,
}

impl Default for Liveness {
    /// 5 s of silence and 4 times the slowest rollout; 10 s without workers.
    fn default() -> Self {
        Self {
            silence: Duration::from_secs(5),
            rollout_factor: 4,
            no_workers: Some(Duration::from_secs(10)),
        }
    }
}

/// How [`Fleet::serve`](crate::Fleet::serve) serves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ServeOptions {
    /// The run's identity (a hash of its configuration), checked against every worker's requests.
    pub identity: u64,
    /// When idle, poll (yielding the CPU) this long before blocking: worth it only when every
    /// process has a core of its own.
    pub spin: Duration,
    /// Hand out the first tasks only once this many workers have asked for them (0 and 1: at
    /// once). A benchmark waits for its whole fleet, so that its clock measures every worker
    /// and no worker's start-up; a run should not wait, its first tasks are done sooner.
    pub start_with: usize,
    /// When workers are given up on.
    pub liveness: Liveness,
}

/// What a fleet run tells its caller while it serves.
pub trait Observer {
    /// The run's progress, every tick (50 ms) and once at the end.
    fn progress(&mut self, progress: &FleetProgress) {
        let _ = progress;
    }

    /// Job `job`'s learner after every outcome it accepted: the place to write checkpoints. An
    /// error ends the run with [`FleetError::Observer`].
    fn told(&mut self, job: usize, learner: &Learner) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
        let _ = (job, learner);
        Ok(())
    }
}

/// A closure observes the progress.
impl<F: FnMut(&FleetProgress)> Observer for F {
    fn progress(&mut self, progress: &FleetProgress) {
        self(progress)
    }
}

/// The learner's place in a run: its node, the run's services and the task server, which only
/// one live process of a run can hold. Fields drop in this order: ports before their node.
pub(crate) struct Seat {
    server: TaskServer,
    services: ipc::Services,
    _node: iceoryx2::node::Node<iceoryx2::prelude::ipc::Service>,
}

impl Seat {
    /// Take the seat of `run`, refused while another learner holds it.
    pub(crate) fn take(run: &RunName) -> Result<Self, ServerError> {
        let node = ipc::node(run, ipc::LEARNER_NODE)?;
        let services = ipc::open_services(&node)?;
        Ok(Self {
            server: ipc::task_server(run, &services.tasks)?,
            services,
            _node: node,
        })
    }
}

/// Serve `jobs` from `seat` to the workers of `run` until every job is done. `started` says how
/// many worker processes the caller started are still running (they count as workers on their
/// way).
pub(crate) fn serve(
    jobs: &mut [FleetJob],
    run: &RunName,
    seat: &Seat,
    options: ServeOptions,
    stop: &dyn Fn() -> bool,
    observer: &mut dyn Observer,
    started: &mut dyn FnMut() -> (usize, usize),
) -> Result<FleetProgress, FleetError> {
    let identity = options.identity;
    let Seat { server, services, .. } = seat;
    let listener = services
        .to_learner
        .listener_builder()
        .create()
        .map_err(|e| IpcError::new("creating the learner's listener", e))?;
    let mut waker = Waker::new(services)?;

    let mut progress = FleetProgress::default();
    let mut parked = VecDeque::new();
    let mut holders: HashMap<(u32, u64), UniqueClientId> = HashMap::new();
    let mut next_job = 0;
    let mut last_tick = Instant::now();
    let mut refused_clients = HashSet::new();
    // Clients that sent a request since the last look for dead workers.
    let mut heard = HashSet::new();
    let mut idle_since: Option<Instant> = None;
    let mut outcomes = VecDeque::new();
    let mut unannounced = 0;
    let mut wake_now = false;
    // Workers that asked for tasks, until `start_with` have; then the time the first tasks went out.
    let mut waiting_for = HashSet::new();
    let mut serving_since = None;
    // When each worker's last request arrived.
    let mut last_heard: HashMap<UniqueClientId, Instant> = HashMap::new();
    // Workers found hung: they get no tasks until they speak again.
    let mut hung: HashSet<UniqueClientId> = HashSet::new();
    let mut slowest_rollout = Duration::ZERO;
    let mut without_workers: Option<Instant> = None;
    let mut last_running = 0;
    loop {
        let mut active_now = false;
        while let Some(request) = server.receive().map_err(|e| IpcError::new("receiving a request", e))? {
            active_now = true;
            heard.insert(request.origin());
            last_heard.insert(request.origin(), Instant::now());
            if hung.remove(&request.origin()) {
                tracing::info!("run '{run}': a worker found hung speaks again");
            }
            let message = request.payload();
            slowest_rollout = slowest_rollout.max(message.slowest_rollout());
            let serves = match admit(message, identity, jobs) {
                Ok(serves) => serves,
                Err(mismatch) => {
                    progress.refused += 1;
                    let (answer, reason) = refusal(&mismatch, identity, jobs);
                    if refused_clients.insert(request.origin()) {
                        tracing::warn!("refused a worker of run '{run}': {reason}");
                    }
                    let _ = ipc::reply(&request, answer, &[]);
                    continue;
                }
            };
            if serving_since.is_none() {
                waiting_for.insert(request.origin());
                if waiting_for.len() >= options.start_with {
                    serving_since = Some(Instant::now());
                }
            }
            for (job, outcome) in message.outcomes() {
                holders.remove(&(job, outcome.task_id));
                outcomes.push_back((job, outcome));
            }
            match message.wanted() {
                // Outcomes only: the worker's last free slot, so it is answered at once rather
                // than parked behind tasks that may need these very outcomes.
                0 => {
                    ipc::reply(&request, Answer::new(Response::Task, identity), &[])?;
                    progress.delivered += 1;
                    waker.answered(request.origin());
                    wake_now = true;
                }
                want => parked.push_back((request, want, serves)),
            }
        }
        // Answer before telling: tasks are created eagerly, so ready ones wait in the cores, and
        // workers get them without waiting for the C-REPS updates (a millisecond each) of the
        // outcomes queued before theirs.
        let answered = if serving_since.is_some() {
            let (answered, asking) = answer(
                jobs,
                &mut parked,
                &hung,
                &mut holders,
                &mut next_job,
                identity,
                // An answered worker is woken, and until the next tick counts as heard: it has
                // had no time yet to send anything for the tasks it now holds.
                |client| {
                    waker.answered(client);
                    heard.insert(client);
                },
            )?;
            progress.learner_seconds += asking.as_secs_f64();
            answered
        } else {
            0
        };
        // Workers that are simulating need no wake-up; one per 8 tasks answered, or once the
        // queued outcomes are told, reaches those that wait without a syscall per task. A worker
        // whose outcomes waited for a free slot may be asleep: it is woken at once. Only the
        // answered workers are woken.
        unannounced += answered;
        if wake_now || (unannounced > 0 && (outcomes.is_empty() || unannounced >= 8)) {
            waker.wake_answered(&services.tasks)?;
            unannounced = 0;
            wake_now = false;
        }
        waker.heartbeat()?;
        // Tell queued outcomes until `TELL_BUDGET` is spent, then look for requests again: an
        // answer waits for at most the budget plus one C-REPS update, and cheap outcomes do not
        // each pay for a look at every request channel (telling one per pass capped the learner
        // at about 650 k trivial outcomes per second).
        let telling = Instant::now();
        let mut told_any = false;
        while let Some((job, outcome)) = outcomes.pop_front() {
            told_any = true;
            let started = Instant::now();
            let told = jobs.get_mut(job as usize).map(|j| j.learner.tell(outcome));
            let finished = Instant::now();
            progress.learner_seconds += (finished - started).as_secs_f64();
            match told {
                Some(Ok(())) => {
                    progress.outcomes += 1;
                    observer
                        .told(job as usize, &jobs[job as usize].learner)
                        .map_err(FleetError::Observer)?;
                }
                Some(Err(LearnerTellError::UnknownTask { .. } | LearnerTellError::Duplicate { .. })) | None => {
                    progress.duplicates += 1
                }
            }
            if finished - telling >= TELL_BUDGET {
                break;
            }
        }
        progress.jobs_done = jobs.iter().filter(|j| j.learner.is_done()).count();
        let serving = || serving_since.map_or(0.0, |since: Instant| since.elapsed().as_secs_f64());
        if progress.jobs_done == jobs.len() {
            progress.serving_seconds = serving();
            progress.learning = LearningProgress::combine(jobs.iter().map(|j| j.learner.progress()));
            // Before the workers are told to stop: a host that watches whether its workers are
            // still there (`acps run` ends a run whose workers all left) must still find them.
            observer.progress(&progress);
            for (request, ..) in parked.drain(..) {
                let _ = ipc::reply(&request, Answer::new(Response::Stop, identity), &[]);
            }
            let _ = waker.wake_all();
            return Ok(progress);
        }
        if last_tick.elapsed() >= TICK {
            last_tick = Instant::now();
            let (running, launched) = started();
            progress.started_running = running;
            progress.serving_seconds = serving();
            progress.learning = LearningProgress::combine(jobs.iter().map(|j| j.learner.progress()));
            let mut connected = HashSet::new();
            services.tasks.dynamic_config().list_clients(|client| {
                connected.insert(client.client_id);
                CallbackProgression::Continue
            });
            // A started worker that exited may have held nothing: it is looked for at once, so
            // that a fleet whose workers all exited is noticed.
            let look = look_is_due(&holders, &heard, &connected) || running < last_running;
            last_running = running;
            heard.clear();
            if look {
                let Some(live) =
                    reissue_tasks_of_dead_workers(run, &services.tasks, jobs, &mut holders, &mut progress.reissued)
                else {
                    observer.progress(&progress);
                    continue;
                };
                progress.workers = live;
            } else {
                progress.workers = connected.len();
            }
            let deadline = options
                .liveness
                .silence
                .max(slowest_rollout * options.liveness.rollout_factor);
            progress.reissued +=
                reissue_tasks_of_silent_workers(run, jobs, &mut holders, &last_heard, &mut hung, deadline);
            last_heard.retain(|client, _| connected.contains(client));
            hung.retain(|client| connected.contains(client));
            if progress.workers > 0 || progress.started_running > 0 {
                without_workers = None;
            } else if let Some(grace) = options.liveness.no_workers {
                let since = *without_workers.get_or_insert_with(Instant::now);
                if since.elapsed() >= grace {
                    return Err(FleetError::NoWorkers {
                        run: run.to_string(),
                        started: launched,
                        waited: since.elapsed(),
                    });
                }
            }
            observer.progress(&progress);
        }
        if stop() {
            return Err(FleetError::Interrupted);
        }
        if active_now || answered > 0 || told_any {
            idle_since = None;
        } else if idle_since.get_or_insert_with(Instant::now).elapsed() < options.spin {
            std::thread::yield_now();
        } else {
            idle_since = None;
            match listener.timed_wait(|_| {}, waker.until_heartbeat()) {
                // Any signal interrupts the wait, also SIGSTOP and SIGCONT (a paused and resumed
                // run): the loop goes on, and only `stop`, which the host's Ctrl-C handler sets,
                // ends it.
                Ok(_) | Err(ListenerWaitError::InterruptSignal) => {}
                Err(error) => return Err(IpcError::new("waiting for workers", error).into()),
            }
        }
    }
}

/// Whether the tick looks for dead workers. The look lists the run's nodes, twice, reading each
/// node's files: 0.3 ms with 3 nodes, 11 ms with 129. A worker that sent a request since the last
/// tick is alive (as is one answered since: `heard` has those too), and only the tasks of a dead
/// worker need the look; so it is due only once a worker holding tasks fell silent for a tick
/// after its answer (one that died is found a tick or two later), or is no longer
/// connected (another process cleaned up after it). A dead worker that holds nothing is found
/// once it is answered. With more workers than ready tasks most of them hold none and send
/// nothing: looking for every silent one took 2/3 of the learner's CPU time at W = 128
/// (docs/FLEET.md#oversubscription).
fn look_is_due(
    holders: &HashMap<(u32, u64), UniqueClientId>,
    heard: &HashSet<UniqueClientId>,
    connected: &HashSet<UniqueClientId>,
) -> bool {
    holders
        .values()
        .any(|client| !heard.contains(client) || !connected.contains(client))
}

/// Give the tasks held by workers that are gone back to their learners. Returns how many workers
/// are alive, or `None` when the nodes could not be listed (a node being created or removed at
/// this moment; the next tick looks again).
fn reissue_tasks_of_dead_workers(
    run: &RunName,
    tasks: &TaskService,
    jobs: &mut [FleetJob],
    holders: &mut HashMap<(u32, u64), UniqueClientId>,
    reissued: &mut u64,
) -> Option<usize> {
    tasks.try_cleanup_dead_nodes();
    let alive_nodes = ipc::alive_nodes(run).ok()?;
    let mut live = HashSet::new();
    tasks.dynamic_config().list_clients(|client| {
        if alive_nodes.contains(&client.node_id) {
            live.insert(client.client_id);
        }
        CallbackProgression::Continue
    });
    let before = *reissued;
    holders.retain(|&(job, task_id), client| {
        let alive = live.contains(client);
        if !alive && jobs[job as usize].learner.reissue(task_id) {
            *reissued += 1;
        }
        alive
    });
    if *reissued > before {
        tracing::info!(
            "run '{run}': a worker is gone; re-issued its {} tasks",
            *reissued - before
        );
    }
    Some(live.len())
}

/// Give the tasks held by workers silent for longer than `deadline` back to their learners, and
/// mark those workers hung. Returns how many tasks were re-issued.
fn reissue_tasks_of_silent_workers(
    run: &RunName,
    jobs: &mut [FleetJob],
    holders: &mut HashMap<(u32, u64), UniqueClientId>,
    last_heard: &HashMap<UniqueClientId, Instant>,
    hung: &mut HashSet<UniqueClientId>,
    deadline: Duration,
) -> u64 {
    let silent = |client: &UniqueClientId| last_heard.get(client).is_some_and(|heard| heard.elapsed() > deadline);
    let mut reissued = 0;
    holders.retain(|&(job, task_id), client| {
        if !silent(client) {
            return true;
        }
        if hung.insert(*client) {
            tracing::warn!(
                "run '{run}': a worker holding tasks has sent nothing for {deadline:?}; its tasks go to other workers (raise the fleet's liveness deadline if rollouts take longer)"
            );
        }
        reissued += u64::from(jobs[job as usize].learner.reissue(task_id));
        false
    });
    reissued
}

/// Why the learner refuses a worker's request.
enum Mismatch {
    /// Another protocol version.
    Protocol(u32),
    /// Another run identity.
    Run(u64),
    /// An environment none of the jobs needs.
    Environment(EnvironmentSpec),
    /// An environment description that is none.
    Unreadable(SpecBuildError),
}

/// What a request's worker serves, if the learner accepts it: this build's protocol, this run
/// (or any), and an environment some job needs (or any).
fn admit(message: &WorkerMessage, identity: u64, jobs: &[FleetJob]) -> Result<Serves, Mismatch> {
    if message.protocol != PROTOCOL_VERSION {
        return Err(Mismatch::Protocol(message.protocol));
    }
    if message.run != 0 && message.run != identity {
        return Err(Mismatch::Run(message.run));
    }
    let serves = message.serves().map_err(Mismatch::Unreadable)?;
    match serves {
        Serves::One(spec) if !jobs.iter().any(|job| *job.environment() == spec) => Err(Mismatch::Environment(spec)),
        serves => Ok(serves),
    }
}

/// The answer refusing a worker for `mismatch`, and the reason in words, naming the worker's
/// and the learner's environments. The answer names one environment the jobs need, preferably
/// one of the worker's environment's name: the closest description of what it should be.
fn refusal(mismatch: &Mismatch, identity: u64, jobs: &[FleetJob]) -> (Answer, String) {
    let mut needed: Vec<EnvironmentSpec> = Vec::new();
    for job in jobs {
        if !needed.contains(job.environment()) {
            needed.push(*job.environment());
        }
    }
    let closest = match mismatch {
        Mismatch::Environment(spec) => needed.iter().find(|need| need.name() == spec.name()),
        _ => None,
    }
    .or(needed.first())
    .copied();
    let code = match mismatch {
        Mismatch::Protocol(_) => Refusal::Protocol,
        Mismatch::Run(_) => Refusal::Run,
        Mismatch::Environment(_) | Mismatch::Unreadable(_) => Refusal::Environment,
    };
    let answer = Answer::refused(code, identity, closest, needed.len());
    let reason = match mismatch {
        Mismatch::Protocol(protocol) => format!("protocol {protocol} (ours {PROTOCOL_VERSION})"),
        Mismatch::Run(run) => format!("run identity {run:016x} (ours {identity:016x})"),
        Mismatch::Environment(spec) => format!("it serves environment {spec}; the jobs need {}", answer.needs()),
        Mismatch::Unreadable(error) => format!(
            "its environment cannot be read ({error}); the jobs need {}",
            answer.needs()
        ),
    };
    (answer, reason)
}

/// Answer parked requests, each with as many ready tasks as it asks for of the environments its
/// worker serves (round robin over the jobs), as soon as at least one is ready; tells
/// `answered_to` of every worker answered; returns how many tasks went out and the time the
/// learners took to hand them out. Requests of hung workers stay parked.
fn answer(
    jobs: &mut [FleetJob],
    parked: &mut VecDeque<(TaskRequest, usize, Serves)>,
    hung: &HashSet<UniqueClientId>,
    holders: &mut HashMap<(u32, u64), UniqueClientId>,
    next_job: &mut usize,
    identity: u64,
    mut answered_to: impl FnMut(UniqueClientId),
) -> Result<(usize, Duration), FleetError> {
    let mut answered = 0;
    let mut asking = Duration::ZERO;
    // Allocated only when a request is waiting: most passes have none.
    let mut tasks = Vec::new();
    // What workers serve whose requests found nothing ready in this pass: the next request of
    // the same kind would find nothing either.
    let mut dry: Vec<Serves> = Vec::new();
    for _ in 0..parked.len() {
        let Some((request, want, serves)) = parked.pop_front() else {
            break;
        };
        if !request.is_connected() {
            continue;
        }
        // Hung workers get nothing until they speak again.
        if hung.contains(&request.origin()) || dry.contains(&serves) {
            parked.push_back((request, want, serves));
            continue;
        }
        tasks.clear();
        tasks.reserve(want);
        let started = Instant::now();
        while tasks.len() < want {
            let Some((job, task)) = next_task(jobs, next_job, &serves) else {
                break;
            };
            tasks.push(WireTask::new(job as u32, &task, *jobs[job].environment())?);
            holders.insert((job as u32, task.id), request.origin());
        }
        asking += started.elapsed();
        if tasks.is_empty() {
            if serves == Serves::Any {
                // Nothing is ready for anyone: the request keeps its place.
                parked.push_front((request, want, serves));
                break;
            }
            dry.push(serves);
            parked.push_back((request, want, serves));
            continue;
        }
        ipc::reply(&request, Answer::new(Response::Task, identity), &tasks)?;
        answered_to(request.origin());
        answered += tasks.len();
    }
    Ok((answered, asking))
}

/// The next ready task of an environment the worker `serves`, round robin over the jobs.
fn next_task(jobs: &mut [FleetJob], next_job: &mut usize, serves: &Serves) -> Option<(usize, acps_shared::Task)> {
    let n = jobs.len();
    for offset in 0..n {
        let job = (*next_job + offset) % n;
        if !serves.includes(jobs[job].environment()) {
            continue;
        }
        if let Some(task) = jobs[job].learner.ask() {
            *next_job = (job + 1) % n;
            return Some((job, task));
        }
    }
    None
}
