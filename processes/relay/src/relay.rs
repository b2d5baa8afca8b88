//! The relay's side: one process per remote host. To the host's workers it is their learner (a
//! [`Fleet`] serving a [`TaskSource`] of the tasks it fetched); to the learner it is one peer
//! that asks for tasks in batches on behalf of all of them and returns their outcomes.

use crate::net::{self, Admission, BUILD, Down, Hello, NET_PROTOCOL, NetError, NetOptions, NetOutcome, Up, Welcome};
use crate::pump::{Bell, Pump, PumpStartError};
use acps_fleet::{
    Fleet, FleetError, FleetProgress, ForwardError, ForwardingSource, Interrupted, LearningProgress, ObserveError,
    Observer, TaskSource,
};
use acps_shared::{EnvironmentSpec, Outcome, Serves, Task};
use acps_wire::ipc::RunName;
use acps_wire::wire::{PROTOCOL_VERSION, Sizes, check_task_sizes};
use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::Wait as _;
use zenoh::qos::CongestionControl;
use zenoh::sample::SampleKind;

/// How long one hello waits for answers.
const HELLO_TIMEOUT: Duration = Duration::from_secs(2);
/// How often a relay asks again while no learner answers or the learner is between serves.
const HELLO_RETRY: Duration = Duration::from_millis(100);
/// Outcomes wait at most this long for more to share their message (or a request to ride on): a
/// message wakes threads at both ends, which on 2 cores took the CPU the workers needed.
const OUTCOMES_WAIT: Duration = Duration::from_millis(3);
/// A relay asks in batches of what its workers take in this long (within [`MIN_BATCH`] and
/// [`net::MAX_NET_BATCH`]): asking for each task its workers took made messages of a few tasks
/// each way, and a fixed batch sized for cheap tasks hoarded slow ones at one relay.
const BATCH_TIME: Duration = Duration::from_millis(5);
/// The smallest batch, also the queue of a relay whose workers took nothing yet.
const MIN_BATCH: usize = 16;
/// The round trip to the learner assumed until one is measured.
const FIRST_ROUND_TRIP: Duration = Duration::from_millis(1);
/// How often the rate at which the workers take tasks is measured.
const RATE_WINDOW: Duration = Duration::from_millis(5);

/// How a relay behaves.
#[derive(Debug, Clone)]
pub struct RelayOptions {
    /// Where the learner listens (`connect`), the lease and the Zenoh configuration file.
    pub net: NetOptions,
    /// The run to join; `None`: whichever the learner serves.
    pub run: Option<RunName>,
    /// The run identity to join; 0: any.
    pub identity: u64,
    /// How long to wait for the learner when the relay starts.
    pub startup_timeout: Duration,
    /// How long to wait for the learner to come back (a resumed run) once it vanished mid-run.
    pub wait_for_learner: Duration,
    /// Most tasks kept asked for or queued beyond those the workers hold.
    pub queue: usize,
}

/// Why a relay stopped.
#[derive(Debug, thiserror::Error)]
pub enum RelayError {
    /// A setting or the session.
    #[error(transparent)]
    Net(#[from] NetError),
    /// No learner answered in time.
    #[error(
        "no learner{} answered at {endpoints} within {waited:?}: is it started with --listen on that address, and does this relay present its credentials (a copy of its relay.key, or the same user and password settings)?",
        run.as_ref().map_or(String::new(), |run| format!(" of run '{run}'"))
    )]
    NoLearner {
        /// The run asked for.
        run: Option<RunName>,
        /// Where.
        endpoints: String,
        /// How long the relay waited.
        waited: Duration,
    },
    /// The learner refused the relay.
    #[error(
        "the learner of run '{}' refused this relay: {reason}",
        run.as_ref().map_or("?", RunName::as_str)
    )]
    Refused {
        /// The learner's run; `None`: its answer could not be read.
        run: Option<RunName>,
        /// Why.
        reason: String,
    },
    /// Several learners answered.
    #[error("several learners answer ({0}): choose one with --run")]
    Ambiguous(String),
    /// The learner vanished and did not come back in time.
    #[error("the learner of run '{run}' is gone and did not come back within {waited:?}")]
    LearnerGone {
        /// The run.
        run: RunName,
        /// How long the relay waited.
        waited: Duration,
    },
    /// Serving the host's workers failed.
    #[error(transparent)]
    Fleet(#[from] FleetError),
    /// The thread that wakes the host's fleet when the learner's messages arrive did not start.
    #[error("starting the relay's wake-up thread")]
    Wake(#[source] PumpStartError),
}

/// What a relay did.
#[derive(Debug, Clone, PartialEq)]
pub struct RelayReport {
    /// The run it served.
    pub run: RunName,
    /// Serves it took part in (experiments of the run, and rejoins).
    pub serves: usize,
    /// Outcomes it forwarded.
    pub outcomes: u64,
}

/// The learner's presence as the relay's liveliness subscriber sees it.
const UNKNOWN: u8 = 0;
const PRESENT: u8 = 1;
const GONE: u8 = 2;

/// Serve this host's workers from the learner that `options` name, through `fleet` (the host's
/// local run: its workers, its Ctrl-C), until the learner's run is over (its process ended after
/// its last serve), Ctrl-C, or an error. `observer` sees the local fleet's progress.
pub fn serve(
    fleet: &mut Fleet,
    options: &RelayOptions,
    observer: &mut dyn Observer,
) -> Result<RelayReport, RelayError> {
    let session = net::open(&options.net)?;
    let endpoints = options.net.connect.join(", ");
    // Once it joined a run.
    let mut joined: Option<RelayReport> = None;
    let learner = Arc::new(AtomicU8::new(UNKNOWN));
    let mut watch = None;
    let mut deadline = Instant::now() + options.startup_timeout;
    // Whether the last serve ended because the learner served every job: its token's going then
    // means the run is over, not a crash.
    let mut finished = false;
    loop {
        let welcome = match hello(&session, options, joined.as_ref().map(|report| &report.run))? {
            Greeted::Accepted(welcome) => welcome,
            Greeted::Wait(run) => {
                if fleet.interrupted() {
                    return Err(FleetError::Interrupted.into());
                }
                // The learner's run ended once its token is gone after it served.
                if finished
                    && learner.load(Ordering::Relaxed) == GONE
                    && run.is_none()
                    && let Some(report) = joined
                {
                    return Ok(report);
                }
                if Instant::now() >= deadline {
                    return Err(match &joined {
                        None => RelayError::NoLearner {
                            run: options.run.clone(),
                            endpoints,
                            waited: options.startup_timeout,
                        },
                        Some(report) => RelayError::LearnerGone {
                            run: report.run.clone(),
                            waited: options.wait_for_learner,
                        },
                    });
                }
                std::thread::sleep(HELLO_RETRY);
                continue;
            }
        };
        if watch.is_none() {
            watch = Some(watch_learner(&session, &welcome.run, learner.clone())?);
        }
        // It answered: it is there, whatever its token's news in flight says.
        learner.store(PRESENT, Ordering::Relaxed);
        let report = joined.get_or_insert_with(|| {
            tracing::info!(
                "relay: joined run '{}' of the learner on {} as peer {}",
                welcome.run,
                welcome.host,
                welcome.peer
            );
            RelayReport {
                run: welcome.run.clone(),
                serves: 0,
                outcomes: 0,
            }
        });
        report.serves += 1;
        let mut source = RelaySource::new(&session, welcome, learner.clone(), options.queue, fleet.run())?;
        let mut watching = Watching {
            observer,
            status: source.status.clone(),
        };
        let served = fleet.serve_forwarded(&mut source, &mut watching);
        report.outcomes += source.forwarded;
        source.flush_now();
        drop(source);
        finished = served.is_ok();
        match served {
            // The experiment is over; the learner may serve another, or end.
            Ok(_) => deadline = Instant::now() + options.wait_for_learner.max(options.startup_timeout),
            Err(FleetError::Source(error @ ForwardError::Evicted { .. })) => {
                tracing::warn!("relay: {error}; joining again");
                deadline = Instant::now() + options.wait_for_learner;
            }
            Err(FleetError::Source(error @ ForwardError::LearnerGone { .. })) => {
                tracing::warn!(
                    "relay: {}; waiting up to {:?} for it to come back",
                    error,
                    options.wait_for_learner
                );
                deadline = Instant::now() + options.wait_for_learner;
            }
            Err(error) => return Err(error.into()),
        }
    }
}

/// A hello's result: admitted, or wait and ask again (`Some(run)`: that learner is between
/// serves; `None`: no learner answered).
enum Greeted {
    Accepted(Admission),
    Wait(Option<RunName>),
}

/// Greet the learner(s) the session reaches, for the run `joined` once the relay joined one.
fn hello(session: &zenoh::Session, options: &RelayOptions, joined: Option<&RunName>) -> Result<Greeted, RelayError> {
    let run = joined.or(options.run.as_ref());
    let greeting = Hello {
        net_protocol: NET_PROTOCOL,
        wire_protocol: PROTOCOL_VERSION,
        build: BUILD.to_string(),
        run: run.map(RunName::to_string).unwrap_or_default(),
        identity: options.identity,
        host: net::host_name(),
        pid: std::process::id(),
    };
    let key = net::hello_key(run);
    let replies = session
        .get(&key)
        .payload(net::encode(&greeting).map_err(|e| NetError::zenoh("greeting the learner", e))?)
        .consolidation(zenoh::query::ConsolidationMode::None)
        .timeout(HELLO_TIMEOUT)
        .wait()
        .map_err(|e| NetError::zenoh("greeting the learner", e))?;
    let mut accepted = Vec::new();
    let mut refusals = Vec::new();
    let mut waiting = None;
    while let Ok(reply) = replies.recv() {
        let Ok(sample) = reply.result() else { continue };
        match net::decode::<Welcome>(&sample.payload().to_bytes()) {
            Ok(Welcome::Accepted(admission)) => accepted.push(admission),
            Ok(Welcome::NotServing { run }) => waiting = Some(run),
            Ok(Welcome::Refused { run, reason }) => refusals.push((Some(run), reason)),
            Err(error) => refusals.push((
                None,
                format!("its answer cannot be read ({error}): another acps build? (this relay runs acps {BUILD}, network protocol {NET_PROTOCOL})"),
            )),
        }
    }
    match accepted.len() {
        0 => {}
        1 => return Ok(Greeted::Accepted(accepted.remove(0))),
        _ => {
            let learners: Vec<String> = accepted
                .iter()
                .map(|a| format!("run '{}' on {}", a.run, a.host))
                .collect();
            return Err(RelayError::Ambiguous(learners.join(", ")));
        }
    }
    if waiting.is_some() {
        return Ok(Greeted::Wait(waiting));
    }
    // A refusal of the run asked for is final; a learner serving another run only says so.
    if let Some((run, reason)) = refusals
        .iter()
        .find(|(learner, _)| run.is_none_or(|run| Some(run) == learner.as_ref()))
        .or(refusals.first())
    {
        return Err(RelayError::Refused {
            run: run.clone(),
            reason: reason.clone(),
        });
    }
    Ok(Greeted::Wait(None))
}

/// Follow the learner's token of `run` into `learner`.
fn watch_learner(
    session: &zenoh::Session,
    run: &RunName,
    learner: Arc<AtomicU8>,
) -> Result<zenoh::pubsub::Subscriber<()>, NetError> {
    session
        .liveliness()
        .declare_subscriber(net::key(run, "learner"))
        .history(true)
        .callback(move |sample| {
            let state = if sample.kind() == SampleKind::Delete {
                GONE
            } else {
                PRESENT
            };
            learner.store(state, Ordering::Relaxed);
        })
        .wait()
        .map_err(|e| NetError::zenoh("watching the learner's token", e))
}

/// What the local fleet reports that the relay forwards: its workers and their slowest rollout.
#[derive(Debug, Clone, Copy, Default)]
struct Status {
    workers: usize,
    slowest_rollout: Duration,
}

/// The caller's observer, and a copy of the status for the source.
struct Watching<'a> {
    observer: &'a mut dyn Observer,
    status: Arc<Mutex<Status>>,
}

impl Observer for Watching<'_> {
    fn progress(&mut self, progress: &FleetProgress) {
        if let Ok(mut status) = self.status.lock() {
            *status = Status {
                workers: progress.workers,
                slowest_rollout: progress.slowest_rollout,
            };
        }
        self.observer.progress(progress);
    }
}

/// What the network callbacks hand to the serving thread.
struct Inbox {
    messages: VecDeque<Down>,
    bell: Bell,
}

/// The tasks a relay fetched from its learner, served to the host's workers.
struct RelaySource {
    run: RunName,
    /// This admission's key, which every message to the learner carries.
    key: u128,
    identity: u64,
    environments: Vec<EnvironmentSpec>,
    sizes: Vec<Sizes>,
    queues: Vec<VecDeque<Task>>,
    queued: usize,
    /// Tasks the host's workers hold, to re-issue locally when one of them dies.
    held: HashMap<(u32, u64), Task>,
    /// Requests sent and not answered: what they serve, how many tasks they asked for, and when.
    requests: HashMap<u64, (Serves, usize, Instant)>,
    pace: Pace,
    next_request: u64,
    /// What the host's workers asked for.
    classes: Vec<Serves>,
    outgoing: Vec<NetOutcome>,
    /// When the oldest of `outgoing` was told.
    outgoing_since: Option<Instant>,
    notes: Vec<String>,
    done: bool,
    forwarded: u64,
    max_queue: usize,
    learner: Arc<AtomicU8>,
    status: Arc<Mutex<Status>>,
    inbox: Arc<Mutex<Inbox>>,
    // Dropped in this order: the pump's node before the fleet's run goes.
    _pump: Pump,
    publisher: zenoh::pubsub::Publisher<'static>,
    _down: zenoh::pubsub::Subscriber<()>,
    _token: zenoh::liveliness::LivelinessToken,
}

/// How many tasks a relay keeps asked for or queued: what its workers take in two round trips
/// to the learner, and one batch more. One round trip's worth hides the wait for an answer; the
/// second and the batch let a relay whose workers ran dry (the rate it measures is then what it
/// got) ask for more than it got, and recover. Deeper would hold back tasks that the learner,
/// whose tasks in flight are bounded, could give elsewhere, and delay the outcomes its jobs
/// wait for.
struct Pace {
    /// Tasks the workers took since `since`.
    taken: usize,
    since: Instant,
    /// Tasks per second the workers take (moving average).
    rate: f64,
    /// Seconds from a request to its answer (moving average).
    round_trip: f64,
}

impl Pace {
    fn new(now: Instant) -> Self {
        Self {
            taken: 0,
            since: now,
            rate: 0.0,
            round_trip: FIRST_ROUND_TRIP.as_secs_f64(),
        }
    }

    /// The request sent at `sent` was answered at `now`.
    fn answered(&mut self, sent: Instant, now: Instant) {
        self.round_trip += ((now - sent).as_secs_f64() - self.round_trip) / 8.0;
    }

    /// The tasks the workers take in [`BATCH_TIME`], within [`MIN_BATCH`]..=[`net::MAX_NET_BATCH`].
    fn batch(&self) -> usize {
        ((self.rate * BATCH_TIME.as_secs_f64()) as usize).clamp(MIN_BATCH, net::MAX_NET_BATCH)
    }

    fn target(&mut self, now: Instant) -> usize {
        let elapsed = now - self.since;
        if elapsed >= RATE_WINDOW {
            self.rate += (self.taken as f64 / elapsed.as_secs_f64() - self.rate) / 4.0;
            (self.taken, self.since) = (0, now);
        }
        (2.0 * self.rate * self.round_trip) as usize + self.batch()
    }
}

impl RelaySource {
    fn new(
        session: &zenoh::Session,
        welcome: Admission,
        learner: Arc<AtomicU8>,
        max_queue: usize,
        local: &RunName,
    ) -> Result<Self, RelayError> {
        let run = welcome.run;
        let (pump, poke) = Pump::start(local, "relay-net").map_err(RelayError::Wake)?;
        let inbox = Arc::new(Mutex::new(Inbox {
            messages: VecDeque::new(),
            bell: Bell::new(poke),
        }));
        let peer = welcome.peer;
        let down = {
            let inbox = inbox.clone();
            session
                .declare_subscriber(net::key(&run, &format!("down/{peer}")))
                .callback(move |sample| match net::decode::<Down>(&sample.payload().to_bytes()) {
                    Ok(message) => {
                        let mut inbox = inbox.lock().unwrap_or_else(|p| p.into_inner());
                        inbox.messages.push_back(message);
                        inbox.bell.ring();
                    }
                    Err(error) => tracing::warn!("a message of the learner cannot be read: {error}"),
                })
                .wait()
                .map_err(|e| NetError::zenoh("subscribing to the learner's messages", e))?
        };
        let publisher = session
            .declare_publisher(net::key(&run, &format!("up/{peer}")))
            .congestion_control(CongestionControl::Block)
            .wait()
            .map_err(|e| NetError::zenoh("opening the channel to the learner", e))?;
        let token = session
            .liveliness()
            .declare_token(net::key(&run, &format!("relay/{peer}")))
            .wait()
            .map_err(|e| NetError::zenoh("declaring the relay's token", e))?;
        let jobs = welcome.environments.len();
        Ok(Self {
            run,
            key: welcome.key,
            identity: welcome.identity,
            environments: welcome.environments,
            sizes: welcome.sizes,
            queues: vec![VecDeque::new(); jobs],
            queued: 0,
            held: HashMap::new(),
            requests: HashMap::new(),
            pace: Pace::new(Instant::now()),
            next_request: 1,
            classes: Vec::new(),
            outgoing: Vec::new(),
            outgoing_since: None,
            notes: Vec::new(),
            done: false,
            forwarded: 0,
            max_queue,
            learner,
            status: Arc::new(Mutex::new(Status::default())),
            inbox,
            _pump: pump,
            publisher,
            _down: down,
            _token: token,
        })
    }

    /// Tasks asked for or queued that a worker serving `class` could take.
    fn supply(&self, class: &Serves) -> usize {
        let asked: usize = self
            .requests
            .values()
            .filter(|(serves, _, _)| serves == class)
            .map(|(_, want, _)| want)
            .sum();
        let queued = match class {
            Serves::Any => self.queued,
            Serves::One(spec) => self
                .queues
                .iter()
                .zip(&self.environments)
                .filter(|(_, environment)| *environment == spec)
                .map(|(queue, _)| queue.len())
                .sum(),
        };
        asked + queued
    }

    /// Send a request for `want` tasks of `class` (0: outcomes only) with the outcomes held.
    fn send(&mut self, want: usize, class: Serves) -> Result<(), ForwardError> {
        let status = *self.status.lock().unwrap_or_else(|p| p.into_inner());
        let request = self.next_request;
        self.next_request += 1;
        if want > 0 {
            self.requests.insert(request, (class, want, Instant::now()));
        }
        let message = Up::Request {
            key: self.key,
            request,
            want: want as u32,
            serves: match class {
                Serves::One(spec) => Some(spec),
                Serves::Any => None,
            },
            workers: status.workers as u32,
            slowest_rollout_us: status.slowest_rollout.as_micros().try_into().unwrap_or(u64::MAX),
            outcomes: std::mem::take(&mut self.outgoing),
        };
        self.outgoing_since = None;
        let bytes = net::encode(&message).map_err(|e| ForwardError::Link(e.into()))?;
        self.publisher.put(bytes).wait().map_err(ForwardError::Link)
    }

    /// Send the outcomes held, if any (at the end of a serve).
    fn flush_now(&mut self) {
        if !self.outgoing.is_empty() {
            let _ = self.send(0, Serves::Any);
        }
    }

    fn take(&mut self, message: Down) -> Result<(), ForwardError> {
        match message {
            Down::Tasks { request, tasks } => {
                if let Some((_, _, sent)) = self.requests.remove(&request) {
                    self.pace.answered(sent, Instant::now());
                }
                for (job, task) in tasks {
                    let Some(queue) = self.queues.get_mut(job as usize) else {
                        return Err(ForwardError::Link(
                            format!(
                                "the learner sent a task of job {job}, it has {} jobs",
                                self.environments.len()
                            )
                            .into(),
                        ));
                    };
                    check_task_sizes(task.context.len(), task.theta.len()).map_err(|e| ForwardError::Link(e.into()))?;
                    queue.push_back(task);
                    self.queued += 1;
                }
            }
            Down::Done => self.done = true,
            Down::Evicted { reason } => {
                return Err(ForwardError::Evicted {
                    run: self.run.clone(),
                    reason,
                });
            }
        }
        Ok(())
    }
}

impl Drop for RelaySource {
    fn drop(&mut self) {
        // The pump thread ends once no callback can poke it: its sender goes first.
        self.inbox.lock().unwrap_or_else(|p| p.into_inner()).bell = Bell::default();
    }
}

impl RelaySource {
    /// [`TaskSource::tell`]: an outcome of a task this relay holds, sent on to the learner.
    fn forward(&mut self, job: usize, outcome: Outcome) -> bool {
        let key = (job as u32, outcome.task_id);
        if self.held.remove(&key).is_none() {
            // Re-issued here after its worker was given up on, and not handed out again yet.
            let Some(queue) = self.queues.get_mut(job) else {
                return false;
            };
            let Some(at) = queue.iter().position(|task| task.id == outcome.task_id) else {
                return false;
            };
            queue.remove(at);
            self.queued -= 1;
        }
        self.outgoing_since.get_or_insert_with(Instant::now);
        self.outgoing.push(NetOutcome::new(key.0, &outcome));
        self.forwarded += 1;
        true
    }
}

impl TaskSource for RelaySource {
    fn jobs(&self) -> usize {
        self.environments.len()
    }

    fn environment(&self, job: usize) -> EnvironmentSpec {
        self.environments[job]
    }

    fn sizes(&self, job: usize) -> Sizes {
        self.sizes[job]
    }

    fn identity(&self) -> u64 {
        self.identity
    }

    fn ask(&mut self, job: usize) -> Option<Task> {
        let task = self.queues[job].pop_front()?;
        self.queued -= 1;
        self.pace.taken += 1;
        self.held.insert((job as u32, task.id), task.clone());
        Some(task)
    }

    /// Outcomes go to the learner, whose updates a relay's Ctrl-C does not stop.
    fn tell(&mut self, job: usize, outcome: Outcome, _: &dyn Fn() -> bool) -> Result<bool, Interrupted> {
        Ok(self.forward(job, outcome))
    }

    fn reissue(&mut self, job: usize, task_id: u64) -> bool {
        match self.held.remove(&(job as u32, task_id)) {
            Some(task) => {
                self.queues[job].push_front(task);
                self.queued += 1;
                true
            }
            None => false,
        }
    }

    fn jobs_done(&self) -> usize {
        if self.done { self.jobs() } else { 0 }
    }

    /// The learning happens at the remote learner.
    fn learning(&self) -> LearningProgress {
        LearningProgress::default()
    }

    /// No learner here to show.
    fn told(&mut self, _: usize, _: &mut dyn Observer) -> Result<(), ObserveError> {
        Ok(())
    }
}

impl ForwardingSource for RelaySource {
    fn starved(&mut self, serves: &Serves, _want: usize) {
        if !self.classes.contains(serves) {
            self.classes.push(*serves);
        }
    }

    fn refused(&mut self, reason: &str) {
        self.notes.push(format!("refused one of its workers: {reason}"));
    }

    fn pass(&mut self, idle: bool) -> Result<bool, ForwardError> {
        if self.learner.load(Ordering::Relaxed) == GONE {
            return Err(ForwardError::LearnerGone { run: self.run.clone() });
        }
        let messages = {
            let mut inbox = self.inbox.lock().unwrap_or_else(|p| p.into_inner());
            inbox.bell.awake();
            std::mem::take(&mut inbox.messages)
        };
        let arrived = !messages.is_empty();
        for message in messages {
            self.take(message)?;
        }
        for text in std::mem::take(&mut self.notes) {
            let note = Up::Note { key: self.key, text };
            let bytes = net::encode(&note).map_err(|e| ForwardError::Link(e.into()))?;
            self.publisher.put(bytes).wait().map_err(ForwardError::Link)?;
        }
        let target = self.pace.target(Instant::now()).min(self.max_queue.max(1));
        // Asking at half the target makes messages of about half of it.
        let ask_at = (target / 2).clamp(1, self.pace.batch());
        for class in self.classes.clone() {
            let lacking = target.saturating_sub(self.supply(&class));
            if lacking >= ask_at {
                self.send(lacking.min(net::MAX_NET_BATCH), class)?;
            }
        }
        // Outcomes ride on the next request, or go alone once a message is full, the oldest has
        // waited OUTCOMES_WAIT, or the workers hold nothing more (no outcome will join them).
        let waited = self
            .outgoing_since
            .is_some_and(|since| since.elapsed() >= OUTCOMES_WAIT);
        let due = self.outgoing.len() >= net::MAX_NET_BATCH || waited || (idle && self.held.is_empty());
        if !self.outgoing.is_empty() && due {
            self.send(0, Serves::Any)?;
        }
        Ok(arrived)
    }

    fn wait_at_most(&self) -> Option<Duration> {
        self.outgoing_since
            .map(|since| OUTCOMES_WAIT.saturating_sub(since.elapsed()))
    }

    fn may_wait(&mut self) -> bool {
        let mut inbox = self.inbox.lock().unwrap_or_else(|p| p.into_inner());
        let queued = inbox.messages.len();
        inbox.bell.may_sleep(queued)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pace fed `windows` windows in which the workers take `per_ms` tasks per millisecond and
    /// each answer takes `round_trip`.
    fn paced(pace: &mut Pace, now: &mut Instant, windows: usize, per_ms: usize, round_trip: Duration) {
        for _ in 0..windows {
            let sent = *now;
            *now += RATE_WINDOW;
            pace.taken += per_ms * RATE_WINDOW.as_millis() as usize;
            pace.answered(sent + RATE_WINDOW - round_trip, sent + RATE_WINDOW);
            pace.target(*now);
        }
    }

    #[test]
    fn a_relay_keeps_what_its_workers_take_in_two_round_trips_and_one_batch() {
        let start = Instant::now();
        let mut pace = Pace::new(start);
        assert_eq!(pace.target(start), MIN_BATCH, "nothing taken yet");
        let mut now = start;
        // Cheap tasks, 100 per millisecond, and answers that take 2 ms: full batches.
        paced(&mut pace, &mut now, 200, 100, Duration::from_millis(2));
        assert_eq!(pace.batch(), net::MAX_NET_BATCH);
        let expected = 2.0 * 100_000.0 * 0.002 + net::MAX_NET_BATCH as f64;
        let target = pace.target(now) as f64;
        assert!(
            (target - expected).abs() < 0.01 * expected,
            "{target} against {expected}"
        );
        // 6 tasks per millisecond: a batch is what they take in BATCH_TIME.
        paced(&mut pace, &mut now, 200, 6, Duration::from_millis(2));
        assert!((29..=30).contains(&pace.batch()), "{}", pace.batch());
        // Slow tasks, one per millisecond: the smallest batch, not 128 tasks hoarded here.
        paced(&mut pace, &mut now, 200, 1, Duration::from_millis(2));
        assert_eq!(pace.batch(), MIN_BATCH);
        assert!(pace.target(now) <= MIN_BATCH + 4, "{}", pace.target(now));
        // Workers that stop taking: the target falls back to the smallest batch.
        paced(&mut pace, &mut now, 200, 0, Duration::from_millis(2));
        assert_eq!(pace.target(now), MIN_BATCH);
        // A window not yet over leaves the estimate alone.
        pace.taken += 1_000_000;
        assert_eq!(pace.target(now + RATE_WINDOW / 2), MIN_BATCH);
    }
}
