//! The learner's side: [`Listener`] admits relays over Zenoh and is the fleet's [`Remote`].

use crate::net::{self, Admission, BUILD, Down, Hello, NET_PROTOCOL, NetError, NetOptions, Up, Welcome};
use crate::pump::{Bell, Pump};
use acps_fleet::{PeerId, Remote, RemoteEvent, RemoteServeError};
use acps_shared::{EnvironmentSpec, Serves, Task};
use acps_wire::ipc::RunName;
use acps_wire::wire::{PROTOCOL_VERSION, Sizes};
use std::collections::{HashMap, HashSet, VecDeque};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use zenoh::Wait as _;
use zenoh::qos::CongestionControl;
use zenoh::sample::SampleKind;

/// How long a starting learner listens for another learner of its run on the network.
const LEARNER_LOOKUP: Duration = Duration::from_millis(300);
/// How long the learner asks whether a relay whose token went has another one left.
const TOKEN_LOOKUP: Duration = Duration::from_millis(200);

/// A learner that could not listen.
#[derive(Debug, thiserror::Error)]
pub enum ListenError {
    /// A setting or the session.
    #[error(transparent)]
    Net(#[from] NetError),
    /// Another learner of the same run is on the network.
    #[error(
        "a learner of run '{run}' is already on the network ({other}); give this run another name, or wait for that learner to end"
    )]
    Taken {
        /// The run.
        run: RunName,
        /// The other learner's key.
        other: String,
    },
}

/// What the network callbacks hand to the serving thread.
enum Incoming {
    Up { peer: PeerId, message: Up },
    Gone { peer: PeerId },
}

/// A relay the learner admitted in the current serve.
struct Admitted {
    host: String,
    /// The admission's key, which the relay's messages must carry.
    key: u128,
    publisher: zenoh::pubsub::Publisher<'static>,
    traffic: Traffic,
}

/// Messages to and from one relay and what they carried, logged when it leaves: how well its
/// messages are batched.
#[derive(Default)]
struct Traffic {
    up: u64,
    outcomes: u64,
    down: u64,
    tasks: u64,
}

impl Traffic {
    fn log(&self, run: &RunName, host: &str) {
        let per = |items: u64, messages: u64| items as f64 / messages.max(1) as f64;
        tracing::info!(
            "run '{run}': the relay on {host} sent {} messages ({:.1} outcomes each) and was sent {} ({:.1} tasks each)",
            self.up,
            per(self.outcomes, self.up),
            self.down,
            per(self.tasks, self.down)
        );
    }
}

/// State shared with the network callbacks.
#[derive(Default)]
struct Shared {
    /// The serve in progress: identity and environments, `None` between serves.
    serving: Option<Serving>,
    /// Admitted relays by peer.
    admitted: HashMap<PeerId, Admitted>,
    /// Peers given up on (evicted, or gone), by their admission's key, and whether they were
    /// told so: a message of theirs is answered once with [`Down::Evicted`].
    dismissed: HashMap<PeerId, (u128, bool)>,
    /// Peers on whose channel a message with another key came, warned of once.
    posed: HashSet<PeerId>,
    /// Peers told the serve is done, until their token goes: the learner's process waits for
    /// them (a little) before it ends, so that the news reaches them before its token goes.
    told_done: HashSet<PeerId>,
    next_peer: PeerId,
    incoming: VecDeque<Incoming>,
    bell: Bell,
}

#[derive(Clone)]
struct Serving {
    identity: u64,
    environments: Vec<EnvironmentSpec>,
    sizes: Vec<Sizes>,
}

/// The learner's network side: listens on its endpoints, holds the run's learner token, answers
/// relays' hellos, and serves the admitted relays as peers of the fleet.
///
/// ```no_run
/// use acps_relay::{Listener, NetOptions, net::RelayKey};
/// use std::time::Duration;
///
/// // Made on the first run; each relay host gets a copy.
/// let (key, _made) = RelayKey::make_or_take("runs/cannon/relay.key".as_ref())?;
/// let options = NetOptions {
///     listen: vec!["tcp/10.0.0.1:7447".into()],
///     connect: vec![],
///     lease: Duration::from_secs(3),
///     config_file: None,
///     key: Some(key),
/// };
/// let mut listener = Listener::open(&"cannon".parse()?, &options)?;
/// // fleet.serve_with(&mut acps_fleet::Learners(&mut jobs), &mut observer, Some(&mut listener))
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct Listener {
    run: RunName,
    shared: Arc<Mutex<Shared>>,
    pump: Option<Pump>,
    // Undeclared on drop, before the session closes.
    _queryable: zenoh::query::Queryable<()>,
    _relays: zenoh::pubsub::Subscriber<()>,
    _up: zenoh::pubsub::Subscriber<()>,
    _token: zenoh::liveliness::LivelinessToken,
    session: zenoh::Session,
}

impl Listener {
    /// Listen for the relays of run `run` (its name) as `options` say. Refused when another
    /// learner of the run is on the network the session reaches.
    pub fn open(run: &RunName, options: &NetOptions) -> Result<Self, ListenError> {
        let session = net::open(options)?;
        let learner_key = net::key(run, "learner");
        let others = session
            .liveliness()
            .get(&learner_key)
            .timeout(LEARNER_LOOKUP)
            .wait()
            .map_err(|e| NetError::zenoh("looking for another learner of the run", e))?;
        if let Ok(reply) = others.recv()
            && let Ok(sample) = reply.result()
        {
            return Err(ListenError::Taken {
                run: run.clone(),
                other: sample.key_expr().to_string(),
            });
        }
        let token = session
            .liveliness()
            .declare_token(&learner_key)
            .wait()
            .map_err(|e| NetError::zenoh("declaring the learner's token", e))?;
        let host = net::host_name();
        let shared = Arc::new(Mutex::new(Shared {
            next_peer: 1,
            ..Shared::default()
        }));

        let up = {
            let shared = shared.clone();
            let prefix = net::key(run, "up/");
            session
                .declare_subscriber(net::key(run, "up/*"))
                .callback(move |sample| {
                    let Some(peer) = peer_of(sample.key_expr().as_str(), &prefix) else {
                        return;
                    };
                    match net::decode::<Up>(&sample.payload().to_bytes()) {
                        Ok(message) => queue(&shared, Incoming::Up { peer, message }),
                        Err(error) => tracing::warn!("a message of relay {peer} cannot be read: {error}"),
                    }
                })
                .wait()
                .map_err(|e| NetError::zenoh("subscribing to the relays' messages", e))?
        };
        let relays = {
            let shared = shared.clone();
            let prefix = net::key(run, "relay/");
            session
                .liveliness()
                .declare_subscriber(net::key(run, "relay/*"))
                .callback(move |sample| {
                    if sample.kind() == SampleKind::Delete
                        && let Some(peer) = peer_of(sample.key_expr().as_str(), &prefix)
                    {
                        lock(&shared).told_done.remove(&peer);
                        queue(&shared, Incoming::Gone { peer });
                    }
                })
                .wait()
                .map_err(|e| NetError::zenoh("watching the relays' tokens", e))?
        };
        let queryable = {
            let shared = shared.clone();
            let session = session.clone();
            let run = run.clone();
            session
                .clone()
                .declare_queryable("acps/hello/**")
                .callback(move |query| {
                    let asked = query.key_expr().as_str().strip_prefix("acps/hello/").unwrap_or_default().to_string();
                    let hello = query.payload().map(|p| net::decode::<Hello>(&p.to_bytes()));
                    let welcome = match hello {
                        Some(Ok(hello)) => welcome(&session, &shared, &run, &asked, &host, &hello),
                        Some(Err(error)) => Welcome::Refused {
                            run: run.clone(),
                            reason: format!("its greeting cannot be read ({error}): another acps build? (this learner runs acps {BUILD}, network protocol {NET_PROTOCOL})"),
                        },
                        None => Welcome::Refused {
                            run: run.clone(),
                            reason: "it sent no greeting".into(),
                        },
                    };
                    if let Ok(bytes) = net::encode(&welcome) {
                        let _ = query.reply(query.key_expr().clone(), bytes).wait();
                    }
                })
                .wait()
                .map_err(|e| NetError::zenoh("answering relays' greetings", e))?
        };
        Ok(Self {
            run: run.clone(),
            shared,
            pump: None,
            _queryable: queryable,
            _relays: relays,
            _up: up,
            _token: token,
            session,
        })
    }

    /// The run's name.
    pub fn run(&self) -> &RunName {
        &self.run
    }

    /// Whether a liveliness token of relay `peer` is still declared.
    fn token_lives(&self, peer: PeerId) -> bool {
        self.session
            .liveliness()
            .get(net::key(&self.run, &format!("relay/{peer}")))
            .timeout(TOKEN_LOOKUP)
            .wait()
            .is_ok_and(|replies| replies.recv().is_ok_and(|reply| reply.result().is_ok()))
    }

    fn tell(&self, peer: PeerId, message: &Down) {
        let mut shared = lock(&self.shared);
        if let Some(admitted) = shared.admitted.get_mut(&peer) {
            admitted.traffic.down += 1;
            if let Down::Tasks { tasks, .. } = message {
                admitted.traffic.tasks += tasks.len() as u64;
            }
            send(&admitted.publisher, message, peer);
        }
    }
}

/// How long an ending learner waits for the relays it told the run is done to leave.
const DRAIN: Duration = Duration::from_secs(2);

impl Drop for Listener {
    fn drop(&mut self) {
        self.finish(false);
        let since = std::time::Instant::now();
        while !lock(&self.shared).told_done.is_empty() && since.elapsed() < DRAIN {
            std::thread::sleep(Duration::from_millis(5));
        }
        let _ = self.session.close().wait();
    }
}

fn lock(shared: &Mutex<Shared>) -> std::sync::MutexGuard<'_, Shared> {
    // A callback that panicked leaves consistent state: every change is one statement.
    shared.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

fn queue(shared: &Mutex<Shared>, incoming: Incoming) {
    let mut shared = lock(shared);
    if shared.serving.is_none() {
        return;
    }
    shared.incoming.push_back(incoming);
    shared.bell.ring();
}

fn send(publisher: &zenoh::pubsub::Publisher<'static>, message: &Down, peer: PeerId) {
    match net::encode(message) {
        Ok(bytes) => {
            if let Err(error) = publisher.put(bytes).wait() {
                tracing::warn!("sending to relay {peer}: {error}");
            }
        }
        Err(error) => tracing::warn!("sending to relay {peer}: {error}"),
    }
}

/// The peer number at the end of `key` after `prefix`.
fn peer_of(key: &str, prefix: &str) -> Option<PeerId> {
    key.strip_prefix(prefix)?.parse().ok()
}

/// Answer a relay's hello to run `asked`: admit it, or say why not, naming both sides.
fn welcome(
    session: &zenoh::Session,
    shared: &Mutex<Shared>,
    run: &RunName,
    asked: &str,
    host: &str,
    hello: &Hello,
) -> Welcome {
    let relay = format!("relay on {} (PID {})", hello.host, hello.pid);
    let refused = |reason: String| {
        tracing::warn!("refused a {relay}: {reason}");
        Welcome::Refused {
            run: run.clone(),
            reason,
        }
    };
    if hello.net_protocol != NET_PROTOCOL || hello.build != BUILD || hello.wire_protocol != PROTOCOL_VERSION {
        return refused(format!(
            "it runs acps {} (network protocol {}, wire protocol {}), this learner acps {BUILD} (network protocol {NET_PROTOCOL}, wire protocol {PROTOCOL_VERSION}): run the same build on every host",
            hello.build, hello.net_protocol, hello.wire_protocol
        ));
    }
    if asked != run.as_str() && asked != "*" {
        // Another learner of the network may serve that run: only say which this one serves.
        return Welcome::Refused {
            run: run.clone(),
            reason: format!("it asked for run '{asked}', this learner serves run '{run}'"),
        };
    }
    let mut state = lock(shared);
    let Some(serving) = state.serving.clone() else {
        return Welcome::NotServing { run: run.clone() };
    };
    if hello.identity != 0 && hello.identity != serving.identity {
        drop(state);
        return refused(format!(
            "it asked for run identity {:016x}, run '{run}' has identity {:016x} (another configuration of the run)",
            hello.identity, serving.identity
        ));
    }
    let key = match acps_wire::secret::random_bytes::<16>() {
        Ok(bytes) => u128::from_le_bytes(bytes),
        Err(error) => {
            drop(state);
            return refused(format!("the learner could not make its key: {error}"));
        }
    };
    let peer = state.next_peer;
    state.next_peer += 1;
    let publisher = match session
        .declare_publisher(net::key(run, &format!("down/{peer}")))
        .congestion_control(CongestionControl::Block)
        .wait()
    {
        Ok(publisher) => publisher,
        Err(error) => {
            drop(state);
            return refused(format!("the learner could not open its channel to it: {error}"));
        }
    };
    state.admitted.insert(
        peer,
        Admitted {
            host: hello.host.clone(),
            key,
            publisher,
            traffic: Traffic::default(),
        },
    );
    tracing::info!("run '{run}': admitted the {relay} as peer {peer}");
    Welcome::Accepted(Admission {
        run: run.clone(),
        peer,
        key,
        identity: serving.identity,
        environments: serving.environments,
        sizes: serving.sizes,
        host: host.to_string(),
    })
}

impl Remote for Listener {
    fn start(
        &mut self,
        run: &RunName,
        identity: u64,
        environments: &[EnvironmentSpec],
        sizes: &[Sizes],
    ) -> Result<(), RemoteServeError> {
        let (pump, poke) = Pump::start(run, "learner-net").map_err(RemoteServeError::new)?;
        let mut shared = lock(&self.shared);
        shared.incoming.clear();
        shared.admitted.clear();
        shared.dismissed.clear();
        shared.posed.clear();
        shared.serving = Some(Serving {
            identity,
            environments: environments.to_vec(),
            sizes: sizes.to_vec(),
        });
        shared.bell = Bell::new(poke);
        drop(shared);
        self.pump = Some(pump);
        Ok(())
    }

    fn poll(&mut self, events: &mut Vec<RemoteEvent>) -> Result<(), RemoteServeError> {
        let mut shared = lock(&self.shared);
        shared.bell.awake();
        let mut evict = Vec::new();
        let mut gone = Vec::new();
        while let Some(incoming) = shared.incoming.pop_front() {
            match incoming {
                Incoming::Gone { peer } => {
                    if shared.admitted.contains_key(&peer) {
                        gone.push(peer);
                    }
                }
                Incoming::Up { peer, message } => {
                    let key = match &message {
                        Up::Request { key, .. } | Up::Note { key, .. } => *key,
                    };
                    let Some(admitted) = shared.admitted.get_mut(&peer).filter(|admitted| admitted.key == key) else {
                        let state = &mut *shared;
                        match state.dismissed.get_mut(&peer) {
                            // Given up on: told once to join again.
                            Some((dismissed, told)) if *dismissed == key && !*told => {
                                *told = true;
                                evict.push(peer);
                            }
                            // Another key on an admitted relay's channel: a relay of an earlier
                            // learner of the run that had the number, or a session posing as
                            // this relay. Either way not the relay's.
                            _ if state.admitted.contains_key(&peer) && state.posed.insert(peer) => {
                                tracing::warn!(
                                    "run '{}': a message on relay {peer}'s channel without its key was dropped (a relay of an earlier learner of the run, or another session posing as it); such messages are not reported again",
                                    self.run
                                );
                            }
                            _ => {}
                        }
                        continue;
                    };
                    match message {
                        Up::Note { text, .. } => {
                            tracing::warn!("run '{}': the relay on {}: {text}", self.run, admitted.host)
                        }
                        Up::Request {
                            request,
                            want,
                            serves,
                            workers,
                            slowest_rollout_us,
                            outcomes,
                            ..
                        } => {
                            admitted.traffic.up += 1;
                            admitted.traffic.outcomes += outcomes.len() as u64;
                            events.push(RemoteEvent::Request {
                                peer,
                                request,
                                want: (want as usize).min(net::MAX_NET_BATCH),
                                serves: serves.map_or(Serves::Any, Serves::One),
                                workers: workers as usize,
                                slowest_rollout: Duration::from_micros(slowest_rollout_us),
                                outcomes: outcomes.iter().map(net::NetOutcome::to_outcome).collect(),
                            })
                        }
                    }
                }
            }
        }
        drop(shared);
        for peer in gone {
            // Any admitted session may declare and drop a token of another relay's key: a relay
            // is gone when no token of its key is left. Asked without the lock, which the
            // callbacks that deliver the answer may need.
            if self.token_lives(peer) {
                continue;
            }
            let mut shared = lock(&self.shared);
            if let Some(admitted) = shared.admitted.remove(&peer) {
                shared.dismissed.insert(peer, (admitted.key, false));
                tracing::warn!(
                    "run '{}': the relay on {} (peer {peer}) is gone",
                    self.run,
                    admitted.host
                );
                admitted.traffic.log(&self.run, &admitted.host);
                events.push(RemoteEvent::Gone { peer });
            }
        }
        for peer in evict {
            // Its publisher is gone with it: answer on a fresh one.
            if let Ok(publisher) = self
                .session
                .declare_publisher(net::key(&self.run, &format!("down/{peer}")))
                .wait()
            {
                send(
                    &publisher,
                    &Down::Evicted {
                        reason: "the learner does not know this relay (it was given up on): join again".into(),
                    },
                    peer,
                );
            }
        }
        Ok(())
    }

    fn send(&mut self, peer: PeerId, request: u64, tasks: Vec<(u32, Task)>) -> Result<(), RemoteServeError> {
        self.tell(peer, &Down::Tasks { request, tasks });
        Ok(())
    }

    fn evict(&mut self, peer: PeerId, silent: Duration) {
        self.tell(
            peer,
            &Down::Evicted {
                reason: format!("it held tasks and sent nothing for {silent:?}"),
            },
        );
        let mut shared = lock(&self.shared);
        if let Some(admitted) = shared.admitted.remove(&peer) {
            admitted.traffic.log(&self.run, &admitted.host);
            shared.dismissed.insert(peer, (admitted.key, true));
        }
    }

    fn finish(&mut self, done: bool) {
        let mut shared = lock(&self.shared);
        if done {
            let peers: Vec<PeerId> = shared.admitted.keys().copied().collect();
            for peer in &peers {
                send(&shared.admitted[peer].publisher, &Down::Done, *peer);
            }
            shared.told_done.extend(peers);
        }
        shared.serving = None;
        for admitted in std::mem::take(&mut shared.admitted).into_values() {
            admitted.traffic.log(&self.run, &admitted.host);
        }
        shared.incoming.clear();
        shared.bell = Bell::default();
        drop(shared);
        // Joins the pump thread, whose node must be gone before the fleet removes the run.
        self.pump = None;
    }

    fn may_wait(&mut self) -> bool {
        let mut shared = lock(&self.shared);
        let queued = shared.incoming.len();
        shared.bell.may_sleep(queued)
    }
}
