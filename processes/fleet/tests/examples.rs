//! Every example runs, does what its documentation says, and leaves no shared memory behind.

use std::path::PathBuf;
use std::process::Command;

/// The example `name`, built by `cargo test` beside this test's binary.
fn example(name: &str) -> Command {
    let deps = std::env::current_exe().expect("the test's path");
    let profile = deps.parent().and_then(|d| d.parent()).expect("target/PROFILE/deps");
    Command::new(profile.join("examples").join(name))
}

/// Run `name` under a watchdog and return its stdout; it must succeed.
fn run(name: &str) -> String {
    let path: PathBuf = example(name).get_program().into();
    let output = Command::new("timeout")
        .args(["--signal=KILL", "300"])
        .arg(&path)
        .output()
        .expect("the example starts");
    let stdout = String::from_utf8_lossy(&output.stdout).into_owned();
    assert!(
        output.status.success(),
        "{name}: {}\n{stdout}",
        String::from_utf8_lossy(&output.stderr)
    );
    stdout
}

/// Files of runs named `prefix`... in /dev/shm and this user's iceoryx2 directory.
fn leftovers(prefix: &str) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let mut stack = vec![PathBuf::from("/dev/shm"), acps_wire::ipc::iceoryx2_root()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).into_iter().flatten().flatten() {
            if entry
                .file_name()
                .to_string_lossy()
                .starts_with(&format!("acps_{prefix}"))
            {
                found.push(entry.path());
            } else if entry.path().is_dir() {
                stack.push(entry.path());
            }
        }
    }
    found
}

/// The number in `stdout` after `before`.
fn miss(stdout: &str, before: &str) -> f64 {
    stdout
        .split(before)
        .nth(1)
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|number| number.parse().ok())
        .unwrap_or_else(|| panic!("no number after {before:?} in {stdout}"))
}

#[test]
fn ask_tell_learns_the_cannon() {
    let stdout = run("ask_tell");
    let (before, after) = (miss(&stdout, "mean miss "), miss(&stdout, "m before learning, "));
    assert!(after < 0.25 * before, "{stdout}");
}

#[test]
fn a_fleet_of_this_program_s_processes_learns_what_the_in_process_run_learns() {
    let stdout = run("fleet");
    assert!(stdout.contains("identical to the in-process run"), "{stdout}");
    assert!(stdout.contains("outcomes for 1500 episodes"), "{stdout}");
    assert!(leftovers("cannon-").is_empty(), "{:?}", leftovers("cannon-"));
}

#[test]
fn an_embedded_worker_serves_a_run_from_its_host_s_thread() {
    let stdout = run("embedded");
    assert!(stdout.contains("the host's worker thread: Finished after"), "{stdout}");
    assert!(leftovers("embedded-").is_empty(), "{:?}", leftovers("embedded-"));
}
