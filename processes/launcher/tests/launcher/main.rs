//! The `acps` command line and the worker fleet end to end, in one test binary: one link of the
//! whole workspace instead of one per file.

use acps_wire::ipc::{self, RunName};
use std::ops::Deref;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::atomic::{AtomicUsize, Ordering};

mod cli;
mod compare;
mod config;
mod docs;
mod fleet;
mod hosts;
mod outputs;
mod problems;
mod python;
mod run_dir;

/// `acps` under a watchdog: a learner that hangs fails the test instead of blocking it.
fn watched() -> Command {
    let mut command = Command::new("timeout");
    command.args(["--signal=KILL", "180", env!("CARGO_BIN_EXE_acps")]);
    command
}

/// The command's stdout, after asserting that it succeeded (showing both outputs if not).
fn succeeded(output: &Output) -> String {
    assert!(
        output.status.success(),
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// The run name of `test` in this test process: tests do not share shared memory.
fn run_name(test: &str) -> RunName {
    RunName::new(&format!("t{}-{test}", std::process::id())).unwrap()
}

/// Fails when `run` left files in shared memory.
fn assert_clean(run: &RunName) {
    let left = ipc::leftover_files(run);
    assert!(left.is_empty(), "run {run} left {left:?}");
}

/// `acps args`, run to its end.
fn acps(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_acps"))
        .args(args)
        .output()
        .expect("acps runs")
}

/// A directory of its own under the system's temp dir, removed when dropped, also when the test
/// that made it fails.
struct TempDir(PathBuf);

impl Deref for TempDir {
    type Target = Path;

    fn deref(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A fresh [`TempDir`] named after `name`, not created yet.
fn temp_dir(name: &str) -> TempDir {
    static MADE: AtomicUsize = AtomicUsize::new(0);
    let made = MADE.fetch_add(1, Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("acps-test-{name}-{}-{made}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    TempDir(dir)
}
