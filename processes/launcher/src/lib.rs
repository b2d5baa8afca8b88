//! `acps`: the command line of Active Contextual Policy Search as a function, [`main`], for
//! the `acps` executable and the Python package's `acps` command. Parse (`cli`), then carry
//! the command out (`commands`) with the libraries: acps-experiments runs experiments and
//! writes run directories, acps-reports draws and compares them. Programs that want acps as a
//! library use those crates, not this one.
#![warn(missing_docs)]

mod bench;
mod cli;
mod commands;
mod evaluate;
#[cfg(feature = "hosts")]
mod hosts;
// Built and tested in every build (the tests turn `hosts` on); used in builds without it.
#[cfg_attr(feature = "hosts", allow(dead_code))]
mod no_hosts;
#[cfg(not(feature = "hosts"))]
use no_hosts as hosts;

use acps_experiments::file::shown_value;
use acps_wire::ipc;
use clap::Parser;
use cli::Cli;
use std::ffi::OsString;
use std::sync::OnceLock;

/// Log to stderr at the level -v asks for, or as ACPS_LOG says; warnings by default.
fn init_logging(verbose: u8) {
    let level = match verbose {
        0 => "warn",
        1 => "info",
        2 => "debug",
        _ => "trace",
    };
    // Zenoh's own notes (its settings, reconnections) say nothing an acps user acts on: acps
    // reports what matters in its words, and every Zenoh call that fails returns its error to
    // acps. Its log stays off by default: a relay killed mid-query made it print "ERROR Received
    // Query for unknown key_expr" into a run that went on unharmed. -v shows its errors.
    let zenoh_level = if verbose == 0 { "off" } else { "error" };
    let zenoh = [
        "zenoh",
        "zenoh_transport",
        "zenoh_link_commons",
        "zenoh_link_tcp",
        "zenoh_config",
    ]
    .map(|target| format!(",{target}={zenoh_level}"))
    .concat();
    let default = || tracing_subscriber::EnvFilter::new(format!("{level}{zenoh}"));
    let filter = match std::env::var("ACPS_LOG") {
        Ok(directives) => tracing_subscriber::EnvFilter::try_new(&directives).unwrap_or_else(|error| {
            // Ignoring it silently would leave the user wondering why nothing more is logged.
            eprintln!(
                "warning: ACPS_LOG={directives:?} is not a log filter ({error}); logging at level {level} (for example ACPS_LOG=debug or ACPS_LOG=acps_fleet=trace)"
            );
            default()
        }),
        Err(_) => default(),
    };
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .try_init()
        // A second command in one process (the Python package's) keeps the first one's logger.
        .ok();
    ipc::quiet_iceoryx2_log();
}

/// `text` with every word of more than
/// [`SHOWN_CHARS`](acps_experiments::file::SHOWN_CHARS) characters shown cut, as a file's values
/// are: clap echoes a bad value whole, twice for some errors (a 100 kB method name made 200 kB
/// of error).
fn shortened(text: &str) -> String {
    let lines: Vec<String> = text
        .split('\n')
        .map(|line| line.split(' ').map(shown_value).collect::<Vec<_>>().join(" "))
        .collect();
    lines.join("\n")
}

/// The command line [`main`] runs.
static COMMAND_LINE: OnceLock<Vec<String>> = OnceLock::new();

/// The command line [`main`] runs, the program first.
fn command_line() -> &'static [String] {
    COMMAND_LINE.get().map_or(&[], Vec::as_slice)
}

/// Run the command line `args` (the program's name first, as `std::env::args_os` gives it) and
/// say how it ended, as the process's exit status: 0 done, 2 an error (printed to stderr), 130
/// stopped by Ctrl-C. Help and usage errors print and exit the process as clap does.
///
/// ```no_run
/// let status = acps::main(["acps", "experiment", "function", "--runs", "1"]);
/// assert_eq!(status, 0);
/// ```
pub fn main<I, T>(args: I) -> u8
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let args: Vec<OsString> = args.into_iter().map(Into::into).collect();
    // Kept for the command that continues an interrupted run: it is what the user typed (the
    // Python package's `acps` runs inside an interpreter, whose own arguments differ).
    let _ = COMMAND_LINE.set(args.iter().map(|a| a.to_string_lossy().into_owned()).collect());
    let cli = match Cli::try_parse_from(args) {
        Ok(cli) => cli,
        // Help and version print as clap does.
        Err(error) if !error.use_stderr() => error.exit(),
        Err(error) => {
            eprint!("{}", shortened(&error.render().to_string()));
            return 2;
        }
    };
    // Every file a command creates (the run directory, checkpoints, iceoryx2's shared memory
    // and its management files, some of which iceoryx2 makes 0666) is its user's alone: no
    // other user can read a run's data or write into its services. Started workers inherit it.
    // SAFETY: umask only swaps the process's file-creation mask.
    unsafe { libc::umask(0o077) };
    init_logging(cli.verbosity());
    match commands::run(cli.command) {
        Ok(()) => 0,
        Err(error) => match error.downcast_ref::<commands::Stopped>() {
            // As other Unix tools: whoever closed the output has what they wanted.
            Some(commands::Stopped::Closed) => 0,
            Some(stopped @ (commands::Stopped::Interrupted { .. } | commands::Stopped::RelayInterrupted)) => {
                eprintln!("{stopped}");
                130
            }
            _ => {
                eprintln!("error: {}", commands::described(&error));
                2
            }
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use acps_experiments::file::SHOWN_CHARS;

    #[test]
    fn a_long_value_in_a_usage_error_is_shown_cut_with_its_length() {
        let long = "x".repeat(100_000);
        let error = format!("error: invalid value '{long}' for '--method <METHOD>'\n  [possible values: a, b]\n");
        let shown = shortened(&error);
        assert!(shown.len() < 300, "{} bytes", shown.len());
        assert!(
            shown.contains(&format!("'{} ... (100002 characters) for", "x".repeat(SHOWN_CHARS - 1))),
            "{shown}"
        );
        assert!(shown.ends_with("[possible values: a, b]\n"), "{shown}");
        let short = "error: unexpected argument '--typo' found\n\nUsage: acps run <NAME>\n";
        assert_eq!(shortened(short), short);
    }
}
