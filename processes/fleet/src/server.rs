//! Serving learners to a fleet of worker processes over iceoryx2 shared memory.
//!
//! The transport boundary: everything iceoryx2-specific on the learner side lives here; the
//! learner cores are driven through `ask`/`tell`/`reissue` only, exactly as in-process runs drive
//! them. Many cores (one per method x run) share the fleet; tasks are handed out round robin over
//! the cores that have one ready, so even P = 1 runs keep many workers busy, and every core's
//! trajectory stays the one it has in-process.
//!
//! Faults: on a tick (50 ms) after which a worker holding tasks has been silent since its answer,
//! or is no longer connected, the server asks iceoryx2 to clean up dead nodes, lists the live
//! clients, and re-issues exactly the tasks held by clients that are gone. A late outcome of a
//! re-issued task is recognised as a duplicate and dropped. Workers of another build or run are
//! refused.

use crate::wake::Waker;
use acps_learner::{Learner, LearningProgress, TellError};
use acps_shared::EnvironmentSpec;
use acps_wire::ipc::{self, IpcError, RunName, TICK, TaskRequest, TaskService};
use acps_wire::wire::{Answer, CapacityError, PROTOCOL_VERSION, Response, WireTask};
use iceoryx2::identifiers::UniqueClientId;
use iceoryx2::port::listener::ListenerWaitError;
use iceoryx2::prelude::{CallbackProgression, PortFactory as _};
use std::collections::{HashMap, HashSet, VecDeque};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// How long the server tells queued outcomes before it looks for requests again.
const TELL_BUDGET: Duration = Duration::from_micros(50);

/// One learner and the environment its tasks run in.
pub struct FleetJob {
    /// The learner core.
    pub learner: Learner,
    /// What workers build to perform its tasks.
    pub environment: EnvironmentSpec,
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
    /// Tasks re-issued because their worker died.
    pub reissued: u64,
    /// Outcomes dropped as duplicates (a re-issued task answered twice).
    pub duplicates: u64,
    /// Requests refused (another build or run).
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
    /// iceoryx2 failed.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// Another learner already serves this run.
    #[error("another learner already serves run '{0}'; choose another --run name")]
    RunTaken(String),
    /// A task does not fit the wire.
    #[error(transparent)]
    Capacity(#[from] CapacityError),
    /// The stop flag was set (Ctrl-C).
    #[error("interrupted")]
    Interrupted,
    /// The caller's `after_tell` hook failed (for example writing a checkpoint).
    #[error(transparent)]
    Hook(Box<dyn std::error::Error + Send + Sync>),
}

/// How [`serve`] serves.
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
}

/// Serve `jobs` to the workers of `run` until every job is done. `after_tell` sees a job's
/// learner after every outcome it accepted (the place to write checkpoints); an error it returns
/// ends the run.
pub fn serve(
    jobs: &mut [FleetJob],
    run: &RunName,
    options: ServeOptions,
    stop: &AtomicBool,
    mut observe: impl FnMut(&FleetProgress),
    mut after_tell: impl FnMut(usize, &Learner) -> Result<(), Box<dyn std::error::Error + Send + Sync>>,
) -> Result<FleetProgress, FleetError> {
    let identity = options.identity;
    let node = ipc::node(run, "learner")?;
    let services = ipc::open_services(&node)?;
    if services.tasks.dynamic_config().number_of_servers() > 0 {
        return Err(FleetError::RunTaken(run.to_string()));
    }
    let server = ipc::task_server(run, &services.tasks)?;
    let listener = services
        .to_learner
        .listener_builder()
        .create()
        .map_err(|e| IpcError::new("creating the learner's listener", e))?;
    let mut waker = Waker::new(&services)?;

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
    loop {
        let mut active_now = false;
        while let Some(request) = server.receive().map_err(|e| IpcError::new("receiving a request", e))? {
            active_now = true;
            heard.insert(request.origin());
            let message = request.payload();
            if message.protocol != PROTOCOL_VERSION || (message.run != 0 && message.run != identity) {
                progress.refused += 1;
                if refused_clients.insert(request.origin()) {
                    tracing::warn!(
                        "refused a worker of run '{run}': protocol {} (ours {PROTOCOL_VERSION}), run identity {:016x} (ours {identity:016x})",
                        message.protocol,
                        message.run
                    );
                }
                let _ = ipc::reply(&request, Answer::new(Response::Refused, identity), &[]);
                continue;
            }
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
                want => parked.push_back((request, want)),
            }
        }
        // Answer before telling: tasks are created eagerly, so ready ones wait in the cores, and
        // workers get them without waiting for the C-REPS updates (a millisecond each) of the
        // outcomes queued before theirs.
        let answered = if serving_since.is_some() {
            answer(
                jobs,
                &mut parked,
                &mut holders,
                &mut next_job,
                identity,
                &mut progress,
                // An answered worker is woken, and until the next tick counts as heard: it has
                // had no time yet to send anything for the tasks it now holds.
                |client| {
                    waker.answered(client);
                    heard.insert(client);
                },
            )?
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
                    after_tell(job as usize, &jobs[job as usize].learner).map_err(FleetError::Hook)?;
                }
                Some(Err(TellError::UnknownTask { .. } | TellError::Duplicate { .. })) | None => {
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
            observe(&progress);
            for (request, _) in parked.drain(..) {
                let _ = ipc::reply(&request, Answer::new(Response::Stop, identity), &[]);
            }
            let _ = waker.wake_all();
            return Ok(progress);
        }
        if last_tick.elapsed() >= TICK {
            last_tick = Instant::now();
            progress.serving_seconds = serving();
            progress.learning = LearningProgress::combine(jobs.iter().map(|j| j.learner.progress()));
            let mut connected = HashSet::new();
            services.tasks.dynamic_config().list_clients(|client| {
                connected.insert(client.client_id);
                CallbackProgression::Continue
            });
            let look = look_is_due(&holders, &heard, &connected);
            heard.clear();
            if look {
                let Some(live) =
                    reissue_tasks_of_dead_workers(run, &services.tasks, jobs, &mut holders, &mut progress.reissued)
                else {
                    observe(&progress);
                    continue;
                };
                progress.workers = live;
            } else {
                progress.workers = connected.len();
            }
            observe(&progress);
        }
        if stop.load(Ordering::Relaxed) {
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

/// Answer parked requests, each with as many ready tasks as it asks for (round robin over the
/// jobs), as soon as at least one is ready; tells `answered_to` of every worker answered;
/// returns how many tasks went out.
fn answer(
    jobs: &mut [FleetJob],
    parked: &mut VecDeque<(TaskRequest, usize)>,
    holders: &mut HashMap<(u32, u64), UniqueClientId>,
    next_job: &mut usize,
    identity: u64,
    progress: &mut FleetProgress,
    mut answered_to: impl FnMut(UniqueClientId),
) -> Result<usize, FleetError> {
    let mut answered = 0;
    // Allocated only when a request is waiting: most passes have none.
    let mut tasks = Vec::new();
    while let Some((request, want)) = parked.pop_front() {
        if !request.is_connected() {
            continue;
        }
        tasks.clear();
        tasks.reserve(want);
        let started = Instant::now();
        while tasks.len() < want {
            let Some((job, task)) = next_task(jobs, next_job) else {
                break;
            };
            tasks.push(WireTask::new(job as u32, &task, jobs[job].environment)?);
            holders.insert((job as u32, task.id), request.origin());
        }
        progress.learner_seconds += started.elapsed().as_secs_f64();
        if tasks.is_empty() {
            parked.push_front((request, want));
            break;
        }
        ipc::reply(&request, Answer::new(Response::Task, identity), &tasks)?;
        answered_to(request.origin());
        answered += tasks.len();
    }
    Ok(answered)
}

/// The next ready task, round robin over the jobs.
fn next_task(jobs: &mut [FleetJob], next_job: &mut usize) -> Option<(usize, acps_shared::Task)> {
    let n = jobs.len();
    for offset in 0..n {
        let job = (*next_job + offset) % n;
        if let Some(task) = jobs[job].learner.ask() {
            *next_job = (job + 1) % n;
            return Some((job, task));
        }
    }
    None
}
