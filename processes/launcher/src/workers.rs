//! Worker processes started by this program: `acps worker` children of the current executable.

use acps_shared::ipc::RunName;
use anyhow::Context;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// How long the learner and the workers of a fleet of `workers` poll before blocking: only
/// when every process (the learner included) has a core of its own, since polling processes
/// that share cores slow each other down.
pub fn spin(workers: usize) -> Duration {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    if workers < cores {
        Duration::from_micros(50)
    } else {
        Duration::ZERO
    }
}

/// Start `workers` worker processes for `run`, each keeping `in_flight` tasks in flight.
pub fn spawn(run: &RunName, workers: usize, in_flight: usize) -> anyhow::Result<Vec<Child>> {
    let spin = spin(workers).as_micros().to_string();
    let exe = std::env::current_exe().context("locating the acps executable")?;
    (0..workers)
        .map(|i| {
            Command::new(&exe)
                .args([
                    "worker",
                    "--run",
                    run.as_str(),
                    "--in-flight",
                    &in_flight.to_string(),
                    "--spin-us",
                    &spin,
                    "--name",
                    &format!("worker-{i}"),
                    "-q",
                ])
                .stdin(Stdio::null())
                .spawn()
                .with_context(|| format!("starting worker {i}"))
        })
        .collect()
}

/// Wait for the workers to leave (they stop when the learner says the run is over or is gone);
/// kill any that does not within a few seconds.
pub fn reap(children: &mut [Child]) -> anyhow::Result<()> {
    let deadline = Instant::now() + Duration::from_secs(5);
    for child in children.iter_mut() {
        loop {
            if child.try_wait()?.is_some() {
                break;
            }
            if Instant::now() > deadline {
                let _ = child.kill();
                let _ = child.wait();
                break;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
    Ok(())
}

/// True when every child has exited (a fleet without workers would wait forever).
pub fn all_exited(children: &mut [Child]) -> bool {
    !children.is_empty() && children.iter_mut().all(|child| matches!(child.try_wait(), Ok(Some(_))))
}
