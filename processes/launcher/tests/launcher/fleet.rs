//! The worker fleet end to end: real learner and worker processes over iceoryx2.

use crate::{assert_clean, run_name, succeeded, temp_dir, watched};
use acps_experiments::paper::{self, Sim};
use acps_experiments::settings::ExperimentFile;
use acps_experiments::workers::ModelFactory;
use acps_fleet::{Fleet, FleetJob, FleetProgress, Liveness};
use acps_learner::{Method, run_in_process};
use acps_models::contextual_function::{ContextualFunction, DEFAULT_N_THETA};
use acps_models::environment;
use acps_models::robot::Robot;
use acps_models::throw::{Simulator, SpeedLimits, Targets, ThrowDesign, ThrowPolicy, ThrowingEnvironment};
use acps_shared::{Environment, EnvironmentSpec, Outcome, Serves, Task};
use acps_wire::ipc::{self, RunName};
use acps_wire::secret::{RunSecret, SecretOrigin};
use acps_wire::wire::{self, Answer, Refusal, Response, Sizes, WorkerMessage};
use acps_worker::{EnvironmentFactory, EnvironmentProvideError, Single, WorkerError, WorkerExit, WorkerOptions};
use iceoryx2::prelude::PortFactory as _;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

fn acps() -> Command {
    Command::new(env!("CARGO_BIN_EXE_acps"))
}

/// A short grid experiment: 2 methods x 2 runs.
pub(crate) const GRID: [&str; 10] = [
    "grid",
    "--runs",
    "2",
    "--episodes",
    "300",
    "--method",
    "monotonic-progress",
    "--method",
    "random-continuous",
    "-q",
];

pub(crate) fn in_process(args: &[&str], out: &Path) -> Vec<u8> {
    succeeded(
        &watched()
            .arg("experiment")
            .args(args)
            .arg("--out")
            .arg(out)
            .output()
            .unwrap(),
    );
    std::fs::read(out.join("summary.json")).unwrap()
}

#[test]
fn fleet_with_one_or_two_workers_matches_the_in_process_run() {
    for p in ["1", "4"] {
        let dir = temp_dir(&format!("match-{p}"));
        let mut args = GRID.to_vec();
        args.extend(["--in-flight", p]);
        let reference = in_process(&args, &dir.join("in-process"));
        let written = dir.join("in-process").join("config.toml");
        let from_file = ["--config", written.to_str().unwrap(), "-q"];
        // One worker runs the options; two run the in-process run's experiment file with 16
        // tasks in flight each, so that tasks and outcomes travel in batches of several.
        for (workers, in_flight, args) in [("1", "4", &args[..]), ("2", "16", &from_file[..])] {
            let run = run_name(&format!("match-{p}-{workers}"));
            let out = dir.join(format!("fleet-{workers}"));
            succeeded(
                &watched()
                    .arg("run")
                    .args(args)
                    .args([
                        "--workers",
                        workers,
                        "--worker-queue-depth",
                        in_flight,
                        "--run",
                        run.as_str(),
                    ])
                    .arg("--out")
                    .arg(&out)
                    .output()
                    .unwrap(),
            );
            assert_eq!(
                std::fs::read(out.join("summary.json")).unwrap(),
                reference,
                "P = {p}, W = {workers}"
            );
            assert_eq!(
                std::fs::read(out.join("updates.csv")).unwrap(),
                std::fs::read(dir.join("in-process").join("updates.csv")).unwrap(),
                "P = {p}, W = {workers}"
            );
            // The fleet records the same experiment file: how a run is executed is not part of it.
            assert_eq!(
                std::fs::read(out.join("config.toml")).unwrap(),
                std::fs::read(&written).unwrap()
            );
            assert_clean(&run);
        }
    }
}

/// C-CMA-ES through a fleet of two workers is the in-process run, bit for bit, and its
/// updates.csv has C-CMA-ES' columns.
#[test]
fn a_c_cmaes_fleet_matches_the_in_process_run() {
    let dir = temp_dir("match-c-cmaes");
    let mut args = GRID.to_vec();
    args.extend(["--in-flight", "4", "--learner", "c-cmaes"]);
    let reference = in_process(&args, &dir.join("in-process"));
    let updates = std::fs::read_to_string(dir.join("in-process").join("updates.csv")).unwrap();
    assert!(updates.starts_with(acps_experiments::records::CCMAES_UPDATES_HEADER));
    // 300 episodes in generations of 4 + floor(3 ln 23) (2 * 6 - 1) = 103 for the grid's 6
    // polar-quadratic features.
    assert_eq!(updates.lines().count(), 1 + 2 * 2 * 2, "{updates}");
    let run = run_name("match-c-cmaes");
    let out = dir.join("fleet");
    succeeded(
        &watched()
            .arg("run")
            .args(&args)
            .args(["--workers", "2", "--run", run.as_str()])
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap(),
    );
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), reference);
    assert_eq!(std::fs::read_to_string(out.join("updates.csv")).unwrap(), updates);
    assert_clean(&run);
}

#[test]
fn learn_is_the_fleet_run_of_monotonic_progress_it_documents() {
    let dir = temp_dir("learn");
    let shape = ["--runs", "2", "--episodes", "300", "-q"];
    let mut args = vec!["grid", "--method", "monotonic-progress", "--in-flight", "8"];
    args.extend(shape);
    let reference = in_process(&args, &dir.join("in-process"));
    let run = run_name("learn");
    let out = dir.join("learn");
    succeeded(
        &watched()
            .args(["learn", "--sim", "analytic", "--workers", "2", "--run", run.as_str()])
            .args(shape)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap(),
    );
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), reference);
    // What each run did: the same rollouts, counted by the fleet and by the in-process loop.
    let report = |dir: &Path| -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(dir.join("run.json")).unwrap()).unwrap()
    };
    let (fleet, local) = (report(&out), report(&dir.join("in-process")));
    assert_eq!(
        (fleet["mode"].as_str(), local["mode"].as_str()),
        (Some("fleet"), Some("in-process"))
    );
    assert_eq!(fleet["episodes"], 600);
    assert_eq!(fleet["rollouts"], local["rollouts"], "{fleet}\n{local}");
    assert!(
        fleet["rollouts"].as_u64().unwrap() > 600,
        "training and evaluation rollouts: {fleet}"
    );
    assert!((1..=2).contains(&fleet["workers"].as_u64().unwrap()), "{fleet}");
    assert_eq!(
        (fleet["reissued"].as_u64(), local["reissued"].as_u64()),
        (Some(0), None)
    );
    assert_clean(&run);
}

/// Wait until `condition` holds, polling; panics naming `what` after `limit` (a watchdog, not a
/// timing claim).
pub(crate) fn wait_until(what: &str, limit: Duration, mut condition: impl FnMut() -> bool) {
    let start = Instant::now();
    while !condition() {
        assert!(start.elapsed() < limit, "waited {limit:?} for {what}");
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Whether the checkpoints directory `dir` holds a checkpoint (record files are there from the
/// start; a checkpoint, once learning has begun).
pub(crate) fn has_checkpoint(dir: &Path) -> bool {
    std::fs::read_dir(dir).is_ok_and(|entries| {
        entries
            .filter_map(Result::ok)
            .any(|e| e.path().extension().is_some_and(|x| x == "ckpt"))
    })
}

/// The number R of "..., N outcomes, R re-issued, ..." that a fleet run prints.
pub(crate) fn reissued(stdout: &str) -> u64 {
    stdout
        .split(" re-issued")
        .next()
        .and_then(|s| s.rsplit(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or(0)
}

/// The command lines of live processes that serve `run`: its learner (`--run NAME`) and the
/// workers it started (`ACPS_RUN=NAME` in their environment).
fn processes_of(run: &RunName) -> Vec<String> {
    let mut found = Vec::new();
    let variable = format!("{}={run}", acps_fleet::RUN_ENV);
    for entry in std::fs::read_dir("/proc").unwrap().flatten() {
        // A zombie's command line is empty.
        let Ok(cmdline) = std::fs::read(entry.path().join("cmdline")) else {
            continue;
        };
        let environ = std::fs::read(entry.path().join("environ")).unwrap_or_default();
        let args: Vec<&[u8]> = cmdline.split(|b| *b == 0).collect();
        let started = environ.split(|b| *b == 0).any(|v| v == variable.as_bytes());
        if started
            || args
                .windows(2)
                .any(|pair| pair == [b"--run".as_slice(), run.as_str().as_bytes()])
        {
            found.push(String::from_utf8_lossy(&cmdline).replace('\0', " "));
        }
    }
    found
}

#[test]
fn an_oversubscribed_fleet_finishes_with_the_in_process_result_and_leaves_nothing() {
    // The most workers a run serves, on a machine of a few cores, for 6 jobs of one task in
    // flight each: nearly every worker waits through the whole run. Such a fleet livelocked:
    // idle workers listed the run's nodes on every tick, the learner woke all of them with every
    // answer and looked for dead workers on every tick (docs/FLEET.md#oversubscription). The
    // watchdog fails a run that does not finish.
    let dir = temp_dir("oversubscribed");
    let args = ["grid", "--sim", "rapier", "--runs", "1", "--episodes", "300", "-q"];
    let reference = in_process(&args, &dir.join("in-process"));
    let run = run_name("oversubscribed");
    let out = dir.join("fleet");
    let workers = ipc::MAX_WORKERS.to_string();
    let output = watched()
        .arg("run")
        .args(args)
        .args(["--workers", &workers, "--run", run.as_str()])
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    succeeded(&output);
    // A worker that could not join (an iceoryx2 limit) would print its error and leave the
    // others to finish the run.
    assert!(!stderr.contains("rror"), "{stderr}");
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), reference);
    assert_eq!(
        std::fs::read(out.join("updates.csv")).unwrap(),
        std::fs::read(dir.join("in-process").join("updates.csv")).unwrap()
    );
    assert_clean(&run);
    assert_eq!(
        processes_of(&run),
        Vec::<String>::new(),
        "processes of run {run} remain"
    );
}

/// Wait for `child` to exit, at most `limit`.
pub(crate) fn wait_for(child: &mut Child, limit: Duration) -> Option<Duration> {
    let start = Instant::now();
    while start.elapsed() < limit {
        if child.try_wait().unwrap().is_some() {
            return Some(start.elapsed());
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    None
}

pub(crate) fn kill(child: &mut Child) {
    // SIGKILL: the process gets no chance to clean up.
    let _ = child.kill();
    let _ = child.wait();
}

/// The rapier backend makes the run last long enough to kill a worker in the middle.
pub(crate) const SLOW: [&str; 10] = [
    "grid",
    "--sim",
    "rapier",
    "--runs",
    "2",
    "--episodes",
    "400",
    "--method",
    "monotonic-progress",
    "-q",
];

/// A slow run named `name`: its directory, the in-process result, its run name and the fleet's
/// output directory.
pub(crate) struct SlowRun {
    pub(crate) dir: crate::TempDir,
    pub(crate) reference: Vec<u8>,
    pub(crate) run: RunName,
    pub(crate) out: PathBuf,
}

fn slow_run(name: &str) -> SlowRun {
    slow_run_with(name, &[])
}

/// [`slow_run`] with `extra` arguments.
pub(crate) fn slow_run_with(name: &str, extra: &[&str]) -> SlowRun {
    let dir = temp_dir(name);
    SlowRun {
        reference: in_process(&[&SLOW[..], extra].concat(), &dir.join("in-process")),
        run: run_name(name),
        out: dir.join("fleet"),
        dir,
    }
}

/// Eight tasks in flight per job: a worker that has joined nearly always holds some.
const KILL_WORKER_P: [&str; 2] = ["--in-flight", "8"];

#[test]
fn a_killed_worker_is_noticed_its_tasks_reissued_and_the_result_unchanged() {
    let SlowRun {
        dir: _dir,
        reference,
        run,
        out,
    } = slow_run_with("kill-worker", &KILL_WORKER_P);
    // Not quiet: the learner reports how many tasks it re-issued.
    let loud: Vec<&str> = SLOW.iter().copied().filter(|a| *a != "-q").collect();
    let learner = watched()
        .arg("run")
        .args(&loud)
        .args(KILL_WORKER_P)
        .args(["--workers", "1", "--run", run.as_str(), "--checkpoint-every", "1"])
        .arg("--out")
        .arg(&out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // A worker started by hand joins the running learner by its run name.
    let mut victim = acps()
        .args([
            "worker",
            "--run",
            run.as_str(),
            "--name",
            "victim",
            "--queue-depth",
            "8",
            "-q",
        ])
        .spawn()
        .unwrap();
    // The learner, its worker and the victim are in, and learning has begun.
    wait_until("the victim to join a learning run", Duration::from_secs(60), || {
        ipc::live_nodes(&run).unwrap_or(0) >= 3 && has_checkpoint(&out.join("checkpoints"))
    });
    assert!(victim.try_wait().unwrap().is_none(), "the victim must still be working");
    kill(&mut victim);
    let output = learner.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout).into_owned();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    // "grid on 1 worker: E episodes, N rollouts ..., R re-issued, ...": the victim held tasks when it died.
    assert!(reissued(&stdout) >= 1, "{stdout}");
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), reference);
    assert_clean(&run);
}

/// Send `signal` to process `pid`; asserts that it was there to receive it.
pub(crate) fn signal(signal: &str, pid: u32) {
    let status = Command::new("kill").args([signal, &pid.to_string()]).status().unwrap();
    assert!(status.success(), "kill {signal} {pid}: no such process");
}

/// Send `signal` to the process group `group`.
pub(crate) fn signal_group(signal: &str, group: u32) {
    let status = Command::new("kill")
        .args([signal, "--", &format!("-{group}")])
        .status()
        .unwrap();
    assert!(status.success(), "kill {signal} -{group}");
}

#[test]
fn a_paused_and_resumed_fleet_finishes_with_the_same_result() {
    let SlowRun {
        dir: _dir,
        reference,
        run,
        out,
    } = slow_run("pause");
    // Its own process group: the learner and the workers it starts are paused together, as
    // Ctrl-Z in a shell pauses them.
    let mut learner = watched()
        .arg("run")
        .args(SLOW)
        .args(["--workers", "2", "--run", run.as_str()])
        .arg("--out")
        .arg(&out)
        .process_group(0)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let group = learner.id();
    let mut pauses = 0;
    while learner.try_wait().unwrap().is_none() {
        std::thread::sleep(Duration::from_millis(60));
        signal_group("-STOP", group);
        std::thread::sleep(Duration::from_millis(20));
        signal_group("-CONT", group);
        pauses += 1;
    }
    let output = learner.wait_with_output().unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    assert!(pauses >= 3, "the run ended before it could be paused ({pauses} pauses)");
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), reference);
    assert_clean(&run);
}

/// Start `command` (arguments of `acps`) in a process group of its own, press Ctrl-C once its
/// first checkpoint is in `out`, check that it stopped as interrupted without a summary, then
/// run the command it printed to continue; returns the summary that command wrote.
fn interrupt_and_continue(command: &[&str], out: &Path) -> Vec<u8> {
    let started = watched()
        .args(command)
        .process_group(0)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    wait_until("a first checkpoint", Duration::from_secs(60), || {
        has_checkpoint(&out.join("checkpoints"))
    });
    // Ctrl-C in a shell signals the whole foreground group.
    signal_group("-INT", started.id());
    let output = started.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(130), "{command:?}: {stderr}");
    // Workers stopped by the same Ctrl-C leave the explaining to the learner.
    assert!(!stderr.contains("LearnerGone"), "{stderr}");
    assert!(
        !out.join("summary.json").exists(),
        "an interrupted run writes no summary"
    );
    let printed = stderr
        .split("continue the run with\n")
        .nth(1)
        .and_then(|rest| rest.lines().next())
        .unwrap_or_else(|| panic!("{command:?} printed no command that continues it: {stderr}"))
        .trim();
    assert!(printed.ends_with(&format!("--resume {}", out.display())), "{printed}");
    let resumed = Command::new("sh").args(["-c", printed]).output().unwrap();
    succeeded(&resumed);
    std::fs::read(out.join("summary.json")).unwrap()
}

#[test]
fn ctrl_c_stops_a_fleet_run_and_the_command_it_prints_finishes_it() {
    let SlowRun {
        dir: _dir,
        reference,
        run,
        out,
    } = slow_run("ctrl-c");
    let mut command = vec!["run"];
    command.extend(SLOW);
    command.extend(["--workers", "2", "--run", run.as_str(), "--checkpoint-every", "1"]);
    command.extend(["--out", out.to_str().unwrap()]);
    assert_eq!(interrupt_and_continue(&command, &out), reference);
    assert_clean(&run);
}

#[test]
fn ctrl_c_stops_an_in_process_experiment_and_the_command_it_prints_finishes_it() {
    let SlowRun {
        dir: _dir,
        reference,
        out,
        ..
    } = slow_run("ctrl-c-in-process");
    let mut command = vec!["experiment"];
    command.extend(SLOW);
    command.extend(["--checkpoint-every", "1", "--out", out.to_str().unwrap()]);
    assert_eq!(interrupt_and_continue(&command, &out), reference);
}

/// `acps learn`, the newcomer's command, continues with `acps learn --resume`.
#[test]
fn ctrl_c_stops_acps_learn_and_learn_resume_finishes_it() {
    let dir = temp_dir("learn-resume");
    // acps learn checkpoints every 10 C-REPS updates: long enough a run that Ctrl-C after the
    // first checkpoint comes well before the end.
    let size = ["--runs", "2", "--episodes", "2000"];
    let mut same = vec![
        "grid",
        "--sim",
        "rapier",
        "--method",
        "monotonic-progress",
        "--in-flight",
        "8",
        "-q",
    ];
    same.extend(size);
    let reference = in_process(&same, &dir.join("in-process"));
    let out = dir.join("learn");
    let run = run_name("learn-resume");
    let mut command = vec![
        "learn",
        "--sim",
        "rapier",
        "--workers",
        "2",
        "-q",
        "--run",
        run.as_str(),
    ];
    command.extend(size);
    command.extend(["--out", out.to_str().unwrap()]);
    assert_eq!(interrupt_and_continue(&command, &out), reference);
    assert_clean(&run);
}

#[test]
fn workers_leave_when_the_learner_is_killed_and_the_next_start_cleans_up() {
    let dir = temp_dir("kill-learner");
    let run = run_name("kill-learner");
    let mut learner = acps()
        .arg("run")
        .args(SLOW)
        // A checkpoint after every C-REPS update tells the test that learning has begun.
        .args(["--workers", "0", "--run", run.as_str(), "--checkpoint-every", "1"])
        .arg("--out")
        .arg(dir.join("a"))
        .spawn()
        .unwrap();
    let mut workers: Vec<Child> = (0..2)
        .map(|i| {
            acps()
                .args(["worker", "--run", run.as_str(), "--name", &format!("w{i}"), "-q"])
                .stderr(Stdio::piped())
                .spawn()
                .unwrap()
        })
        .collect();
    wait_until("both workers to join a learning run", Duration::from_secs(60), || {
        ipc::live_nodes(&run).unwrap_or(0) >= 3 && has_checkpoint(&dir.join("a").join("checkpoints"))
    });
    kill(&mut learner);
    for worker in &mut workers {
        let waited = wait_for(worker, Duration::from_secs(10));
        assert!(waited.is_some(), "a worker kept waiting for a dead learner");
        eprintln!("worker left {:?} after the learner was killed", waited.unwrap());
    }
    // The crash left resources; a new run of the same name cleans them at start and its own at the end.
    assert!(!ipc::leftover_files(&run).is_empty());
    let mut args = GRID.to_vec();
    args.extend(["--workers", "1", "--run", run.as_str()]);
    succeeded(
        &watched()
            .arg("run")
            .args(&args)
            .arg("--out")
            .arg(dir.join("b"))
            .output()
            .unwrap(),
    );
    assert_clean(&run);
}

#[test]
fn workers_of_another_build_run_or_environment_are_refused_and_an_embedded_worker_serves() {
    let dir = temp_dir("refuse");
    let run = run_name("refuse");
    let out = dir.join("fleet");
    let mut learner = watched()
        .arg("run")
        .args(GRID)
        .args(["--workers", "0", "--run", run.as_str()])
        .arg("--out")
        .arg(&out)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // An impostor speaks the wire directly; its node and ports go away at the end of the block.
    {
        // One node for the whole wait: creating and dropping nodes while the learner starts
        // is churn no real worker causes.
        let node = ipc::node(&run, "impostor").unwrap();
        let services = ipc::open_services(&node).unwrap();
        let start = Instant::now();
        while services.tasks.dynamic_config().number_of_servers() == 0 {
            if let Some(status) = learner.try_wait().unwrap() {
                let mut stderr = String::new();
                std::io::Read::read_to_string(learner.stderr.as_mut().unwrap(), &mut stderr).unwrap();
                panic!("the learner exited ({status}) before serving: {stderr}");
            }
            assert!(start.elapsed() < Duration::from_secs(60), "the learner did not start");
            std::thread::sleep(Duration::from_millis(20));
        }
        let _node = node;
        let client = services.tasks.client_builder().create().unwrap();
        let notifier = services.to_learner.notifier_builder().create().unwrap();
        let ask = |message: WorkerMessage| -> Answer {
            let pending = client.send_copy(message).unwrap();
            notifier.notify().unwrap();
            let start = Instant::now();
            loop {
                if let Some(response) = pending.receive().unwrap() {
                    assert!(response.payload().is_empty(), "a refusal carries no tasks");
                    return *response.user_header();
                }
                assert!(start.elapsed() < Duration::from_secs(10), "no answer");
                std::thread::sleep(Duration::from_millis(5));
            }
        };
        let wrong_protocol = WorkerMessage {
            protocol: 99,
            ..WorkerMessage::request(0, 1, Serves::Any)
        };
        assert_eq!(ask(wrong_protocol).response(), Some(Response::Refused));
        // Without the run's secret: refused as a stranger, before anything else is looked at.
        let answer = ask(WorkerMessage::request(0, 1, Serves::Any));
        assert_eq!(answer.refusal(), Some(Refusal::Secret));
        let (secret, origin) = RunSecret::for_worker(&run).unwrap();
        assert_eq!(origin, SecretOrigin::File(RunSecret::path(&run)));
        let wrong_run = WorkerMessage::request(0x1234_5678, 1, Serves::Any).carrying(secret.unwrap());
        let answer = ask(wrong_run);
        assert_eq!(answer.refusal(), Some(Refusal::Run));
        assert_ne!(answer.run, 0x1234_5678, "the refusal carries the learner's identity");
    }

    // An embedded worker on this thread serves the run to its end.
    let options = WorkerOptions {
        queue_depth: 4,
        name: "embedded".into(),
        ..WorkerOptions::default()
    };
    // Before it, one whose arm follows trajectories sampled at another control period: the
    // same model with other settings, refused when it first asks.
    let policy = ThrowPolicy::new(ThrowDesign::pa10(), 0.25).unwrap();
    let other = ThrowingEnvironment::new(
        Robot::pa10(),
        policy,
        Simulator::Analytic,
        Targets::Grid,
        SpeedLimits::Ignore,
    );
    let (theirs, ours) = (other.spec(), environment::grid(Sim::Analytic).unwrap().spec());
    assert_ne!(theirs, ours);
    let error = acps_worker::serve(&run, &options, &mut Single(other), &AtomicBool::new(false)).unwrap_err();
    // Both sides' settings texts, not only their hashes.
    let [theirs, ours] = [theirs, ours].map(|spec| wire::serves_shown(&Serves::One(spec)));
    assert!(theirs.contains(" = \"") && ours.contains(" = \""), "{theirs} / {ours}");
    assert_eq!(
        error.to_string(),
        format!(
            "the learner of run '{run}' refused this worker: this worker serves {theirs}; the run's jobs need {ours}"
        )
    );
    // One that declares parameters of another length than the problem's: refused at once,
    // with both sides' sizes.
    let grid = environment::grid(Sim::Analytic).unwrap();
    let needed = Sizes {
        context: grid.context_dim(),
        theta: grid.param_dim(),
    };
    let declared = Sizes {
        theta: needed.theta + 1,
        ..needed
    };
    let sized = WorkerOptions {
        sizes: Some(declared),
        ..options.clone()
    };
    let error = acps_worker::serve(&run, &sized, &mut ModelFactory::default(), &AtomicBool::new(false)).unwrap_err();
    assert_eq!(
        error.to_string(),
        format!(
            "the learner of run '{run}' refused this worker: this worker serves contexts of {} and parameters of {} values; the run's jobs need contexts of {} and parameters of {} values",
            declared.context, declared.theta, needed.context, needed.theta
        )
    );
    // Declaring the problem's own sizes joins like declaring none.
    let report = acps_worker::serve(
        &run,
        &WorkerOptions {
            sizes: Some(needed),
            ..options
        },
        &mut ModelFactory::default(),
        &AtomicBool::new(false),
    )
    .unwrap();
    assert_eq!(report.exit, WorkerExit::Finished);
    assert!(report.rollouts >= 2 * 2 * 300);
    let output = learner.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert!(output.status.success(), "{stderr}");
    assert!(
        stderr.contains("refused a worker") && stderr.contains("protocol 99"),
        "{stderr}"
    );
    // The learner names both environments too, and both sizes.
    assert!(
        stderr.contains(&format!("it serves environment {theirs}; the jobs need {ours}")),
        "{stderr}"
    );
    assert!(
        stderr.contains(&format!("it serves {declared}; the jobs need {needed}")),
        "{stderr}"
    );
    assert_eq!(
        std::fs::read(out.join("summary.json")).unwrap(),
        in_process(&GRID, &dir.join("in-process"))
    );
    ipc::remove_run_files(&run).unwrap();
    assert_clean(&run);
}

#[test]
fn an_embedded_worker_stops_cleanly_when_asked() {
    let run = run_name("stop");
    let stop = AtomicBool::new(true);
    let options = WorkerOptions {
        queue_depth: 2,
        name: "stopped".into(),
        ..WorkerOptions::default()
    };
    let report = acps_worker::serve(&run, &options, &mut ModelFactory::default(), &stop).unwrap();
    assert_eq!(report.exit, WorkerExit::Stopped);
    let error = acps_worker::serve(
        &run,
        &WorkerOptions {
            queue_depth: 0,
            ..options
        },
        &mut ModelFactory::default(),
        &stop,
    )
    .unwrap_err();
    assert!(
        error.to_string().contains("queue_depth must be in 1..=128, got 0"),
        "{error}"
    );
    ipc::remove_run_files(&run).unwrap();
    assert_clean(&run);
}

#[test]
fn a_killed_fleet_learner_resumes_from_its_checkpoints_to_the_in_process_result() {
    let dir = temp_dir("resume");
    let args = [
        "grid",
        "--sim",
        "rapier",
        "--runs",
        "1",
        "--episodes",
        "300",
        "--method",
        "monotonic-progress",
        "--checkpoint-every",
        "1",
        "-q",
    ];
    let reference = in_process(&args, &dir.join("in-process"));
    let run = run_name("resume");
    let out = dir.join("fleet");
    let mut learner = acps()
        .arg("run")
        .args(args)
        .args(["--workers", "2", "--run", run.as_str()])
        .arg("--out")
        .arg(&out)
        .spawn()
        .unwrap();
    // SIGKILL as soon as a checkpoint is written, with tasks out at the workers.
    let start = Instant::now();
    let written = || {
        std::fs::read_dir(out.join("checkpoints"))
            .map(|entries| {
                entries
                    .flatten()
                    .any(|e| e.path().extension().is_some_and(|x| x == "ckpt"))
            })
            .unwrap_or(false)
    };
    while !written() {
        assert!(start.elapsed() < Duration::from_secs(120), "no checkpoint appeared");
        assert!(
            learner.try_wait().unwrap().is_none(),
            "the learner ended before a checkpoint"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    kill(&mut learner);
    assert!(!out.join("summary.json").exists(), "killed before the end");
    // Its workers notice and leave.
    let start = Instant::now();
    while ipc::live_nodes(&run).map_or(true, |alive| alive > 0) && start.elapsed() < Duration::from_secs(20) {
        std::thread::sleep(Duration::from_millis(50));
    }
    succeeded(
        &watched()
            .arg("run")
            .args(args)
            .args(["--workers", "2", "--run", run.as_str()])
            .arg("--resume")
            .arg(&out)
            .output()
            .unwrap(),
    );
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), reference);
    // The update reports were saved in the checkpoints: the table is the uninterrupted run's.
    assert_eq!(
        std::fs::read(out.join("updates.csv")).unwrap(),
        std::fs::read(dir.join("in-process").join("updates.csv")).unwrap()
    );
    assert_clean(&run);
}

/// The niceness of process `pid`: field 19 of /proc/PID/stat, the 17th after the parenthesised
/// command name.
fn niceness(pid: u32) -> Option<i32> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    stat.rsplit_once(") ")?.1.split(' ').nth(16)?.parse().ok()
}

#[test]
fn started_workers_run_at_the_chosen_niceness_and_the_learner_at_its_own() {
    let dir = temp_dir("nice");
    let run = run_name("nice");
    let mut learner = acps()
        .args([
            "run",
            "grid",
            "--runs",
            "2",
            "--episodes",
            "3000",
            "--method",
            "monotonic-progress",
            "-q",
        ])
        .args(["--workers", "1", "--worker-nice", "7", "--run", run.as_str()])
        .arg("--out")
        .arg(&*dir)
        .spawn()
        .unwrap();
    let children = format!("/proc/{0}/task/{0}/children", learner.id());
    let deadline = Instant::now() + Duration::from_secs(30);
    let mut seen = None;
    while seen.is_none() && learner.try_wait().unwrap().is_none() && Instant::now() < deadline {
        let pids = std::fs::read_to_string(&children).unwrap_or_default();
        // A worker lowers its priority first thing after it starts.
        if pids
            .split_whitespace()
            .filter_map(|p| niceness(p.parse().ok()?))
            .any(|n| n == 7)
        {
            seen = niceness(learner.id());
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    assert!(learner.wait().unwrap().success());
    assert_eq!(seen, Some(0), "a worker at niceness 7 beside a learner at 0");
    assert_clean(&run);
}

/// Serve `jobs` to their end, or fail the test once `limit` has passed (a deadlock fails it
/// instead of hanging it).
fn serve_within(fleet: &mut Fleet, jobs: &mut [FleetJob], limit: Duration) -> FleetProgress {
    let stop = fleet.stop_flag();
    let started = Instant::now();
    fleet
        .serve(jobs, &mut |_: &FleetProgress| {
            if started.elapsed() > limit {
                stop.store(true, std::sync::atomic::Ordering::Relaxed);
            }
        })
        .unwrap_or_else(|e| panic!("the run did not finish within {limit:?}: {e}"))
}

/// How the tests serve in-process jobs: no polling, a fixed run identity.
fn test_fleet(run: &RunName, start_with: usize) -> Fleet {
    Fleet::builder(run.clone())
        .identity(7)
        .spin(Duration::ZERO)
        .start_with(start_with)
        .start()
        .unwrap()
}

/// A short analytic grid experiment (2 runs x 40 episodes, P = `in_flight`) with
/// [`served_and_in_process`]'s jobs and episodes.
fn short_grid(in_flight: usize) -> (acps_experiments::experiment::Experiment, Vec<FleetJob>, Vec<String>) {
    let options = ExperimentFile {
        runs: Some(2),
        episodes: Some(40),
        in_flight: Some(in_flight),
        methods: Some(vec![Method::MonotonicProgress]),
        ..Default::default()
    };
    let experiment = paper::grid(Sim::Analytic, &options);
    let (jobs, reference) = served_and_in_process(&experiment);
    (experiment, jobs, reference)
}

/// `experiment`'s jobs ready for a fleet, and each job's episodes when run in-process (as text:
/// the bits, NaN included).
fn served_and_in_process(experiment: &acps_experiments::experiment::Experiment) -> (Vec<FleetJob>, Vec<String>) {
    let reference = experiment
        .jobs()
        .unwrap()
        .into_iter()
        .map(|mut job| {
            let environment = job
                .environment
                .as_mut()
                .expect("the paper's problems have environments");
            run_in_process(&mut job.learner, environment.as_mut()).unwrap();
            format!("{:?}", job.learner.episodes())
        })
        .collect();
    let jobs = experiment
        .jobs()
        .unwrap()
        .into_iter()
        .map(|job| FleetJob::new(job.learner).unwrap())
        .collect();
    (jobs, reference)
}

/// Each fleet job's episodes, as [`served_and_in_process`] gives the in-process ones.
fn episodes(jobs: &[FleetJob]) -> Vec<String> {
    jobs.iter()
        .map(|job| format!("{:?}", job.learner().episodes()))
        .collect()
}

/// Every rollout of the wrapped environment takes a millisecond, longer than a batch's worth of
/// simulation, so each travels alone.
struct Sleepy(Box<dyn Environment>);

impl Environment for Sleepy {
    fn spec(&self) -> EnvironmentSpec {
        self.0.spec()
    }

    fn context_dim(&self) -> usize {
        self.0.context_dim()
    }

    fn param_dim(&self) -> usize {
        self.0.param_dim()
    }

    fn rollout(&mut self, task: &Task) -> Outcome {
        std::thread::sleep(Duration::from_millis(1));
        self.0.rollout(task)
    }
}

#[test]
fn outcomes_go_out_alone_while_every_asking_request_waits() {
    // P = 1 and two jobs: at most two tasks are ready at a time, so a worker with 64 tasks in
    // flight keeps all its 8 asking requests waiting, and its outcomes need the delivery slot.
    let (experiment, mut jobs, reference) = short_grid(1);
    let run = run_name("deliver");
    let environment = Sleepy(experiment.jobs().unwrap().remove(0).environment.unwrap());
    let progress = std::thread::scope(|scope| {
        let worker = scope.spawn(|| {
            let options = WorkerOptions {
                queue_depth: 64,
                name: "sleepy".into(),
                ..WorkerOptions::default()
            };
            acps_worker::serve(&run, &options, &mut Single(environment), &AtomicBool::new(false))
        });
        // A deadlock fails the test instead of hanging it.
        let mut fleet = test_fleet(&run, 0);
        let progress = serve_within(&mut fleet, &mut jobs, Duration::from_secs(60));
        assert_eq!(worker.join().unwrap().unwrap().exit, WorkerExit::Finished);
        progress
    });
    assert!(progress.delivered > 0, "{progress:?}");
    assert_eq!(episodes(&jobs), reference);
    ipc::remove_run_files(&run).unwrap();
    assert_clean(&run);
}

#[test]
fn a_fleet_told_to_start_with_two_workers_gives_the_first_nothing_until_the_second_asks() {
    let (_, mut jobs, reference) = short_grid(4);
    let run = run_name("start-with");
    let second_may_start = AtomicBool::new(false);
    let served = AtomicBool::new(false);
    let mut outcomes_before_second = None;
    let serve_started = Instant::now();
    let worker = |name: &str| {
        let options = WorkerOptions {
            name: name.into(),
            ..WorkerOptions::default()
        };
        acps_worker::serve(&run, &options, &mut ModelFactory::default(), &AtomicBool::new(false))
    };
    let progress = std::thread::scope(|scope| {
        let first = scope.spawn(|| worker("first"));
        // Started once the first has waited, or not at all if the run ends before.
        let second = scope.spawn(|| {
            while !served.load(std::sync::atomic::Ordering::Relaxed) {
                if second_may_start.load(std::sync::atomic::Ordering::Relaxed) {
                    return Some(worker("second"));
                }
                std::thread::sleep(Duration::from_millis(1));
            }
            None
        });
        let mut fleet = test_fleet(&run, 2);
        let stop = fleet.stop_flag();
        let mut first_seen: Option<Instant> = None;
        let progress = fleet
            .serve(&mut jobs, &mut |progress: &FleetProgress| {
                // Several ticks after the first worker connected, it has asked and waits.
                if progress.workers >= 1 && outcomes_before_second.is_none() {
                    let seen = *first_seen.get_or_insert_with(Instant::now);
                    if seen.elapsed() > Duration::from_millis(200) {
                        outcomes_before_second = Some(progress.outcomes);
                        second_may_start.store(true, std::sync::atomic::Ordering::Relaxed);
                    }
                }
                if serve_started.elapsed() > Duration::from_secs(60) {
                    stop.store(true, std::sync::atomic::Ordering::Relaxed);
                }
            })
            .expect("the run finishes within a minute");
        served.store(true, std::sync::atomic::Ordering::Relaxed);
        assert_eq!(first.join().unwrap().unwrap().exit, WorkerExit::Finished);
        if let Some(second) = second.join().unwrap() {
            assert_eq!(second.unwrap().exit, WorkerExit::Finished);
        }
        progress
    });
    assert_eq!(outcomes_before_second, Some(0), "the first worker got no task alone");
    let waited = serve_started.elapsed().as_secs_f64() - progress.serving_seconds;
    assert!(waited >= 0.2, "the serving time leaves out the wait: {progress:?}");
    assert_eq!(episodes(&jobs), reference);
    ipc::remove_run_files(&run).unwrap();
    assert_clean(&run);
}

#[test]
fn a_bench_whose_worker_dies_stops_with_an_error_instead_of_a_row() {
    let dir = temp_dir("bench-worker-dies");
    let mut bench = watched()
        .args([
            "bench",
            "--env",
            "rapier",
            "--max-workers",
            "1",
            "--rounds",
            "1",
            "--scale",
            "0.2",
        ])
        .arg("--out")
        .arg(&*dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The bench is the watchdog's child; its fleet's worker is the bench's only child.
    let deadline = Instant::now() + Duration::from_secs(120);
    let children = |pid: u32| {
        std::fs::read_to_string(format!("/proc/{pid}/task/{pid}/children"))
            .unwrap_or_default()
            .split_whitespace()
            .filter_map(|p| p.parse::<u32>().ok())
            .collect::<Vec<_>>()
    };
    let mut killed = None;
    while killed.is_none() && bench.try_wait().unwrap().is_none() && Instant::now() < deadline {
        for acps in children(bench.id()) {
            if let Some(worker) = children(acps).first() {
                let status = Command::new("kill")
                    .args(["-KILL", &worker.to_string()])
                    .status()
                    .unwrap();
                killed = status.success().then_some(acps);
            }
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    let acps = killed.expect("the bench started a worker");
    let output = bench.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(
        stderr.contains("fleet of 1 on rapier: a worker exited before the bench was done"),
        "{stderr}"
    );
    assert!(!dir.join("bench.json").exists(), "no table of a broken fleet");
    assert_clean(&RunName::new(&format!("bench-{acps}-rapier-1")).unwrap());
}

/// Blocks in its first rollout until released: a worker that lives but says nothing, as one
/// stopped with SIGSTOP or hung in a simulator.
struct Stuck<'a> {
    inner: Box<dyn Environment>,
    release: &'a AtomicBool,
    stuck_once: bool,
}

impl Environment for Stuck<'_> {
    fn spec(&self) -> EnvironmentSpec {
        self.inner.spec()
    }

    fn context_dim(&self) -> usize {
        self.inner.context_dim()
    }

    fn param_dim(&self) -> usize {
        self.inner.param_dim()
    }

    fn rollout(&mut self, task: &Task) -> Outcome {
        if !self.stuck_once {
            self.stuck_once = true;
            wait_until("the test to release the stuck worker", Duration::from_secs(120), || {
                self.release.load(std::sync::atomic::Ordering::Relaxed)
            });
        }
        self.inner.rollout(task)
    }
}

#[test]
fn a_hung_worker_s_tasks_go_to_another_and_the_result_is_unchanged() {
    let (experiment, mut jobs, reference) = short_grid(4);
    let run = run_name("hung");
    let release = AtomicBool::new(false);
    let environment = || experiment.jobs().unwrap().remove(0).environment.unwrap();
    let joined = AtomicBool::new(false);
    let worker = |name: &str, environment: &mut dyn EnvironmentFactory| {
        let options = WorkerOptions {
            name: name.into(),
            ..WorkerOptions::default()
        };
        acps_worker::serve(&run, &options, environment, &AtomicBool::new(false))
    };
    let progress = std::thread::scope(|scope| {
        // The stuck worker asks first, so the first tasks are its (the fleet starts with both).
        let stuck = scope.spawn(|| {
            let mut factory = Single(Stuck {
                inner: environment(),
                release: &release,
                stuck_once: false,
            });
            worker("stuck", &mut factory)
        });
        let healthy = scope.spawn(|| {
            wait_until("the stuck worker to join", Duration::from_secs(60), || {
                joined.load(std::sync::atomic::Ordering::Relaxed)
            });
            worker("healthy", &mut Single(environment()))
        });
        let mut fleet = Fleet::builder(run.clone())
            .identity(7)
            .spin(Duration::ZERO)
            .start_with(2)
            .liveness(Liveness {
                silence: Duration::from_millis(300),
                ..Liveness::default()
            })
            .start()
            .unwrap();
        let progress = fleet
            .serve(&mut jobs, &mut |progress: &FleetProgress| {
                if progress.workers >= 1 {
                    joined.store(true, std::sync::atomic::Ordering::Relaxed);
                }
            })
            .expect("the healthy worker finishes the run");
        release.store(true, std::sync::atomic::Ordering::Relaxed);
        assert_eq!(healthy.join().unwrap().unwrap().exit, WorkerExit::Finished);
        // Released after the run, it finds the learner done or gone.
        let exit = stuck.join().unwrap().unwrap().exit;
        assert!(
            matches!(exit, WorkerExit::Finished | WorkerExit::LearnerGone),
            "{exit:?}"
        );
        progress
    });
    assert!(progress.reissued >= 1, "{progress:?}");
    assert_eq!(episodes(&jobs), reference);
    assert_clean(&run);
}

#[test]
fn a_fleet_whose_workers_all_exit_stops_with_an_error_naming_the_run() {
    // Worker processes that exit at once: with status 0 the fleet waits out its grace for
    // others (200 ms); failing, as a broken worker command does, they stop it at once (a grace
    // of 2 minutes would fail the message's test).
    for (command, grace, said) in [
        ("true", 200, "none connected for"),
        (
            "false",
            120_000,
            "all 2 started worker processes failed: 2 with status 1 (see their messages above), and no other is connected",
        ),
    ] {
        let (_, mut jobs, _) = short_grid(4);
        let run = run_name(&format!("no-workers-{command}"));
        let mut fleet = Fleet::builder(run.clone())
            .spawn_workers(2, move |_| Command::new(command))
            .liveness(Liveness {
                no_workers: Some(Duration::from_millis(grace)),
                ..Liveness::default()
            })
            .start()
            .unwrap();
        let error = fleet
            .serve(&mut jobs, &mut |_: &FleetProgress| {})
            .unwrap_err()
            .to_string();
        assert!(
            error.starts_with(&format!("no worker can go on with run '{run}': {said}")),
            "{error}"
        );
        assert!(error.contains("all 2 started worker processes"), "{error}");
        drop(fleet);
        assert_clean(&run);
    }
}

/// The pids of `pid`'s children.
fn children_of(pid: u32) -> Vec<u32> {
    std::fs::read_to_string(format!("/proc/{pid}/task/{pid}/children"))
        .unwrap_or_default()
        .split_whitespace()
        .filter_map(|p| p.parse().ok())
        .collect()
}

/// `acps run` of the slow run `run` into `out` with one started worker, its stderr piped.
fn slow_learner(run: &RunName, out: &Path) -> Child {
    acps()
        .arg("run")
        .args(SLOW)
        .args(["--workers", "1", "--run", run.as_str()])
        .arg("--out")
        .arg(out)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

#[test]
fn a_hand_started_worker_keeps_a_run_going_after_the_started_ones_exit() {
    let SlowRun {
        dir: _dir,
        reference,
        run,
        out,
    } = slow_run("hand-worker");
    let learner = slow_learner(&run, &out);
    let mut hand = acps()
        .args(["worker", "--run", run.as_str(), "--name", "by-hand", "-q"])
        .spawn()
        .unwrap();
    wait_until("the hand-started worker to join", Duration::from_secs(60), || {
        ipc::live_nodes(&run).unwrap_or(0) >= 3
    });
    // Kill the worker the learner started: the one it serves by hand goes on.
    let started = children_of(learner.id());
    assert_eq!(started.len(), 1, "{started:?}");
    signal("-KILL", started[0]);
    let output = learner.wait_with_output().unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), reference);
    assert!(
        wait_for(&mut hand, Duration::from_secs(20)).is_some(),
        "the hand worker left"
    );
    assert_clean(&run);
}

/// Held by the tests that run acps as user nobody: one of them replaces that user's iceoryx2
/// directory.
static NOBODY: std::sync::Mutex<()> = std::sync::Mutex::new(());

#[test]
fn a_worker_of_another_user_is_told_whose_run_it_is() {
    // Needs root to become another user; elsewhere, and where that user cannot run this build
    // (its directories closed to others), it says so and checks nothing.
    let as_nobody = || {
        let mut command = Command::new("runuser");
        command.args([
            "-u",
            "nobody",
            "--",
            "timeout",
            "--signal=KILL",
            "60",
            env!("CARGO_BIN_EXE_acps"),
        ]);
        command
    };
    let runs = as_nobody().arg("--version").output();
    if !runs.is_ok_and(|output| output.status.success()) {
        eprintln!("skipped: this test runs acps as user nobody, which needs root and a build others may run");
        return;
    }
    let _nobody = NOBODY.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let SlowRun {
        dir: _dir, run, out, ..
    } = slow_run("other-user");
    let learner = slow_learner(&run, &out);
    wait_until("the learner to serve", Duration::from_secs(60), || {
        ipc::live_nodes(&run).unwrap_or(0) >= 1
    });
    let output = as_nobody().args(["worker", "--run", run.as_str()]).output().unwrap();
    let said = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{said}");
    // The run's files, or iceoryx2's directory when it is closed to other users (iceoryx2 made
    // it so under acps's umask): either way the owner is named.
    assert!(
        said.contains(&format!("of run '{run}': "))
            && said.contains(
                " belongs to user 0, who alone may use it; run this process as that user (this one runs as user 65534)"
            ),
        "{said}"
    );
    let output = learner.wait_with_output().unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    assert_clean(&run);
}

#[test]
fn two_users_run_fleets_on_one_machine() {
    // iceoryx2's own directory, /tmp/iceoryx2, is writable by its first user alone: a second
    // user's run failed there. Needs root to become user nobody, as the test above.
    let as_nobody = |args: &[&str]| {
        Command::new("runuser")
            .args([
                "-u",
                "nobody",
                "--",
                "timeout",
                "--signal=KILL",
                "180",
                env!("CARGO_BIN_EXE_acps"),
            ])
            .args(args)
            .output()
    };
    if !as_nobody(&["--version"]).is_ok_and(|output| output.status.success()) {
        eprintln!("skipped: this test runs acps as user nobody, which needs root and a build others may run");
        return;
    }
    let _nobody = NOBODY.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let short = ["function", "--runs", "1", "--episodes", "100", "--workers", "1", "-q"];
    let (mine, theirs) = (temp_dir("user-mine"), temp_dir("user-theirs"));
    let run = run_name("user-mine");
    succeeded(
        &watched()
            .arg("run")
            .args(short)
            .args(["--run", run.as_str(), "--out"])
            .arg(&*mine)
            .output()
            .unwrap(),
    );
    std::fs::create_dir(&*theirs).unwrap();
    std::os::unix::fs::chown(&*theirs, Some(65534), Some(65534)).unwrap();
    let output = as_nobody(&[&["run"], &short[..], &["--out", theirs.to_str().unwrap()]].concat()).unwrap();
    succeeded(&output);
    assert_eq!(
        std::fs::read(theirs.join("summary.json")).unwrap(),
        std::fs::read(mine.join("summary.json")).unwrap()
    );
    // Each user's iceoryx2 directory is theirs alone; one another user made is refused.
    use std::os::unix::fs::MetadataExt as _;
    let root = Path::new("/tmp/acps-iceoryx2-65534");
    let made = std::fs::metadata(root).unwrap();
    assert_eq!((made.uid(), made.mode() & 0o777), (65534, 0o700));
    std::fs::remove_dir_all(root).unwrap();
    std::fs::create_dir(root).unwrap();
    let output = as_nobody(&[&["run"], &short[..], &["--out", theirs.join("again").to_str().unwrap()]].concat());
    std::fs::remove_dir_all(root).unwrap();
    let said = String::from_utf8_lossy(&output.as_ref().unwrap().stderr).into_owned();
    assert_eq!(output.unwrap().status.code(), Some(2), "{said}");
    assert!(
        said.contains("iceoryx2's directory /tmp/acps-iceoryx2-65534/ for run '")
            && said.contains("it belongs to user 0, not to this process's user 65534; remove it"),
        "{said}"
    );
    assert_clean(&run);
}

#[test]
fn after_a_kill_9_of_everything_the_next_start_of_any_fleet_removes_what_was_left() {
    let dir = temp_dir("kill-all");
    let run = run_name("kill-all");
    let mut learner = acps()
        .arg("run")
        .args(SLOW)
        .args(["--workers", "2", "--run", run.as_str(), "--checkpoint-every", "1"])
        .arg("--out")
        .arg(&*dir)
        .process_group(0)
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    wait_until("a learning run with both workers", Duration::from_secs(60), || {
        ipc::live_nodes(&run).unwrap_or(0) >= 3 && has_checkpoint(&dir.join("checkpoints"))
    });
    signal_group("-KILL", learner.id());
    learner.wait().unwrap();
    // Not merely until the workers show as zombies: a killed process's main thread does so
    // before its other threads have exited, and until the last of them has, the lock on its
    // node's files stays held and iceoryx2 reports the node alive, so that the start below left
    // the run alone (this test failed about one time in four beside the other fleet tests).
    wait_until(
        "every node of the killed run to be dead",
        Duration::from_secs(20),
        || ipc::live_nodes(&run).is_ok_and(|alive| alive == 0),
    );
    // The next fleet, of another name, removes what the run left when it starts. Fleets that
    // other tests start meanwhile may have removed it already, or be midway (seen once in some
    // 200 runs beside the other fleet tests: one of the three nodes' files gone, the rest left
    // to the other cleaner), so the test waits for the files to go.
    let other = run_name("kill-all-next");
    let fleet = Fleet::builder(other.clone()).start().unwrap();
    wait_until("the killed run's files to be removed", Duration::from_secs(20), || {
        ipc::leftover_files(&run).is_empty()
    });
    drop(fleet);
    assert_clean(&other);
}

#[test]
fn a_worker_that_gives_up_waiting_leaves_nothing_behind() {
    let run = run_name("gives-up");
    let output = acps()
        .args(["worker", "--run", run.as_str(), "--startup-timeout", "0.2"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(stderr.contains(&format!("no learner serves run '{run}'")), "{stderr}");
    assert_clean(&run);
}

/// A factory that says it serves any environment, but provides the one it holds for every task,
/// as a worker whose build configures the project's models differently would.
struct Liar(ContextualFunction);

impl EnvironmentFactory for Liar {
    fn serves(&self) -> Serves {
        Serves::Any
    }

    fn environment(&mut self, _: &EnvironmentSpec) -> Result<&mut dyn Environment, EnvironmentProvideError> {
        Ok(&mut self.0)
    }
}

#[test]
fn workers_of_other_environments_are_refused_and_the_result_stays_the_in_process_one() {
    // Two runs of the function experiment: two problem instances (seeds 0 and 1), so two
    // environments.
    let options = ExperimentFile {
        runs: Some(2),
        episodes: Some(100),
        in_flight: Some(2),
        methods: Some(vec![Method::MonotonicProgress]),
        ..Default::default()
    };
    let (mut jobs, reference) = served_and_in_process(&paper::function(&options));
    let function = |seed| ContextualFunction::new(2, DEFAULT_N_THETA, seed).unwrap();
    let run = run_name("environments");
    let worker = |name: &str, factory: &mut dyn EnvironmentFactory| {
        let options = WorkerOptions {
            name: name.into(),
            startup_timeout: Duration::from_secs(60),
            ..WorkerOptions::default()
        };
        acps_worker::serve(&run, &options, factory, &AtomicBool::new(false))
    };
    let (progress, (refused, liar, zero, one)) = std::thread::scope(|scope| {
        let workers = scope.spawn(|| {
            // The function of another problem seed: refused when it first asks.
            let refused = worker("seed-7", &mut Single(function(7)));
            // Takes tasks as any worker, and refuses the first: the learner re-issues them.
            let liar = worker("liar", &mut Liar(function(7)));
            // One worker per instance, each handed only its own instance's tasks.
            let zero = scope.spawn(|| worker("seed-0", &mut Single(function(0))));
            let one = worker("seed-1", &mut Single(function(1)));
            (refused, liar, zero.join().unwrap(), one)
        });
        let mut fleet = test_fleet(&run, 0);
        let progress = serve_within(&mut fleet, &mut jobs, Duration::from_secs(120));
        (progress, workers.join().unwrap())
    });
    let [seed0, seed1, seed7] = [0, 1, 7].map(|seed| function(seed).spec());
    match refused {
        Err(WorkerError::Refused { reason, .. }) => assert_eq!(
            reason,
            format!(
                "this worker serves {}; the run's jobs need {} and 1 other",
                wire::serves_shown(&Serves::One(seed7)),
                wire::serves_shown(&Serves::One(seed0))
            )
        ),
        other => panic!("expected a refusal at the handshake, got {other:?}"),
    }
    match liar {
        Err(WorkerError::TaskRefused { needed, provided, .. }) => {
            assert!(
                [seed0, seed1].contains(&needed) && *provided == seed7,
                "{needed} {provided}"
            )
        }
        other => panic!("expected a refused task, got {other:?}"),
    }
    for served in [zero, one] {
        assert_eq!(served.unwrap().exit, WorkerExit::Finished);
    }
    assert!(progress.refused >= 1 && progress.reissued >= 1, "{progress:?}");
    assert_eq!(episodes(&jobs), reference);
    ipc::remove_run_files(&run).unwrap();
    assert_clean(&run);
}

#[test]
fn a_fleet_job_with_contexts_larger_than_the_wire_carries_is_refused_before_serving() {
    // Section 5.1.3's problem in 9 dimensions: it runs in-process, and its contexts are one value
    // more than a task on the wire carries.
    let options = ExperimentFile {
        runs: Some(1),
        episodes: Some(20),
        methods: Some(vec![Method::Random]),
        ..Default::default()
    };
    let experiment = paper::dims(9, &options);
    let summary = experiment
        .run(&acps_experiments::progress::Progress::new("dims", 0, true))
        .unwrap();
    assert_eq!(summary.methods["random"].episodes, [0, 20]);
    let run = run_name("too-large");
    let mut fleet = test_fleet(&run, 0);
    let error = experiment
        .run_fleet(&mut fleet, None, None, |_| panic!("nothing is served"))
        .err()
        .unwrap();
    drop(fleet);
    assert_eq!(
        error.to_string(),
        "problem 'dims-9' cannot be served to workers: a task's context has 9 values, the wire carries at most 8 (MAX_CONTEXT)"
    );
    assert_clean(&run);
}

/// The `acps` process that the watchdog `timeout` process `watchdog` runs.
fn watched_acps(watchdog: &Child) -> u32 {
    let mut pid = None;
    wait_until("the watchdog to start acps", Duration::from_secs(10), || {
        pid = children_of(watchdog.id()).first().copied();
        pid.is_some()
    });
    pid.expect("waited for it")
}

#[test]
fn a_second_learner_of_a_running_run_is_refused_at_once_and_starts_no_worker() {
    let dir = temp_dir("second-learner");
    let run = run_name("second-learner");
    // The first learner waits for workers started by hand, for as long as the test needs.
    let mut first = watched()
        .args(["run", "grid", "--runs", "1", "--episodes", "20", "--workers", "0"])
        .args(["--run", run.as_str()])
        .arg("--out")
        .arg(dir.join("first"))
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let first_pid = watched_acps(&first);
    let mut first_err = std::io::BufReader::new(first.stderr.take().unwrap());
    // Printed once it serves the run, after any log lines (once, under load, one came first);
    // the pipe closes if it dies.
    let mut before = String::new();
    while !before.contains(&format!("run '{run}' waits for workers")) {
        let read = std::io::BufRead::read_line(&mut first_err, &mut before).unwrap();
        assert!(read > 0, "the first learner ended: {before}");
    }
    // Another experiment, so that a worker it started would be refused by the first learner,
    // which says so on stderr. -v shows the info lines too.
    let second = watched()
        .args([
            "-v",
            "run",
            "function",
            "--runs",
            "1",
            "--episodes",
            "20",
            "--workers",
            "1",
        ])
        .args(["--run", run.as_str()])
        .arg("--out")
        .arg(dir.join("second"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&second.stderr);
    assert_eq!(second.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.ends_with(&format!(
            "error: --run {run}: a learner of run '{run}' is already running (PID {first_pid}); give this run another name, or wait for that learner to end\n"
        )),
        "{stderr}"
    );
    assert!(!stderr.contains("still use"), "{stderr}");
    assert!(!dir.join("second").exists(), "the refused run wrote nothing");
    signal("-INT", first_pid);
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut first_err, &mut rest).unwrap();
    assert_eq!(first.wait().unwrap().code(), Some(130), "{rest}");
    assert!(
        !rest.contains("refused a worker"),
        "the second learner started a worker: {rest}"
    );
    assert_clean(&run);
}

#[test]
fn a_fleet_is_refused_while_another_holds_its_run_and_serving_releases_it() {
    use acps_fleet::{FleetError, FleetStartError};
    use ipc::ServerError;
    let run = run_name("seat");
    let taken = |error: &ServerError| {
        *error
            == ServerError::Taken {
                run: run.clone(),
                pid: Some(std::process::id() as i32),
            }
    };
    let serve = |fleet: &mut Fleet| fleet.serve(&mut [], &mut |_: &FleetProgress| {});
    let mut first = Fleet::builder(run.clone()).start().unwrap();
    match Fleet::builder(run.clone()).start() {
        Err(FleetStartError::Serve(error)) => assert!(taken(&error), "{error}"),
        Err(other) => panic!("expected the run to be taken, got {other}"),
        Ok(_) => panic!("two fleets hold run {run}"),
    }
    // Serving ends by releasing the run: a worker left busy in a rollout finds its learner gone.
    serve(&mut first).unwrap();
    let second = Fleet::builder(run.clone()).start().expect("the first serves no more");
    match serve(&mut first) {
        Err(FleetError::Seat(error)) => assert!(taken(&error), "{error}"),
        other => panic!("expected the run to be taken, got {other:?}"),
    }
    drop(second);
    serve(&mut first).expect("the run is free again");
    drop(first);
    assert_clean(&run);
}

#[test]
fn killing_the_only_worker_ends_the_run_saying_so() {
    let dir = temp_dir("only-worker");
    let run = run_name("only-worker");
    let learner = watched()
        .args([
            "run",
            "function",
            "--runs",
            "1",
            "--episodes",
            "20000",
            "--workers",
            "1",
        ])
        .args(["--run", run.as_str(), "--checkpoint-every", "0"])
        .arg("--out")
        .arg(&*dir)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let acps = watched_acps(&learner);
    // At once: a worker killed while it opened the run's services made the learner blame a
    // worker of another build.
    let mut worker = Vec::new();
    wait_until("the learner to start its worker", Duration::from_secs(30), || {
        worker = children_of(acps);
        !worker.is_empty()
    });
    signal("-KILL", worker[0]);
    let output = learner.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "no worker can go on with run '{run}': all 1 started worker processes failed: 1 killed by signal 9"
        )),
        "{stderr}"
    );
    assert!(!stderr.contains("another"), "{stderr}");
    assert_clean(&run);
}

/// A fleet run that fails half-way (its only worker killed after learning began) says which
/// command continues it from its checkpoints, and that command finishes the run.
#[test]
fn a_fleet_run_that_fails_half_way_prints_the_command_that_continues_it() {
    let SlowRun {
        dir: _dir,
        reference,
        run,
        out,
    } = slow_run("fails-half-way");
    let learner = watched()
        .arg("run")
        .args(SLOW)
        .args(["--workers", "1", "--run", run.as_str(), "--checkpoint-every", "1"])
        .arg("--out")
        .arg(&out)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let acps = watched_acps(&learner);
    wait_until("a first checkpoint", Duration::from_secs(60), || {
        has_checkpoint(&out.join("checkpoints"))
    });
    let worker = children_of(acps);
    assert_eq!(worker.len(), 1, "one started worker");
    signal("-KILL", worker[0]);
    let output = learner.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("no worker can go on"), "{stderr}");
    // How the started worker ended, so that the user knows it did not just finish.
    assert!(
        stderr.contains("all 1 started worker processes failed: 1 killed by signal 9"),
        "{stderr}"
    );
    let printed = stderr
        .split("the checkpoints written so far continue the run with\n")
        .nth(1)
        .and_then(|rest| rest.lines().next())
        .unwrap_or_else(|| panic!("no command that continues the run: {stderr}"))
        .trim();
    assert!(printed.ends_with(&format!("--resume {}", out.display())), "{printed}");
    succeeded(&Command::new("sh").args(["-c", printed]).output().unwrap());
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), reference);
    assert_clean(&run);
}

#[test]
fn bad_worker_and_run_names_are_refused_naming_the_flag_and_what_names_may_be() {
    let run = run_name("names");
    let long = "x".repeat(300);
    let names = "must be 1 to 128 characters of ASCII letters, digits, '-', '_' and '.', other than 'learner' (the learner's node), got";
    let cases: [(&[&str], Option<&str>, String); 8] = [
        (&["--name", ""], None, format!("--name {names} \"\"")),
        (&["--name", "a/b"], None, format!("--name {names} \"a/b\"")),
        (&["--name", "é"], None, format!("--name {names} \"é\"")),
        (&["--name", "learner"], None, format!("--name {names} \"learner\"")),
        (&["--name", &long], None, format!("--name {names} 300 characters")),
        (
            &["--run", "a/b"],
            None,
            "--run a/b: run name: 'a/b' must be 1 to 40 characters of letters, digits and '-'".into(),
        ),
        (
            &["--run", &long],
            None,
            "must be 1 to 40 characters of letters, digits and '-'".into(),
        ),
        (
            &[],
            Some("a_b"),
            "ACPS_RUN: run name: 'a_b' must be 1 to 40 characters of letters, digits and '-'".into(),
        ),
    ];
    for (args, env, message) in cases {
        let mut command = acps();
        command.arg("worker").env_remove(acps_fleet::RUN_ENV);
        if !args.contains(&"--run") && env.is_none() {
            command.args(["--run", run.as_str()]);
        }
        if let Some(env) = env {
            command.env(acps_fleet::RUN_ENV, env);
        }
        let output = command.args(args).args(["--startup-timeout", "0"]).output().unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(&message), "{args:?}: {stderr}");
    }
    // An embedded worker is refused the same way.
    let options = WorkerOptions {
        name: String::new(),
        ..WorkerOptions::default()
    };
    let error = acps_worker::serve(&run, &options, &mut ModelFactory::default(), &AtomicBool::new(false))
        .unwrap_err()
        .to_string();
    assert_eq!(error, format!("worker option name {names} \"\""));
    assert_clean(&run);
}

#[test]
fn outcomes_of_processes_without_the_secret_or_without_the_task_are_dropped_and_change_nothing() {
    // Short grid jobs with P = 4 served by one worker whose rollouts take a millisecond, so
    // tasks are held for a while. Beside it two processes of the same user speak the wire and
    // report a reward of 1e300 for every task id of both jobs, over and over: one that knows
    // only the run's name (refused: no secret), and one that read the run's secret file
    // (admitted, but it holds no task). Taken, the first of those outcomes for a held task
    // would replace the worker's.
    let (experiment, mut jobs, reference) = short_grid(4);
    let run = run_name("stranger");
    let environment = Sleepy(experiment.jobs().unwrap().remove(0).environment.unwrap());
    let done = AtomicBool::new(false);
    let stranger = |reads_secret: bool| {
        let node = ipc::node(&run, if reads_secret { "insider" } else { "stranger" }).unwrap();
        let services = ipc::open_services(&node).unwrap();
        // A request sent before the learner's server exists is lost; the secret file follows it.
        let mut secret = None;
        while services.tasks.dynamic_config().number_of_servers() == 0 || (reads_secret && secret.is_none()) {
            if done.load(std::sync::atomic::Ordering::Relaxed) {
                return 0;
            }
            if services.tasks.dynamic_config().number_of_servers() > 0 {
                secret = RunSecret::for_worker(&run).unwrap().0;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        let client = services.tasks.client_builder().create().unwrap();
        let notifier = services.to_learner.notifier_builder().create().unwrap();
        let mut sent = 0u64;
        let mut task_id = 0;
        while !done.load(std::sync::atomic::Ordering::Relaxed) {
            // Test fleets have identity 7 (`test_fleet`); a stranger learns it from any refusal.
            let mut message = WorkerMessage::request(7, 0, Serves::Any);
            if let Some(secret) = secret {
                message = message.carrying(secret);
            }
            for job in 0..2 {
                for id in task_id..task_id + 32 {
                    message
                        .push(wire::WireOutcome::new(job, &Outcome::new(id, 1e300, 0.0)).unwrap())
                        .unwrap();
                }
            }
            task_id = (task_id + 32) % 256;
            let pending = client.send_copy(message).unwrap();
            notifier.notify().unwrap();
            sent += 64;
            // Each request is answered (with nothing, or a refusal) before the next goes out, or
            // given up on after a second.
            let asked = Instant::now();
            loop {
                if let Some(answer) = pending.receive().unwrap() {
                    let refusal = answer.user_header().refusal();
                    assert_eq!(refusal, (!reads_secret).then_some(Refusal::Secret));
                    break;
                }
                if done.load(std::sync::atomic::Ordering::Relaxed) || asked.elapsed() > Duration::from_secs(1) {
                    break;
                }
                std::thread::sleep(Duration::from_micros(200));
            }
        }
        sent
    };
    let served = std::thread::scope(|scope| {
        let worker = scope.spawn(|| {
            let options = WorkerOptions {
                name: "honest".into(),
                ..WorkerOptions::default()
            };
            acps_worker::serve(&run, &options, &mut Single(environment), &AtomicBool::new(false))
        });
        let insider = scope.spawn(|| stranger(true));
        let outsider = scope.spawn(|| stranger(false));
        // Serving starts once the worker and the insider have asked, so the insider's first
        // outcomes are seen.
        let mut fleet = test_fleet(&run, 2);
        // The run's shared memory is its user's alone: iceoryx2's node counter, which iceoryx2
        // makes writable by everyone, and the secret.
        let shared: Vec<_> = ipc::leftover_files(&run)
            .into_iter()
            .filter(|path| path.starts_with("/dev/shm"))
            .collect();
        for end in [".global_mgmt", "_secret"] {
            assert!(
                shared.iter().any(|path| path.to_string_lossy().ends_with(end)),
                "{end}: {shared:?}"
            );
        }
        for path in &shared {
            let mode = std::os::unix::fs::PermissionsExt::mode(&std::fs::metadata(path).unwrap().permissions());
            assert_eq!(mode & 0o077, 0, "{} has mode {mode:o}", path.display());
        }
        let progress = serve_within(&mut fleet, &mut jobs, Duration::from_secs(60));
        done.store(true, std::sync::atomic::Ordering::Relaxed);
        (
            progress,
            insider.join().unwrap(),
            outsider.join().unwrap(),
            worker.join().unwrap(),
        )
    });
    let (progress, insider, outsider, worker) = served;
    assert_eq!(episodes(&jobs), reference);
    assert_eq!(worker.unwrap().exit, WorkerExit::Finished);
    assert!(
        progress.foreign > 0 && progress.foreign <= insider,
        "{progress:?}, {insider} sent by the insider"
    );
    assert!(
        progress.refused > 0 && progress.refused * 64 <= outsider,
        "{progress:?}, {outsider} sent without the secret"
    );
    ipc::remove_run_files(&run).unwrap();
    assert_clean(&run);
}
