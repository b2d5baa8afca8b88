//! Outputs are checked before anything is computed or started: a run whose results could not be
//! written fails at once, naming the directory.

use crate::{temp_dir, watched};

#[test]
fn an_output_that_cannot_be_written_is_refused_before_the_run() {
    let dir = temp_dir("outputs");
    std::fs::create_dir_all(&*dir).unwrap();
    let file = dir.join("a-file");
    std::fs::write(&file, "not a directory").unwrap();
    let file = file.to_str().unwrap().to_string();
    let under = format!("{file}/run");
    let looped = dir.join("loop");
    std::os::unix::fs::symlink(&looped, &looped).unwrap();
    let looped = looped.to_str().unwrap().to_string();
    // Each command would run for a minute or more if it did not check its output first, and
    // fits in memory (a larger request is refused for that, also before it runs).
    let long = ["--runs", "1", "--episodes", "300000"];
    let cases: Vec<(Vec<&str>, &str, String)> = vec![
        (
            [&["experiment", "grid", "--out", &file][..], &long].concat(),
            "experiment, --out a file",
            format!("output directory {file} exists and is not a directory"),
        ),
        (
            [
                &["experiment", "grid", "--checkpoint-every", "0", "--out", &under][..],
                &long,
            ]
            .concat(),
            "experiment without checkpoints, --out under a file",
            format!("output directory {under}: cannot create it: Not a directory"),
        ),
        (
            [&["run", "grid", "--workers", "2", "--out", &under][..], &long].concat(),
            "run, --out under a file",
            format!("output directory {under}: cannot create it"),
        ),
        (
            vec!["learn", "--episodes", "300000", "--out", &file],
            "learn, --out a file",
            format!("output directory {file} exists and is not a directory"),
        ),
        (
            vec!["bench", "--scale", "50", "--out", &file],
            "bench, --out a file",
            format!("output directory {file} exists and is not a directory"),
        ),
        // It used to say only "File exists (os error 17)".
        (
            [&["experiment", "grid", "--out", &looped][..], &long].concat(),
            "experiment, --out a symbolic link to itself",
            format!(
                "output directory {looped} is a symbolic link that leads nowhere (Too many levels of symbolic links (os error 40))"
            ),
        ),
    ];
    for (args, case, expected) in cases {
        let output = watched().args(&args).output().unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{case}: {stderr}");
        assert!(stderr.contains(&expected), "{case}: {stderr}");
        // The OS error is said once.
        assert_eq!(
            stderr.matches("os error").count(),
            usize::from(expected.contains("cannot") || expected.contains("leads nowhere")),
            "{case}: {stderr}"
        );
    }
}

/// The lines a finished run prints are the summary's numbers, with the unit and the word SEM.
#[test]
fn the_final_lines_give_the_summarys_scores_with_unit_and_sem() {
    let dir = temp_dir("final-lines");
    let cases = [
        (
            vec!["grid", "--runs", "2", "--episodes", "200", "--method", "random"],
            "test error",
            " cm",
        ),
        (
            vec!["function", "--runs", "3", "--episodes", "100", "--method", "random"],
            "test ln cost",
            "",
        ),
    ];
    for (args, name, unit) in cases {
        let out = dir.join(args[0]);
        let stdout = crate::succeeded(
            &watched()
                .arg("experiment")
                .args(&args)
                .arg("--out")
                .arg(&out)
                .output()
                .unwrap(),
        );
        let summary: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
        let random = &summary["methods"]["random"];
        let (mean, sem) = (
            random["final_mean"].as_f64().unwrap(),
            random["final_sem"].as_f64().unwrap(),
        );
        let runs = summary["runs"].as_u64().unwrap();
        let expected = format!("random: final {name} {mean:.3}{unit} ± {sem:.3}{unit} (mean ± SEM over {runs} runs)");
        assert!(
            stdout.contains(&expected),
            "{args:?}: expected {expected:?} in {stdout}"
        );
    }
}

#[test]
fn a_run_directory_is_its_users_alone() {
    // Under the most permissive umask, every file and folder acps writes is still 0600 / 0700.
    let dir = temp_dir("modes");
    let out = dir.join("run");
    let mut command = watched();
    command
        .args([
            "experiment",
            "function",
            "--runs",
            "1",
            "--episodes",
            "60",
            "-q",
            "--out",
        ])
        .arg(&out);
    // SAFETY: umask only sets the child's file-creation mask, between fork and exec.
    unsafe {
        std::os::unix::process::CommandExt::pre_exec(&mut command, || {
            libc::umask(0);
            Ok(())
        });
    }
    crate::succeeded(&command.output().unwrap());
    let mut seen = 0;
    let mut stack = vec![out];
    while let Some(path) = stack.pop() {
        let metadata = std::fs::metadata(&path).unwrap();
        let mode = std::os::unix::fs::PermissionsExt::mode(&metadata.permissions()) & 0o777;
        if metadata.is_dir() {
            assert_eq!(mode, 0o700, "{}", path.display());
            stack.extend(std::fs::read_dir(&path).unwrap().map(|entry| entry.unwrap().path()));
        } else {
            assert_eq!(mode, 0o600, "{}", path.display());
        }
        seen += 1;
    }
    assert!(seen > 10, "{seen} files and folders");
}

#[test]
fn a_finished_run_is_replaced_only_when_asked_and_an_interrupted_one_holds_no_summary() {
    let dir = temp_dir("finished");
    let out = dir.join("run");
    let experiment = |extra: &[&str]| {
        watched()
            .args(["experiment", "function", "--runs", "1", "--episodes", "60", "-q"])
            .arg("--out")
            .arg(&out)
            .args(extra)
            .output()
            .unwrap()
    };
    crate::succeeded(&experiment(&[]));
    let summary = std::fs::read(out.join("summary.json")).unwrap();
    std::fs::write(out.join("mine.txt"), "kept").unwrap();
    // Again into the same directory: refused, the finished run untouched.
    let again = experiment(&[]);
    let said = String::from_utf8_lossy(&again.stderr);
    assert_eq!(again.status.code(), Some(2), "{said}");
    assert!(
        said.contains(&format!(
            "{} holds a finished run (its summary.json): continue it with --resume, write this run elsewhere with --out, or replace it with --force",
            out.display()
        )),
        "{said}"
    );
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), summary);
    let both = experiment(&["--force", "--resume", out.to_str().unwrap()]);
    assert_eq!(both.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&both.stderr).contains("cannot be used with"));
    // Replaced when asked: the same results again, the user's file kept.
    crate::succeeded(&experiment(&["--force"]));
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), summary);
    assert_eq!(std::fs::read_to_string(out.join("mine.txt")).unwrap(), "kept");
    // A forced run stopped half way leaves checkpoints, and no summary that could be taken for
    // its result.
    let started = std::time::SystemTime::now();
    // Not under the watchdog: SIGINT must reach acps itself.
    let mut long = std::process::Command::new(env!("CARGO_BIN_EXE_acps"))
        .args([
            "experiment",
            "grid",
            "--runs",
            "1",
            "--episodes",
            "1000000",
            "--method",
            "monotonic-progress",
            "-q",
            "--force",
        ])
        .arg("--out")
        .arg(&out)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    crate::fleet::wait_until(
        "a checkpoint of the long run",
        std::time::Duration::from_secs(60),
        || {
            std::fs::read_dir(out.join("checkpoints")).is_ok_and(|entries| {
                // A checkpoint of this run, not of the finished one before it.
                entries
                    .flatten()
                    .any(|e| e.metadata().and_then(|m| m.modified()).is_ok_and(|at| at > started))
            })
        },
    );
    crate::fleet::signal("-INT", long.id());
    let status = long.wait().unwrap();
    assert_eq!(status.code(), Some(130));
    assert!(!out.join("summary.json").exists(), "an interrupted run left a summary");
    assert!(
        !out.join("curves.png").exists(),
        "an interrupted run left the earlier pictures"
    );
    assert_eq!(std::fs::read_to_string(out.join("mine.txt")).unwrap(), "kept");
}
