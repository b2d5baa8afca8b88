//! The `acps experiment` command-line contract: files written, summary.json fields, and errors
//! that name the bad option.

use crate::{acps, temp_dir};
use std::path::Path;
use std::process::Command;

fn summary(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// `acps experiment toy --panel b` with a short fixed configuration into `dir`.
fn short_toy_panel(dir: &Path) {
    let out = acps(&[
        "experiment",
        "toy",
        "--panel",
        "b",
        "--runs",
        "3",
        "--episodes",
        "120",
        "--seed",
        "4",
        "-q",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn toy_panel_writes_the_summary_contract() {
    let dir = temp_dir("toy");
    short_toy_panel(&dir);
    let s = summary(&dir.join("summary.json"));
    assert_eq!(s["experiment"], "toy");
    assert_eq!(s["runs"], 3);
    assert!(s["metric"].as_str().unwrap().contains("J ="));
    assert!(s["j_opt_mean"].as_f64().unwrap() > 9.0);
    let methods = s["methods"].as_object().unwrap();
    let names: Vec<&str> = methods.keys().map(String::as_str).collect();
    for name in [
        "round-robin",
        "best-reward",
        "diversity",
        "one-step-progress",
        "monotonic-progress",
        "sagg-riac",
    ] {
        assert!(names.contains(&name), "{name} missing from {names:?}");
    }
    for (name, m) in methods {
        // Evaluations at 0, 10, ..., 120.
        assert_eq!(m["episodes"].as_array().unwrap().len(), 13, "{name}");
        assert_eq!(m["mean"].as_array().unwrap().len(), 13);
        assert_eq!(m["sem"].as_array().unwrap().len(), 13);
        assert_eq!(m["final_mean"], *m["mean"].as_array().unwrap().last().unwrap());
        assert!(m["final_sem"].as_f64().unwrap() >= 0.0);
        assert_eq!(m["selections_run0"].as_array().unwrap().len(), 120);
    }
    // The Section 4 model has no policy: no C-REPS update, so no rows and no picture of them.
    assert_eq!(
        std::fs::read_to_string(dir.join("updates.csv")).unwrap(),
        format!("{}\n", acps::records::UPDATES_HEADER)
    );
    assert!(!dir.join("updates.png").exists());
    for picture in ["curves.svg", "selections.svg"] {
        let svg = std::fs::read_to_string(dir.join(picture)).unwrap();
        assert!(
            svg.starts_with("<svg") && svg.contains("monotonic-progress"),
            "{picture}"
        );
    }
    // Same command, same bits.
    let again = temp_dir("toy-again");
    short_toy_panel(&again);
    assert_eq!(
        std::fs::read(dir.join("summary.json")).unwrap(),
        std::fs::read(again.join("summary.json")).unwrap()
    );
}

#[test]
fn toy_without_panel_writes_all_four_and_function_runs_one_method() {
    let dir = temp_dir("panels");
    let out = acps(&[
        "experiment",
        "toy",
        "--runs",
        "1",
        "--episodes",
        "20",
        "-q",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    for panel in ["a", "b", "c", "d"] {
        assert!(dir.join(panel).join("summary.json").is_file(), "panel {panel}");
    }
    let out = acps(&[
        "experiment",
        "function",
        "--runs",
        "2",
        "--episodes",
        "100",
        "--method",
        "corners",
        "-q",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let s = summary(&dir.join("summary.json"));
    assert_eq!(
        s["methods"].as_object().unwrap().keys().collect::<Vec<_>>(),
        ["corners"]
    );
    assert_eq!(s["methods"]["corners"]["episodes"], serde_json::json!([0, 50, 100]));
}

#[test]
fn bad_options_are_refused_naming_the_option() {
    let cases: [(&[&str], &str); 9] = [
        (&["worker"], "--run is missing: name the run to join"),
        (
            &["run", "grid", "--run", "a_b"],
            "'a_b' must be 1 to 40 characters of letters, digits and '-'",
        ),
        (
            &["experiment", "toy", "--panel", "e"],
            "--panel must be one of a, b, c, d",
        ),
        (
            &["experiment", "function", "--method", "monotonic"],
            "unknown method 'monotonic'",
        ),
        (
            &["experiment", "dims", "--n-s", "5"],
            "--n-s must be an integer in 1..=4, got 5",
        ),
        (
            &["experiment", "function", "--runs", "0"],
            "--runs must be an integer in 1..=2^63-1, got 0",
        ),
        (
            &[
                "experiment",
                "function",
                "--in-flight",
                "0",
                "--runs",
                "1",
                "--episodes",
                "10",
            ],
            "--in-flight must be an integer in 1..=16384 (what a full fleet holds), got 0",
        ),
        (
            &["experiment", "toy", "--epsilon", "1"],
            "--epsilon applies to function, dims, grid, dartboard, [problem] tables only, not to the toy experiment",
        ),
        (
            &["experiment", "grid", "--method", "random", "--method", "random"],
            "--method must be a non-empty list of distinct methods",
        ),
    ];
    for (args, expected) in cases {
        let out = acps(args);
        assert!(!out.status.success(), "{args:?} succeeded");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
    }
}

#[test]
fn throwing_experiments_write_their_results() {
    let dir = temp_dir("throwing");
    let grid = dir.join("grid");
    let out = acps(&[
        "experiment",
        "grid",
        "--runs",
        "2",
        "--episodes",
        "300",
        "--method",
        "monotonic-progress",
        "-q",
        "--out",
        grid.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let s = summary(&grid.join("summary.json"));
    assert_eq!(s["settings"]["sim"], "analytic");
    let m = &s["methods"]["monotonic-progress"];
    // theta_0 lands at (-3.55, -3.55): the 16 test targets are 0.3 m to 1.8 m away at first.
    let first = m["mean"][0].as_f64().unwrap();
    assert!((60.0..120.0).contains(&first), "{first}");
    assert!(
        m["final_mean"].as_f64().unwrap() < first,
        "learning reduces the test distance"
    );
    assert!(grid.join("throw.svg").is_file());

    let board = dir.join("dartboard");
    let out = acps(&[
        "experiment",
        "dartboard",
        "--runs",
        "1",
        "--episodes",
        "200",
        "-q",
        "--out",
        board.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let s = summary(&board.join("summary.json"));
    let m = &s["methods"]["monotonic-progress"];
    let hits = m["hits"].as_object().unwrap();
    let names: Vec<&str> = hits.keys().map(String::as_str).collect();
    assert_eq!(names, ["bull", "double", "inner", "outer", "treble"]);
    // A policy barely trained cannot hit every field; the total is the sum over the rings.
    let total: f64 = hits.values().map(|h| h.as_f64().unwrap()).sum();
    assert_eq!(m["fields_hit"].as_f64().unwrap(), total);
    assert!(total < 81.0);
    let error = &m["error_cm"];
    assert!(error["median"].as_f64().unwrap() <= error["max"].as_f64().unwrap());
    assert_eq!(m["landings_run0"].as_array().unwrap().len(), 81);
    assert!(board.join("board.svg").is_file());
}

#[test]
fn bench_writes_its_table_and_json() {
    let dir = temp_dir("bench");
    let run_bench = |more: &[&str]| {
        let mut args = vec![
            "bench",
            "--scale",
            "0.01",
            "--max-workers",
            "1",
            "--out",
            dir.to_str().unwrap(),
        ];
        args.extend_from_slice(more);
        let out = acps(&args);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        out
    };
    let out = run_bench(&[]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("rollouts/s") && stdout.contains("inprocess-rayon"),
        "{stdout}"
    );
    let bench = summary(&dir.join("bench.json"));
    let rows = bench["rows"].as_array().unwrap();
    // Three environments x (one thread, rayon, a fleet of one).
    assert_eq!(rows.len(), 9);
    let numbers = |value: &serde_json::Value| -> Vec<f64> {
        value.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
    };
    let lower_median = |values: &[f64]| {
        let mut sorted = values.to_vec();
        sorted.sort_by(f64::total_cmp);
        sorted[(sorted.len() - 1) / 2]
    };
    for env in rows.chunks(3) {
        // Three interleaved rounds (the default); each round's ratio is paired with the same
        // round's single-thread rate.
        let single = numbers(&env[0]["round_rates"]);
        assert_eq!(single.len(), 3, "{}", env[0]);
        for row in env {
            let (rates, ratios) = (numbers(&row["round_rates"]), numbers(&row["round_ratios"]));
            let workers = row["workers"].as_f64().unwrap();
            for ((rate, ratio), single) in rates.iter().zip(&ratios).zip(&single) {
                assert!((ratio - rate / (workers * single)).abs() <= 1e-9 * ratio, "{row}");
            }
            assert_eq!(row["rollouts_per_s"].as_f64().unwrap(), lower_median(&rates), "{row}");
            assert_eq!(row["ratio"].as_f64().unwrap(), lower_median(&ratios), "{row}");
        }
    }
    for row in rows {
        assert!(["trivial", "analytic", "rapier"].contains(&row["env"].as_str().unwrap()));
        let mode = row["mode"].as_str().unwrap();
        assert!(["inprocess-1", "inprocess-rayon", "fleet"].contains(&mode));
        let rate = row["rollouts_per_s"].as_f64().unwrap();
        assert!(rate > 0.0 && row["ratio"].as_f64().unwrap() > 0.0);
        // Linux says how much of the CPU other processes took.
        let others = row["others_share"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&others), "{row}");
        let (rollouts, seconds) = (row["rollouts"].as_f64().unwrap(), row["seconds"].as_f64().unwrap());
        assert!((rate - rollouts / seconds).abs() <= 1e-9 * rate, "{row}");
        // A fleet's rate leaves out the workers' start-up, which its row reports instead.
        let startup = row["startup_seconds"].as_f64();
        assert_eq!(startup.is_some(), mode == "fleet", "{row}");
        assert!(startup.is_none_or(|s| s > 0.0), "{row}");
    }
    for picture in ["bench.svg", "bench.png"] {
        assert!(
            std::fs::metadata(dir.join(picture)).is_ok_and(|m| m.len() > 0),
            "{picture}"
        );
    }
    // --env picks environments, in its order.
    run_bench(&["--env", "rapier,trivial", "--rounds", "1"]);
    let envs: Vec<String> = summary(&dir.join("bench.json"))["rows"]
        .as_array()
        .unwrap()
        .iter()
        .map(|row| row["env"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(envs, ["rapier", "rapier", "rapier", "trivial", "trivial", "trivial"]);
    let error = acps(&["bench", "--scale", "0"]);
    assert!(String::from_utf8_lossy(&error.stderr).contains("--scale must be finite and > 0"));
    let error = acps(&["bench", "--rounds", "0"]);
    assert!(String::from_utf8_lossy(&error.stderr).contains("--rounds must be in 1..=100, got 0"));
    let error = acps(&["bench", "--env", "mujoco"]);
    assert!(
        String::from_utf8_lossy(&error.stderr).contains("invalid value 'mujoco' for '--env <ENV>'"),
        "{}",
        String::from_utf8_lossy(&error.stderr)
    );
}

#[test]
fn fleet_options_are_checked_before_anything_starts() {
    let cases: [(&[&str], &str); 9] = [
        (&["worker"], "--run is missing: name the run to join"),
        (
            &["run", "grid", "--run", "a_b"],
            "'a_b' must be 1 to 40 characters of letters, digits and '-'",
        ),
        (
            &["run", "grid", "--worker-in-flight", "0"],
            "--worker-in-flight must be in 1..=128, got 0",
        ),
        (
            &["worker", "--run", "x", "--in-flight", "129"],
            "--in-flight must be in 1..=128, got 129",
        ),
        (
            &["worker", "--run", "x", "--startup-timeout=-1"],
            "--startup-timeout must be finite and >= 0",
        ),
        (&["worker", "--run", "bad/name"], "must be 1 to 40 characters"),
        (
            &["worker", "--run", "x", "--nice", "20"],
            "'--nice <N>': 20 is not in 0..=19",
        ),
        (
            &["run", "grid", "--worker-nice", "25"],
            "'--worker-nice <WORKER_NICE>': 25 is not in 0..=19",
        ),
        (
            &["bench", "--worker-nice", "20"],
            "'--worker-nice <WORKER_NICE>': 20 is not in 0..=19",
        ),
    ];
    for (args, expected) in cases {
        let out = acps(args);
        assert!(!out.status.success(), "{args:?} succeeded");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            stderr.contains(expected) && !stderr.contains("panicked"),
            "{args:?}: {stderr}"
        );
    }
}

/// The function experiment with a checkpoint every 2 C-REPS updates, into `dir`.
fn checkpointed(dir: &Path, extra: &[&str]) -> Vec<String> {
    let mut args: Vec<String> = [
        "experiment",
        "function",
        "--runs",
        "2",
        "--episodes",
        "1000",
        "--checkpoint-every",
        "2",
        "-q",
    ]
    .map(String::from)
    .to_vec();
    args.extend(extra.iter().map(|a| a.to_string()));
    args.extend(["--out".into(), dir.to_str().unwrap().into()]);
    args
}

fn acps_strings(args: &[String]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_acps"))
        .args(args)
        .output()
        .expect("acps runs")
}

fn checkpoint_files(dir: &Path) -> Vec<std::path::PathBuf> {
    std::fs::read_dir(dir.join("checkpoints"))
        .map(|entries| {
            entries
                .map(|e| e.unwrap().path())
                .filter(|p| p.extension().is_some_and(|e| e == "ckpt"))
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn a_run_killed_mid_way_resumes_to_the_same_summary() {
    use std::os::unix::process::ExitStatusExt;
    let dir = temp_dir("resume");
    let reference_dir = dir.join("reference");
    let out = acps_strings(&checkpointed(&reference_dir, &[]));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let reference = std::fs::read(reference_dir.join("summary.json")).unwrap();
    // One file per (method, run) job.
    let methods = summary(&reference_dir.join("summary.json"))["methods"]
        .as_object()
        .unwrap()
        .len();
    assert_eq!(checkpoint_files(&reference_dir).len(), 2 * methods);

    // The same command, killed with SIGKILL as soon as its first checkpoint is on disk.
    let killed_dir = dir.join("killed");
    let mut child = Command::new(env!("CARGO_BIN_EXE_acps"))
        .args(checkpointed(&killed_dir, &[]))
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    while checkpoint_files(&killed_dir).is_empty() {
        assert!(start.elapsed().as_secs() < 60, "no checkpoint appeared");
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    child.kill().unwrap();
    let status = child.wait().unwrap();
    assert_eq!(status.signal(), Some(9), "killed mid-run, not finished: {status:?}");
    assert!(!killed_dir.join("summary.json").exists());

    // Resumed with the arguments it was started with: the uninterrupted run's summary.
    let resume = ["--resume", killed_dir.to_str().unwrap()];
    let mut args = checkpointed(&killed_dir, &resume);
    args.truncate(args.len() - 2); // --resume names the output directory
    let out = acps_strings(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(std::fs::read(killed_dir.join("summary.json")).unwrap(), reference);
    // Resuming a finished run rebuilds the same summary from the final checkpoints.
    let out = acps_strings(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(std::fs::read(killed_dir.join("summary.json")).unwrap(), reference);

    // Other arguments: another experiment, refused naming a checkpoint file.
    let resumed = |extra: &[&str]| {
        let mut args = checkpointed(&killed_dir, extra);
        args.truncate(args.len() - 2);
        args.extend(resume.map(String::from));
        let out = acps_strings(&args);
        assert!(!out.status.success(), "{extra:?} succeeded");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let stderr = resumed(&["--seed", "1"]);
    assert!(
        stderr.contains("belongs to another experiment") && stderr.contains(".ckpt"),
        "{stderr}"
    );
    let stderr = resumed(&["--method", "corners"]);
    assert!(stderr.contains("belongs to no job of this experiment"), "{stderr}");
    // A truncated checkpoint.
    let victim = killed_dir.join("checkpoints").join("monotonic-progress-run-1.ckpt");
    let bytes = std::fs::read(&victim).unwrap();
    std::fs::write(&victim, &bytes[..bytes.len() / 2]).unwrap();
    let stderr = resumed(&[]);
    assert!(
        stderr.contains("truncated") && stderr.contains("monotonic-progress-run-1.ckpt"),
        "{stderr}"
    );
    // --resume where no run wrote checkpoints, and --resume against --out.
    let stderr = String::from_utf8_lossy(
        &acps(&[
            "experiment",
            "function",
            "--resume",
            dir.join("nowhere").to_str().unwrap(),
        ])
        .stderr,
    )
    .into_owned();
    assert!(stderr.contains("nothing to resume"), "{stderr}");
    let stderr =
        String::from_utf8_lossy(&acps(&["experiment", "function", "--resume", "a", "--out", "b"]).stderr).into_owned();
    assert!(
        stderr.contains("--resume a and --out b name different directories"),
        "{stderr}"
    );
}
