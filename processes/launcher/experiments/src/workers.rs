//! The acps binary's workers: the project's models plugged into `acps-worker`, and the commands
//! a fleet starts them, or the user's own workers, with.

use acps_shared::{Environment, EnvironmentSpec, Serves};
use acps_worker::{EnvironmentFactory, EnvironmentProvideError};
use std::collections::HashMap;
use std::collections::hash_map::Entry;
use std::path::Path;
use std::process::Command;

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

/// The command of started worker `index`: `acps worker` of this executable, with a queue of
/// `queue_depth` tasks, which joins the run the fleet names in its environment. `workers` is the
/// size of the fleet, which decides whether workers poll before they block.
pub fn command(queue_depth: usize, workers: usize) -> impl Fn(usize) -> Command {
    let exe = std::env::current_exe();
    let spin = acps_fleet::processes::spin(workers).as_micros().to_string();
    move |index| {
        // A missing executable fails the spawn, which names it.
        let mut command = Command::new(exe.as_deref().unwrap_or(Path::new("acps")));
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
