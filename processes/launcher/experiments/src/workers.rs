//! The acps binary's workers: the project's models plugged into `acps-worker`, and the commands
//! a fleet starts them, or the user's own workers, with.

use acps_shared::{Environment, EnvironmentSpec, Serves};
use acps_worker::{EnvironmentFactory, EnvironmentProvideError};
use std::collections::HashMap;
use std::collections::hash_map::Entry;
use std::ffi::OsString;
use std::path::PathBuf;
use std::process::Command;
use std::sync::OnceLock;

/// Builds environments with `acps_models::environment::build` and keeps them for later tasks:
/// it serves any spec of the project's models, and the worker checks that what it built is
/// the environment a task needs (this build may configure it differently from the learner's).
#[derive(Default)]
pub struct ModelFactory {
    cache: HashMap<EnvironmentSpec, Box<dyn Environment>>,
}

impl EnvironmentFactory for ModelFactory {
    fn serves(&self) -> Serves {
        Serves::Any
    }

    fn environment(&mut self, spec: &EnvironmentSpec) -> Result<&mut dyn Environment, EnvironmentProvideError> {
        let environment = match self.cache.entry(*spec) {
            Entry::Occupied(built) => built.into_mut(),
            Entry::Vacant(slot) => {
                slot.insert(acps_models::environment::build(spec).map_err(EnvironmentProvideError::new)?)
            }
        };
        Ok(environment.as_mut())
    }
}

/// How this program starts itself again, when it is not its own executable: the Python
/// package's `acps` runs inside the interpreter, so its workers are `python -m acps worker`.
static THIS_PROGRAM: OnceLock<Vec<OsString>> = OnceLock::new();

/// Start this program's own workers and relays as `program` (its first element the
/// executable, the rest arguments before the subcommand) instead of this executable. Takes
/// effect once per process; returns false when a program was set already.
pub fn set_this_program(program: Vec<OsString>) -> bool {
    THIS_PROGRAM.set(program).is_ok()
}

/// A command that runs this program (`acps`), ready for a subcommand's arguments.
pub fn this_program() -> Command {
    match THIS_PROGRAM.get().and_then(|p| p.split_first()) {
        Some((executable, arguments)) => {
            let mut command = Command::new(executable);
            command.args(arguments);
            command
        }
        // A missing executable fails the spawn, which names it.
        None => Command::new(std::env::current_exe().unwrap_or_else(|_| PathBuf::from("acps"))),
    }
}

/// The command of started worker `index`: `acps worker` of this program, with a queue of
/// `queue_depth` tasks, which joins the run the fleet names in its environment. `workers` is the
/// size of the fleet, which decides whether workers poll before they block.
pub fn command(queue_depth: usize, workers: usize) -> impl Fn(usize) -> Command {
    let spin = acps_fleet::processes::spin(workers).as_micros().to_string();
    move |index| {
        let mut command = this_program();
        command.args([
            "worker",
            "--queue-depth",
            &queue_depth.to_string(),
            "--spin-us",
            &spin,
            "--name",
            &format!("worker-{index}"),
            "-q",
        ]);
        command
    }
}

/// The environment variable that tells a worker started from `--worker-command` its index
/// among the fleet's started workers (0..W-1).
pub const WORKER_INDEX_ENV: &str = "ACPS_WORKER_INDEX";

/// The command of started worker `index` from the user's shell command `command`: `sh -c "exec
/// CMD"`, so that quoting and variables work as in a shell and the process the fleet watches,
/// signals and reaps is the user's program itself.
pub fn user_command(command: String) -> impl Fn(usize) -> Command {
    move |index| {
        let mut shell = Command::new("sh");
        shell
            .arg("-c")
            .arg(format!("exec {command}"))
            .env(WORKER_INDEX_ENV, index.to_string());
        shell
    }
}
