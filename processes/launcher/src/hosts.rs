//! Workers on other hosts: a learner's `--listen`, `acps relay`, and `acps bench --relay`. Built
//! with the `hosts` feature (Zenoh); without it, `no_hosts.rs` takes this module's place and
//! refuses each, saying how to build an `acps` that has them.

use crate::bench::BenchOptions;
use crate::cli::{NetArgs, RelayArgs};
use crate::commands::Stopped;
use acps_fleet::{Fleet, FleetProgress, Remote};
use acps_relay::net::{self, RelayKey};
use acps_relay::{Listener, NetOptions, RelayOptions};
use acps_wire::ipc::RunName;
use anyhow::{Context, bail};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::Path;
use std::process::Command;
use std::time::Duration;

/// Whether `seconds` is a lease the network accepts (`--lease`).
pub(crate) fn lease_ok(seconds: f64) -> bool {
    net::LEASES.contains(&seconds)
}

/// Nothing to refuse: this build has every multi-host command.
pub(crate) fn available(_what: &str) -> anyhow::Result<()> {
    Ok(())
}

/// A learner's listener for relays, checked before its run directory exists and opened after.
pub(crate) struct Plan(NetOptions);

/// The listener `listen` asks for, or `None` without `--listen`.
pub(crate) fn plan(args: &NetArgs, listen: &[String]) -> anyhow::Result<Option<Plan>> {
    Ok(net_options(args, listen, &[])?.map(Plan))
}

impl Plan {
    /// Listen for the relays of run `name`, whose run directory is `out` (where the relays' key
    /// is made, unless --relay-key gives it), and tell the user how relays join.
    pub(crate) fn open(
        self,
        args: &NetArgs,
        name: &RunName,
        out: &Path,
        quiet: bool,
    ) -> anyhow::Result<Box<dyn Remote>> {
        let Plan(mut options) = self;
        let (key, told) = learner_key(args, out)?;
        options.key = key;
        let listener = Listener::open(name, &options)
            .with_context(|| format!("--listen {}", options.listen.join(" --listen ")))?;
        if args.no_relay_key {
            eprintln!(
                "warning: run '{name}' admits relays without credentials (--no-relay-key): any process of this host can join as a relay and report outcomes"
            );
        }
        if !quiet {
            eprintln!(
                "run '{name}' serves relays at {}: on each other host, `acps relay --connect ENDPOINT{}",
                options.listen.join(", "),
                if told.is_empty() { "`".to_string() } else { told }
            );
        }
        Ok(Box::new(listener))
    }
}

/// Serve this host's workers from a learner on another host.
pub(crate) fn relay(args: RelayArgs) -> anyhow::Result<()> {
    let run = crate::commands::run_name(args.run.as_deref())?;
    let Some(net) = net_options(&args.net, &[], &args.connect)? else {
        bail!("--connect ENDPOINT is missing: where the learner listens (its --listen)");
    };
    args.started.check()?;
    let local = args
        .local_run
        .clone()
        .unwrap_or_else(|| format!("relay-{}", std::process::id()));
    let builder = Fleet::builder(RunName::new(&local).with_context(|| format!("--local-run {local}"))?).ctrl_c(true);
    let mut fleet = args
        .started
        .spawn(builder)
        .start()
        .with_context(|| format!("--local-run {local}"))?;
    if !args.quiet {
        eprintln!(
            "relay: this host's run is '{local}' (workers started by hand: `acps worker --run {local}`); asking {} for tasks",
            args.connect.join(", ")
        );
    }
    let options = RelayOptions {
        net,
        run,
        identity: 0,
        startup_timeout: Duration::from_secs_f64(args.startup_timeout),
        wait_for_learner: Duration::from_secs_f64(args.wait_for_learner),
        queue: args.queue,
    };
    let bar = (!args.quiet).then(|| {
        ProgressBar::new_spinner()
            .with_style(ProgressStyle::with_template("{spinner} relay: {msg}, {elapsed}").expect("a valid template"))
    });
    let mut observer = |progress: &FleetProgress| {
        if let Some(bar) = &bar {
            bar.set_message(format!(
                "{} outcomes from {} workers",
                progress.outcomes, progress.workers
            ));
            bar.tick();
        }
    };
    let served = acps_relay::relay::serve(&mut fleet, &options, &mut observer);
    if let Some(bar) = &bar {
        bar.finish_and_clear();
    }
    match served {
        Ok(report) => {
            if !args.quiet {
                eprintln!(
                    "relay: run '{}' is over: {} outcomes forwarded in {} serves",
                    report.run, report.outcomes, report.serves
                );
            }
            Ok(())
        }
        Err(acps_relay::RelayError::Fleet(acps_fleet::FleetError::Interrupted)) => {
            Err(Stopped::RelayInterrupted.into())
        }
        Err(error) => Err(anyhow::Error::new(error).context(format!("relay to {}", args.connect.join(", ")))),
    }
}

/// The network settings of a learner that listens on `listen` or a relay that connects to
/// `connect`; `None` when there is neither.
fn net_options(args: &NetArgs, listen: &[String], connect: &[String]) -> anyhow::Result<Option<NetOptions>> {
    if listen.is_empty() && connect.is_empty() {
        if args.zenoh_config.is_some() || args.lease.is_some() {
            bail!(
                "--zenoh-config and --lease set up the network of hosts, which only --listen (acps run) or --connect (acps relay) opens"
            );
        }
        return Ok(None);
    }
    let (flag, endpoints) = if listen.is_empty() {
        ("--connect", connect)
    } else {
        ("--listen", listen)
    };
    for endpoint in endpoints {
        net::check_endpoint(endpoint).with_context(|| format!("{flag} {endpoint}"))?;
    }
    if let Some(path) = &args.zenoh_config
        && !path.is_file()
    {
        bail!("--zenoh-config {}: not a readable file", path.display());
    }
    let key = match &args.relay_key {
        // A learner's key is made or taken once its run directory exists (`learner_key`).
        Some(path) if listen.is_empty() => Some(RelayKey::read(path).context("--relay-key")?),
        None if listen.is_empty() && !args.no_relay_key && args.zenoh_config.is_none() => bail!(
            "--relay-key FILE is missing: a copy of the relay.key its learner made in its run directory (or --no-relay-key for a learner that admits relays without credentials)"
        ),
        _ => None,
    };
    Ok(Some(NetOptions {
        listen: listen.to_vec(),
        connect: connect.to_vec(),
        lease: args.lease.map_or(net::DEFAULT_LEASE, Duration::from_secs_f64),
        config_file: args.zenoh_config.clone(),
        key,
    }))
}

/// The relays' key of a learner whose run directory is `out`, made there unless taken from
/// --relay-key, or none (--no-relay-key, or --zenoh-config without --relay-key), and the words
/// that tell the user how relays join with it.
fn learner_key(args: &NetArgs, out: &Path) -> anyhow::Result<(Option<RelayKey>, String)> {
    if args.no_relay_key || (args.zenoh_config.is_some() && args.relay_key.is_none()) {
        return Ok((None, String::new()));
    }
    let path = args.relay_key.clone().unwrap_or_else(|| out.join("relay.key"));
    let (key, made) = RelayKey::make_or_take(&path).context("--relay-key")?;
    let told = format!(
        " --relay-key relay.key` with this host's address and a copy of {} ({})",
        path.display(),
        if made { "made now" } else { "made before" }
    );
    Ok((Some(key), told))
}

/// Listen for relays of run `name` on a free loopback port, and the command of `acps relay` (this
/// executable) there with `workers` workers, its own local run named after `name`.
pub(crate) fn relay_command(
    name: &RunName,
    options: &BenchOptions,
    workers: usize,
) -> anyhow::Result<(Box<dyn Remote>, Command)> {
    // A port the system had free a moment ago; Zenoh binds it again at once.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|socket| socket.local_addr())
        .context("finding a free loopback port")?
        .port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    // Among the run's files in /dev/shm, which go with them.
    let key_file = std::path::PathBuf::from(format!("/dev/shm/{}relay.key", name.prefix()));
    let (key, _) = RelayKey::make_or_take(&key_file)?;
    let net = NetOptions {
        listen: vec![endpoint.clone()],
        connect: Vec::new(),
        lease: net::DEFAULT_LEASE,
        config_file: None,
        key: Some(key),
    };
    let listener = Listener::open(name, &net).with_context(|| format!("listening at {endpoint}"))?;
    let mut command = acps_experiments::workers::this_program();
    command.args([
        "relay",
        "--connect",
        &endpoint,
        "--run",
        name.as_str(),
        "--local-run",
        &format!("{name}-host"),
    ]);
    command.arg("--relay-key").arg(&key_file);
    command.args(["--workers", &workers.to_string()]);
    command.args(["--worker-queue-depth", &options.worker_queue_depth.to_string(), "-q"]);
    if let Some(nice) = options.worker_nice {
        command.args(["--worker-nice", &nice.to_string()]);
    }
    Ok((Box::new(listener), command))
}
