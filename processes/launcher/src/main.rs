//! `acps`: the command line of Active Contextual Policy Search. Parse ([`cli`]), then carry
//! the command out ([`commands`]) with the libraries: acps-experiments runs experiments and
//! writes run directories, acps-reports draws and compares them.

mod bench;
mod cli;
mod commands;
mod evaluate;

use acps_wire::ipc;
use clap::Parser;
use cli::Cli;
use std::process::ExitCode;

/// Log to stderr at the level -v asks for, or as ACPS_LOG says; warnings by default.
fn init_logging(verbose: u8) {
    let level = match verbose {
        0 => "warn",
        1 => "info",
        2 => "debug",
        _ => "trace",
    };
    // Zenoh's own notes (its settings, reconnections) say nothing an acps user acts on: acps
    // reports what matters in its words.
    let zenoh = [
        "zenoh",
        "zenoh_transport",
        "zenoh_link_commons",
        "zenoh_link_tcp",
        "zenoh_config",
    ]
    .map(|target| format!(",{target}=error"))
    .concat();
    let filter = tracing_subscriber::EnvFilter::try_from_env("ACPS_LOG")
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(format!("{level}{zenoh}")));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .init();
    ipc::quiet_iceoryx2_log();
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    init_logging(cli.verbosity());
    match commands::run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => match error.downcast_ref::<commands::Stopped>() {
            Some(stopped @ (commands::Stopped::Interrupted { .. } | commands::Stopped::RelayInterrupted)) => {
                eprintln!("{stopped}");
                ExitCode::from(130)
            }
            _ => {
                eprintln!("error: {error:#}");
                ExitCode::from(2)
            }
        },
    }
}
