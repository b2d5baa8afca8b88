//! Workers on other hosts: a learner that listens, relays that connect, on emulated hosts. Each
//! relay has its own run name, hence its own iceoryx2 domain: shared memory cannot carry the
//! learner's work to its workers, only the network can. Where the machine allows (root and
//! iproute2), the relays of a test run in a network namespace of their own, with their own
//! address, joined to the learner's by a virtual link; elsewhere on loopback. No traffic leaves
//! the machine.

use crate::fleet::{
    GRID, SLOW, SlowRun, has_checkpoint, in_process, reissued, signal_group, slow_run_with, wait_for, wait_until,
};
use crate::{assert_clean, run_name, succeeded, temp_dir, watched};
use acps_wire::ipc::{self, RunName};
use std::os::unix::process::CommandExt as _;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

/// Where a test's emulated hosts are: a network namespace of their own, or (where the machine
/// cannot make one) this host's loopback.
struct Network {
    netns: Option<Netns>,
    /// The relays' key of its learner, as a learner makes it.
    key: std::path::PathBuf,
    _keys: crate::TempDir,
}

impl Network {
    /// The network of test number `tag` (distinct per test of this file). CI sets
    /// ACPS_REQUIRE_NETNS, so that there no test falls back to loopback.
    fn new(tag: u32) -> Self {
        let netns = match Netns::new(tag) {
            Ok(netns) => Some(netns),
            Err(why) if std::env::var_os("ACPS_REQUIRE_NETNS").is_none() => {
                eprintln!("emulated hosts on loopback: no network namespace here ({why})");
                None
            }
            Err(why) => panic!("ACPS_REQUIRE_NETNS is set, and no network namespace can be made: {why}"),
        };
        let keys = temp_dir("relay-key");
        std::fs::create_dir_all(&*keys).unwrap();
        let key = keys.join("relay.key");
        acps_relay::net::RelayKey::make_or_take(&key).unwrap();
        Self {
            netns,
            key,
            _keys: keys,
        }
    }

    /// The network's key as a learner or relay takes it, unless `extra` sets the credentials.
    fn key_args(&self, extra: &[&str]) -> Vec<String> {
        let own = ["--zenoh-config", "--relay-key", "--no-relay-key"];
        if extra.iter().any(|arg| own.contains(arg)) {
            return Vec::new();
        }
        vec!["--relay-key".into(), self.key.display().to_string()]
    }

    /// An endpoint for the learner, on a port that was free a moment ago: the learner's side of
    /// the link, or loopback.
    fn endpoint(&self) -> String {
        let address = self.netns.as_ref().map_or("127.0.0.1", |netns| netns.here.as_str());
        let socket = std::net::TcpListener::bind((address, 0)).unwrap();
        format!("tcp/{address}:{}", socket.local_addr().unwrap().port())
    }

    /// `acps` under a watchdog, on the emulated hosts' side.
    fn watched(&self) -> Command {
        let watched = watched();
        let Some(netns) = &self.netns else {
            return watched;
        };
        let mut inside = Command::new("ip");
        inside.args(["netns", "exec", &netns.name]).arg(watched.get_program());
        inside.args(watched.get_args());
        inside
    }
}

/// `acps relay` of an emulated host on `network`: its own run `local`, `workers` workers,
/// under a watchdog.
fn relay(network: &Network, endpoint: &str, local: &RunName, workers: usize, extra: &[&str]) -> Command {
    let mut command = network.watched();
    command
        .args([
            "relay",
            "--connect",
            endpoint,
            "--local-run",
            local.as_str(),
            "--workers",
        ])
        .arg(workers.to_string())
        .args(network.key_args(extra))
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    // A group of its own, the watchdog's and the workers' too: `kill_host` takes them all.
    command.process_group(0);
    command
}

/// SIGKILL the process group of `child` (an emulated host, or a learner under its watchdog) and
/// reap it.
fn kill_host(child: &mut Child) {
    signal_group("-KILL", child.id());
    let _ = child.wait();
}

/// `acps run ARGS --listen ENDPOINT --run RUN --out OUT` with `network`'s key, not quiet (it
/// reports re-issued tasks).
fn learner(network: &Network, args: &[&str], endpoint: &str, run: &RunName, out: &Path, extra: &[&str]) -> Child {
    let loud: Vec<&str> = args.iter().copied().filter(|a| *a != "-q").collect();
    watched()
        .arg("run")
        .args(&loud)
        .args(["--listen", endpoint, "--run", run.as_str()])
        .args(network.key_args(extra))
        .args(extra)
        .arg("--out")
        .arg(out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .process_group(0)
        .spawn()
        .unwrap()
}

fn finished(child: Child) -> String {
    succeeded(&child.wait_with_output().unwrap())
}

/// The grid run `name`, served only by one relay of two workers on network `tag`, both started,
/// with the in-process run's summary to compare.
struct RelayedGrid {
    _dir: crate::TempDir,
    reference: Vec<u8>,
    run: RunName,
    local: RunName,
    network: Network,
    endpoint: String,
    out: std::path::PathBuf,
    learner: Child,
    relay: Child,
}

/// The grid run `name` to serve on network `tag`: its directory (the in-process run's summary
/// read from it), its name, the network, the learner's endpoint and its run directory.
fn grid_on_network(name: &str, tag: u32) -> (crate::TempDir, Vec<u8>, RunName, Network, String, std::path::PathBuf) {
    let dir = temp_dir(name);
    let reference = in_process(&GRID, &dir.join("in-process"));
    let network = Network::new(tag);
    let endpoint = network.endpoint();
    let out = dir.join("fleet");
    (dir, reference, run_name(name), network, endpoint, out)
}

fn relayed_grid(name: &str, tag: u32, relay_args: &[&str]) -> RelayedGrid {
    let (dir, reference, run, network, endpoint, out) = grid_on_network(name, tag);
    let local = run_name(&format!("{name}-h1"));
    let learner = learner(&network, &GRID, &endpoint, &run, &out, &["--workers", "0"]);
    let relay = relay(&network, &endpoint, &local, 2, relay_args).spawn().unwrap();
    RelayedGrid {
        _dir: dir,
        reference,
        run,
        local,
        network,
        endpoint,
        out,
        learner,
        relay,
    }
}

#[test]
fn a_run_served_only_through_a_relay_matches_the_in_process_run() {
    // Every field bound: one left to `..` would be dropped here, the network's namespace with it.
    let RelayedGrid {
        _dir,
        reference,
        run,
        local,
        network: _network,
        endpoint: _,
        out,
        learner,
        relay,
    } = relayed_grid("relay-only", 1, &[]);
    let stdout = finished(learner);
    assert!(stdout.contains("and relays of other hosts"), "{stdout}");
    let relayed = relay.wait_with_output().unwrap();
    let said = String::from_utf8_lossy(&relayed.stderr);
    assert!(relayed.status.success(), "{said}");
    assert!(said.contains(&format!("run '{run}' is over")), "{said}");
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), reference);
    assert_clean(&run);
    assert_clean(&local);
}

#[test]
fn a_killed_relay_s_tasks_go_to_other_workers_and_a_late_relay_joins() {
    let SlowRun {
        dir: _dir,
        reference,
        run,
        out,
    } = slow_run_with("relay-kill", &["--in-flight", "8"]);
    let network = Network::new(2);
    let endpoint = network.endpoint();
    let (first, second) = (run_name("relay-kill-h1"), run_name("relay-kill-h2"));
    let learner = learner(
        &network,
        &SLOW,
        &endpoint,
        &run,
        &out,
        &["--in-flight", "8", "--workers", "1", "--checkpoint-every", "1"],
    );
    let mut victim = relay(&network, &endpoint, &first, 1, &["-q"]).spawn().unwrap();
    // The relay and its worker are in, and learning has begun.
    wait_until("the relay to serve a learning run", Duration::from_secs(60), || {
        ipc::live_nodes(&first).unwrap_or(0) >= 2 && has_checkpoint(&out.join("checkpoints"))
    });
    kill_host(&mut victim);
    // A relay that joins late; its start removes what the killed one left.
    let late = relay(&network, &endpoint, &second, 1, &["-q"]).spawn().unwrap();
    let output = learner.wait_with_output().unwrap();
    let stdout = succeeded(&output);
    assert!(reissued(&stdout) >= 1, "{stdout}");
    // The learner reports the lost relay itself; Zenoh's own log, which printed "ERROR Received
    // Query for unknown key_expr" for it, stays off without -v.
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!stderr.contains("ERROR") && !stderr.contains("key_expr"), "{stderr}");
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), reference);
    let late = late.wait_with_output().unwrap();
    assert!(late.status.success(), "{}", String::from_utf8_lossy(&late.stderr));
    // The killed host's files go with the next start of any fleet on it.
    ipc::clean_dead_runs();
    for run in [&run, &first, &second] {
        assert_clean(run);
    }
}

/// The lease of the tests that freeze or cut off a relay: they end sooner.
const LEASE: [&str; 2] = ["--lease", "0.5"];

/// A slow run, eight tasks in flight per job, served by a learner with `workers` local workers
/// that listens on `network` with [`LEASE`], and the run name of the relay host to come.
struct LeasedRun {
    slow: SlowRun,
    endpoint: String,
    local: RunName,
    learner: Child,
}

fn leased_run(name: &str, network: &Network, workers: usize) -> LeasedRun {
    let slow = slow_run_with(name, &["--in-flight", "8"]);
    let endpoint = network.endpoint();
    let workers = workers.to_string();
    let options = ["--in-flight", "8", "--workers", &workers, "--checkpoint-every", "1"];
    let learner = learner(
        network,
        &SLOW,
        &endpoint,
        &slow.run,
        &slow.out,
        &[&options[..], &LEASE].concat(),
    );
    LeasedRun {
        local: run_name(&format!("{name}-h1")),
        slow,
        endpoint,
        learner,
    }
}

#[test]
fn a_frozen_relay_is_given_up_on_after_its_lease_and_the_result_is_unchanged() {
    let network = Network::new(3);
    let LeasedRun {
        slow: SlowRun {
            dir: _dir,
            reference,
            run,
            out,
        },
        endpoint,
        local,
        learner,
    } = leased_run("relay-freeze", &network, 1);
    // The relay and its worker freeze together (a process group), as a host does.
    let mut frozen = relay(
        &network,
        &endpoint,
        &local,
        1,
        &[&LEASE[..], &["-q", "--wait-for-learner", "1"]].concat(),
    )
    .spawn()
    .unwrap();
    wait_until("the relay to serve a learning run", Duration::from_secs(60), || {
        ipc::live_nodes(&local).unwrap_or(0) >= 2 && has_checkpoint(&out.join("checkpoints"))
    });
    signal_group("-STOP", frozen.id());
    let stdout = finished(learner);
    signal_group("-CONT", frozen.id());
    assert!(reissued(&stdout) >= 1, "{stdout}");
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), reference);
    // Woken, it finds itself given up on, or its learner gone, and leaves.
    assert!(
        wait_for(&mut frozen, Duration::from_secs(60)).is_some(),
        "the thawed relay must leave"
    );
    assert_clean(&run);
    assert_clean(&local);
}

#[test]
fn a_relay_waits_for_its_killed_learner_to_resume_and_the_run_ends_as_in_process() {
    let SlowRun {
        dir: _dir,
        reference,
        run,
        out,
    } = slow_run_with("relay-resume", &[]);
    let network = Network::new(4);
    let endpoint = network.endpoint();
    let local = run_name("relay-resume-h1");
    let args = ["--workers", "0", "--checkpoint-every", "1"];
    let mut first = learner(&network, &SLOW, &endpoint, &run, &out, &args);
    let relay = relay(&network, &endpoint, &local, 1, &["-q", "--wait-for-learner", "120"])
        .spawn()
        .unwrap();
    wait_until("the first checkpoints", Duration::from_secs(60), || {
        has_checkpoint(&out.join("checkpoints"))
    });
    kill_host(&mut first);
    // The relay waits; the resumed learner (same run, same address) gets it back.
    let resumed = learner(
        &network,
        &SLOW,
        &endpoint,
        &run,
        &out,
        &[&args[..], &["--resume"], &[out.to_str().unwrap()]].concat(),
    );
    finished(resumed);
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), reference);
    let relayed = relay.wait_with_output().unwrap();
    assert!(relayed.status.success(), "{}", String::from_utf8_lossy(&relayed.stderr));
    assert_clean(&run);
    assert_clean(&local);
}

#[test]
fn a_relay_whose_learner_is_gone_for_good_stops_its_workers_and_says_so() {
    let dir = temp_dir("relay-orphan");
    let (run, local) = (run_name("relay-orphan"), run_name("relay-orphan-h1"));
    let network = Network::new(5);
    let endpoint = network.endpoint();
    let out = dir.join("fleet");
    let mut learner = learner(
        &network,
        &SLOW,
        &endpoint,
        &run,
        &out,
        &["--workers", "0", "--checkpoint-every", "1"],
    );
    let relay = relay(&network, &endpoint, &local, 1, &["-q", "--wait-for-learner", "1"])
        .spawn()
        .unwrap();
    wait_until("the first checkpoints", Duration::from_secs(60), || {
        has_checkpoint(&out.join("checkpoints"))
    });
    kill_host(&mut learner);
    let relayed = relay.wait_with_output().unwrap();
    let said = String::from_utf8_lossy(&relayed.stderr);
    assert_eq!(relayed.status.code(), Some(2), "{said}");
    assert!(
        said.contains(&format!(
            "the learner of run '{run}' is gone and did not come back within 1s"
        )),
        "{said}"
    );
    assert_clean(&local);
    // What the killed learner left goes with the next start of any fleet.
    ipc::clean_dead_runs();
    assert_clean(&run);
}

#[test]
fn relays_of_another_run_or_with_the_wrong_password_are_refused_naming_why() {
    let (dir, reference, run, network, endpoint, out) = grid_on_network("relay-refused", 6);
    let users = dir.join("users.txt");
    std::fs::create_dir_all(&*dir).unwrap();
    std::fs::write(&users, "relay:right\n").unwrap();
    let config = |name: &str, user: &str, password: &str, dictionary: bool| {
        let path = dir.join(name);
        let dictionary = if dictionary {
            format!(", dictionary_file: {:?}", users.to_str().unwrap())
        } else {
            String::new()
        };
        std::fs::write(
            &path,
            format!(
                "{{ transport: {{ auth: {{ usrpwd: {{ user: {user:?}, password: {password:?}{dictionary} }} }} }} }}"
            ),
        )
        .unwrap();
        path
    };
    let learner_config = config("learner.json5", "learner", "learner", true);
    let learner = learner(
        &network,
        &GRID,
        &endpoint,
        &run,
        &out,
        &["--workers", "0", "--zenoh-config", learner_config.to_str().unwrap()],
    );
    let right = config("right.json5", "relay", "right", false);
    let wrong = config("wrong.json5", "relay", "wrong", false);
    let refused = |local: &str, extra: &[&str]| {
        let output = relay(
            &network,
            &endpoint,
            &run_name(local),
            1,
            &[&["-q", "--startup-timeout", "2"][..], extra].concat(),
        )
        .output()
        .unwrap();
        assert_eq!(output.status.code(), Some(2));
        assert_clean(&run_name(local));
        String::from_utf8_lossy(&output.stderr).into_owned()
    };
    let said = refused("relay-refused-h1", &["--zenoh-config", wrong.to_str().unwrap()]);
    assert!(
        said.contains("no learner answered") && said.contains("same user and password settings"),
        "{said}"
    );
    let said = refused(
        "relay-refused-h2",
        &["--zenoh-config", right.to_str().unwrap(), "--run", "another"],
    );
    assert!(
        said.contains(&format!("it asked for run 'another', this learner serves run '{run}'")),
        "{said}"
    );
    let served = relay(
        &network,
        &endpoint,
        &run_name("relay-refused-h3"),
        2,
        &["-q", "--zenoh-config", right.to_str().unwrap()],
    )
    .output()
    .unwrap();
    assert!(served.status.success(), "{}", String::from_utf8_lossy(&served.stderr));
    finished(learner);
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), reference);
    assert_clean(&run);
}

#[test]
fn a_learner_makes_its_relays_key_and_relays_without_it_are_refused() {
    use std::os::unix::fs::PermissionsExt as _;
    let (dir, reference, run, network, endpoint, out) = grid_on_network("relay-key", 8);
    // No credentials given: the learner makes the key in its run directory and says where.
    let learner = watched()
        .arg("run")
        .args(GRID.iter().filter(|a| **a != "-q"))
        .args(["--listen", &endpoint, "--run", run.as_str(), "--workers", "0"])
        .arg("--out")
        .arg(&out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .process_group(0)
        .spawn()
        .unwrap();
    let key = out.join("relay.key");
    wait_until("the learner's key", Duration::from_secs(60), || key.exists());
    let mode = std::fs::metadata(&key).unwrap().permissions().mode();
    assert_eq!(mode & 0o777, 0o600, "{mode:o}");
    let relay_with = |local: &str, credentials: &[&str], startup: &str| {
        relay(
            &network,
            &endpoint,
            &run_name(local),
            2,
            &[&["-q", "--startup-timeout", startup][..], credentials].concat(),
        )
        .output()
        .unwrap()
    };
    // A relay must say which credentials it presents.
    let output = network
        .watched()
        .args(["relay", "--connect", &endpoint, "--local-run", "relay-key-h0"])
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{said}");
    assert!(said.contains("--relay-key FILE is missing"), "{said}");
    // Without the key, or with another, the learner's session does not admit it.
    let other = dir.join("other.key");
    acps_relay::net::RelayKey::make_or_take(&other).unwrap();
    for (local, credentials) in [
        ("relay-key-h1", vec!["--no-relay-key"]),
        ("relay-key-h2", vec!["--relay-key", other.to_str().unwrap()]),
    ] {
        let output = relay_with(local, &credentials, "2");
        let said = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{said}");
        assert!(said.contains("no learner") && said.contains("relay.key"), "{said}");
        assert_clean(&run_name(local));
    }
    // With the learner's key it serves the run to its in-process end.
    let served = relay_with("relay-key-h3", &["--relay-key", key.to_str().unwrap()], "30");
    assert!(served.status.success(), "{}", String::from_utf8_lossy(&served.stderr));
    let output = learner.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "--relay-key relay.key` with this host's address and a copy of {} (made now)",
            key.display()
        )),
        "{stderr}"
    );
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), reference);
    assert_clean(&run);
    // Without credentials a learner listens on loopback only.
    let short_run = |listen: &str, out: &str| {
        watched()
            .args([
                "run",
                "function",
                "--runs",
                "1",
                "--episodes",
                "10",
                "--workers",
                "1",
                "-q",
            ])
            .args(["--listen", listen, "--no-relay-key"])
            .arg("--out")
            .arg(dir.join(out))
            .output()
            .unwrap()
    };
    let output = short_run("tcp/0.0.0.0:7447", "exposed");
    let said = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{said}");
    assert!(
        said.contains("listening on tcp/0.0.0.0:7447 without relay credentials would let any program that reaches it join as a relay"),
        "{said}"
    );
    assert!(!dir.join("exposed").exists(), "a refused run leaves no directory");
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let output = short_run(&format!("tcp/127.0.0.1:{port}"), "loopback");
    succeeded(&output);
    let said = String::from_utf8_lossy(&output.stderr);
    assert!(
        said.contains("admits relays without credentials (--no-relay-key): any process of this host can join"),
        "{said}"
    );
}

#[test]
fn a_session_posing_as_an_admitted_relay_changes_nothing() {
    // An honest relay serves the run; beside it a session with the relays' credentials joins
    // as a relay itself (so it has an admission key of its own) and publishes outcomes of 1e300
    // for every task id on the channels of the other relay numbers, as if it were them. Its key
    // is not theirs: none is taken.
    use acps_relay::net::{self, Hello, NetOutcome, RelayKey, Up, Welcome};
    use zenoh::Wait as _;
    let RelayedGrid {
        _dir,
        reference,
        run,
        local,
        network,
        endpoint,
        out,
        learner,
        relay,
    } = relayed_grid("relay-posing", 9, &["-q"]);
    let admitted_session = || {
        net::open(&acps_relay::NetOptions {
            listen: Vec::new(),
            connect: vec![endpoint.clone()],
            lease: net::DEFAULT_LEASE,
            config_file: None,
            key: Some(RelayKey::read(&network.key).unwrap()),
        })
        .unwrap()
    };
    let session = admitted_session();
    // Another admitted session listens to every relay's messages to the learner: it must hear
    // none (they go to the learner alone, whose peer-mode session forwards nothing), or the
    // admission keys they carry could be read and used.
    let sniffer = admitted_session();
    let listen = |what: &str| {
        let heard = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
        let counter = heard.clone();
        let subscriber = sniffer
            .declare_subscriber(net::key(&run, what))
            .callback(move |_| {
                counter.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            })
            .wait()
            .unwrap();
        (heard, subscriber)
    };
    // The learner's tasks to the relays it does hear: it is connected and listening.
    let (heard, _up) = listen("up/*");
    let (tasks, _down) = listen("down/*");
    let hello = Hello {
        net_protocol: net::NET_PROTOCOL,
        wire_protocol: acps_wire::wire::PROTOCOL_VERSION,
        build: net::BUILD.into(),
        run: run.to_string(),
        identity: 0,
        host: "poser".into(),
        pid: std::process::id(),
    };
    let mut admission = None;
    wait_until("the posing session's admission", Duration::from_secs(60), || {
        let replies = session
            .get(net::hello_key(Some(&run)))
            .payload(net::encode(&hello).unwrap())
            .wait()
            .unwrap();
        if let Ok(reply) = replies.recv()
            && let Ok(sample) = reply.result()
            && let Ok(Welcome::Accepted(admitted)) = net::decode(&sample.payload().to_bytes())
        {
            admission = Some(admitted);
        }
        admission.is_some()
    });
    let admission = admission.unwrap();
    let done = std::sync::atomic::AtomicBool::new(false);
    let posed = std::thread::scope(|scope| {
        let poser = scope.spawn(|| {
            let mut sent = 0u64;
            while !done.load(std::sync::atomic::Ordering::Relaxed) {
                for peer in (1..=4u32).filter(|&peer| peer != admission.peer) {
                    let outcomes = (0..2)
                        .flat_map(|job| {
                            (0..128).map(move |id| NetOutcome::new(job, &acps_shared::Outcome::new(id, 1e300, 0.0)))
                        })
                        .collect();
                    let message = Up::Request {
                        key: admission.key,
                        request: sent,
                        want: 0,
                        serves: None,
                        workers: 1,
                        slowest_rollout_us: 0,
                        outcomes,
                    };
                    let bytes = net::encode(&message).unwrap();
                    session
                        .put(net::key(&run, &format!("up/{peer}")), bytes)
                        .wait()
                        .unwrap();
                    sent += 1;
                }
                std::thread::sleep(Duration::from_millis(5));
            }
            sent
        });
        let output = learner.wait_with_output().unwrap();
        done.store(true, std::sync::atomic::Ordering::Relaxed);
        (output, poser.join().unwrap())
    });
    let (output, sent) = posed;
    let said = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{said}");
    assert!(sent > 0);
    assert!(said.contains("channel without its key was dropped"), "{said}");
    assert_eq!(
        heard.load(std::sync::atomic::Ordering::Relaxed),
        0,
        "relays' messages reached another session"
    );
    assert!(
        tasks.load(std::sync::atomic::Ordering::Relaxed) > 0,
        "the listening session heard no tasks either"
    );
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), reference);
    let relayed = relay.wait_with_output().unwrap();
    assert!(relayed.status.success(), "{}", String::from_utf8_lossy(&relayed.stderr));
    let _ = session.close().wait();
    let _ = sniffer.close().wait();
    assert_clean(&run);
    assert_clean(&local);
}

/// An emulated host with a network of its own: a network namespace joined to this one by a
/// virtual Ethernet pair, with an address on each side (in 198.18.0.0/15, the range set aside for
/// benchmarking networks). Dropping it removes the namespace and with it the pair.
struct Netns {
    name: String,
    /// The pair's end on this side: taken down, it cuts the host off.
    link: String,
    /// This side's address, which the learner listens on.
    here: String,
}

impl Netns {
    /// Namespace `tag` of this test process, or why the machine cannot make one (network
    /// namespaces need root, or CAP_NET_ADMIN, and iproute2).
    fn new(tag: u32) -> Result<Self, String> {
        Self::remove_dead();
        let pid = std::process::id();
        let name = format!("acpst{pid}-{tag}");
        // Interface names have at most 15 characters.
        let (link, inside) = (format!("a{pid}-{tag}h"), format!("a{pid}-{tag}n"));
        // A /30 per test: 64 tests, and processes 256 PIDs apart share no subnet.
        let (third, fourth) = (pid % 256, tag % 64 * 4);
        let here = format!("198.18.{third}.{}", fourth + 1);
        let there = format!("198.18.{third}.{}", fourth + 2);
        ip(&["netns", "add", &name])?;
        let netns = Self { name, link, here };
        let name = netns.name.as_str();
        ip(&["link", "add", &netns.link, "type", "veth", "peer", "name", &inside])?;
        ip(&["link", "set", &inside, "netns", name])?;
        ip(&["addr", "add", &format!("{}/30", netns.here), "dev", &netns.link])?;
        ip(&["link", "set", &netns.link, "up"])?;
        ip(&["-n", name, "addr", "add", &format!("{there}/30"), "dev", &inside])?;
        ip(&["-n", name, "link", "set", &inside, "up"])?;
        ip(&["-n", name, "link", "set", "lo", "up"])?;
        Ok(netns)
    }

    /// Remove the namespaces of test processes that are gone (killed before their drop ran).
    fn remove_dead() {
        let Ok(entries) = std::fs::read_dir("/var/run/netns") else {
            return;
        };
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            let pid = name.strip_prefix("acpst").and_then(|rest| rest.split('-').next());
            if let Some(pid) = pid.and_then(|p| p.parse::<u32>().ok())
                && !Path::new(&format!("/proc/{pid}")).exists()
            {
                let _ = ip(&["netns", "del", &name]);
            }
        }
    }

    /// Take this side's end of the link down (`false`) or up again.
    fn connect(&self, up: bool) {
        let state = if up { "up" } else { "down" };
        ip(&["link", "set", &self.link, state]).unwrap();
    }
}

impl Drop for Netns {
    fn drop(&mut self) {
        // The pair goes with the namespace, unless it was never moved into it.
        let _ = ip(&["link", "del", &self.link]);
        let _ = ip(&["netns", "del", &self.name]);
    }
}

fn ip(args: &[&str]) -> Result<(), String> {
    let output = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| format!("ip {}: {e}", args.join(" ")))?;
    if output.status.success() {
        Ok(())
    } else {
        Err(format!(
            "ip {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&output.stderr).trim()
        ))
    }
}

#[test]
fn a_host_cut_off_from_the_network_is_given_up_on_and_rejoins_when_the_link_is_back() {
    let network = Network::new(7);
    let Some(host) = &network.netns else {
        eprintln!("network cut: skipped, it needs a network namespace");
        return;
    };
    // The relay is the only way to the workers: nothing is learnt while the link is down.
    let LeasedRun {
        slow: SlowRun {
            dir: _dir,
            reference,
            run,
            out,
        },
        endpoint,
        local,
        learner,
    } = leased_run("relay-cut", &network, 0);
    let relay = relay(
        &network,
        &endpoint,
        &local,
        1,
        &[&LEASE[..], &["-q", "--wait-for-learner", "120"]].concat(),
    )
    .spawn()
    .unwrap();
    wait_until("the relay to serve a learning run", Duration::from_secs(60), || {
        ipc::live_nodes(&local).unwrap_or(0) >= 2 && has_checkpoint(&out.join("checkpoints"))
    });
    host.connect(false);
    // Cut off, the relay loses its learner after the lease and stops its workers.
    wait_until("the cut-off relay to stop its workers", Duration::from_secs(60), || {
        ipc::live_nodes(&local).unwrap_or(0) < 2
    });
    host.connect(true);
    let stdout = finished(learner);
    assert!(reissued(&stdout) >= 1, "{stdout}");
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), reference);
    let relayed = relay.wait_with_output().unwrap();
    let said = String::from_utf8_lossy(&relayed.stderr);
    assert!(relayed.status.success(), "{said}");
    assert!(
        said.contains(&format!("the learner of run '{run}' is gone; waiting up to 120s")),
        "{said}"
    );
    assert_clean(&run);
    assert_clean(&local);
}
