//! The worker fleet end to end: real learner and worker processes over iceoryx2.

use acps::models::ModelFactory;
use acps::paper::{self, Options, Sim};
use acps_fleet::{self as fleet, FleetJob, ServeOptions};
use acps_learner::{Method, run_in_process};
use acps_shared::{Environment, Outcome, Task};
use acps_wire::ipc::{self, RunName};
use acps_wire::wire::{Answer, Response, WorkerMessage};
use acps_worker::{Single, WorkerExit, WorkerOptions};
use iceoryx2::prelude::PortFactory as _;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

fn acps() -> Command {
    Command::new(env!("CARGO_BIN_EXE_acps"))
}

/// `acps` under a watchdog: a learner that hangs fails the test instead of blocking it.
fn watched() -> Command {
    let mut command = Command::new("timeout");
    command.args(["--signal=KILL", "180", env!("CARGO_BIN_EXE_acps")]);
    command
}

fn run_name(test: &str) -> RunName {
    RunName::new(&format!("t{}-{test}", std::process::id())).unwrap()
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("acps-fleet-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// A short grid experiment: 2 methods x 2 runs.
const GRID: [&str; 10] = [
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

fn check(output: Output) -> String {
    assert!(
        output.status.success(),
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8_lossy(&output.stdout).into_owned()
}

fn in_process(args: &[&str], out: &Path) -> Vec<u8> {
    check(
        watched()
            .arg("experiment")
            .args(args)
            .arg("--out")
            .arg(out)
            .output()
            .unwrap(),
    );
    std::fs::read(out.join("summary.json")).unwrap()
}

fn assert_clean(run: &RunName) {
    let left = ipc::leftover_files(run);
    assert!(left.is_empty(), "run {run} left {left:?}");
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
            check(
                watched()
                    .arg("run")
                    .args(args)
                    .args([
                        "--workers",
                        workers,
                        "--worker-in-flight",
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
        let _ = std::fs::remove_dir_all(dir);
    }
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
    check(
        watched()
            .args(["learn", "--sim", "analytic", "--workers", "2", "--run", run.as_str()])
            .args(shape)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap(),
    );
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), reference);
    assert_clean(&run);
    let _ = std::fs::remove_dir_all(dir);
}

/// The command lines of live processes that serve `run` (its learner and workers).
fn processes_of(run: &RunName) -> Vec<String> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir("/proc").unwrap().flatten() {
        // A zombie's command line is empty.
        let Ok(cmdline) = std::fs::read(entry.path().join("cmdline")) else {
            continue;
        };
        let args: Vec<&[u8]> = cmdline.split(|b| *b == 0).collect();
        if args
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
    check(output);
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
    let _ = std::fs::remove_dir_all(dir);
}

/// Wait for `child` to exit, at most `limit`.
fn wait_for(child: &mut Child, limit: Duration) -> Option<Duration> {
    let start = Instant::now();
    while start.elapsed() < limit {
        if child.try_wait().unwrap().is_some() {
            return Some(start.elapsed());
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    None
}

fn kill(child: &mut Child) {
    // SIGKILL: the process gets no chance to clean up.
    let _ = child.kill();
    let _ = child.wait();
}

/// The rapier backend makes the run last long enough to kill a worker in the middle.
const SLOW: [&str; 10] = [
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
struct SlowRun {
    dir: PathBuf,
    reference: Vec<u8>,
    run: RunName,
    out: PathBuf,
}

fn slow_run(name: &str) -> SlowRun {
    let dir = temp_dir(name);
    SlowRun {
        reference: in_process(&SLOW, &dir.join("in-process")),
        run: run_name(name),
        out: dir.join("fleet"),
        dir,
    }
}

#[test]
fn a_killed_worker_is_noticed_its_tasks_reissued_and_the_result_unchanged() {
    let SlowRun {
        dir,
        reference,
        run,
        out,
    } = slow_run("kill-worker");
    // Not quiet: the learner reports how many tasks it re-issued.
    let loud: Vec<&str> = SLOW.iter().copied().filter(|a| *a != "-q").collect();
    let learner = watched()
        .arg("run")
        .args(&loud)
        .args(["--workers", "1", "--run", run.as_str()])
        .arg("--out")
        .arg(&out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // A worker started by hand joins the running learner by its run name.
    let mut victim = acps()
        .args(["worker", "--run", run.as_str(), "--name", "victim", "-q"])
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(600));
    assert!(victim.try_wait().unwrap().is_none(), "the victim must still be working");
    kill(&mut victim);
    let output = learner.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout).into_owned();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    // "grid on 1 workers: N outcomes, R re-issued, ...": the victim held tasks when it died.
    let reissued: u64 = stdout
        .split(" re-issued")
        .next()
        .and_then(|s| s.rsplit(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or(0);
    assert!(reissued >= 1, "{stdout}");
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), reference);
    assert_clean(&run);
    let _ = std::fs::remove_dir_all(dir);
}

/// Send `signal` to the process group `group`.
fn signal_group(signal: &str, group: u32) {
    let status = Command::new("kill")
        .args([signal, "--", &format!("-{group}")])
        .status()
        .unwrap();
    assert!(status.success(), "kill {signal} -{group}");
}

#[test]
fn a_paused_and_resumed_fleet_finishes_with_the_same_result() {
    let SlowRun {
        dir,
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
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn ctrl_c_stops_a_fleet_run_and_resume_finishes_it() {
    let SlowRun {
        dir,
        reference,
        run,
        out,
    } = slow_run("ctrl-c");
    let fleet = |extra: &[&str]| {
        watched()
            .arg("run")
            .args(SLOW)
            .args(["--workers", "2", "--run", run.as_str(), "--checkpoint-every", "1"])
            .args(extra)
            .arg("--out")
            .arg(&out)
            .process_group(0)
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let learner = fleet(&[]);
    std::thread::sleep(Duration::from_millis(400));
    // Ctrl-C in a shell signals the whole foreground group.
    signal_group("-INT", learner.id());
    let output = learner.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(130), "{stderr}");
    assert!(stderr.contains("interrupted"), "{stderr}");
    assert!(
        !out.join("summary.json").exists(),
        "an interrupted run writes no summary"
    );
    assert_clean(&run);
    let resumed = fleet(&["--resume", out.to_str().unwrap()]).wait_with_output().unwrap();
    assert!(resumed.status.success(), "{}", String::from_utf8_lossy(&resumed.stderr));
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), reference);
    assert_clean(&run);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn workers_leave_when_the_learner_is_killed_and_the_next_start_cleans_up() {
    let dir = temp_dir("kill-learner");
    let run = run_name("kill-learner");
    let mut learner = acps()
        .arg("run")
        .args(SLOW)
        .args(["--workers", "0", "--run", run.as_str()])
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
    std::thread::sleep(Duration::from_millis(800));
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
    check(
        watched()
            .arg("run")
            .args(&args)
            .arg("--out")
            .arg(dir.join("b"))
            .output()
            .unwrap(),
    );
    assert_clean(&run);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn workers_of_another_build_or_run_are_refused_and_an_embedded_worker_serves() {
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
            ..WorkerMessage::request(0, 1)
        };
        assert_eq!(ask(wrong_protocol).response(), Some(Response::Refused));
        let wrong_run = WorkerMessage::request(0x1234_5678, 1);
        let answer = ask(wrong_run);
        assert_eq!(answer.response(), Some(Response::Refused));
        assert_ne!(answer.run, 0x1234_5678, "the refusal carries the learner's identity");
    }

    // An embedded worker on this thread serves the run to its end.
    let options = WorkerOptions {
        in_flight: 4,
        name: "embedded".into(),
        ..WorkerOptions::default()
    };
    let report = acps_worker::serve(&run, &options, &mut ModelFactory::default(), &AtomicBool::new(false)).unwrap();
    assert_eq!(report.exit, WorkerExit::Finished);
    assert!(report.rollouts >= 2 * 2 * 300);
    let output = learner.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert!(output.status.success(), "{stderr}");
    assert!(
        stderr.contains("refused a worker") && stderr.contains("protocol 99"),
        "{stderr}"
    );
    assert_eq!(
        std::fs::read(out.join("summary.json")).unwrap(),
        in_process(&GRID, &dir.join("in-process"))
    );
    ipc::remove_run_files(&run).unwrap();
    assert_clean(&run);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn an_embedded_worker_stops_cleanly_when_asked() {
    let run = run_name("stop");
    let stop = AtomicBool::new(true);
    let options = WorkerOptions {
        in_flight: 2,
        name: "stopped".into(),
        ..WorkerOptions::default()
    };
    let report = acps_worker::serve(&run, &options, &mut ModelFactory::default(), &stop).unwrap();
    assert_eq!(report.exit, WorkerExit::Stopped);
    let error = acps_worker::serve(
        &run,
        &WorkerOptions {
            in_flight: 0,
            ..options
        },
        &mut ModelFactory::default(),
        &stop,
    )
    .unwrap_err();
    assert!(
        error.to_string().contains("in_flight must be in 1..=128, got 0"),
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
    check(
        watched()
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
    let _ = std::fs::remove_dir_all(dir);
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
        .arg(&dir)
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
    let _ = std::fs::remove_dir_all(dir);
}

/// How the tests serve in-process jobs: no polling, a fixed run identity.
fn serve_options(start_with: usize) -> ServeOptions {
    ServeOptions {
        identity: 7,
        spin: Duration::ZERO,
        start_with,
    }
}

/// A short analytic grid experiment (2 runs x 40 episodes, P = `in_flight`), its jobs ready for a
/// fleet, and each job's episodes when run in-process (as text: the bits, NaN included).
fn short_grid(in_flight: usize) -> (acps::experiment::Experiment, Vec<FleetJob>, Vec<String>) {
    let options = Options {
        runs: 2,
        episodes: Some(40),
        in_flight,
        methods: Some(vec![Method::MonotonicProgress]),
        ..Options::default()
    };
    let experiment = paper::grid(Sim::Analytic, &options);
    let reference = experiment
        .jobs()
        .unwrap()
        .into_iter()
        .map(|mut job| {
            run_in_process(&mut job.learner, job.environment.as_mut());
            format!("{:?}", job.learner.episodes())
        })
        .collect();
    let jobs = experiment
        .jobs()
        .unwrap()
        .into_iter()
        .map(|job| FleetJob {
            environment: job.spec.unwrap(),
            learner: job.learner,
        })
        .collect();
    (experiment, jobs, reference)
}

/// Each fleet job's episodes, as [`short_grid`] gives the in-process ones.
fn episodes(jobs: &[FleetJob]) -> Vec<String> {
    jobs.iter().map(|job| format!("{:?}", job.learner.episodes())).collect()
}

/// Every rollout of the wrapped environment takes a millisecond, longer than a batch's worth of
/// simulation, so each travels alone.
struct Sleepy(Box<dyn Environment>);

impl Environment for Sleepy {
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
    let environment = Sleepy(experiment.jobs().unwrap().remove(0).environment);
    let progress = std::thread::scope(|scope| {
        let worker = scope.spawn(|| {
            let options = WorkerOptions {
                in_flight: 64,
                name: "sleepy".into(),
                ..WorkerOptions::default()
            };
            acps_worker::serve(&run, &options, &mut Single(environment), &AtomicBool::new(false))
        });
        // A deadlock fails the test instead of hanging it.
        let stop = AtomicBool::new(false);
        let started = Instant::now();
        let progress = fleet::serve(
            &mut jobs,
            &run,
            serve_options(0),
            &stop,
            |_| {
                if started.elapsed() > Duration::from_secs(60) {
                    stop.store(true, std::sync::atomic::Ordering::Relaxed);
                }
            },
            |_, _| Ok(()),
        )
        .expect("the run finishes within a minute");
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
        let stop = AtomicBool::new(false);
        let mut first_seen: Option<Instant> = None;
        let progress = fleet::serve(
            &mut jobs,
            &run,
            serve_options(2),
            &stop,
            |progress| {
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
            },
            |_, _| Ok(()),
        )
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
        .arg(&dir)
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
    let _ = std::fs::remove_dir_all(dir);
}
