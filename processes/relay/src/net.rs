//! What crosses the network between a learner and its relays: Zenoh sessions, key expressions and
//! messages.
//!
//! Keys (all carry the run, so runs sharing a network never mix):
//! - `acps/hello/<run>`: the handshake, a query, on a key without the protocol version, so that
//!   a relay of another version gets a refusal in words rather than silence;
//! - `acps/v<N>/<run>/learner`: the learner's liveliness token;
//! - `acps/v<N>/<run>/relay/<peer>`: a relay's liveliness token;
//! - `acps/v<N>/<run>/up/<peer>`: a relay's requests and outcomes;
//! - `acps/v<N>/<run>/down/<peer>`: the learner's tasks and notices to one relay.

use acps_shared::{EnvironmentSpec, Outcome, Task};
use acps_wire::ipc::RunName;
use acps_wire::wire::Sizes;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Version of these messages and keys; bump on any change.
pub const NET_PROTOCOL: u32 = 2;
/// This build's version, which a relay and its learner must share.
pub const BUILD: &str = env!("CARGO_PKG_VERSION");
/// Most tasks (or outcomes) one message carries: 128 PA-10 tasks (36 parameters, about 350 bytes
/// each) fit one of Zenoh's 64 KiB batches; Zenoh splits larger messages.
pub const MAX_NET_BATCH: usize = 128;
/// The lease when none is given: a frozen or cut-off peer is noticed after this long.
pub const DEFAULT_LEASE: Duration = Duration::from_secs(3);
/// The accepted leases.
pub const LEASES: std::ops::RangeInclusive<f64> = 0.1..=3600.0;

/// The key of the handshake of `run`; `None`: of whichever run a learner serves.
pub fn hello_key(run: Option<&RunName>) -> String {
    match run {
        Some(run) => format!("acps/hello/{run}"),
        None => "acps/hello/*".to_string(),
    }
}

/// The key of `what` in run `run`.
pub fn key(run: &RunName, what: &str) -> String {
    format!("acps/v{NET_PROTOCOL}/{run}/{what}")
}

/// A relay's greeting: who it is and what it was built as.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Hello {
    /// [`NET_PROTOCOL`].
    pub net_protocol: u32,
    /// The task wire's protocol (`acps_wire::wire::PROTOCOL_VERSION`) of the relay's workers.
    pub wire_protocol: u32,
    /// [`BUILD`].
    pub build: String,
    /// The run the relay means to join ("" for whichever the learner serves).
    pub run: String,
    /// The run identity it means to join (0: any).
    pub identity: u64,
    /// The relay's host name, for messages.
    pub host: String,
    /// The relay's process id, for messages.
    pub pid: u32,
}

/// What a learner tells a relay it admitted.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Admission {
    /// The run's name.
    pub run: RunName,
    /// The relay's number in this learner.
    pub peer: u32,
    /// 128 random bits the learner made for this admission, which the relay's messages carry:
    /// a message on the relay's key expression without them is not the relay's (any admitted
    /// session may publish there), nor one of an earlier admission or learner.
    pub key: u128,
    /// The run's identity.
    pub identity: u64,
    /// The environment of each job.
    pub environments: Vec<EnvironmentSpec>,
    /// The lengths of each job's contexts and parameters.
    pub sizes: Vec<Sizes>,
    /// The learner's host, for messages.
    pub host: String,
}

/// The learner's answer to a [`Hello`].
#[derive(Debug, Clone, Serialize, Deserialize)]
pub enum Welcome {
    /// Joined.
    Accepted(Admission),
    /// The learner is between two serves (one experiment ended, the next not begun): ask again.
    NotServing {
        /// The run's name.
        run: RunName,
    },
    /// Refused, and why, naming both sides.
    Refused {
        /// The learner's run.
        run: RunName,
        /// Why.
        reason: String,
    },
}

/// An outcome as it crosses the network.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct NetOutcome {
    /// The job.
    pub job: u32,
    /// The task.
    pub task_id: u64,
    /// Whether the rollout succeeded.
    pub ok: bool,
    /// The return.
    pub reward: f64,
    /// The score.
    pub score: f64,
    /// The diagnostics.
    pub diagnostics: Vec<f64>,
}

impl NetOutcome {
    /// `job`'s outcome.
    pub fn new(job: u32, outcome: &Outcome) -> Self {
        Self {
            job,
            task_id: outcome.task_id,
            ok: outcome.is_ok(),
            reward: outcome.reward,
            score: outcome.score,
            diagnostics: outcome.diagnostics.clone(),
        }
    }

    /// The job and outcome; one marked ok with non-finite numbers becomes a failed outcome
    /// (`Outcome::new` checks), so a NaN cannot come in through the network.
    pub fn to_outcome(&self) -> (u32, Outcome) {
        let outcome = if self.ok {
            Outcome::new(self.task_id, self.reward, self.score).with_diagnostics(self.diagnostics.clone())
        } else {
            Outcome::failed(self.task_id)
        };
        (self.job, outcome)
    }
}

/// A relay's message to its learner.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub enum Up {
    /// Outcomes, and a request for `want` tasks (0: none) of the environment `serves` (`None`:
    /// any), answered once with [`Down::Tasks`] of the same `request`.
    Request {
        /// The relay's [`Admission::key`].
        key: u128,
        /// The request's number.
        request: u64,
        /// Tasks asked for.
        want: u32,
        /// The environment the tasks must need, `None` for any.
        serves: Option<EnvironmentSpec>,
        /// Workers connected to the relay.
        workers: u32,
        /// Their slowest rollout, in microseconds.
        slowest_rollout_us: u64,
        /// Outcomes.
        outcomes: Vec<NetOutcome>,
    },
    /// Something the learner's user should read (a worker the relay refused).
    Note {
        /// The relay's [`Admission::key`].
        key: u128,
        /// What happened.
        text: String,
    },
}

/// A learner's message to one relay.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub enum Down {
    /// The answer to a request.
    Tasks {
        /// The request answered.
        request: u64,
        /// The tasks, by job.
        tasks: Vec<(u32, Task)>,
    },
    /// The learner served every job of this serve: stop the workers.
    Done,
    /// The learner gave up on the relay (silent, cut off, unknown): join again.
    Evicted {
        /// Why.
        reason: String,
    },
}

/// A message that could not be encoded or decoded.
#[derive(Debug, thiserror::Error)]
#[error("{what}: {reason}")]
pub struct CodecError {
    what: &'static str,
    reason: String,
}

/// Encode a message.
pub fn encode<T: Serialize>(message: &T) -> Result<Vec<u8>, CodecError> {
    bincode::serde::encode_to_vec(message, bincode::config::standard()).map_err(|e| CodecError {
        what: "encoding a message",
        reason: e.to_string(),
    })
}

/// Decode a message of `len` bytes or fewer.
pub fn decode<T: for<'de> Deserialize<'de>>(bytes: &[u8]) -> Result<T, CodecError> {
    let config = bincode::config::standard().with_limit::<{ 16 << 20 }>();
    let (message, _) = bincode::serde::decode_from_slice(bytes, config).map_err(|e| CodecError {
        what: "decoding a message",
        reason: e.to_string(),
    })?;
    Ok(message)
}

/// The user relays present to their learner with a [`RelayKey`].
pub const RELAY_USER: &str = "acps-relay";

/// The credentials of a learner's relays: a password of 32 random hexadecimal digits, in a
/// file of one line `acps-relay:PASSWORD`, only its user's. The learner's Zenoh session takes
/// the file as its dictionary of users (and so admits only sessions that present it); a relay's
/// presents the user and password. The learner makes it (`acps run --listen`); relay hosts get
/// a copy.
#[derive(Clone, PartialEq, Eq)]
pub struct RelayKey {
    path: PathBuf,
    password: String,
}

impl std::fmt::Debug for RelayKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RelayKey")
            .field("path", &self.path)
            .finish_non_exhaustive()
    }
}

impl RelayKey {
    /// The key in `path`, or a new one written there (0600) when there is no file; the flag
    /// says whether it was made.
    pub fn make_or_take(path: &Path) -> Result<(Self, bool), NetError> {
        if let Some(key) = Self::try_read(path)? {
            return Ok((key, false));
        }
        let error = |reason: String| NetError::Key {
            path: path.to_path_buf(),
            reason,
        };
        let password = acps_wire::secret::random_bytes::<16>()
            .map(|bytes| acps_wire::secret::to_hex(&bytes))
            .map_err(|e| error(format!("no random bytes: {e}")))?;
        acps_wire::secret::write_private(
            path,
            &format!("{RELAY_USER}:{password}\n"),
            acps_wire::secret::Replace::Never,
        )
        .map_err(error)?;
        Ok((
            Self {
                path: path.to_path_buf(),
                password,
            },
            true,
        ))
    }

    /// The key in `path`, which must exist: a relay's copy of its learner's.
    pub fn read(path: &Path) -> Result<Self, NetError> {
        Self::try_read(path)?.ok_or_else(|| NetError::Key {
            path: path.to_path_buf(),
            reason: "no such file (copy the key file the learner made, `relay.key` in its run directory, to this host)"
                .into(),
        })
    }

    fn try_read(path: &Path) -> Result<Option<Self>, NetError> {
        let error = |reason: String| NetError::Key {
            path: path.to_path_buf(),
            reason,
        };
        let Some(text) = acps_wire::secret::read_private(path).map_err(error)? else {
            return Ok(None);
        };
        let password = text
            .trim()
            .strip_prefix(RELAY_USER)
            .and_then(|rest| rest.strip_prefix(':'))
            .filter(|password| acps_wire::secret::from_hex::<16>(password).is_some())
            .ok_or_else(|| {
                error(format!(
                    "not a relay key (one line `{RELAY_USER}:` and 32 hexadecimal digits, as `acps run --listen` writes)"
                ))
            })?;
        Ok(Some(Self {
            path: path.to_path_buf(),
            password: password.to_string(),
        }))
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// How a process joins the network: where it listens or connects, its lease, its relays'
/// credentials, and an optional Zenoh configuration file under those.
#[derive(Debug, Clone, PartialEq)]
pub struct NetOptions {
    /// Endpoints to listen on (`tcp/127.0.0.1:7447`).
    pub listen: Vec<String>,
    /// Endpoints to connect to.
    pub connect: Vec<String>,
    /// A frozen or cut-off peer is noticed after this long.
    pub lease: Duration,
    /// A Zenoh configuration file (JSON5) whose settings (authentication) apply under
    /// those above.
    pub config_file: Option<PathBuf>,
    /// The relays' credentials: a learner admits only sessions that present them, a relay
    /// presents them. A learner without them, or a user and password of `config_file`, may
    /// listen on loopback only ([`NetError::Unauthenticated`]).
    pub key: Option<RelayKey>,
}

/// A network setting that cannot work.
#[derive(Debug, thiserror::Error)]
pub enum NetError {
    /// An endpoint that is not one.
    #[error("endpoint {endpoint:?}: {reason} (expected tcp/HOST:PORT, e.g. tcp/127.0.0.1:7447)")]
    Endpoint {
        /// The endpoint given.
        endpoint: String,
        /// Why it is not one.
        reason: String,
    },
    /// A relay key file that cannot be made or read.
    #[error("relay key {}: {reason}", path.display())]
    Key {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// A learner would listen where other hosts reach it without requiring credentials.
    #[error(
        "listening on {endpoints} without relay credentials would let any program that reaches it join as a relay and report outcomes: give relays a key (a key file, which `acps run --listen` makes by default), require a user and password in a Zenoh configuration, or listen on loopback only (docs/HOSTS.md#security)"
    )]
    Unauthenticated {
        /// The endpoints that are not loopback.
        endpoints: String,
    },
    /// The lease is outside its range.
    #[error("lease must be 0.1..=3600 seconds, got {0:?}")]
    Lease(Duration),
    /// The Zenoh configuration file cannot be read.
    #[error("Zenoh configuration {}: {reason}", path.display())]
    ConfigFile {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// Zenoh refused a setting or could not open the session (an address in use, say).
    #[error("{what}: {reason}")]
    Zenoh {
        /// What was being done.
        what: String,
        /// Zenoh's reason.
        reason: String,
    },
}

impl NetError {
    pub(crate) fn zenoh(what: impl Into<String>, reason: impl std::fmt::Display) -> Self {
        let mut reason = without_sources(&reason.to_string());
        if reason.contains("Address already in use") {
            reason += ": another program listens there (another acps run?); stop it or choose another port";
        }
        Self::Zenoh {
            what: what.into(),
            reason,
        }
    }
}

/// Zenoh's message without the places in Zenoh's sources it adds (" at $CARGO_HOME/...rs:61."),
/// which tell a user nothing.
fn without_sources(text: &str) -> String {
    let mut shown = String::new();
    let mut rest = text;
    while let Some(at) = rest.find(" at ") {
        let after = &rest[at + 4..];
        let end = after.find([' ', ']']).unwrap_or(after.len());
        let source = after[..end].contains(".rs:");
        shown.push_str(&rest[..if source { at } else { at + 4 }]);
        rest = if source { &after[end..] } else { after };
    }
    shown.push_str(rest);
    shown
}

/// Why `tls/` endpoints are refused, and what to use instead.
const TLS_REFUSED: &str = "TLS is not built in: Zenoh 1.10's TLS links are unsound under traffic both ways \
     (eclipse-zenoh/zenoh issue 2557; ours dropped within a second); to encrypt, carry tcp/ through an SSH tunnel \
     or a VPN, and authenticate with a user and password (docs/HOSTS.md#security)";

/// An endpoint's protocol and address (`HOST:PORT`), without its options or fragment.
fn split_endpoint(endpoint: &str) -> Option<(&str, &str)> {
    endpoint.split(['?', '#']).next().unwrap_or_default().split_once('/')
}

/// Check an endpoint's form: `tcp/`, a host and a port. TLS is refused with its reason: Zenoh
/// 1.10's TLS link lets a read and a write use one rustls session at once (eclipse-zenoh/zenoh
/// issue 2557), and under traffic both ways, as a relay's, our links dropped within a second.
pub fn check_endpoint(endpoint: &str) -> Result<(), NetError> {
    let error = |reason: &str| NetError::Endpoint {
        endpoint: endpoint.to_string(),
        reason: reason.to_string(),
    };
    let Some((protocol, address)) = split_endpoint(endpoint) else {
        return Err(error("no protocol"));
    };
    match protocol {
        "tcp" => {}
        "tls" => return Err(error(TLS_REFUSED)),
        _ => return Err(error(&format!("protocol {protocol:?} is not built in"))),
    }
    let Some((host, port)) = address.rsplit_once(':') else {
        return Err(error("no port"));
    };
    if host.is_empty() {
        return Err(error("no host"));
    }
    match port.parse::<u16>() {
        // The system would pick a free port that nothing could tell the relays (Zenoh does not
        // report it), and a relay cannot connect to port 0.
        Ok(0) => Err(error(
            "port 0 is no port relays could reach (listening on it would take any free port, which relays would not know): give one in 1..=65535, such as 7447",
        )),
        Ok(_) => Ok(()),
        Err(_) => Err(error(&format!("port {port:?} is not 1..=65535"))),
    }
}

/// The Zenoh configuration of `options`: peer mode, only the given endpoints, no multicast or
/// gossip scouting (nothing is announced or discovered unless configured in the file), the
/// lease, and quick reconnection.
pub(crate) fn zenoh_config(options: &NetOptions) -> Result<zenoh::Config, NetError> {
    for endpoint in options.listen.iter().chain(&options.connect) {
        check_endpoint(endpoint)?;
    }
    if !LEASES.contains(&options.lease.as_secs_f64()) {
        return Err(NetError::Lease(options.lease));
    }
    let mut config = match &options.config_file {
        Some(path) => read_config(path)?,
        None => zenoh::Config::default(),
    };
    let json = |value: &Vec<String>| serde_json_list(value);
    let lease_ms = options.lease.as_millis().max(1);
    let settings = [
        ("mode", "\"peer\"".to_string()),
        ("listen/endpoints", json(&options.listen)),
        ("connect/endpoints", json(&options.connect)),
        ("scouting/multicast/enabled", "false".to_string()),
        ("scouting/gossip/enabled", "false".to_string()),
        ("scouting/delay", "0".to_string()),
        ("transport/link/tx/lease", lease_ms.to_string()),
        (
            "connect/retry",
            "{period_init_ms: 100, period_max_ms: 500, period_increase_factor: 2}".to_string(),
        ),
        // Zenoh's own admin space and timestamps are not used.
        ("adminspace/enabled", "false".to_string()),
    ];
    for (key, value) in settings {
        config
            .insert_json5(key, &value)
            .map_err(|e| NetError::zenoh(format!("setting {key} = {value}"), e))?;
    }
    if let Some(key) = &options.key {
        let mut credentials = vec![
            ("transport/auth/usrpwd/user", format!("{RELAY_USER:?}")),
            ("transport/auth/usrpwd/password", format!("{:?}", key.password)),
        ];
        if !options.listen.is_empty() {
            // The key file is a dictionary of one user: the relays'.
            credentials.push((
                "transport/auth/usrpwd/dictionary_file",
                format!("{:?}", key.path.display().to_string()),
            ));
        }
        for (setting, value) in credentials {
            config
                .insert_json5(setting, &value)
                .map_err(|e| NetError::zenoh(format!("setting {setting} from {}", key.path.display()), e))?;
        }
    }
    let checks_users = config
        .get_json("transport/auth/usrpwd/dictionary_file")
        .is_ok_and(|file| file != "null");
    let exposed: Vec<&String> = options.listen.iter().filter(|e| !is_loopback(e)).collect();
    if !checks_users && !exposed.is_empty() {
        return Err(NetError::Unauthenticated {
            endpoints: exposed.iter().map(|e| e.as_str()).collect::<Vec<_>>().join(", "),
        });
    }
    Ok(config)
}

/// Whether `endpoint` (checked by [`check_endpoint`]) is on this host's loopback only.
fn is_loopback(endpoint: &str) -> bool {
    let host = split_endpoint(endpoint)
        .and_then(|(_, address)| address.rsplit_once(':'))
        .map_or("", |(host, _)| host.trim_start_matches('[').trim_end_matches(']'));
    host == "localhost" || host.parse::<std::net::IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

fn serde_json_list(values: &[String]) -> String {
    let quoted: Vec<String> = values.iter().map(|v| format!("{v:?}")).collect();
    format!("[{}]", quoted.join(", "))
}

fn read_config(path: &Path) -> Result<zenoh::Config, NetError> {
    if !path.is_file() {
        return Err(NetError::ConfigFile {
            path: path.to_path_buf(),
            reason: "not a readable file".into(),
        });
    }
    zenoh::Config::from_file(path).map_err(|e| NetError::ConfigFile {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })
}

/// Open a Zenoh session as `options` say: what the learner's [`Listener`](crate::Listener) and
/// a relay open, for a program that speaks the network's messages itself.
pub fn open(options: &NetOptions) -> Result<zenoh::Session, NetError> {
    use zenoh::Wait as _;
    let config = zenoh_config(options)?;
    zenoh::open(config).wait().map_err(|e| {
        let endpoints = options
            .listen
            .iter()
            .chain(&options.connect)
            .cloned()
            .collect::<Vec<_>>()
            .join(", ");
        NetError::zenoh(format!("opening the network session on {endpoints}"), e)
    })
}

/// This host's name, for messages.
pub(crate) fn host_name() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|name| name.trim().to_string())
        .ok()
        .filter(|name| !name.is_empty())
        .unwrap_or_else(|| "unknown host".into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zenoh_s_reasons_lose_its_source_places_and_an_address_in_use_says_what_to_do() {
        // As Zenoh 1.10 reported a second learner listening on a taken port.
        let reason = "Can not create a new TCP listener bound to tcp/127.0.0.1:17931: [127.0.0.1:17931: Address already in use (os error 98) at $CARGO_HOME/registry/src/index.crates.io-1949cf8c6b5b557f/zenoh-link-commons-1.10.2/src/tcp.rs:61.] at $CARGO_HOME/registry/src/index.crates.io-1949cf8c6b5b557f/zenoh-link-tcp-1.10.2/src/unicast.rs:338.";
        assert_eq!(
            NetError::zenoh("opening the network session on tcp/127.0.0.1:17931", reason).to_string(),
            "opening the network session on tcp/127.0.0.1:17931: Can not create a new TCP listener bound to tcp/127.0.0.1:17931: [127.0.0.1:17931: Address already in use (os error 98)]: another program listens there (another acps run?); stop it or choose another port"
        );
        // " at " in words stays.
        assert_eq!(without_sources("look at me at home"), "look at me at home");
    }

    #[test]
    fn a_relay_key_is_made_once_taken_after_and_refused_when_it_is_none() {
        use std::os::unix::fs::PermissionsExt as _;
        let dir = std::env::temp_dir().join(format!("acps-relay-key-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("relay.key");
        let (made, fresh) = RelayKey::make_or_take(&path).unwrap();
        assert!(fresh);
        assert_eq!(std::fs::metadata(&path).unwrap().permissions().mode() & 0o777, 0o600);
        let (taken, fresh) = RelayKey::make_or_take(&path).unwrap();
        assert!(!fresh);
        assert_eq!(taken, made);
        assert_eq!(RelayKey::read(&path).unwrap(), made);
        std::fs::write(&path, "hello\n").unwrap();
        let error = RelayKey::read(&path).unwrap_err().to_string();
        assert_eq!(
            error,
            format!(
                "relay key {}: not a relay key (one line `acps-relay:` and 32 hexadecimal digits, as `acps run --listen` writes)",
                path.display()
            )
        );
        std::fs::remove_dir_all(&dir).unwrap();
        let error = RelayKey::read(&path).unwrap_err().to_string();
        assert!(
            error.ends_with(
                "no such file (copy the key file the learner made, `relay.key` in its run directory, to this host)"
            ),
            "{error}"
        );
    }

    #[test]
    fn endpoints_are_checked_naming_what_is_wrong() {
        for good in ["tcp/127.0.0.1:7447", "tcp/learner.lab:7447", "tcp/[::1]:1"] {
            assert!(check_endpoint(good).is_ok(), "{good}");
        }
        for (bad, why) in [
            ("127.0.0.1:7447", "no protocol"),
            ("udp/127.0.0.1:7447", "protocol \"udp\" is not built in"),
            ("tls/learner.lab:7447", "issue 2557"),
            ("tcp/127.0.0.1", "no port"),
            ("tcp/:7447", "no host"),
            ("tcp/127.0.0.1:70000", "port \"70000\" is not 1..=65535"),
            ("tcp/127.0.0.1:0", "port 0 is no port relays could reach"),
        ] {
            let message = check_endpoint(bad).unwrap_err().to_string();
            assert!(message.contains(why) && message.contains(bad), "{bad}: {message}");
        }
        for (endpoint, loopback) in [
            ("tcp/127.0.0.1:7447", true),
            ("tcp/127.1.2.3:7447?opt#x", true),
            ("tcp/[::1]:1", true),
            ("tcp/localhost:1", true),
            ("tcp/0.0.0.0:7447", false),
            ("tcp/10.0.0.1:7447", false),
            ("tcp/learner.lab:7447", false),
        ] {
            assert_eq!(is_loopback(endpoint), loopback, "{endpoint}");
        }
    }

    #[test]
    fn messages_round_trip_and_a_nan_outcome_arrives_failed() {
        let outcome = Outcome::new(7, -1.5, 2.0).with_diagnostics(vec![0.25]);
        let up = Up::Request {
            key: u128::MAX - 3,
            request: 9,
            want: 4,
            serves: None,
            workers: 2,
            slowest_rollout_us: 1500,
            outcomes: vec![NetOutcome::new(1, &outcome)],
        };
        let Up::Request { outcomes, key, .. } = decode::<Up>(&encode(&up).unwrap()).unwrap() else {
            panic!("not a request")
        };
        assert_eq!(key, u128::MAX - 3);
        assert_eq!(outcomes[0].to_outcome(), (1, outcome));
        let nan = NetOutcome {
            reward: f64::NAN,
            ..NetOutcome::new(0, &Outcome::new(1, 0.0, 0.0))
        };
        assert!(!nan.to_outcome().1.is_ok());
        assert!(decode::<Up>(&[0xff, 0xff, 0xff]).is_err());
    }
}
