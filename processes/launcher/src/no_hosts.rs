//! `hosts.rs` in a build without the `hosts` feature (where it is `crate::hosts`): every
//! multi-host command is refused, saying how to build an `acps` that has it. Zenoh is about 200 of the crates a clean build
//! compiles, which the main job and every single-host run do without.

use crate::bench::BenchOptions;
use crate::cli::{NetArgs, RelayArgs};
use acps_fleet::Remote;
use acps_wire::ipc::RunName;
use std::path::Path;
use std::process::Command;

/// Any lease passes the parser: `--lease` is refused as a whole by [`plan`].
pub(crate) fn lease_ok(_seconds: f64) -> bool {
    true
}

/// The error of `what` in this build.
fn unavailable(what: &str) -> anyhow::Error {
    anyhow::anyhow!(
        "{what} is for workers on other hosts, which this build of acps leaves out (it spares compiling Zenoh): build one that has it with `cargo build --release -p acps --features hosts` (docs/HOSTS.md) and run target/release/acps"
    )
}

/// Refuses `what`: this build has no multi-host command.
pub(crate) fn available(what: &str) -> anyhow::Result<()> {
    Err(unavailable(what))
}

/// A learner's listener for relays: none can exist in this build.
pub(crate) enum Plan {}

/// `None` when no setting of the network of hosts is given, else the refusal naming the first.
pub(crate) fn plan(args: &NetArgs, listen: &[String]) -> anyhow::Result<Option<Plan>> {
    let given = [
        ("--listen", !listen.is_empty()),
        ("--relay-key", args.relay_key.is_some()),
        ("--no-relay-key", args.no_relay_key),
        ("--zenoh-config", args.zenoh_config.is_some()),
        ("--lease", args.lease.is_some()),
    ];
    match given.iter().find(|(_, set)| *set) {
        Some((flag, _)) => Err(unavailable(flag)),
        None => Ok(None),
    }
}

impl Plan {
    /// Never called: no `Plan` exists.
    pub(crate) fn open(self, _: &NetArgs, _: &RunName, _: &Path, _: bool) -> anyhow::Result<Box<dyn Remote>> {
        match self {}
    }
}

/// Refuses `acps relay`.
pub(crate) fn relay(_: RelayArgs) -> anyhow::Result<()> {
    Err(unavailable("acps relay"))
}

/// Refuses a relay of `acps bench --relay` (which `available` refused before).
pub(crate) fn relay_command(_: &RunName, _: &BenchOptions, _: usize) -> anyhow::Result<(Box<dyn Remote>, Command)> {
    Err(unavailable("acps bench --relay"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    /// The network arguments of `acps run function ARGS`.
    fn net(args: &[&str]) -> (NetArgs, Vec<String>) {
        let cli = crate::cli::Cli::try_parse_from(["acps", "run", "function"].iter().chain(args)).unwrap();
        match cli.command {
            crate::cli::Command::Run(run) => (run.net, run.listen),
            _ => unreachable!("parsed as acps run"),
        }
    }

    #[test]
    fn every_setting_of_the_hosts_network_is_refused_naming_it_and_the_feature() {
        let (args, listen) = net(&[]);
        assert!(plan(&args, &listen).unwrap().is_none());
        for (given, flag) in [
            (&["--listen", "tcp/127.0.0.1:7447"][..], "--listen"),
            (&["--relay-key", "k"][..], "--relay-key"),
            (&["--no-relay-key"][..], "--no-relay-key"),
            (&["--zenoh-config", "z.json5"][..], "--zenoh-config"),
            (&["--lease", "5"][..], "--lease"),
        ] {
            let (args, listen) = net(given);
            let error = plan(&args, &listen)
                .err()
                .unwrap_or_else(|| panic!("{given:?} accepted"))
                .to_string();
            assert!(
                error.starts_with(&format!("{flag} is for workers on other hosts"))
                    && error.contains("cargo build --release -p acps --features hosts"),
                "{error}"
            );
        }
        assert!(
            available("acps bench --relay")
                .unwrap_err()
                .to_string()
                .starts_with("acps bench --relay is for")
        );
        let cli = crate::cli::Cli::try_parse_from(["acps", "relay", "--connect", "tcp/10.0.0.1:7447"]).unwrap();
        let crate::cli::Command::Relay(args) = cli.command else {
            unreachable!("parsed as acps relay")
        };
        let error = relay(args).unwrap_err().to_string();
        assert!(error.starts_with("acps relay is for workers on other hosts"), "{error}");
    }
}
