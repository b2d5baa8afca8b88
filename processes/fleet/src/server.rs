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
//! - A remote peer (a relay serving another host's workers, [`Remote`]) that is gone, silent for
//!   its deadline, or cut off: its tasks are re-issued and it is evicted; a relay that comes back
//!   joins again as a new peer.
//!
//! What the server hands out is a [`TaskSource`]: the run's learner cores (`[FleetJob]`), or, in
//! a relay, the tasks a remote learner sent. A late outcome of a re-issued task is recognised as
//! a duplicate and dropped (or, arriving first, accepted: the rollout is seeded, so both copies
//! carry the same bits). Workers of
//! another build or run, and workers serving an environment no job needs, are refused; a worker
//! that serves one environment is handed only tasks of jobs that need it.

use crate::wake::Waker;
use acps_learner::{Interrupted, Learner, LearnerTellError, LearningProgress};
use acps_shared::{EnvironmentSpec, Outcome, Serves, SpecBuildError, Task};
use acps_wire::ipc::{self, IpcError, RunName, ServerError, TICK, TaskRequest, TaskServer, TaskService};
use acps_wire::secret::RunSecret;
use acps_wire::wire::{
    Answer, CapacityError, PROTOCOL_VERSION, Refusal, Response, Sizes, WireTask, WorkerMessage, check_task_sizes,
};
use iceoryx2::identifiers::UniqueClientId;
use iceoryx2::port::listener::{Listener, ListenerWaitError};
use iceoryx2::prelude::{CallbackProgression, PortFactory as _};
use std::collections::{HashMap, HashSet, VecDeque};
use std::time::{Duration, Instant};

/// How long the server tells queued outcomes before it looks for requests again.
const TELL_BUDGET: Duration = Duration::from_micros(50);

/// A remote peer's answer waits until it carries this many tasks (a relay's largest request, or
/// all it asked for) or has waited [`REMOTE_GATHER`]: a network message costs both ends tens of
/// microseconds, and answering each freed task at once sent messages of 14-16 tasks that halved
/// a relay's throughput.
const REMOTE_BATCH: usize = 128;

/// How long a remote peer's answer may wait for [`REMOTE_BATCH`] tasks.
const REMOTE_GATHER: Duration = Duration::from_micros(500);

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

/// Why an [`Observer`] ended the run: its own error (writing a checkpoint, say).
#[derive(Debug, thiserror::Error)]
#[error(transparent)]
pub struct ObserveError(Box<dyn std::error::Error + Send + Sync>);

impl ObserveError {
    /// The observer's `error`.
    pub fn new(error: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> Self {
        Self(error.into())
    }
}

/// Why a [`ForwardingSource`] ended the run.
#[derive(Debug, thiserror::Error)]
pub enum ForwardError {
    /// The learner the tasks came from vanished.
    #[error("the learner of run '{run}' is gone")]
    LearnerGone {
        /// The learner's run.
        run: RunName,
    },
    /// The learner gave up on this source (it was silent too long, or the learner is a new one).
    #[error("the learner of run '{run}' gave up on this relay: {reason}")]
    Evicted {
        /// The learner's run.
        run: RunName,
        /// The learner's reason.
        reason: String,
    },
    /// The link to the learner failed, or it sent what cannot be served.
    #[error(transparent)]
    Link(Box<dyn std::error::Error + Send + Sync>),
}

/// Why a [`Remote`] ended the run: its network side failed.
#[derive(Debug, thiserror::Error)]
#[error(transparent)]
pub struct RemoteServeError(Box<dyn std::error::Error + Send + Sync>);

impl RemoteServeError {
    /// The remote's `error`.
    pub fn new(error: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> Self {
        Self(error.into())
    }
}

/// What a server hands out to workers: jobs (numbered from 0), each of one environment, whose
/// ready tasks go to workers that serve it and whose outcomes come back.
///
/// [`Learners`], the run's learner cores, is the source of every learner; a relay's source, a
/// [`ForwardingSource`], is the tasks its remote learner sent (`acps-relay`).
///
/// The contract the server relies on, for the whole of one serve:
/// - [`jobs`](Self::jobs), every job's [`environment`](Self::environment) and the
///   [`identity`](Self::identity) do not change.
/// - [`ask`](Self::ask) hands out each ready task once; a task handed out waits for its outcome
///   until [`tell`](Self::tell) accepts one, or [`reissue`](Self::reissue) makes it ready again.
/// - `tell` accepts the first outcome of a task that waits for one, and drops any other
///   (returning `false`): the server counts those as duplicates.
/// - [`jobs_done`](Self::jobs_done) never decreases; the server serves until it is `jobs`.
/// - [`learning`](Self::learning) and [`told`](Self::told) only report.
pub trait TaskSource {
    /// How many jobs.
    fn jobs(&self) -> usize;

    /// The environment job `job`'s tasks need.
    fn environment(&self, job: usize) -> EnvironmentSpec;

    /// The lengths of job `job`'s contexts and parameters.
    fn sizes(&self, job: usize) -> Sizes;

    /// The identity workers must name (or 0) in their requests.
    fn identity(&self) -> u64;

    /// Job `job`'s next ready task, if any.
    fn ask(&mut self, job: usize) -> Option<Task>;

    /// Job `job`'s outcome; `Ok(false)` when it was dropped: a duplicate, or of a task that is
    /// no longer waiting for one. A learner's update asks `stop` between its steps, and a
    /// stopped one is `Err` ([`Learner::tell_until`]): the server then stops too.
    fn tell(&mut self, job: usize, outcome: Outcome, stop: &dyn Fn() -> bool) -> Result<bool, Interrupted>;

    /// Hand task `task_id` of job `job` out again (its worker is gone); `false` when it is no
    /// longer waiting for an outcome.
    fn reissue(&mut self, job: usize, task_id: u64) -> bool;

    /// How many jobs are done; the server serves until all are.
    fn jobs_done(&self) -> usize;

    /// Training episodes and latest test scores of all jobs together (none for a source that
    /// holds no learner).
    fn learning(&self) -> LearningProgress;

    /// Show `observer` job `job`'s learner after it accepted an outcome (nothing, for a source
    /// that holds no learner).
    fn told(&mut self, job: usize, observer: &mut dyn Observer) -> Result<(), ObserveError>;
}

/// A [`TaskSource`] that forwards: its tasks come from elsewhere (a remote learner, for a relay)
/// and its outcomes go there, so the server also tells it what workers lacked, gives it every
/// pass of its loop, and asks it before it waits.
pub trait ForwardingSource: TaskSource {
    /// A request of a worker that serves `serves` found no ready task for `want`: ask for more.
    fn starved(&mut self, serves: &Serves, want: usize);

    /// The server refused a worker, for `reason`: tell the learner.
    fn refused(&mut self, reason: &str);

    /// Called once per pass of the server's loop, `idle` when it is about to wait for workers:
    /// send the outcomes held, and take in the tasks that arrived. Returns whether anything
    /// arrived (the server then looks again before it waits).
    fn pass(&mut self, idle: bool) -> Result<bool, ForwardError>;

    /// The server is about to wait for workers: whether it may (`false`: something came in
    /// meanwhile). The source is fed from other threads, which wake the server only while it
    /// waits, so this must say that the server sleeps.
    fn may_wait(&mut self) -> bool;

    /// The server is about to wait: at most how long (the source's outcomes fall due then);
    /// `None`: until the next heartbeat.
    fn wait_at_most(&self) -> Option<Duration>;
}

/// What one serve hands out: a source of its own, or one that forwards, whose extras the server
/// calls. A source of its own lacks nothing, refuses nobody's requests, and never makes the
/// server look again or wake early.
pub(crate) enum Source<'s> {
    Own(&'s mut dyn TaskSource),
    Forwarding(&'s mut dyn ForwardingSource),
}

impl Source<'_> {
    fn starved(&mut self, serves: &Serves, want: usize) {
        if let Self::Forwarding(source) = self {
            source.starved(serves, want);
        }
    }

    fn refused(&mut self, reason: &str) {
        if let Self::Forwarding(source) = self {
            source.refused(reason);
        }
    }

    fn pass(&mut self, idle: bool) -> Result<bool, ForwardError> {
        match self {
            Self::Own(_) => Ok(false),
            Self::Forwarding(source) => source.pass(idle),
        }
    }

    fn may_wait(&mut self) -> bool {
        match self {
            Self::Own(_) => true,
            Self::Forwarding(source) => source.may_wait(),
        }
    }

    fn wait_at_most(&self) -> Option<Duration> {
        match self {
            Self::Own(_) => None,
            Self::Forwarding(source) => source.wait_at_most(),
        }
    }
}

/// Both kinds serve as the source they are.
impl TaskSource for Source<'_> {
    fn jobs(&self) -> usize {
        match self {
            Self::Own(source) => source.jobs(),
            Self::Forwarding(source) => source.jobs(),
        }
    }

    fn environment(&self, job: usize) -> EnvironmentSpec {
        match self {
            Self::Own(source) => source.environment(job),
            Self::Forwarding(source) => source.environment(job),
        }
    }

    fn sizes(&self, job: usize) -> Sizes {
        match self {
            Self::Own(source) => source.sizes(job),
            Self::Forwarding(source) => source.sizes(job),
        }
    }

    fn identity(&self) -> u64 {
        match self {
            Self::Own(source) => source.identity(),
            Self::Forwarding(source) => source.identity(),
        }
    }

    fn ask(&mut self, job: usize) -> Option<Task> {
        match self {
            Self::Own(source) => source.ask(job),
            Self::Forwarding(source) => source.ask(job),
        }
    }

    fn tell(&mut self, job: usize, outcome: Outcome, stop: &dyn Fn() -> bool) -> Result<bool, Interrupted> {
        match self {
            Self::Own(source) => source.tell(job, outcome, stop),
            Self::Forwarding(source) => source.tell(job, outcome, stop),
        }
    }

    fn reissue(&mut self, job: usize, task_id: u64) -> bool {
        match self {
            Self::Own(source) => source.reissue(job, task_id),
            Self::Forwarding(source) => source.reissue(job, task_id),
        }
    }

    fn jobs_done(&self) -> usize {
        match self {
            Self::Own(source) => source.jobs_done(),
            Self::Forwarding(source) => source.jobs_done(),
        }
    }

    fn learning(&self) -> LearningProgress {
        match self {
            Self::Own(source) => source.learning(),
            Self::Forwarding(source) => source.learning(),
        }
    }

    fn told(&mut self, job: usize, observer: &mut dyn Observer) -> Result<(), ObserveError> {
        match self {
            Self::Own(source) => source.told(job, observer),
            Self::Forwarding(source) => source.told(job, observer),
        }
    }
}

/// The worker processes a fleet started, as the server looks at them every tick.
pub(crate) struct Started {
    /// Still running (connected or not).
    pub(crate) running: usize,
    /// Started in all.
    pub(crate) launched: usize,
    /// Ended with a failure (a status other than 0, or a signal).
    pub(crate) failed: usize,
}

/// The run's learner cores: the [`TaskSource`] of a learner's fleet.
pub struct Learners<'a>(pub &'a mut [FleetJob]);

impl TaskSource for Learners<'_> {
    fn jobs(&self) -> usize {
        self.0.len()
    }

    fn environment(&self, job: usize) -> EnvironmentSpec {
        *self.0[job].environment()
    }

    fn sizes(&self, job: usize) -> Sizes {
        let problem = self.0[job].learner().problem();
        Sizes {
            context: problem.context_dim(),
            theta: problem.theta0.len(),
        }
    }

    /// A hash of the jobs' problems (their environments included) and seeds, stable across builds.
    fn identity(&self) -> u64 {
        self.0.iter().fold(acps_shared::FNV_OFFSET, |hash, job| {
            let learner = job.learner();
            acps_shared::fnv1a(hash, format!("{:?} {}", learner.problem(), learner.seed()).as_bytes())
        })
    }

    fn ask(&mut self, job: usize) -> Option<Task> {
        self.0[job].learner.ask()
    }

    fn tell(&mut self, job: usize, outcome: Outcome, stop: &dyn Fn() -> bool) -> Result<bool, Interrupted> {
        let Some(job) = self.0.get_mut(job) else {
            return Ok(false);
        };
        match job.learner.tell_until(outcome, stop) {
            Ok(()) => Ok(true),
            Err(LearnerTellError::Interrupted { .. }) => Err(Interrupted),
            // An unknown task or a second outcome: a re-issued task answered twice.
            Err(LearnerTellError::UnknownTask { .. } | LearnerTellError::Duplicate { .. }) => Ok(false),
        }
    }

    fn reissue(&mut self, job: usize, task_id: u64) -> bool {
        self.0[job].learner.reissue(task_id)
    }

    fn jobs_done(&self) -> usize {
        self.0.iter().filter(|j| j.learner.is_done()).count()
    }

    fn learning(&self) -> LearningProgress {
        LearningProgress::combine(self.0.iter().map(|j| j.learner.progress()))
    }

    fn told(&mut self, job: usize, observer: &mut dyn Observer) -> Result<(), ObserveError> {
        observer.told(job, &mut self.0[job].learner)
    }
}

/// A remote peer's number, given by the [`Remote`] that admitted it.
pub type PeerId = u32;

/// What happened on a [`Remote`] since the server last looked.
#[derive(Debug, Clone, PartialEq)]
pub enum RemoteEvent {
    /// An admitted peer's message: outcomes of tasks it held, and, if `want` > 0, a request for
    /// up to `want` tasks of the environments it `serves`, to be answered once by
    /// [`Remote::send`] with request number `request`.
    Request {
        /// The peer.
        peer: PeerId,
        /// The request's number, for the answer.
        request: u64,
        /// Tasks asked for (0: outcomes only, not answered).
        want: usize,
        /// Which tasks may go to it.
        serves: Serves,
        /// The workers behind the peer.
        workers: usize,
        /// The slowest rollout any of them reported.
        slowest_rollout: Duration,
        /// Outcomes, by job.
        outcomes: Vec<(u32, Outcome)>,
    },
    /// The peer is gone (its process or its link): its tasks go to others.
    Gone {
        /// The peer.
        peer: PeerId,
    },
}

/// Peers served over a network (relays of other hosts, `acps-relay`): the server hands them tasks
/// as it does local workers, and wakes when they speak through the run's own wake-up event (a
/// remote notifies the run's `to-learner` event service when it queues a message while the
/// server waits, see [`Remote::may_wait`]).
pub trait Remote {
    /// Serving of `run` starts: admit peers for a source of this `identity` whose jobs need
    /// these `environments` and carry contexts and parameters of these `sizes` (by job).
    fn start(
        &mut self,
        run: &RunName,
        identity: u64,
        environments: &[EnvironmentSpec],
        sizes: &[Sizes],
    ) -> Result<(), RemoteServeError>;

    /// Append what happened since the last call to `events`, without blocking.
    fn poll(&mut self, events: &mut Vec<RemoteEvent>) -> Result<(), RemoteServeError>;

    /// Answer `peer`'s request `request` with `tasks` (job, task): at least one.
    fn send(&mut self, peer: PeerId, request: u64, tasks: Vec<(u32, Task)>) -> Result<(), RemoteServeError>;

    /// `peer` is given up on (silent for `silent`): its later messages are refused, and it is
    /// told so, to join again.
    fn evict(&mut self, peer: PeerId, silent: Duration);

    /// Serving ends (done, or stopped): tell every peer.
    fn finish(&mut self, done: bool);

    /// The server is about to wait: whether it may (`false`: a message came in meanwhile). A
    /// remote wakes the server through the run's event only while it waits, so this must say
    /// that the server sleeps, or its messages wait for the next tick.
    fn may_wait(&mut self) -> bool;
}

/// Progress of a fleet run, reported every tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FleetProgress {
    /// Jobs finished.
    pub jobs_done: usize,
    /// Outcomes consumed (all kinds).
    pub outcomes: u64,
    /// Connected workers, those behind remote peers included.
    pub workers: usize,
    /// The most workers connected at once so far (counted every tick, and at the end from the
    /// workers heard from): a run shorter than a tick still counts its workers.
    pub most_workers: usize,
    /// Connected remote peers (relays of other hosts).
    pub relays: usize,
    /// The slowest rollout any worker reported.
    pub slowest_rollout: Duration,
    /// Worker processes the fleet started that are still running (connected or not).
    pub started_running: usize,
    /// Tasks re-issued because their worker died.
    pub reissued: u64,
    /// Outcomes dropped as duplicates (a re-issued task answered twice).
    pub duplicates: u64,
    /// Outcomes dropped because they came from a worker that never held their task.
    pub foreign: u64,
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
    /// ([`Liveness::no_workers`]): every started worker exited, and no other joined; or at
    /// once, when every started worker failed.
    #[error(
        "no worker can go on with run '{run}': {how}{why}",
        how = if *failed {
            format!("all {started} started worker processes failed{} (see their messages above), and no other is connected", if exits.is_empty() { String::new() } else { format!(": {exits}") })
        } else {
            format!("none connected for {:.1} s{}", waited.as_secs_f64(), if *started > 0 { format!(", and all {started} started worker processes exited{} (see their messages above)", if exits.is_empty() { String::new() } else { format!(": {exits}") }) } else { String::new() })
        },
        why = refused.as_ref().map_or(String::new(), |reason| format!("; the learner refused a worker: {reason}"))
    )]
    NoWorkers {
        /// The run.
        run: RunName,
        /// Worker processes the fleet started.
        started: usize,
        /// Whether every one of them failed (a status other than 0, or a signal): the run then
        /// stops without waiting out the grace period.
        failed: bool,
        /// How they ended, counted by exit status (`2 with status 1`), once the fleet has
        /// reaped them; empty before, or without started workers.
        exits: String,
        /// How long the run was without a worker.
        waited: Duration,
        /// Why the learner refused the last worker it refused, if it refused any and no
        /// worker served since: the workers (or the problem) must change before the run can go
        /// on.
        refused: Option<String>,
    },
    /// Worker processes the fleet started ran for the start-up deadline ([`Liveness::startup`])
    /// and none connected.
    #[error(
        "no worker of run '{run}' connected within {seconds:.0} s: {started} started worker processes (`{command}`) ran but none asked for tasks; are they stuck starting up (see their messages above)? If they need longer, raise --worker-startup-timeout",
        seconds = waited.as_secs_f64()
    )]
    NeverConnected {
        /// The run.
        run: RunName,
        /// Worker processes the fleet started.
        started: usize,
        /// How long they ran.
        waited: Duration,
        /// The command they were started with.
        command: String,
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
    Observer(ObserveError),
    /// The [`ForwardingSource`] failed (a relay's link to its learner).
    #[error(transparent)]
    Source(ForwardError),
    /// The [`Remote`] failed (the network side of a learner that serves relays).
    #[error("remote peers")]
    Remote(#[source] RemoteServeError),
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
    /// Stop with [`FleetError::NeverConnected`] once worker processes the fleet started have
    /// run this long and no worker has ever connected (a worker stuck at start-up, say at an
    /// import, would otherwise keep the run waiting for ever); `None`: wait for ever.
    pub startup: Option<Duration>,
}

/// How long started workers may take to connect unless set: long enough for a Python worker
/// that imports a simulator and compiles its model (seconds to a minute), short enough that a
/// stuck one is noticed.
pub const WORKER_STARTUP: Duration = Duration::from_secs(120);

impl Default for Liveness {
    /// 5 s of silence and 4 times the slowest rollout; 10 s without workers; started workers
    /// connect within [`WORKER_STARTUP`].
    fn default() -> Self {
        Self {
            silence: Duration::from_secs(5),
            rollout_factor: 4,
            no_workers: Some(Duration::from_secs(10)),
            startup: Some(WORKER_STARTUP),
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

    /// Job `job`'s learner after every outcome it accepted: the place to take its records
    /// ([`Learner::take_records`]) and write checkpoints; nothing else of it may change. An
    /// error ends the run with [`FleetError::Observer`].
    fn told(&mut self, job: usize, learner: &mut Learner) -> Result<(), ObserveError> {
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
    secret: RunSecret,
}

impl Seat {
    /// Take the seat of `run`, refused while another learner holds it, and publish the run's
    /// `secret` for workers started by hand: once the seat is this learner's, so that the secret
    /// of another learner of the name is never replaced. (Written again by each serve: between
    /// serves the run has no node, and another fleet's start may remove its files.)
    pub(crate) fn take(run: &RunName, secret: RunSecret) -> Result<Self, ServerError> {
        let node = ipc::node(run, ipc::LEARNER_NODE)?;
        let services = ipc::open_services(&node)?;
        let server = ipc::task_server(run, &services.tasks)?;
        secret.publish(run)?;
        Ok(Self {
            server,
            services,
            _node: node,
            secret,
        })
    }
}

/// Who holds tasks or asks for them: a local worker's task client, or a remote peer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Client {
    Local(UniqueClientId),
    Remote(PeerId),
}

/// Who holds each handed-out task, and who held it before it was re-issued. An outcome is
/// taken only from those: any process of the run's user can open its services, and the first
/// outcome of a task wins, so a stranger's made-up outcome for another worker's task would be
/// learnt from. A late outcome of a re-issued task from its former holder stays valid.
#[derive(Default)]
struct Holders {
    current: HashMap<(u32, u64), Client>,
    /// Kept for the whole run: re-issues are rare (a worker died or hung), and the former
    /// holder's late outcome may come after the new holder's.
    former: HashMap<(u32, u64), Vec<Client>>,
    /// Clients whose outcomes were dropped, each warned of once.
    strangers: HashSet<Client>,
}

impl Holders {
    fn give(&mut self, job: u32, task_id: u64, client: Client) {
        self.current.insert((job, task_id), client);
    }

    /// Whether an outcome of task `task_id` of `job` from `client` may be taken: it holds the
    /// task, or held it before the task was re-issued.
    fn answered(&mut self, job: u32, task_id: u64, client: Client) -> bool {
        let key = (job, task_id);
        // One lookup for the usual answer, from the holder; a stranger's costs a second.
        match self.current.remove(&key) {
            Some(holder) if holder == client => return true,
            Some(holder) => {
                self.current.insert(key, holder);
            }
            None => {}
        }
        self.former.get(&key).is_some_and(|former| former.contains(&client))
    }

    /// Re-issue every task held by a client for which `gone` says so. Returns how many tasks
    /// went back to `source`.
    fn reissue_where(&mut self, source: &mut dyn TaskSource, mut gone: impl FnMut(&Client) -> bool) -> u64 {
        let Self { current, former, .. } = self;
        let mut reissued = 0;
        current.retain(|&(job, task_id), client| {
            if !gone(client) {
                return true;
            }
            reissued += u64::from(source.reissue(job as usize, task_id));
            former.entry((job, task_id)).or_default().push(*client);
            false
        });
        reissued
    }

    fn clients(&self) -> impl Iterator<Item = &Client> {
        self.current.values()
    }
}

/// Queue the outcomes `client` delivered that it may give ([`Holders::answered`]); the others
/// are dropped, counted in `progress.foreign` and warned of once per client.
fn take_outcomes(
    run: &RunName,
    client: Client,
    delivered: impl IntoIterator<Item = (u32, Outcome)>,
    holders: &mut Holders,
    outcomes: &mut VecDeque<(u32, Outcome)>,
    progress: &mut FleetProgress,
) {
    for (job, outcome) in delivered {
        if holders.answered(job, outcome.task_id, client) {
            outcomes.push_back((job, outcome));
            continue;
        }
        progress.foreign += 1;
        if holders.strangers.insert(client) {
            let who = match client {
                Client::Local(_) => "a local worker".to_string(),
                Client::Remote(peer) => format!("remote peer {peer}"),
            };
            tracing::warn!(
                "run '{run}': dropped an outcome of task {} of job {job} from {who}, which was never handed that task: outcomes are taken only from the worker that holds the task (is another program speaking to this run?)",
                outcome.task_id
            );
        }
    }
}

/// Where a parked request came from, to answer it.
enum Requester {
    Local(TaskRequest),
    /// A remote peer's request, with the tasks gathered for it so far (they count as held by the
    /// peer) since `since`.
    Remote {
        peer: PeerId,
        request: u64,
        gathered: Vec<(u32, Task)>,
        since: Instant,
    },
}

/// A request waiting for tasks.
struct Parked {
    from: Requester,
    want: usize,
    serves: Serves,
}

impl Parked {
    fn client(&self) -> Client {
        match &self.from {
            Requester::Local(request) => Client::Local(request.origin()),
            Requester::Remote { peer, .. } => Client::Remote(*peer),
        }
    }
}

/// Serve `source` from `seat` to the workers of `run`, and to `remote`'s peers (started by the
/// caller), until every job is done. `started` says how many worker processes the caller started
/// are still running (they count as workers on their way).
#[allow(clippy::too_many_arguments)]
pub(crate) fn serve<'r>(
    source: &mut Source<'_>,
    run: &RunName,
    seat: &Seat,
    options: ServeOptions,
    stop: &dyn Fn() -> bool,
    observer: &mut dyn Observer,
    started: &mut dyn FnMut() -> Started,
    mut remote: Option<&mut (dyn Remote + 'r)>,
) -> Result<FleetProgress, FleetError> {
    let Seat { server, services, .. } = seat;
    let listener = services
        .to_learner
        .listener_builder()
        .create()
        .map_err(|source| IpcError::ListenerCreate {
            owner: "the learner",
            source,
        })?;
    let mut waker = Waker::new(services)?;
    let identity = options.identity;
    let mut progress = FleetProgress::default();
    let mut parked: VecDeque<Parked> = VecDeque::new();
    let mut holders = Holders::default();
    let mut next_job = 0;
    let mut last_tick = Instant::now();
    let mut refused_clients = HashSet::new();
    // The last refusal's reason and the outcomes taken by then.
    let mut last_refusal: Option<(String, u64)> = None;
    // Workers whose first outcome the learner has seen.
    let mut first_outcomes = HashSet::new();
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
    let mut last_heard: HashMap<Client, Instant> = HashMap::new();
    // Workers found hung: they get no tasks until they speak again.
    let mut hung: HashSet<Client> = HashSet::new();
    let mut slowest_rollout = Duration::ZERO;
    let mut without_workers: Option<Instant> = None;
    // For the start-up deadline: when serving began, and whether any worker connected since.
    let serving_start = Instant::now();
    let mut ever_connected = false;
    let mut last_running = 0;
    // Workers behind each remote peer, as it last said.
    let mut peers: HashMap<PeerId, usize> = HashMap::new();
    let mut events = Vec::new();
    loop {
        let mut active_now = false;
        while let Some(request) = server.receive().map_err(IpcError::RequestReceive)? {
            active_now = true;
            let client = Client::Local(request.origin());
            heard.insert(client);
            last_heard.insert(client, Instant::now());
            if hung.remove(&client) {
                tracing::info!("run '{run}': a worker found hung speaks again");
            }
            let message = request.payload();
            slowest_rollout = slowest_rollout.max(message.slowest_rollout());
            let serves = match admit(message, &seat.secret, identity, source) {
                Ok(serves) => serves,
                Err(mismatch) => {
                    progress.refused += 1;
                    let (answer, reason) = refusal(&mismatch, run, identity, source);
                    if refused_clients.insert(request.origin()) {
                        tracing::warn!("refused a worker of run '{run}': {reason}");
                        source.refused(&reason);
                    }
                    last_refusal = Some((reason, progress.outcomes));
                    let _ = ipc::reply(&request, answer, &[]);
                    continue;
                }
            };
            if serving_since.is_none() {
                waiting_for.insert(client);
                if waiting_for.len() >= options.start_with {
                    serving_since = Some(Instant::now());
                }
            }
            let mut delivered = message.outcomes().peekable();
            if let Some((job, first)) = delivered.peek()
                && message.sizes().is_none()
                && first_outcomes.insert(client)
                && !first.is_ok()
                && (*job as usize) < source.jobs()
            {
                // A worker that declared no sizes is checked on its first outcome: one written
                // for another problem fails every rollout, and is told of now, not at the end.
                tracing::warn!(
                    "run '{run}': a worker's first rollout (task {} of job {job}) failed; the job's tasks carry {}: a worker written for other sizes fails every rollout (a worker that declares its sizes is refused at once, naming both)",
                    first.task_id,
                    source.sizes(*job as usize)
                );
            }
            take_outcomes(run, client, delivered, &mut holders, &mut outcomes, &mut progress);
            match message.wanted() {
                // Outcomes only: the worker's last free slot, so it is answered at once rather
                // than parked behind tasks that may need these very outcomes.
                0 => {
                    ipc::reply(&request, Answer::new(Response::Task, identity), &[])?;
                    progress.delivered += 1;
                    waker.answered(request.origin());
                    wake_now = true;
                }
                want => parked.push_back(Parked {
                    from: Requester::Local(request),
                    want,
                    serves,
                }),
            }
        }
        if let Some(remote) = remote.as_deref_mut() {
            remote.poll(&mut events).map_err(FleetError::Remote)?;
            for event in events.drain(..) {
                active_now = true;
                match event {
                    RemoteEvent::Request {
                        peer,
                        request,
                        want,
                        serves,
                        workers,
                        slowest_rollout: slowest,
                        outcomes: delivered,
                    } => {
                        let client = Client::Remote(peer);
                        heard.insert(client);
                        last_heard.insert(client, Instant::now());
                        peers.insert(peer, workers);
                        slowest_rollout = slowest_rollout.max(slowest);
                        take_outcomes(run, client, delivered, &mut holders, &mut outcomes, &mut progress);
                        if serving_since.is_none() {
                            waiting_for.insert(client);
                            if waiting_for.len() >= options.start_with {
                                serving_since = Some(Instant::now());
                            }
                        }
                        if want > 0 {
                            parked.push_back(Parked {
                                from: Requester::Remote {
                                    peer,
                                    request,
                                    gathered: Vec::new(),
                                    since: Instant::now(),
                                },
                                want,
                                serves,
                            });
                        }
                    }
                    RemoteEvent::Gone { peer } => {
                        let reissued = forget_peer(source, peer, &mut holders, &mut parked, &mut peers);
                        last_heard.remove(&Client::Remote(peer));
                        hung.remove(&Client::Remote(peer));
                        progress.reissued += reissued;
                        tracing::info!("run '{run}': remote peer {peer} is gone; re-issued its {reissued} tasks");
                    }
                }
            }
        }
        // Answer before telling: tasks are created eagerly, so ready ones wait in the cores, and
        // workers get them without waiting for the C-REPS updates (a millisecond each) of the
        // outcomes queued before theirs.
        let answered = if serving_since.is_some() {
            let (answered, asking) = answer(
                source,
                &mut parked,
                &hung,
                &mut holders,
                &mut next_job,
                identity,
                !outcomes.is_empty(),
                remote.as_deref_mut(),
                // An answered worker is woken, and until the next tick counts as heard: it has
                // had no time yet to send anything for the tasks it now holds.
                |client| {
                    if let Client::Local(client) = client {
                        waker.answered(client);
                    }
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
            let job = job as usize;
            let told = job < source.jobs() && source.tell(job, outcome, stop).map_err(|_| FleetError::Interrupted)?;
            let finished = Instant::now();
            progress.learner_seconds += (finished - started).as_secs_f64();
            if told {
                progress.outcomes += 1;
                source.told(job, observer).map_err(FleetError::Observer)?;
            } else {
                progress.duplicates += 1;
            }
            if finished - telling >= TELL_BUDGET {
                break;
            }
        }
        let mut busy = active_now || answered > 0 || told_any;
        busy |= source.pass(!busy).map_err(FleetError::Source)?;
        progress.jobs_done = source.jobs_done();
        let serving = || serving_since.map_or(0.0, |since: Instant| since.elapsed().as_secs_f64());
        if progress.jobs_done == source.jobs() {
            let heard_locally = last_heard.keys().filter(|c| matches!(c, Client::Local(_))).count();
            progress.most_workers = progress.most_workers.max(heard_locally + peers.values().sum::<usize>());
            progress.serving_seconds = serving();
            progress.learning = source.learning();
            // Before the workers are told to stop: a host that watches whether its workers are
            // still there (`acps run` ends a run whose workers all left) must still find them.
            observer.progress(&progress);
            for parked in parked.drain(..) {
                if let Requester::Local(request) = parked.from {
                    let _ = ipc::reply(&request, Answer::new(Response::Stop, identity), &[]);
                }
            }
            let _ = waker.wake_all();
            return Ok(progress);
        }
        if last_tick.elapsed() >= TICK {
            last_tick = Instant::now();
            let Started {
                running,
                launched,
                failed,
            } = started();
            progress.started_running = running;
            progress.slowest_rollout = slowest_rollout;
            progress.serving_seconds = serving();
            progress.learning = source.learning();
            let mut connected = HashSet::new();
            services.tasks.dynamic_config().list_clients(|client| {
                connected.insert(Client::Local(client.client_id));
                CallbackProgression::Continue
            });
            // A started worker that exited may have held nothing: it is looked for at once, so
            // that a fleet whose workers all exited is noticed.
            let look = look_is_due(&holders, &heard, &connected) || running < last_running;
            last_running = running;
            heard.clear();
            let local = if look {
                let Some(live) =
                    reissue_tasks_of_dead_workers(run, &services.tasks, source, &mut holders, &mut progress.reissued)
                else {
                    observer.progress(&progress);
                    continue;
                };
                live
            } else {
                connected.len()
            };
            progress.relays = peers.len();
            progress.workers = local + peers.values().sum::<usize>();
            progress.most_workers = progress.most_workers.max(progress.workers);
            let deadline = options
                .liveness
                .silence
                .max(slowest_rollout * options.liveness.rollout_factor);
            let silent = reissue_tasks_of_silent_workers(run, source, &mut holders, &last_heard, &mut hung, deadline);
            progress.reissued += silent.reissued;
            // A silent peer is evicted: it joins again as a new one if it lives.
            for peer in silent.peers {
                progress.reissued += forget_peer(source, peer, &mut holders, &mut parked, &mut peers);
                last_heard.remove(&Client::Remote(peer));
                hung.remove(&Client::Remote(peer));
                if let Some(remote) = remote.as_deref_mut() {
                    remote.evict(peer, deadline);
                }
            }
            let known = |client: &Client| match client {
                Client::Local(_) => connected.contains(client),
                Client::Remote(peer) => peers.contains_key(peer),
            };
            last_heard.retain(|client, _| known(client));
            hung.retain(known);
            if progress.workers > 0 || progress.relays > 0 {
                ever_connected = true;
            } else if !ever_connected
                && progress.started_running > 0
                && let Some(limit) = options.liveness.startup
                && serving_start.elapsed() >= limit
            {
                return Err(FleetError::NeverConnected {
                    run: run.clone(),
                    started: launched,
                    waited: serving_start.elapsed(),
                    command: String::new(),
                });
            }
            if progress.workers > 0 || progress.relays > 0 || progress.started_running > 0 {
                without_workers = None;
                // Someone served since: an old refusal is not why the run would stop.
                if last_refusal.as_ref().is_some_and(|(_, at)| progress.outcomes > *at) {
                    last_refusal = None;
                }
            } else if let Some(grace) = options.liveness.no_workers {
                let since = *without_workers.get_or_insert_with(Instant::now);
                // Workers started only to fail (a problem they refuse, an outcome the wire
                // cannot carry) do not come back: waiting for others would only delay the error.
                let all_failed = launched > 0 && failed == launched;
                if all_failed || since.elapsed() >= grace {
                    return Err(FleetError::NoWorkers {
                        run: run.clone(),
                        started: launched,
                        failed: all_failed,
                        exits: String::new(),
                        waited: since.elapsed(),
                        refused: last_refusal.map(|(reason, _)| reason),
                    });
                }
            }
            observer.progress(&progress);
        }
        if stop() {
            return Err(FleetError::Interrupted);
        }
        if busy {
            idle_since = None;
        } else if idle_since.get_or_insert_with(Instant::now).elapsed() < options.spin {
            std::thread::yield_now();
        } else if source.may_wait() && remote.as_deref_mut().is_none_or(|remote| remote.may_wait()) {
            idle_since = None;
            let heartbeat = waker.until_heartbeat();
            match wait(
                &listener,
                source.wait_at_most().map_or(heartbeat, |most| most.min(heartbeat)),
            ) {
                // Any signal interrupts the wait, also SIGSTOP and SIGCONT (a paused and resumed
                // run): the loop goes on, and only `stop`, which the host's Ctrl-C handler sets,
                // ends it.
                Ok(_) | Err(ListenerWaitError::InterruptSignal) => {}
                Err(source) => {
                    return Err(IpcError::ListenerWait {
                        whom: "workers",
                        source,
                    }
                    .into());
                }
            }
        }
    }
}

/// Wait for a notification on `listener` for at most `timeout`. A zero timeout returns at once:
/// iceoryx2 makes it the socket's receive timeout, where 0 means for ever, and a relay whose
/// outcomes were due just then slept until a worker spoke, so for ever once its learner was gone.
fn wait(listener: &Listener<iceoryx2::prelude::ipc::Service>, timeout: Duration) -> Result<(), ListenerWaitError> {
    if timeout.is_zero() {
        return Ok(());
    }
    listener.timed_wait(|_| {}, timeout).map(|_| ())
}

/// Forget remote `peer`: re-issue the tasks it holds and drop its parked requests. Returns how
/// many tasks were re-issued.
fn forget_peer(
    source: &mut dyn TaskSource,
    peer: PeerId,
    holders: &mut Holders,
    parked: &mut VecDeque<Parked>,
    peers: &mut HashMap<PeerId, usize>,
) -> u64 {
    let gone = Client::Remote(peer);
    let reissued = holders.reissue_where(source, |client| *client == gone);
    parked.retain(|request| request.client() != gone);
    peers.remove(&peer);
    reissued
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
fn look_is_due(holders: &Holders, heard: &HashSet<Client>, connected: &HashSet<Client>) -> bool {
    holders
        .clients()
        .any(|client| matches!(client, Client::Local(_)) && (!heard.contains(client) || !connected.contains(client)))
}

/// Give the tasks held by workers that are gone back to their learners. Returns how many workers
/// are alive, or `None` when the nodes could not be listed (a node being created or removed at
/// this moment; the next tick looks again).
fn reissue_tasks_of_dead_workers(
    run: &RunName,
    tasks: &TaskService,
    source: &mut dyn TaskSource,
    holders: &mut Holders,
    reissued: &mut u64,
) -> Option<usize> {
    tasks.try_cleanup_dead_nodes();
    let alive_nodes = ipc::alive_nodes(run).ok()?;
    let mut live = HashSet::new();
    tasks.dynamic_config().list_clients(|client| {
        if alive_nodes.contains(&client.node_id) {
            live.insert(Client::Local(client.client_id));
        }
        CallbackProgression::Continue
    });
    // Remote peers are looked after by their remote.
    let gone = holders.reissue_where(source, |client| {
        matches!(client, Client::Local(_)) && !live.contains(client)
    });
    *reissued += gone;
    if gone > 0 {
        tracing::info!("run '{run}': a worker is gone; re-issued its {gone} tasks");
    }
    Some(live.len())
}

/// Workers found silent by [`reissue_tasks_of_silent_workers`].
struct Silent {
    /// Tasks re-issued.
    reissued: u64,
    /// Remote peers among them, to be evicted (their other tasks are re-issued then).
    peers: Vec<PeerId>,
}

/// Give the tasks held by workers silent for longer than `deadline` back to their source, and
/// mark those workers hung.
fn reissue_tasks_of_silent_workers(
    run: &RunName,
    source: &mut dyn TaskSource,
    holders: &mut Holders,
    last_heard: &HashMap<Client, Instant>,
    hung: &mut HashSet<Client>,
    deadline: Duration,
) -> Silent {
    let silent = |client: &Client| last_heard.get(client).is_some_and(|heard| heard.elapsed() > deadline);
    let mut found = Silent {
        reissued: 0,
        peers: Vec::new(),
    };
    found.reissued = holders.reissue_where(source, |client| {
        if !silent(client) {
            return false;
        }
        if hung.insert(*client) {
            match client {
                Client::Local(_) => tracing::warn!(
                    "run '{run}': a worker holding tasks has sent nothing for {deadline:?}; its tasks go to other workers (raise the fleet's liveness deadline if rollouts take longer)"
                ),
                Client::Remote(peer) => {
                    tracing::warn!(
                        "run '{run}': remote peer {peer} holds tasks and has sent nothing for {deadline:?}; its tasks go to other workers and it is evicted"
                    );
                    found.peers.push(*peer);
                }
            }
        }
        true
    });
    found
}

/// Why the learner refuses a worker's request.
enum Mismatch {
    /// Another protocol version.
    Protocol(u32),
    /// Not the run's secret: a process that was not given it.
    Secret,
    /// Another run identity.
    Run(u64),
    /// An environment none of the jobs needs, and how the worker described it (with the
    /// settings text it sent).
    Environment(EnvironmentSpec, String),
    /// An environment description that is none.
    Unreadable(SpecBuildError),
    /// Declared lengths of contexts and parameters other than those of a job it would serve.
    Sizes {
        /// What the worker declared.
        worker: Sizes,
        /// What that job's tasks carry.
        job: Sizes,
    },
}

/// What a request's worker serves, if the learner accepts it: this build's protocol, this run
/// (or any), and an environment some job needs (or any).
fn admit(
    message: &WorkerMessage,
    secret: &RunSecret,
    identity: u64,
    source: &dyn TaskSource,
) -> Result<Serves, Mismatch> {
    if message.protocol != PROTOCOL_VERSION {
        return Err(Mismatch::Protocol(message.protocol));
    }
    if !secret.matches(&message.secret) {
        return Err(Mismatch::Secret);
    }
    if message.run != 0 && message.run != identity {
        return Err(Mismatch::Run(message.run));
    }
    let serves = message.serves().map_err(Mismatch::Unreadable)?;
    if let Serves::One(spec) = serves
        && !(0..source.jobs()).any(|job| source.environment(job) == spec)
    {
        return Err(Mismatch::Environment(spec, message.serves_shown()));
    }
    // A declared size must be every served job's: a worker of other sizes would fail each of
    // its rollouts, and the run would find out only at its end.
    if let Some(worker) = message.sizes()
        && let Some(job) = (0..source.jobs())
            .filter(|&job| serves.includes(&source.environment(job)))
            .map(|job| source.sizes(job))
            .find(|&job| job != worker)
    {
        return Err(Mismatch::Sizes { worker, job });
    }
    Ok(serves)
}

/// The answer refusing a worker for `mismatch`, and the reason in words, naming the worker's
/// and the learner's environments. The answer names one environment the jobs need, preferably
/// one of the worker's environment's name: the closest description of what it should be.
fn refusal(mismatch: &Mismatch, run: &RunName, identity: u64, source: &dyn TaskSource) -> (Answer, String) {
    let mut needed: Vec<EnvironmentSpec> = Vec::new();
    for job in 0..source.jobs() {
        let environment = source.environment(job);
        if !needed.contains(&environment) {
            needed.push(environment);
        }
    }
    let closest = match mismatch {
        Mismatch::Environment(spec, _) => needed.iter().find(|need| need.name() == spec.name()),
        _ => None,
    }
    .or(needed.first())
    .copied();
    let answer = match mismatch {
        Mismatch::Protocol(_) => Answer::refused(Refusal::Protocol, identity, closest, needed.len()),
        Mismatch::Run(_) => Answer::refused(Refusal::Run, identity, closest, needed.len()),
        Mismatch::Secret => Answer::refused(Refusal::Secret, identity, None, 0),
        Mismatch::Environment(..) | Mismatch::Unreadable(_) => {
            Answer::refused(Refusal::Environment, identity, closest, needed.len())
        }
        Mismatch::Sizes { job, .. } => Answer::refused_sizes(identity, *job),
    };
    let reason = match mismatch {
        Mismatch::Protocol(protocol) => format!("protocol {protocol} (ours {PROTOCOL_VERSION})"),
        Mismatch::Run(run) => format!("run identity {run:016x} (ours {identity:016x})"),
        Mismatch::Secret => format!(
            "its messages do not carry the run's secret (a process the run did not start, or one started by hand that did not read {})",
            RunSecret::path(run).display()
        ),
        Mismatch::Environment(_, shown) => format!("it serves environment {shown}; the jobs need {}", answer.needs()),
        Mismatch::Unreadable(error) => format!(
            "its environment cannot be read ({error}); the jobs need {}",
            answer.needs()
        ),
        Mismatch::Sizes { worker, job } => format!("it serves {worker}; the jobs need {job}"),
    };
    (answer, reason)
}

/// Answer parked requests, each with as many ready tasks as it asks for of the environments its
/// worker serves (round robin over the jobs), as soon as at least one is ready; tells
/// `answered_to` of every worker answered; returns how many tasks went out and the time the
/// source took to hand them out. Requests of hung workers stay parked. While `more_coming`
/// (outcomes wait to be told, which frees tasks), a remote peer's answer keeps gathering tasks
/// until it has [`REMOTE_BATCH`] or has waited [`REMOTE_GATHER`].
#[allow(clippy::too_many_arguments)]
fn answer<'r>(
    source: &mut Source<'_>,
    parked: &mut VecDeque<Parked>,
    hung: &HashSet<Client>,
    holders: &mut Holders,
    next_job: &mut usize,
    identity: u64,
    more_coming: bool,
    mut remote: Option<&mut (dyn Remote + 'r)>,
    mut answered_to: impl FnMut(Client),
) -> Result<(usize, Duration), FleetError> {
    let mut answered = 0;
    let mut asking = Duration::ZERO;
    // Allocated only when a request is waiting: most passes have none.
    let mut wire = Vec::new();
    let mut tasks = Vec::new();
    // What workers serve whose requests found nothing more ready in this pass: the next request
    // of the same kind would find nothing either.
    let mut dry: Vec<Serves> = Vec::new();
    for _ in 0..parked.len() {
        let Some(mut request) = parked.pop_front() else {
            break;
        };
        if let Requester::Local(local) = &request.from
            && !local.is_connected()
        {
            continue;
        }
        let client = request.client();
        // Hung workers get nothing until they speak again.
        if hung.contains(&client) || dry.contains(&request.serves) {
            parked.push_back(request);
            continue;
        }
        let (want, serves) = (request.want, request.serves);
        let (ready, gathering) = match &mut request.from {
            Requester::Local(_) => {
                tasks.clear();
                (&mut tasks, false)
            }
            Requester::Remote { gathered, since, .. } => (gathered, more_coming && since.elapsed() < REMOTE_GATHER),
        };
        let started = Instant::now();
        while ready.len() < want {
            let Some((job, task)) = next_task(source, next_job, &serves) else {
                break;
            };
            holders.give(job as u32, task.id, client);
            ready.push((job as u32, task));
        }
        asking += started.elapsed();
        let sent = ready.len();
        if sent == 0 || (gathering && sent < want.min(REMOTE_BATCH)) {
            if sent == 0 {
                source.starved(&serves, want);
            }
            if serves == Serves::Any {
                // Nothing more is ready for anyone: the request keeps its place.
                parked.push_front(request);
                break;
            }
            dry.push(serves);
            parked.push_back(request);
            continue;
        }
        match &mut request.from {
            Requester::Local(local) => {
                wire.clear();
                for (job, task) in &tasks {
                    wire.push(WireTask::new(*job, task, source.environment(*job as usize))?);
                }
                ipc::reply(local, Answer::new(Response::Task, identity), &wire)?;
            }
            Requester::Remote {
                peer,
                request,
                gathered,
                ..
            } => {
                if let Some(remote) = remote.as_deref_mut() {
                    remote
                        .send(*peer, *request, std::mem::take(gathered))
                        .map_err(FleetError::Remote)?;
                }
            }
        }
        answered_to(client);
        answered += sent;
    }
    Ok((answered, asking))
}

/// The next ready task of an environment the worker `serves`, round robin over the jobs.
fn next_task(source: &mut dyn TaskSource, next_job: &mut usize, serves: &Serves) -> Option<(usize, Task)> {
    let n = source.jobs();
    for offset in 0..n {
        let job = (*next_job + offset) % n;
        if !serves.includes(&source.environment(job)) {
            continue;
        }
        if let Some(task) = source.ask(job) {
            *next_job = (job + 1) % n;
            return Some((job, task));
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::mpsc;

    #[test]
    fn a_wait_of_no_time_returns_at_once() {
        let run = RunName::new(&format!("t{}-zero-wait", std::process::id())).unwrap();
        let (done, returned) = mpsc::channel();
        // No notification ever comes: a wait that blocked would end only with the test process.
        let waiting = std::thread::spawn(move || {
            let node = ipc::node(&run, "zero-wait").unwrap();
            let services = ipc::open_services(&node).unwrap();
            let listener = services.to_learner.listener_builder().create().unwrap();
            wait(&listener, Duration::ZERO).unwrap();
            done.send(()).unwrap();
        });
        assert!(
            returned.recv_timeout(Duration::from_secs(60)).is_ok(),
            "a zero timeout waited for a notification"
        );
        waiting.join().unwrap();
    }
}
