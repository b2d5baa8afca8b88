//! The iceoryx2 plumbing both sides of a fleet share: one prefix per run (so runs never see each
//! other's resources), one function that opens every service with the same limits (whoever
//! creates a service fixes its QoS), and stale-resource cleanup.
//!
//! Services of a run:
//! - `tasks`: request-response; the learner is the only server, every worker a client. A request
//!   carries the outcomes of tasks the worker performed, its response up to as many new tasks
//!   as it asks for (workers pull work).
//! - `to-learner`: event; workers wake the learner after sending requests.
//! - `to-workers`: event; the learner wakes workers after answering.

use crate::wire::{Answer, MAX_BATCH, WireTask, WorkerMessage};
use iceoryx2::node::{NodeCreationFailure, NodeListFailure};
use iceoryx2::port::client::RequestSendError;
use iceoryx2::port::listener::{ListenerCreateError, ListenerWaitError};
use iceoryx2::port::notifier::{NotifierCreateError, NotifierNotifyError};
use iceoryx2::port::{LoanError, ReceiveError, SendError};
use iceoryx2::prelude::*;
use iceoryx2::service::builder::event::EventOpenOrCreateError;
use iceoryx2::service::builder::request_response::RequestResponseOpenOrCreateError;
use iceoryx2::service::port_factory::client::ClientCreateError;
use iceoryx2::service::port_factory::server::ServerCreateError;
use std::path::Path;
use std::time::Duration;

/// Most workers one run serves.
pub const MAX_WORKERS: usize = 128;
/// Most tasks one worker keeps in flight.
pub const MAX_IN_FLIGHT_PER_WORKER: usize = 128;
/// A worker's queue unless set: the tasks it keeps asked for or queued (the Rust and Python
/// workers and `acps run --worker-queue-depth` alike).
pub const DEFAULT_QUEUE_DEPTH: usize = 4;
/// Most requests one worker has waiting for tasks; one more may only deliver outcomes. The
/// learner pays for every request channel of every worker whenever it loans an answer
/// (iceoryx2 looks for returned chunks on each), so there are few: batches fill them.
pub const MAX_ASKING_REQUESTS: usize = 8;

/// The task service.
pub type TaskService =
    iceoryx2::service::port_factory::request_response::PortFactory<ipc::Service, WorkerMessage, (), [WireTask], Answer>;
/// The learner's end of the task service.
pub type TaskServer = iceoryx2::port::server::Server<ipc::Service, WorkerMessage, (), [WireTask], Answer>;
/// A worker's request as the learner holds it until it answers.
pub type TaskRequest = iceoryx2::active_request::ActiveRequest<ipc::Service, WorkerMessage, (), [WireTask], Answer>;
/// A worker's request waiting for its answer.
pub type PendingTasks =
    iceoryx2::pending_response::PendingResponse<ipc::Service, WorkerMessage, (), [WireTask], Answer>;
/// An event service.
pub type EventService = iceoryx2::service::port_factory::event::PortFactory<ipc::Service>;

/// An iceoryx2 operation of a run that failed: the object and the operation, named as iceoryx2
/// names its errors, with iceoryx2's error as the source.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum IpcError {
    /// A node name iceoryx2 refuses: empty, longer than [`MAX_NODE_NAME`], or not ASCII.
    #[error("node name: must be 1 to {MAX_NODE_NAME} ASCII characters other than NUL, got {got}")]
    NodeNameInvalid {
        /// The name as the message shows it: quoted, or its length when it is too long to show.
        got: String,
    },
    /// A file of the run could not be made its owner's alone (another user created it?).
    #[error("making {path} of run '{run}' accessible to its owner only: {reason} (did another user create it?)")]
    Restrict {
        /// The file.
        path: std::path::PathBuf,
        /// The run.
        run: RunName,
        /// The system's reason.
        reason: String,
    },
    /// The run's shared memory belongs to another user, who alone may write there.
    #[error(
        "creating node '{node}' of run '{run}': the run's shared memory belongs to user {owner}, who alone may use it; run this process as that user (this one runs as user {user})"
    )]
    OtherUser {
        /// The node's name.
        node: String,
        /// The run.
        run: RunName,
        /// The user who owns the run's files.
        owner: u32,
        /// This process's user.
        user: u32,
    },
    /// This user's directory of iceoryx2's files ([`iceoryx2_root`]) cannot be made, or is not
    /// a directory of this user's alone.
    #[error("iceoryx2's directory {} for run '{run}': {reason}", path.display())]
    Root {
        /// The directory.
        path: std::path::PathBuf,
        /// The run.
        run: RunName,
        /// Why it cannot be used.
        reason: String,
    },
    /// iceoryx2 could not create the process's node of the run (permissions, resources).
    #[error("creating node '{node}' of run '{run}'")]
    NodeCreate {
        /// The node's name.
        node: String,
        /// The run.
        run: RunName,
        /// iceoryx2's error.
        #[source]
        source: NodeCreationFailure,
    },
    /// Listing the run's nodes failed on every attempt: nodes of runs were created or removed
    /// while each read the shared node directory, or it cannot be read.
    #[error("listing the nodes of run '{run}'")]
    NodeList {
        /// The run.
        run: RunName,
        /// iceoryx2's error of the last attempt.
        #[source]
        source: NodeListFailure,
    },
    /// The run's task service could not be opened or created; the message says why in words,
    /// as iceoryx2's reasons name its internals.
    #[error("opening the task service ({})", OpenFailure::of_task_service(source).words())]
    TaskServiceOpen {
        /// iceoryx2's error.
        #[source]
        source: RequestResponseOpenOrCreateError,
    },
    /// An event service of the run could not be opened or created; the message says why in
    /// words.
    #[error("opening the event service '{service}' ({})", OpenFailure::of_event_service(source).words())]
    EventServiceOpen {
        /// The service's name.
        service: &'static str,
        /// iceoryx2's error.
        #[source]
        source: EventOpenOrCreateError,
    },
    /// The run's task server could not be created, other than because another learner holds it
    /// ([`ServerError::Taken`]).
    #[error("serving run '{run}'")]
    ServerCreate {
        /// The run.
        run: RunName,
        /// iceoryx2's error.
        #[source]
        source: ServerCreateError,
    },
    /// A worker's task client could not be created (the service has its most clients).
    #[error("creating the worker's client")]
    ClientCreate(#[source] ClientCreateError),
    /// A notifier of an event service could not be created (the service has its most notifiers).
    #[error("creating {owner}'s notifier")]
    NotifierCreate {
        /// Whose: "the learner", "the worker", ...
        owner: &'static str,
        /// iceoryx2's error.
        #[source]
        source: NotifierCreateError,
    },
    /// A listener of an event service could not be created (the service has its most listeners).
    #[error("creating {owner}'s listener")]
    ListenerCreate {
        /// Whose: "the learner", "the worker", ...
        owner: &'static str,
        /// iceoryx2's error.
        #[source]
        source: ListenerCreateError,
    },
    /// A worker's request could not be sent (its active requests are all in use, or the
    /// connection broke).
    #[error("sending a request")]
    RequestSend(#[source] RequestSendError),
    /// The learner could not receive a worker's request.
    #[error("receiving a request")]
    RequestReceive(#[source] ReceiveError),
    /// No memory for an answer: more tasks than an answer holds, or every chunk in use.
    #[error("loaning an answer")]
    AnswerLoan(#[source] LoanError),
    /// An answer could not be sent (the worker's connection broke).
    #[error("answering a request")]
    AnswerSend(#[source] SendError),
    /// A worker could not receive its answer.
    #[error("receiving a response")]
    ResponseReceive(#[source] ReceiveError),
    /// A notification could not be sent.
    #[error("waking {whom}")]
    NotifierNotify {
        /// Who was to be woken: "the learner", "a worker", ...
        whom: &'static str,
        /// iceoryx2's error.
        #[source]
        source: NotifierNotifyError,
    },
    /// Waiting on a listener failed other than by a signal.
    #[error("waiting for {whom}")]
    ListenerWait {
        /// Who was waited for: "the learner", "workers".
        whom: &'static str,
        /// iceoryx2's error.
        #[source]
        source: ListenerWaitError,
    },
    /// A run's files cannot be removed while a node of the run is alive.
    #[error("removing the files of run '{run}': {alive} node(s) still alive")]
    RunFilesRemove {
        /// The run.
        run: RunName,
        /// Its live nodes.
        alive: usize,
    },
}

/// The environment variable that names the run a started worker process joins.
pub const RUN_ENV: &str = "ACPS_RUN";

/// The node name of a run's learner; no worker may take it.
pub const LEARNER_NODE: &str = "learner";

/// The longest node name iceoryx2 takes (its `MAX_NODE_NAME_LENGTH`).
pub const MAX_NODE_NAME: usize = 128;

/// What a worker's name may be, as messages state it. Stricter than iceoryx2, which takes any
/// ASCII but NUL: the name appears in log lines and node listings.
pub const WORKER_NAMES: &str =
    "1 to 128 characters of ASCII letters, digits, '-', '_' and '.', other than 'learner' (the learner's node)";

/// A worker name that is none of [`WORKER_NAMES`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("must be {WORKER_NAMES}, got {got}")]
pub struct WorkerNameError {
    /// The name as the message shows it: quoted, or its length when it is too long to show.
    pub got: String,
}

/// Refuse a worker name that is none of [`WORKER_NAMES`].
pub fn check_worker_name(name: &str) -> Result<(), WorkerNameError> {
    let valid = (1..=MAX_NODE_NAME).contains(&name.len())
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.'))
        && name != LEARNER_NODE;
    if valid {
        Ok(())
    } else {
        Err(WorkerNameError { got: shown(name) })
    }
}

/// A node name as a message shows it: quoted (escaped), or only its length when it is longer than
/// a node name can be.
fn shown(name: &str) -> String {
    let characters = name.chars().count();
    if characters > MAX_NODE_NAME {
        format!("{characters} characters")
    } else {
        format!("{name:?}")
    }
}

/// The settings every process opens a run's services with: whoever creates a service fixes them,
/// and iceoryx2 refuses an opener that asks for more (docs/PROTOCOL.md lists them).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ServiceLimits {
    /// Most nodes of a service: every worker and the learner, with room for a few tools.
    pub nodes: usize,
    /// Most requests of one client the task service holds: the asking ones and one delivery.
    pub active_requests_per_client: usize,
    /// Answers one request may have waiting.
    pub response_buffer: usize,
    /// Requests one client may have loaned at once.
    pub loaned_requests: usize,
    /// How long a process waits for another to finish creating a service of the run (iceoryx2
    /// waits 1 s by default; a loaded machine starting many processes at once can take longer,
    /// and only a creator that died makes everyone wait the whole time).
    pub creation_timeout: Duration,
}

/// The limits of every run.
pub const LIMITS: ServiceLimits = ServiceLimits {
    nodes: MAX_WORKERS + 8,
    active_requests_per_client: MAX_ASKING_REQUESTS + 1,
    response_buffer: 2,
    loaned_requests: 2,
    creation_timeout: Duration::from_secs(10),
};

/// What the files of every acps run start with.
const PREFIX: &str = "acps_";

/// A run's name: it names the run's shared-memory prefix, and workers join a run by it. Parsed
/// once where it comes in (the command line, [`RUN_ENV`], a network message), it travels as this
/// type, so no other part validates it again.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct RunName(String);

/// A run name that is not 1 to 40 characters of letters, digits and '-'.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("run name: '{got}' must be 1 to 40 characters of letters, digits and '-'")]
pub struct RunNameParseError {
    /// The refused name.
    pub got: String,
}

impl RunName {
    /// A validated run name: 1 to 40 characters of `[A-Za-z0-9-]`. No `_`: the run's files are
    /// named `acps_<run>_...`, so a name without one can be read back from any of them (see
    /// [`clean_dead_runs`]).
    pub fn new(name: &str) -> Result<Self, RunNameParseError> {
        let valid = (1..=40).contains(&name.len()) && name.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'-');
        if valid {
            Ok(Self(name.to_string()))
        } else {
            Err(RunNameParseError { got: name.to_string() })
        }
    }

    /// The run a file of `/dev/shm` or [`iceoryx2_root`] belongs to, if it is an acps run's.
    fn of_file(file: &str) -> Option<Self> {
        let rest = file.strip_prefix(PREFIX)?;
        let (name, _) = rest.split_once('_')?;
        Self::new(name).ok()
    }

    /// The run named by the [`RUN_ENV`] environment variable, which a fleet sets for the
    /// worker processes it starts; `None` when it is not set.
    pub fn from_env() -> Result<Option<Self>, RunNameParseError> {
        std::env::var(RUN_ENV).ok().map(|name| Self::new(&name)).transpose()
    }

    /// The name.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// The iceoryx2 file prefix of the run's resources in /dev/shm and [`iceoryx2_root`].
    pub fn prefix(&self) -> String {
        format!("{PREFIX}{}_", self.0)
    }

    /// The iceoryx2 configuration of the run: its prefix, in this user's [`iceoryx2_root`].
    pub fn config(&self) -> Config {
        let mut config = Config::default();
        config.global.prefix =
            FileName::new(self.prefix().as_bytes()).expect("a run name's prefix is a short file name of [A-Za-z0-9_-]");
        let root = iceoryx2_root();
        config.global.set_root_path(
            &iceoryx2::prelude::Path::new(root.as_os_str().as_encoded_bytes())
                .expect("/tmp/acps-iceoryx2-<uid>/ is a short absolute path"),
        );
        config.global.creation_timeout = LIMITS.creation_timeout;
        config
    }
}

impl std::str::FromStr for RunName {
    type Err = RunNameParseError;

    fn from_str(name: &str) -> Result<Self, Self::Err> {
        Self::new(name)
    }
}

/// As a string: a network message carries it so.
impl serde::Serialize for RunName {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(&self.0)
    }
}

/// Parsed on the way in: a message that names no valid run does not decode.
impl<'de> serde::Deserialize<'de> for RunName {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let name = String::deserialize(deserializer)?;
        Self::new(&name).map_err(serde::de::Error::custom)
    }
}

impl std::fmt::Display for RunName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// The services of one run, opened with the limits every side agrees on.
pub struct Services {
    /// Request-response: workers request, the learner answers with tasks.
    pub tasks: TaskService,
    /// Workers notify the learner.
    pub to_learner: EventService,
    /// The learner notifies workers.
    pub to_workers: EventService,
}

/// Quiet iceoryx2's own log down to errors unless `IOX2_LOG_LEVEL` asks for more: its
/// warnings (such as "no config file was loaded") say nothing an acps user can act on. For
/// programs (the `acps` binary), not libraries: the level is process-wide.
pub fn quiet_iceoryx2_log() {
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
}

/// This user's directory of iceoryx2's node and service files, `/tmp/acps-iceoryx2-<uid>/`.
/// iceoryx2's default, `/tmp/iceoryx2`, is one directory for every user, which only the user
/// who made it first may write in: no other user could run acps on the machine. The Python
/// worker (`acps_worker/_ipc.py`) names the same.
pub fn iceoryx2_root() -> std::path::PathBuf {
    format!("/tmp/acps-iceoryx2-{}/", crate::secret::current_user()).into()
}

/// Make this user's [`iceoryx2_root`] if it is missing, accessible to its owner only, or
/// refuse one that is not a directory of this user's (another user could read or fill it).
fn own_root(run: &RunName) -> Result<(), IpcError> {
    use std::os::unix::fs::{DirBuilderExt as _, MetadataExt as _, PermissionsExt as _};
    let root = iceoryx2_root();
    let refused = |reason: String| IpcError::Root {
        path: root.clone(),
        run: run.clone(),
        reason,
    };
    match std::fs::DirBuilder::new().mode(0o700).create(&root) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
        Err(e) => return Err(refused(e.to_string())),
    }
    let metadata = std::fs::symlink_metadata(&root).map_err(|e| refused(e.to_string()))?;
    let user = crate::secret::current_user();
    if !metadata.is_dir() {
        return Err(refused("it is not a directory; remove it".into()));
    }
    if metadata.uid() != user {
        return Err(refused(format!(
            "it belongs to user {}, not to this process's user {user}; remove it",
            metadata.uid()
        )));
    }
    if metadata.mode() & 0o077 != 0 {
        std::fs::set_permissions(&root, std::fs::Permissions::from_mode(0o700)).map_err(|e| refused(e.to_string()))?;
    }
    Ok(())
}

/// A node of `run` named `name`. Signal handling stays with the host program (library code must
/// not swallow SIGINT/SIGTERM).
pub fn node(run: &RunName, name: &str) -> Result<Node<ipc::Service>, IpcError> {
    let node = node_with(run, name, &run.config())?;
    owner_only(run)?;
    Ok(node)
}

/// Take every access but the owner's from the run's files in /dev/shm. iceoryx2 makes the
/// segment that numbers a run's nodes (`..._node.0_10_0.global_mgmt`) writable by every user,
/// whatever the umask: another user who wrote into it would make every new worker of the run
/// fail. A file of the run that this user cannot restrict (another user made it) is an error.
fn owner_only(run: &RunName) -> Result<(), IpcError> {
    use std::os::unix::fs::PermissionsExt;
    for entry in shm_entries(run) {
        let path = entry.path();
        let restrict = |path: &std::path::Path| -> std::io::Result<()> {
            let mode = std::fs::metadata(path)?.permissions().mode();
            if mode & 0o077 != 0 {
                std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode & 0o700))?;
            }
            Ok(())
        };
        match restrict(&path) {
            Ok(()) => {}
            // Removed since it was listed: a node or port that went away.
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(error) => {
                return Err(IpcError::Restrict {
                    path,
                    run: run.clone(),
                    reason: error.to_string(),
                });
            }
        }
    }
    Ok(())
}

/// A worker's node of `run`, like [`node`], that leaves looking for dead nodes to the learner.
/// iceoryx2 looks when a node is created or dropped and whenever it opens a service, and each
/// look reads the files of every node of the run (50-80 us per node): 128 workers that start
/// or leave together spent seconds of CPU on them (docs/FLEET.md#oversubscription). The learner
/// cleans up when it starts, on its looks for dead workers, and at the end of the run.
pub fn worker_node(run: &RunName, name: &str) -> Result<Node<ipc::Service>, IpcError> {
    let mut config = run.config();
    config.global.node.cleanup_dead_nodes_on_creation = false;
    config.global.node.cleanup_dead_nodes_on_destruction = false;
    config.global.service.cleanup_dead_nodes_on_open = false;
    node_with(run, name, &config)
}

fn node_with(run: &RunName, name: &str, config: &Config) -> Result<Node<ipc::Service>, IpcError> {
    let node_name = NodeName::new(name).map_err(|_| IpcError::NodeNameInvalid { got: shown(name) })?;
    // /dev/shm is every user's: a run of this name there may be another user's, whose nodes
    // are in that user's iceoryx2 directory, where this process would never find them.
    let user = crate::secret::current_user();
    if let Some(owner) = shm_owners(run).into_iter().find(|&owner| owner != user) {
        return Err(IpcError::OtherUser {
            node: name.to_string(),
            run: run.clone(),
            owner,
            user,
        });
    }
    own_root(run)?;
    NodeBuilder::new()
        .name(&node_name)
        .config(config)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|source| IpcError::NodeCreate {
            node: name.to_string(),
            run: run.clone(),
            source,
        })
}

/// The owners of `run`'s files in /dev/shm.
fn shm_owners(run: &RunName) -> Vec<u32> {
    use std::os::unix::fs::MetadataExt as _;
    shm_entries(run)
        .iter()
        .filter_map(|entry| entry.metadata().ok().map(|m| m.uid()))
        .collect()
}

/// `run`'s files in /dev/shm (none when it cannot be read).
fn shm_entries(run: &RunName) -> Vec<std::fs::DirEntry> {
    let prefix = run.prefix();
    let Ok(entries) = std::fs::read_dir("/dev/shm") else {
        return Vec::new();
    };
    entries
        .flatten()
        .filter(|entry| entry.file_name().to_string_lossy().starts_with(&prefix))
        .collect()
}

/// Why a process could not open a service of its run, in words: iceoryx2's reasons name its
/// internals.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum OpenFailure {
    /// Still in creation after [`ServiceLimits::creation_timeout`].
    DiedCreating,
    /// Gone between creating and opening it, or with files missing.
    Incomplete,
    /// Being created or removed by another process at this moment.
    InFlux,
    /// Opened by as many processes as it takes.
    Full,
    /// Created by another user.
    Permissions,
    /// Created with other types or settings.
    OtherBuild,
    /// Anything else.
    Other,
}

impl OpenFailure {
    fn words(self) -> String {
        match self {
            Self::DiedCreating => "a process of this run died while creating it".into(),
            Self::Incomplete => {
                "it was removed while this process opened it, or has files missing: a process of this run died while creating it, or the run was ending".into()
            }
            Self::InFlux => "other processes of this run were creating or removing it at the same moment".into(),
            Self::Full => format!("it already serves the most processes a run has ({})", LIMITS.nodes),
            Self::Permissions => "another user's process created it".into(),
            Self::OtherBuild => "a process of another acps build created it with other types or settings".into(),
            Self::Other => "iceoryx2 failed".into(),
        }
    }

    fn of_task_service(error: &RequestResponseOpenOrCreateError) -> Self {
        use iceoryx2::service::builder::request_response::{
            RequestResponseCreateError as Create, RequestResponseOpenError as Open,
            RequestResponseOpenOrCreateError as Either,
        };
        match error {
            Either::RequestResponseOpenError(Open::HangsInCreation)
            | Either::RequestResponseCreateError(Create::HangsInCreation) => Self::DiedCreating,
            Either::RequestResponseOpenError(Open::DoesNotExist | Open::ServiceInCorruptedState)
            | Either::RequestResponseCreateError(Create::ServiceInCorruptedState) => Self::Incomplete,
            Either::SystemInFlux
            | Either::RequestResponseOpenError(Open::IsMarkedForDestruction)
            | Either::RequestResponseCreateError(Create::IsBeingCreatedByAnotherInstance) => Self::InFlux,
            Either::RequestResponseOpenError(Open::ExceedsMaxNumberOfNodes) => Self::Full,
            Either::RequestResponseOpenError(Open::InsufficientPermissions)
            | Either::RequestResponseCreateError(Create::InsufficientPermissions) => Self::Permissions,
            Either::RequestResponseOpenError(
                Open::IncompatibleRequestOrResponseType
                | Open::IncompatibleAttributes
                | Open::IncompatibleMessagingPattern
                | Open::IncompatibleOverflowBehaviorForRequests
                | Open::IncompatibleOverflowBehaviorForResponses
                | Open::IncompatibleBehaviorForFireAndForgetRequests
                | Open::DoesNotSupportRequestedAmountOfClientRequestLoans
                | Open::DoesNotSupportRequestedAmountOfActiveRequestsPerClient
                | Open::DoesNotSupportRequestedResponseBufferSize
                | Open::DoesNotSupportRequestedAmountOfServers
                | Open::DoesNotSupportRequestedAmountOfClients
                | Open::DoesNotSupportRequestedAmountOfNodes
                | Open::DoesNotSupportRequestedAmountOfBorrowedResponsesPerPendingResponse
                | Open::VersionMismatch,
            ) => Self::OtherBuild,
            _ => Self::Other,
        }
    }

    fn of_event_service(error: &EventOpenOrCreateError) -> Self {
        use iceoryx2::service::builder::event::{
            EventCreateError as Create, EventOpenError as Open, EventOpenOrCreateError as Either,
        };
        match error {
            Either::EventOpenError(Open::HangsInCreation) => Self::DiedCreating,
            Either::EventOpenError(Open::DoesNotExist | Open::ServiceInCorruptedState)
            | Either::EventCreateError(Create::ServiceInCorruptedState) => Self::Incomplete,
            Either::SystemInFlux
            | Either::EventOpenError(Open::IsMarkedForDestruction)
            | Either::EventCreateError(Create::IsBeingCreatedByAnotherInstance) => Self::InFlux,
            Either::EventOpenError(Open::ExceedsMaxNumberOfNodes) => Self::Full,
            Either::EventOpenError(Open::InsufficientPermissions)
            | Either::EventCreateError(Create::InsufficientPermissions) => Self::Permissions,
            Either::EventOpenError(
                Open::IncompatibleMessagingPattern
                | Open::IncompatibleAttributes
                | Open::IncompatibleDeadline
                | Open::IncompatibleNotifierCreatedEvent
                | Open::IncompatibleNotifierDroppedEvent
                | Open::IncompatibleNotifierDeadEvent
                | Open::DoesNotSupportRequestedAmountOfNotifiers
                | Open::DoesNotSupportRequestedAmountOfListeners
                | Open::DoesNotSupportRequestedMaxEventId
                | Open::DoesNotSupportRequestedAmountOfNodes
                | Open::VersionMismatch,
            ) => Self::OtherBuild,
            _ => Self::Other,
        }
    }
}

/// Open (or create) every service of the run on `node`.
pub fn open_services(node: &Node<ipc::Service>) -> Result<Services, IpcError> {
    let nodes = LIMITS.nodes;
    let service_name = |name: &str| ServiceName::new(name).expect("the run's service names are short ASCII");
    let tasks = node
        .service_builder(&service_name("tasks"))
        .request_response::<WorkerMessage, [WireTask]>()
        .response_user_header::<Answer>()
        .max_servers(1)
        .max_clients(MAX_WORKERS)
        .max_nodes(nodes)
        .max_active_requests_per_client(LIMITS.active_requests_per_client)
        .max_response_buffer_size(LIMITS.response_buffer)
        .max_loaned_requests(LIMITS.loaned_requests)
        .open_or_create()
        .map_err(|source| IpcError::TaskServiceOpen { source })?;
    let event = |service: &'static str| {
        node.service_builder(&service_name(service))
            .event()
            .max_listeners(nodes)
            .max_notifiers(nodes)
            .max_nodes(nodes)
            .open_or_create()
            .map_err(|source| IpcError::EventServiceOpen { service, source })
    };
    Ok(Services {
        tasks,
        to_learner: event("to-learner")?,
        to_workers: event("to-workers")?,
    })
}

/// Why a process could not serve a run's tasks.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ServerError {
    /// Another process serves the run: a learner of the same run name.
    #[error(
        "a learner of run '{run}' is already running{}; give this run another name, or wait for that learner to end",
        pid.map_or(String::new(), |pid| format!(" (PID {pid})"))
    )]
    Taken {
        /// The run.
        run: RunName,
        /// The process of the learner that serves it, when iceoryx2 can tell.
        pid: Option<i32>,
    },
    /// iceoryx2 failed otherwise.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// The run's secret could not be made or written for its workers.
    #[error(transparent)]
    Secret(#[from] crate::secret::SecretError),
}

/// The server of `run`'s task service: its learner, the only one. Answers are sized to their
/// tasks, up to [`MAX_BATCH`]. Refused with [`ServerError::Taken`] while a live process serves
/// the run; the server of a dead one is cleaned up first.
pub fn task_server(run: &RunName, tasks: &TaskService) -> Result<TaskServer, ServerError> {
    let create = || tasks.server_builder().initial_max_slice_len(MAX_BATCH).create();
    let mut created = create();
    if matches!(created, Err(ServerCreateError::ExceedsMaxSupportedServers))
        && !server_pid(tasks).is_some_and(process_runs)
    {
        // The server of a learner that died, which no cleanup has removed yet.
        tasks.try_cleanup_dead_nodes();
        created = create();
    }
    created.map_err(|e| match e {
        ServerCreateError::ExceedsMaxSupportedServers => ServerError::Taken {
            run: run.clone(),
            pid: server_pid(tasks),
        },
        source => IpcError::ServerCreate {
            run: run.clone(),
            source,
        }
        .into(),
    })
}

/// The process of the task service's server, if it has one and iceoryx2 can tell.
fn server_pid(tasks: &TaskService) -> Option<i32> {
    let mut pid = None;
    tasks.dynamic_config().list_servers(|server| {
        pid = server.node_id.pid::<ipc::Service>().ok().map(|pid| pid.value());
        CallbackProgression::Stop
    });
    pid
}

/// Answer `request` with `tasks` (none for `Stop` and `Refused`), written straight into shared
/// memory.
pub fn reply(request: &TaskRequest, answer: Answer, tasks: &[WireTask]) -> Result<(), IpcError> {
    let mut response = request
        .loan_slice_uninit(tasks.len())
        .map_err(IpcError::AnswerLoan)?
        .write_from_slice(tasks);
    *response.user_header_mut() = answer;
    response.send().map_err(IpcError::AnswerSend)
}

/// Remove what dead processes of `run` left behind (crashed learners or workers). Returns the
/// number of dead nodes cleaned up.
pub fn clean_stale(run: &RunName) -> Result<usize, IpcError> {
    let cleaned = list_nodes(run, 0, |cleaned, state| {
        if let NodeState::Dead(view) = state
            && view.try_remove_stale_resources().is_ok()
        {
            *cleaned += 1;
        }
    })?;
    remove_orphaned_node_dirs(&nodes_dir(), ORPHAN_AGE);
    Ok(cleaned)
}

/// Attempts at listing a run's nodes: a listing fails when a node of any run is created or
/// removed while it reads the shared node directory, which concurrent runs do all the time.
const LIST_ATTEMPTS: usize = 50;

/// Visit the nodes of `run`, starting from `initial` each attempt; retried while the listing
/// fails.
fn list_nodes<T: Clone>(
    run: &RunName,
    initial: T,
    mut visit: impl FnMut(&mut T, NodeState<ipc::Service>),
) -> Result<T, IpcError> {
    let config = run.config();
    let mut attempt = 0;
    loop {
        let mut value = initial.clone();
        let listed = Node::<ipc::Service>::list(&config, |state| {
            visit(&mut value, state);
            CallbackProgression::Continue
        });
        attempt += 1;
        match listed {
            Ok(()) => return Ok(value),
            Err(source) if attempt == LIST_ATTEMPTS => {
                return Err(IpcError::NodeList {
                    run: run.clone(),
                    source,
                });
            }
            Err(_) => std::thread::sleep(Duration::from_millis(1)),
        }
    }
}

/// Where iceoryx2 keeps a directory per node, `<id>/`, holding files named by the run's prefix.
fn nodes_dir() -> std::path::PathBuf {
    iceoryx2_root().join("nodes")
}

/// An empty node directory older than this is an orphan: iceoryx2 fills a node's directory as
/// it creates the node, within microseconds.
const ORPHAN_AGE: Duration = Duration::from_secs(1);

/// Remove the empty node directories in `nodes` that are older than `age`. Concurrent runs that
/// create and remove nodes at the same moment occasionally leave a node's directory behind
/// empty; it names no run, so whichever run starts next removes it.
fn remove_orphaned_node_dirs(nodes: &Path, age: Duration) {
    let Ok(entries) = std::fs::read_dir(nodes) else { return };
    for entry in entries.flatten() {
        let path = entry.path();
        let old = entry
            .metadata()
            .and_then(|m| m.modified())
            .is_ok_and(|modified| modified.elapsed().is_ok_and(|elapsed| elapsed > age));
        if old && path.is_dir() {
            // Fails, and leaves it, unless the directory is empty.
            let _ = std::fs::remove_dir(&path);
        }
    }
}

/// Ids of the live nodes of `run`. A port whose node is not among them belongs to a dead
/// process, whether or not iceoryx2's cleanup of that node has succeeded (a cleanup interrupted
/// by a concurrent one can leave a dead node's ports listed).
pub fn alive_nodes(run: &RunName) -> Result<std::collections::HashSet<iceoryx2::identifiers::UniqueNodeId>, IpcError> {
    use iceoryx2::node::NodeView;
    list_nodes(run, std::collections::HashSet::new(), |alive, state| {
        if let NodeState::Alive(view) = state {
            alive.insert(*view.id());
        }
    })
}

/// Number of live nodes of `run`.
pub fn live_nodes(run: &RunName) -> Result<usize, IpcError> {
    list_nodes(run, 0, |alive, state| {
        if let NodeState::Alive(_) = state {
            *alive += 1;
        }
    })
}

/// Files of `run` in /dev/shm and this user's [`iceoryx2_root`] (recursively).
pub fn leftover_files(run: &RunName) -> Vec<std::path::PathBuf> {
    let prefix = run.prefix();
    acps_files()
        .into_iter()
        .filter(|(name, _)| name.starts_with(&prefix))
        .map(|(_, path)| path)
        .collect()
}

/// Every file of any acps run in /dev/shm and this user's [`iceoryx2_root`] (recursively), with
/// its name.
fn acps_files() -> Vec<(String, std::path::PathBuf)> {
    let mut found = Vec::new();
    let mut stack = vec![std::path::PathBuf::from("/dev/shm"), iceoryx2_root()];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else { continue };
        for entry in entries.flatten() {
            let path = entry.path();
            let name = entry.file_name().to_string_lossy().into_owned();
            if name.starts_with(PREFIX) {
                found.push((name, path));
            } else if path.is_dir() {
                stack.push(path);
            }
        }
    }
    found
}

/// A run whose files are younger than this and that has no node yet may be starting: iceoryx2
/// creates a run's first files and its first node within milliseconds.
const STARTING_AGE: Duration = Duration::from_secs(2);

/// Remove everything that runs whose every node is dead left in /dev/shm and this user's
/// [`iceoryx2_root`], whatever their names: after a `kill -9` of a learner and its workers
/// nothing else would ever remove it. A run with a live node, a node in creation, or no node
/// and files younger than a few seconds (a run that is starting) is left alone. Returns the runs
/// cleaned.
pub fn clean_dead_runs() -> Vec<RunName> {
    let mut runs: std::collections::BTreeMap<String, (RunName, bool)> = std::collections::BTreeMap::new();
    for (name, path) in acps_files() {
        let Some(run) = RunName::of_file(&name) else { continue };
        let young = std::fs::metadata(&path)
            .and_then(|m| m.modified())
            .map_or(true, |modified| {
                modified.elapsed().map_or(true, |age| age < STARTING_AGE)
            });
        runs.entry(run.as_str().to_string())
            .and_modify(|(_, any_young)| *any_young |= young)
            .or_insert((run, young));
    }
    let mut cleaned = Vec::new();
    for (_, (run, young)) in runs {
        let Ok(nodes) = node_states(&run) else { continue };
        let dead = nodes.dead > 0 && nodes.other == 0;
        let abandoned = nodes.dead == 0 && nodes.other == 0 && !young;
        if (dead || abandoned) && remove_run_files(&run).is_ok() {
            cleaned.push(run);
        }
    }
    cleaned
}

/// Whether process `pid` runs: it exists and is no zombie (a killed process whose parent has not
/// reaped it, or whose new parent never will, is gone).
pub fn process_runs(pid: i32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|stat| {
        // "pid (comm) state ...": comm may hold spaces and parentheses, so read after the last ')'.
        stat.rsplit_once(')')
            .is_some_and(|(_, rest)| !rest.trim_start().starts_with(['Z', 'X']))
    })
}

/// How many nodes of a run are dead, and how many are alive or in an undefined state (being
/// created or removed). A node iceoryx2 reports dead whose process still exists counts as
/// alive: a node in creation has no lock on its monitor yet, nor its details.
#[derive(Clone)]
struct NodeStates {
    dead: usize,
    other: usize,
}

fn node_states(run: &RunName) -> Result<NodeStates, IpcError> {
    list_nodes(run, NodeStates { dead: 0, other: 0 }, |states, state| {
        use iceoryx2::node::NodeView;
        match state {
            NodeState::Dead(view)
                if view
                    .details()
                    .as_ref()
                    .is_some_and(|details| !process_runs(details.process_id().value())) =>
            {
                states.dead += 1
            }
            _ => states.other += 1,
        }
    })
}

/// After the last node of a run is gone: clean stale nodes, then remove the files iceoryx2 keeps
/// on purpose (one 16-byte management file per prefix) and anything a crash left. Refuses while
/// a node of the run is alive.
pub fn remove_run_files(run: &RunName) -> Result<usize, IpcError> {
    clean_stale(run)?;
    let alive = live_nodes(run)?;
    if alive > 0 {
        return Err(IpcError::RunFilesRemove {
            run: run.clone(),
            alive,
        });
    }
    let files = leftover_files(run);
    let count = files.len();
    let nodes = nodes_dir();
    for path in files {
        let _ = if path.is_dir() {
            std::fs::remove_dir_all(&path)
        } else {
            std::fs::remove_file(&path)
        };
        // A node's directory holds only its run's files; the emptied one goes too.
        if let Some(parent) = path.parent().filter(|parent| parent.parent() == Some(nodes.as_path())) {
            let _ = std::fs::remove_dir(parent);
        }
    }
    Ok(count)
}

/// How long blocking waits last before a liveness check.
pub const TICK: Duration = Duration::from_millis(50);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_names_are_validated() {
        assert_eq!(RunName::new("grid-1").unwrap().prefix(), "acps_grid-1_");
        assert_eq!("grid-1".parse::<RunName>().unwrap().as_str(), "grid-1");
        for bad in ["", "a/b", "with space", "a_b", &"x".repeat(41)] {
            let error = bad.parse::<RunName>().unwrap_err();
            assert_eq!(error, RunNameParseError { got: bad.to_string() });
            assert_eq!(
                error.to_string(),
                format!("run name: '{bad}' must be 1 to 40 characters of letters, digits and '-'")
            );
        }
    }

    #[test]
    fn a_run_name_crosses_the_network_as_its_string_and_is_parsed_on_the_way_in() {
        let run = RunName::new("grid-1").unwrap();
        let json = serde_json::to_string(&run).unwrap();
        assert_eq!(json, serde_json::to_string("grid-1").unwrap());
        assert_eq!(serde_json::from_str::<RunName>(&json).unwrap(), run);
        let error = serde_json::from_str::<RunName>("\"a b\"").unwrap_err().to_string();
        assert!(error.contains("must be 1 to 40 characters"), "{error}");
    }

    #[test]
    fn worker_names_are_checked_and_a_refusal_says_what_names_may_be() {
        assert_eq!(MAX_NODE_NAME, NodeName::max_len());
        let long = "x".repeat(MAX_NODE_NAME);
        for good in ["w0", "worker-12", "host.thread_1", long.as_str(), "learners"] {
            assert_eq!(check_worker_name(good), Ok(()), "{good}");
        }
        let cases = [
            ("", "got \"\""),
            ("a/b", "got \"a/b\""),
            ("with space", "got \"with space\""),
            ("é", "got \"é\""),
            ("tab\t", "got \"tab\\t\""),
            (LEARNER_NODE, "got \"learner\""),
            (&"x".repeat(MAX_NODE_NAME + 1), "got 129 characters"),
            (&"x".repeat(300), "got 300 characters"),
        ];
        for (bad, got) in cases {
            let error = check_worker_name(bad).unwrap_err().to_string();
            assert_eq!(error, format!("must be {WORKER_NAMES}, {got}"), "{bad:?}");
        }
    }

    #[test]
    fn node_names_iceoryx2_refuses_are_refused_in_words() {
        let run = RunName::new(&format!("test-node-name-{}", std::process::id())).unwrap();
        for (bad, got) in [("é", "got \"é\""), (&"x".repeat(300), "got 300 characters")] {
            let error = node(&run, bad).expect_err("refused").to_string();
            assert_eq!(
                error,
                format!("node name: must be 1 to 128 ASCII characters other than NUL, {got}")
            );
        }
        assert!(leftover_files(&run).is_empty());
    }

    #[test]
    fn failures_to_open_a_service_say_what_happened() {
        use iceoryx2::service::builder::event::{EventOpenError, EventOpenOrCreateError};
        use iceoryx2::service::builder::request_response::{
            RequestResponseCreateError, RequestResponseOpenError as Open, RequestResponseOpenOrCreateError as Either,
        };
        let tasks = [
            (
                Either::RequestResponseOpenError(Open::HangsInCreation),
                OpenFailure::DiedCreating,
            ),
            // A worker killed while it created the run's services.
            (
                Either::RequestResponseOpenError(Open::DoesNotExist),
                OpenFailure::Incomplete,
            ),
            (
                Either::RequestResponseOpenError(Open::ServiceInCorruptedState),
                OpenFailure::Incomplete,
            ),
            (
                Either::RequestResponseOpenError(Open::IsMarkedForDestruction),
                OpenFailure::InFlux,
            ),
            (Either::SystemInFlux, OpenFailure::InFlux),
            (
                Either::RequestResponseOpenError(Open::ExceedsMaxNumberOfNodes),
                OpenFailure::Full,
            ),
            (
                Either::RequestResponseOpenError(Open::InsufficientPermissions),
                OpenFailure::Permissions,
            ),
            (
                Either::RequestResponseOpenError(Open::IncompatibleRequestOrResponseType),
                OpenFailure::OtherBuild,
            ),
            (
                Either::RequestResponseOpenError(Open::DoesNotSupportRequestedAmountOfClients),
                OpenFailure::OtherBuild,
            ),
            (
                Either::RequestResponseOpenError(Open::VersionMismatch),
                OpenFailure::OtherBuild,
            ),
            (
                Either::RequestResponseCreateError(RequestResponseCreateError::InternalFailure),
                OpenFailure::Other,
            ),
        ];
        for (error, failure) in tasks {
            assert_eq!(OpenFailure::of_task_service(&error), failure, "{error:?}");
        }
        let events = [
            (
                EventOpenOrCreateError::EventOpenError(EventOpenError::HangsInCreation),
                OpenFailure::DiedCreating,
            ),
            (
                EventOpenOrCreateError::EventOpenError(EventOpenError::DoesNotExist),
                OpenFailure::Incomplete,
            ),
            (EventOpenOrCreateError::SystemInFlux, OpenFailure::InFlux),
            (
                EventOpenOrCreateError::EventOpenError(EventOpenError::IncompatibleDeadline),
                OpenFailure::OtherBuild,
            ),
        ];
        for (error, failure) in events {
            assert_eq!(OpenFailure::of_event_service(&error), failure, "{error:?}");
        }
        assert!(OpenFailure::Full.words().ends_with(&format!("({})", LIMITS.nodes)));
    }

    #[test]
    fn a_task_service_of_other_types_is_refused_as_another_build_s() {
        let run = RunName::new(&format!("test-other-build-{}", std::process::id())).unwrap();
        {
            let node = node(&run, "test").unwrap();
            let _other = node
                .service_builder(&ServiceName::new("tasks").unwrap())
                .request_response::<u64, u64>()
                .open_or_create()
                .unwrap();
            let error = open_services(&node).err().expect("refused");
            assert_eq!(
                error.to_string(),
                "opening the task service (a process of another acps build created it with other types or settings)"
            );
            let source = std::error::Error::source(&error).expect("iceoryx2's error").to_string();
            assert!(source.starts_with("RequestResponseOpenOrCreateError::"), "{source}");
        }
        remove_run_files(&run).unwrap();
        assert!(leftover_files(&run).is_empty());
    }

    #[test]
    fn a_second_server_of_a_run_is_refused_naming_the_first_s_process() {
        let run = RunName::new(&format!("test-taken-{}", std::process::id())).unwrap();
        {
            let node = node(&run, LEARNER_NODE).unwrap();
            let services = open_services(&node).unwrap();
            let first = task_server(&run, &services.tasks).unwrap();
            let error = task_server(&run, &services.tasks).expect_err("refused");
            assert_eq!(
                error,
                ServerError::Taken {
                    run: run.clone(),
                    pid: Some(std::process::id() as i32)
                }
            );
            assert_eq!(
                error.to_string(),
                format!(
                    "a learner of run '{run}' is already running (PID {}); give this run another name, or wait for that learner to end",
                    std::process::id()
                )
            );
            drop(first);
            task_server(&run, &services.tasks).expect("the seat is free once its server is gone");
        }
        remove_run_files(&run).unwrap();
        assert!(leftover_files(&run).is_empty());
    }

    #[test]
    fn services_open_and_leave_nothing_behind() {
        let run = RunName::new(&format!("test-services-{}", std::process::id())).unwrap();
        {
            let node = node(&run, "test").unwrap();
            let services = open_services(&node).unwrap();
            assert_eq!(services.tasks.dynamic_config().number_of_servers(), 0);
            let second = open_services(&node).unwrap();
            assert_eq!(second.tasks.static_config().max_clients(), MAX_WORKERS);
            assert_eq!(live_nodes(&run).unwrap(), 1);
            assert!(remove_run_files(&run).is_err(), "refused while a node is alive");
        }
        remove_run_files(&run).unwrap();
        assert!(leftover_files(&run).is_empty(), "{:?}", leftover_files(&run));
    }

    #[test]
    fn answers_carry_exactly_their_tasks() {
        use crate::wire::Response;
        use acps_shared::{Task, TaskKind};
        let run = RunName::new(&format!("test-answers-{}", std::process::id())).unwrap();
        {
            let node = node(&run, "test").unwrap();
            let services = open_services(&node).unwrap();
            let server = task_server(&run, &services.tasks).unwrap();
            let client = services.tasks.client_builder().create().unwrap();
            let spec = acps_shared::EnvironmentSpec::new("test", [0; 3], &()).unwrap();
            let task = |id: u64| {
                let task = Task {
                    id,
                    kind: TaskKind::Train,
                    seed: id,
                    context: vec![id as f64],
                    theta: vec![0.5; 3],
                };
                WireTask::new(2, &task, spec).unwrap()
            };
            let answered = |tasks: &[WireTask]| {
                let pending = client
                    .send_copy(WorkerMessage::request(0, tasks.len(), acps_shared::Serves::Any))
                    .unwrap();
                let request = server.receive().unwrap().expect("the request arrived");
                let sent = reply(&request, Answer::new(Response::Task, 5), tasks);
                drop(request);
                sent.map(|()| {
                    let response = pending.receive().unwrap().expect("the answer arrived");
                    let ids: Vec<u64> = response.payload().iter().map(|t| t.task_id).collect();
                    (*response.user_header(), ids)
                })
            };
            let three: Vec<WireTask> = (0..3).map(task).collect();
            assert_eq!(
                answered(&three).unwrap(),
                (Answer::new(Response::Task, 5), vec![0, 1, 2])
            );
            let full: Vec<WireTask> = (0..MAX_BATCH as u64).map(task).collect();
            assert_eq!(answered(&full).unwrap().1.len(), MAX_BATCH);
            let error = answered(&[full.as_slice(), &three].concat()).unwrap_err();
            assert!(error.to_string().starts_with("loaning an answer"), "{error}");
        }
        remove_run_files(&run).unwrap();
        assert!(leftover_files(&run).is_empty());
    }

    #[test]
    fn a_process_that_is_gone_or_a_zombie_does_not_run() {
        assert!(process_runs(std::process::id() as i32));
        assert!(!process_runs(i32::MAX), "beyond Linux's largest PID");
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let pid = child.id() as i32;
        let state = || {
            let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap();
            stat.rsplit_once(") ").unwrap().1.chars().next().unwrap()
        };
        let start = std::time::Instant::now();
        while state() != 'Z' {
            assert!(start.elapsed() < Duration::from_secs(10), "`true` did not exit");
            std::thread::sleep(Duration::from_millis(1));
        }
        assert!(!process_runs(pid), "exited, not yet reaped");
        child.wait().unwrap();
        assert!(!process_runs(pid), "reaped");
    }

    #[test]
    fn runs_without_nodes_are_removed_once_their_files_are_old() {
        let file = |run: &str| std::path::PathBuf::from(format!("/dev/shm/acps_{run}-{}_fake", std::process::id()));
        let (old, young) = (file("old"), file("young"));
        std::fs::write(&old, b"").unwrap();
        std::fs::write(&young, b"").unwrap();
        let long_ago = std::time::SystemTime::now() - 2 * STARTING_AGE;
        std::fs::File::options()
            .write(true)
            .open(&old)
            .unwrap()
            .set_modified(long_ago)
            .unwrap();
        let cleaned = clean_dead_runs();
        let name = |path: &std::path::Path| RunName::of_file(&path.file_name().unwrap().to_string_lossy()).unwrap();
        assert!(cleaned.contains(&name(&old)), "{cleaned:?}");
        assert!(!old.exists());
        assert!(young.exists(), "a run that may be starting is left alone");
        std::fs::remove_file(young).unwrap();
    }

    #[test]
    fn only_old_empty_node_directories_are_removed() {
        let nodes = std::env::temp_dir().join(format!("acps-orphans-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&nodes);
        for dir in ["old-empty", "old-full"] {
            std::fs::create_dir_all(nodes.join(dir)).unwrap();
        }
        std::fs::write(nodes.join("old-full/acps_x_node.details"), b"").unwrap();
        std::fs::write(nodes.join("acps_x_1.node_monitor"), b"").unwrap();
        std::thread::sleep(Duration::from_millis(300));
        std::fs::create_dir(nodes.join("new-empty")).unwrap();
        remove_orphaned_node_dirs(&nodes, Duration::from_millis(200));
        let mut left: Vec<String> = std::fs::read_dir(&nodes)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(left, ["acps_x_1.node_monitor", "new-empty", "old-full"]);
        std::fs::remove_dir_all(&nodes).unwrap();
    }
}
