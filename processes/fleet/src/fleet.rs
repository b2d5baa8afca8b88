//! [`Fleet`]: one run's lifecycle around the server, for `acps run`, `acps bench` and any program
//! that serves its own learners.
//!
//! A fleet owns the run's name and identity; when it starts, it removes what dead runs left in
//! shared memory (under any name); when it serves, it starts the worker processes it was asked
//! to, stops when the run is done or cannot go on (no worker for a grace period, Ctrl-C, the
//! caller's stop flag), and reaps them; when it is dropped, also on an error or Ctrl-C, it
//! removes the run's shared memory.

use crate::processes;
use crate::server::{
    self, FleetError, FleetJob, FleetProgress, ForwardingSource, Learners, Liveness, Observer, Remote, Seat,
    ServeOptions, Source, Started, TaskSource,
};
use acps_wire::ipc::{self, RunName, ServerError};
use std::os::unix::process::CommandExt as _;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Duration;

/// The environment variable that tells a worker process the fleet started which run to join
/// (read it with [`RunName::from_env`]).
pub use acps_wire::ipc::RUN_ENV;
use acps_wire::secret::RunSecret;
/// The environment variable that gives a worker process the fleet started the run's secret.
pub use acps_wire::secret::SECRET_ENV;

/// Set by the Ctrl-C handler of [`FleetBuilder::ctrl_c`]; one per process, as the handler is.
static INTERRUPTED: AtomicBool = AtomicBool::new(false);
/// Whether the handler could be installed (once per process).
static CTRL_C: OnceLock<Result<(), String>> = OnceLock::new();

/// Builds the command of worker process `index` (from 0). The fleet adds [`RUN_ENV`],
/// [`SECRET_ENV`], a null stdin and the niceness.
type WorkerCommand = Box<dyn Fn(usize) -> Command>;

/// The worker processes a fleet starts for every [`Fleet::serve`].
struct Spawn {
    count: usize,
    command: WorkerCommand,
    nice: u8,
}

/// Configures a [`Fleet`]; [`start`](Self::start) starts it.
///
/// ```no_run
/// use acps_fleet::{Fleet, RunName};
/// use std::process::Command;
///
/// let fleet = Fleet::builder("cannon".parse::<RunName>()?)
///     // Two processes of this very program, which serve as workers when told to.
///     .spawn_workers(2, |_| {
///         let mut command = Command::new(std::env::current_exe().expect("this program"));
///         command.arg("--worker");
///         command
///     })
///     .ctrl_c(true)
///     .start()?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[must_use]
pub struct FleetBuilder {
    run: RunName,
    secret: Option<RunSecret>,
    identity: Option<u64>,
    spawn: Option<(usize, WorkerCommand)>,
    nice: Option<u8>,
    liveness: Option<Liveness>,
    worker_startup: Option<Duration>,
    spin: Option<Duration>,
    start_with: usize,
    ctrl_c: bool,
}

/// A fleet that could not start.
#[derive(Debug, thiserror::Error)]
pub enum FleetStartError {
    /// The run could not be served: another learner of the same name is running
    /// ([`ServerError::Taken`]), or iceoryx2 failed.
    #[error(transparent)]
    Serve(#[from] ServerError),
    /// The Ctrl-C handler could not be installed: the program installed its own. Leave
    /// [`FleetBuilder::ctrl_c`] off and set [`Fleet::stop_flag`] from your handler instead.
    #[error("installing the Ctrl-C handler: {0}")]
    CtrlC(String),
    /// A setting outside the range that makes sense for it.
    #[error("fleet setting {field} must be {accepted}, got {got}")]
    Setting {
        /// The setting.
        field: &'static str,
        /// The accepted range.
        accepted: &'static str,
        /// The value given.
        got: String,
    },
}

impl FleetBuilder {
    /// The run's identity, which workers learn from the learner and which refuses workers of
    /// an earlier run of the same name. Default: a hash of the jobs' problems, environments
    /// and seeds.
    pub fn identity(mut self, identity: u64) -> Self {
        self.identity = Some(identity);
        self
    }

    /// The run's secret, which every worker's messages must carry. Default: 16 fresh random
    /// bytes. Set it only to hand workers the fleet does not start a secret made beforehand;
    /// [`Fleet::secret`] tells any fleet's.
    pub fn secret(mut self, secret: RunSecret) -> Self {
        self.secret = Some(secret);
        self
    }

    /// Start `count` worker processes for every [`Fleet::serve`], each from `command(index)`.
    /// The fleet tells them the run and its secret in the [`RUN_ENV`] and [`SECRET_ENV`]
    /// environment variables, gives them a null
    /// stdin, and lowers their priority (see [`worker_niceness`](Self::worker_niceness)). Without
    /// this the fleet starts none and serves the workers that join (then it waits for them,
    /// unless [`Liveness::no_workers`] is set).
    pub fn spawn_workers(mut self, count: usize, command: impl Fn(usize) -> Command + 'static) -> Self {
        self.spawn = Some((count, Box::new(command)));
        self
    }

    /// The niceness (0..=19) of started workers. Default: 10 when the workers and the learner
    /// outnumber the cores, else 0. Every worker waits for the learner's answers, so the learner
    /// should get a core as soon as it wakes.
    pub fn worker_niceness(mut self, nice: u8) -> Self {
        self.nice = Some(nice);
        self
    }

    /// When workers are given up on. Default: [`Liveness::default`] when the fleet starts
    /// workers; when it starts none, the same but waiting for workers forever.
    pub fn liveness(mut self, liveness: Liveness) -> Self {
        self.liveness = Some(liveness);
        self
    }

    /// How long started workers may take to connect ([`Liveness::startup`]), whatever the
    /// liveness otherwise is. Default: [`WORKER_STARTUP`](crate::server::WORKER_STARTUP).
    pub fn worker_startup(mut self, startup: Duration) -> Self {
        self.worker_startup = Some(startup);
        self
    }

    /// How long the server polls before it blocks when idle. Default: 50 us when every process
    /// of the fleet has a core of its own, else 0.
    pub fn spin(mut self, spin: Duration) -> Self {
        self.spin = Some(spin);
        self
    }

    /// Hand out the first tasks only once `workers` workers have asked for them (a benchmark's
    /// clock then measures the whole fleet). Default 0: at once.
    pub fn start_with(mut self, workers: usize) -> Self {
        self.start_with = workers;
        self
    }

    /// Stop serving on Ctrl-C (SIGINT, SIGTERM, SIGHUP), with [`FleetError::Interrupted`].
    /// Installs a handler for the whole process, once. Default: off.
    pub fn ctrl_c(mut self, on: bool) -> Self {
        self.ctrl_c = on;
        self
    }

    /// Start the fleet: install the Ctrl-C handler if asked, remove what
    /// dead runs left in shared memory (those of any name whose every node is dead, and the dead
    /// nodes of this run: workers started by hand may already wait for it), and take the run's
    /// learner seat, which is refused at once while another learner of the same run name lives.
    pub fn start(self) -> Result<Fleet, FleetStartError> {
        let run = self.run;
        let setting = |ok: bool, field, accepted, got: String| {
            if ok {
                Ok(())
            } else {
                Err(FleetStartError::Setting { field, accepted, got })
            }
        };
        if let Some(nice) = self.nice {
            setting(
                nice <= processes::MAX_NICE,
                "worker_niceness",
                "in 0..=19",
                nice.to_string(),
            )?;
        }
        if let Some(liveness) = &self.liveness {
            setting(
                liveness.silence > Duration::ZERO,
                "liveness.silence",
                "> 0 (how long a worker holding tasks may say nothing)",
                format!("{:?}", liveness.silence),
            )?;
            setting(
                liveness.rollout_factor >= 1,
                "liveness.rollout_factor",
                ">= 1 (times the slowest rollout)",
                liveness.rollout_factor.to_string(),
            )?;
            if let Some(grace) = liveness.no_workers {
                setting(
                    grace > Duration::ZERO,
                    "liveness.no_workers",
                    "> 0, or None to wait for workers for ever",
                    format!("{grace:?}"),
                )?;
            }
            if let Some(startup) = liveness.startup {
                setting(
                    startup > Duration::ZERO,
                    "liveness.startup",
                    "> 0, or None to wait for started workers for ever",
                    format!("{startup:?}"),
                )?;
            }
        }
        if self.ctrl_c {
            CTRL_C
                .get_or_init(|| {
                    ctrlc::set_handler(|| INTERRUPTED.store(true, Ordering::Relaxed)).map_err(|e| e.to_string())
                })
                .clone()
                .map_err(FleetStartError::CtrlC)?;
        }
        let cleaned = ipc::clean_dead_runs();
        if !cleaned.is_empty() {
            tracing::info!("removed the shared memory of {} dead runs", cleaned.len());
        }
        // Listing nodes can fail while one is being created or removed; the next start looks
        // again.
        let _ = ipc::clean_stale(&run);
        let secret = match self.secret {
            Some(secret) => secret,
            None => RunSecret::generate(&run).map_err(ServerError::from)?,
        };
        // Before any worker starts: those of a refused fleet would join the other learner.
        let seat = Seat::take(&run, secret)?;
        let workers = self.spawn.as_ref().map_or(0, |(count, _)| *count);
        let mut liveness = self.liveness.unwrap_or(Liveness {
            no_workers: (workers > 0).then_some(Liveness::default().no_workers).flatten(),
            ..Liveness::default()
        });
        if let Some(startup) = self.worker_startup {
            setting(
                startup > Duration::ZERO,
                "worker_startup",
                "> 0 (how long started workers may take to connect)",
                format!("{startup:?}"),
            )?;
            liveness.startup = Some(startup);
        }
        Ok(Fleet {
            seat: Some(seat),
            run: OwnedRun(run),
            secret,
            identity: self.identity,
            spin: self.spin.unwrap_or_else(|| processes::spin(workers)),
            spawn: self.spawn.map(|(count, command)| Spawn {
                count,
                command,
                nice: self.nice.unwrap_or_else(|| processes::default_nice(count)),
            }),
            liveness,
            start_with: self.start_with,
            ctrl_c: self.ctrl_c,
            stop: Arc::new(AtomicBool::new(false)),
        })
    }
}

/// One run of learners served to worker processes: it owns the run's name and identity, removes
/// what dead runs left when it starts, starts and reaps worker processes, stops on Ctrl-C or when
/// no worker can go on, and removes its shared memory when dropped.
///
/// ```no_run
/// use acps_fleet::{Fleet, FleetJob};
/// # fn jobs() -> Vec<FleetJob> { unimplemented!() }
///
/// let mut jobs: Vec<FleetJob> = jobs();
/// let mut fleet = Fleet::builder("cannon".parse()?).ctrl_c(true).start()?;
/// println!("start workers with ACPS_RUN={}", fleet.run());
/// let report = fleet.serve(&mut jobs, &mut |progress: &acps_fleet::FleetProgress| {
///     eprintln!("{} outcomes from {} workers", progress.outcomes, progress.workers);
/// })?;
/// println!("{} outcomes, {} tasks re-issued", report.outcomes, report.reissued);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct Fleet {
    /// The seat [`start`](FleetBuilder::start) took, until [`serve`](Self::serve) uses it.
    /// Dropped before `run`: the learner's node must be gone before the run's files are removed.
    seat: Option<Seat>,
    run: OwnedRun,
    secret: RunSecret,
    identity: Option<u64>,
    spawn: Option<Spawn>,
    liveness: Liveness,
    spin: Duration,
    start_with: usize,
    ctrl_c: bool,
    stop: Arc<AtomicBool>,
}

impl Fleet {
    /// A fleet for the run `run`: its shared-memory prefix, and how workers started by hand join
    /// it.
    pub fn builder(run: RunName) -> FleetBuilder {
        FleetBuilder {
            run,
            secret: None,
            identity: None,
            spawn: None,
            nice: None,
            liveness: None,
            worker_startup: None,
            spin: None,
            start_with: 0,
            ctrl_c: false,
        }
    }

    /// The run's name.
    pub fn run(&self) -> &RunName {
        &self.run.0
    }

    /// The run's secret. Workers the fleet starts get it in [`SECRET_ENV`]; workers started by
    /// hand read it from [`RunSecret::path`], which the fleet writes while it serves. Give it to
    /// workers you start by other means in [`SECRET_ENV`].
    pub fn secret(&self) -> RunSecret {
        self.secret
    }

    /// A flag that stops [`serve`](Self::serve) with [`FleetError::Interrupted`] when set, from
    /// any thread.
    pub fn stop_flag(&self) -> Arc<AtomicBool> {
        self.stop.clone()
    }

    /// Whether the stop flag is set, or Ctrl-C was pressed (with [`FleetBuilder::ctrl_c`]): for
    /// a program that waits for something else between serves.
    pub fn interrupted(&self) -> bool {
        self.stop.load(Ordering::Relaxed) || (self.ctrl_c && INTERRUPTED.load(Ordering::Relaxed))
    }

    /// When workers are given up on.
    pub fn liveness(&self) -> Liveness {
        self.liveness
    }

    /// Serve `jobs` until every one is done: start the worker processes, if any, hand out
    /// tasks, re-issue those of workers that die or hang, and reap the processes. `observer`
    /// sees the progress every tick and every job's learner after each accepted outcome. The
    /// run's learner seat, taken at start, is released when it returns, and taken again by the
    /// next `serve` ([`FleetError::Seat`] if another learner took it meanwhile).
    pub fn serve(&mut self, jobs: &mut [FleetJob], observer: &mut dyn Observer) -> Result<FleetProgress, FleetError> {
        self.serve_with(&mut Learners(jobs), observer, None)
    }

    /// [`serve`](Self::serve) any [`TaskSource`], and, with a [`Remote`], its peers on other
    /// hosts beside the local workers: what `acps run --listen` does.
    pub fn serve_with(
        &mut self,
        source: &mut dyn TaskSource,
        observer: &mut dyn Observer,
        remote: Option<&mut dyn Remote>,
    ) -> Result<FleetProgress, FleetError> {
        self.serve_source(&mut Source::Own(source), observer, remote)
    }

    /// [`serve`](Self::serve) a [`ForwardingSource`]: what `acps relay` does with the tasks of
    /// its remote learner.
    pub fn serve_forwarded(
        &mut self,
        source: &mut dyn ForwardingSource,
        observer: &mut dyn Observer,
    ) -> Result<FleetProgress, FleetError> {
        self.serve_source(&mut Source::Forwarding(source), observer, None)
    }

    fn serve_source(
        &mut self,
        source: &mut Source<'_>,
        observer: &mut dyn Observer,
        remote: Option<&mut dyn Remote>,
    ) -> Result<FleetProgress, FleetError> {
        let identity = self.identity.unwrap_or_else(|| source.identity());
        // The seat taken at start, or, for a fleet that served before, the seat again.
        let seat = match self.seat.take() {
            Some(seat) => seat,
            None => Seat::take(&self.run.0, self.secret)?,
        };
        let mut children = match &self.spawn {
            Some(spawn) => start_workers(&self.run.0, self.secret, spawn)?,
            None => Vec::new(),
        };
        let launched = children.len();
        let mut remote = remote;
        if let Some(remote) = remote.as_deref_mut() {
            let environments: Vec<_> = (0..source.jobs()).map(|job| source.environment(job)).collect();
            let sizes: Vec<_> = (0..source.jobs()).map(|job| source.sizes(job)).collect();
            if let Err(error) = remote.start(&self.run.0, identity, &environments, &sizes) {
                processes::reap(&mut children);
                return Err(FleetError::Remote(error));
            }
        }
        let stop = || self.interrupted();
        let served = server::serve(
            source,
            &self.run.0,
            &seat,
            ServeOptions {
                identity,
                spin: self.spin,
                start_with: self.start_with,
                liveness: self.liveness,
            },
            &stop,
            observer,
            &mut || Started {
                running: processes::running(&mut children),
                launched,
                failed: processes::failed(&mut children),
            },
            remote.as_deref_mut(),
        );
        // Before the seat goes: a remote's own node of the run must be gone with it.
        if let Some(remote) = remote {
            remote.finish(served.is_ok());
        }
        // Before the workers are reaped: one that was not told to stop (busy in a rollout when
        // the run ended) leaves once it finds the learner's node gone.
        drop(seat);
        processes::reap(&mut children);
        served.map_err(|error| match (error, &self.spawn) {
            (
                FleetError::NeverConnected {
                    run, started, waited, ..
                },
                Some(spawn),
            ) => FleetError::NeverConnected {
                run,
                started,
                waited,
                command: shown((spawn.command)(0)),
            },
            (
                FleetError::NoWorkers {
                    run,
                    started,
                    failed,
                    waited,
                    refused,
                    ..
                },
                _,
            ) => FleetError::NoWorkers {
                run,
                started,
                failed,
                waited,
                refused,
                exits: processes::exits(&mut children),
            },
            (error, _) => error,
        })
    }
}

/// A fleet's run, whose shared memory goes when the fleet is dropped (after its learner's node).
struct OwnedRun(RunName);

impl Drop for OwnedRun {
    /// Remove the run's shared memory, or, while processes the fleet did not start (workers
    /// started by hand) still use it, only what dead nodes left: the next fleet to start removes
    /// the rest once they are gone.
    fn drop(&mut self) {
        let run = &self.0;
        let _ = ipc::clean_stale(run);
        match ipc::live_nodes(run) {
            Ok(0) => {
                let _ = ipc::remove_run_files(run);
            }
            alive => tracing::info!(
                "run '{run}': {} processes this fleet did not start (workers started by hand) still use its shared memory; the next fleet to start removes it once they are gone",
                alive.map_or("some".to_string(), |n| n.to_string())
            ),
        }
    }
}

/// `command` as a user would type it: the program and its arguments, those with spaces quoted.
fn shown(command: Command) -> String {
    std::iter::once(command.get_program())
        .chain(command.get_args())
        .map(|part| {
            let part = part.to_string_lossy();
            if part.contains(char::is_whitespace) {
                format!("'{part}'")
            } else {
                part.into_owned()
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// Start `spawn`'s worker processes for `run`, whose secret is `secret`.
fn start_workers(run: &RunName, secret: RunSecret, spawn: &Spawn) -> Result<Vec<Child>, FleetError> {
    let nice = spawn.nice;
    let mut children = Vec::with_capacity(spawn.count);
    for index in 0..spawn.count {
        let mut command = (spawn.command)(index);
        command
            .env(RUN_ENV, run.as_str())
            .env(SECRET_ENV, secret.to_hex())
            .stdin(Stdio::null());
        // SAFETY: the closure runs in the child between fork and exec, and only makes a
        // syscall (setpriority is async-signal-safe); its failure leaves the niceness as is.
        unsafe {
            command.pre_exec(move || {
                libc::setpriority(libc::PRIO_PROCESS as _, 0, nice.into());
                Ok(())
            });
        }
        match command.spawn() {
            Ok(child) => children.push(child),
            Err(error) => {
                processes::reap(&mut children);
                return Err(FleetError::Spawn {
                    program: format!("{:?}", command.get_program()),
                    error: error.to_string(),
                });
            }
        }
    }
    Ok(children)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The message `builder` fails to start with.
    fn refusal(builder: FleetBuilder) -> String {
        match builder.start() {
            Err(error) => error.to_string(),
            Ok(_) => panic!("the fleet started"),
        }
    }

    #[test]
    fn bad_settings_are_refused_naming_the_setting_and_its_range() {
        let fleet = || Fleet::builder(RunName::new("settings").unwrap());
        let liveness = |change: fn(&mut Liveness)| {
            let mut liveness = Liveness::default();
            change(&mut liveness);
            fleet().liveness(liveness)
        };
        let cases = [
            (
                fleet().worker_niceness(20),
                "fleet setting worker_niceness must be in 0..=19, got 20",
            ),
            (
                liveness(|l| l.silence = Duration::ZERO),
                "fleet setting liveness.silence must be > 0 (how long a worker holding tasks may say nothing), got 0ns",
            ),
            (
                liveness(|l| l.rollout_factor = 0),
                "fleet setting liveness.rollout_factor must be >= 1 (times the slowest rollout), got 0",
            ),
            (
                liveness(|l| l.no_workers = Some(Duration::ZERO)),
                "fleet setting liveness.no_workers must be > 0, or None to wait for workers for ever, got 0ns",
            ),
            (
                liveness(|l| l.startup = Some(Duration::ZERO)),
                "fleet setting liveness.startup must be > 0, or None to wait for started workers for ever, got 0ns",
            ),
            (
                fleet().worker_startup(Duration::ZERO),
                "fleet setting worker_startup must be > 0 (how long started workers may take to connect), got 0ns",
            ),
        ];
        for (builder, message) in cases {
            assert_eq!(refusal(builder), message);
        }
    }
}
