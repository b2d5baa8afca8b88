//! The `acps experiment` command-line contract: files written, summary.json fields, and errors
//! that name the bad option.

use crate::{acps, assert_clean, succeeded, temp_dir, watched};
use acps_wire::ipc::RunName;
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
        format!("{}\n", acps_experiments::records::UPDATES_HEADER)
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
fn an_invalid_acps_log_filter_is_named_not_ignored() {
    let out = Command::new(env!("CARGO_BIN_EXE_acps"))
        .arg("protocol")
        .env("ACPS_LOG", "acps=bogus[")
        .output()
        .unwrap();
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("warning: ACPS_LOG=\"acps=bogus[\" is not a log filter")
            && stderr.contains("logging at level warn"),
        "{stderr}"
    );
}

#[test]
fn bad_options_are_refused_naming_the_option() {
    let cases: [(&[&str], &str); 11] = [
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
            "--runs must be an integer in 1..=1000 (repetitions with seeds seed ..= seed + runs - 1, all in memory at once), got 0",
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
            "--epsilon applies to function, dims, grid, dartboard, sphere, rosenbrock, [problem] tables only, not to the toy experiment",
        ),
        (
            &["experiment", "grid", "--method", "random", "--method", "random"],
            "--method must be a non-empty list of distinct methods",
        ),
        // Listening on port 0 would take a port nothing tells the relays.
        (
            &["run", "function", "--listen", "tcp/127.0.0.1:0", "--workers", "0"],
            "port 0 is no port relays could reach",
        ),
        (
            &["run", "function", "--worker-startup-timeout", "0"],
            "a number of seconds in 1..=86400",
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
    // The long run, once a round: 1,000,000 x 0.01 episodes, a tenth of them in each window.
    assert!(stdout.contains("start us/ep"), "{stdout}");
    let long_runs = bench["long_run"].as_array().unwrap();
    assert_eq!(long_runs.len(), 3, "{bench}");
    for run in long_runs {
        let number = |key: &str| run[key].as_f64().unwrap_or_else(|| panic!("{key} in {run}"));
        assert_eq!((number("episodes"), number("window")), (10_000.0, 1000.0), "{run}");
        for key in [
            "start_cpu_us",
            "end_cpu_us",
            "early_rss_mib",
            "end_rss_mib",
            "checkpoint_bytes",
            "record_bytes",
        ] {
            assert!(number(key) > 0.0, "{key} in {run}");
        }
        // At most one checkpoint every 10 updates of one every 25 episodes, and the final one.
        assert!((10.0..=41.0).contains(&number("checkpoints")), "{run}");
    }
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
    assert!(rows.iter().any(|row| row["others_share"].is_f64()), "{bench}");
    for row in rows {
        assert!(["trivial", "analytic", "rapier"].contains(&row["env"].as_str().unwrap()));
        let mode = row["mode"].as_str().unwrap();
        assert!(["inprocess-1", "inprocess-rayon", "fleet"].contains(&mode));
        let rate = row["rollouts_per_s"].as_f64().unwrap();
        assert!(rate > 0.0 && row["ratio"].as_f64().unwrap() > 0.0);
        // Linux says how much of the CPU other processes took, unless a measurement was
        // shorter than the counters' tick.
        let others = row["others_share"].as_f64();
        assert!(others.is_none_or(|share| (0.0..=1.0).contains(&share)), "{row}");
        let (rollouts, seconds) = (row["rollouts"].as_f64().unwrap(), row["seconds"].as_f64().unwrap());
        assert!((rate - rollouts / seconds).abs() <= 1e-9 * rate, "{row}");
        // A fleet's rate leaves out the workers' start-up, which its row reports instead.
        let startup = row["startup_seconds"].as_f64();
        assert_eq!(startup.is_some(), mode == "fleet", "{row}");
        assert!(startup.is_none_or(|s| s > 0.0), "{row}");
        // Fleets only, and none where the serve took less than a tick of the CPU counters.
        let cpu = row["learner_cpu_us_per_task"].as_f64();
        assert!(cpu.is_none_or(|us| us > 0.0 && mode == "fleet"), "{row}");
    }
    for picture in ["bench.svg", "bench.png"] {
        assert!(
            std::fs::metadata(dir.join(picture)).is_ok_and(|m| m.len() > 0),
            "{picture}"
        );
    }
    // --env picks environments, in its order; without long-run there is none.
    run_bench(&["--env", "rapier,trivial", "--rounds", "1"]);
    assert_eq!(summary(&dir.join("bench.json"))["long_run"], serde_json::json!([]));
    let envs: Vec<String> = summary(&dir.join("bench.json"))["rows"]
        .as_array()
        .unwrap()
        .iter()
        .map(|row| row["env"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(envs, ["rapier", "rapier", "rapier", "trivial", "trivial", "trivial"]);
    let error = acps(&["bench", "--scale", "0"]);
    assert!(String::from_utf8_lossy(&error.stderr).contains("'--scale <SCALE>': must be a number in (0, 100]"));
    let error = acps(&["bench", "--rounds", "0"]);
    assert!(String::from_utf8_lossy(&error.stderr).contains("'--rounds <ROUNDS>': must be an integer in 1..=100"));
    let error = acps(&["bench", "--env", "mujoco"]);
    assert!(
        String::from_utf8_lossy(&error.stderr).contains("invalid value 'mujoco' for '--env <ENV>'"),
        "{}",
        String::from_utf8_lossy(&error.stderr)
    );
}

#[test]
fn bench_relay_measures_each_fleet_again_through_a_relay() {
    let dir = temp_dir("bench-relay");
    let child = Command::new(env!("CARGO_BIN_EXE_acps"))
        .args([
            "bench",
            "--relay",
            "--env",
            "trivial",
            "--max-workers",
            "1",
            "--scale",
            "0.05",
        ])
        .args(["--rounds", "1", "--out", dir.to_str().unwrap()])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("acps runs");
    let pid = child.id();
    let stdout = succeeded(&child.wait_with_output().unwrap());
    assert!(stdout.contains("learner us/task"), "{stdout}");
    let bench = summary(&dir.join("bench.json"));
    let rows = bench["rows"].as_array().unwrap();
    let modes: Vec<&str> = rows.iter().map(|row| row["mode"].as_str().unwrap()).collect();
    assert_eq!(modes, ["inprocess-1", "inprocess-rayon", "fleet", "relay"], "{bench}");
    let (fleet, relay) = (&rows[2], &rows[3]);
    let rate = |row: &serde_json::Value| row["rollouts_per_s"].as_f64().unwrap();
    assert!(
        rate(relay) > 0.0 && relay["startup_seconds"].as_f64().unwrap() > 0.0,
        "{relay}"
    );
    // The relay's ratio is to the same round's fleet of as many workers connected directly.
    let ratio = relay["ratio"].as_f64().unwrap();
    assert!((ratio - rate(relay) / rate(fleet)).abs() <= 1e-9 * ratio, "{bench}");
    assert!(relay["learner_cpu_us_per_task"].as_f64().unwrap() > 0.0, "{relay}");
    // The learner's runs, and the relay's own run of its workers, are gone.
    for run in [
        format!("bench-{pid}-trivial-1"),
        format!("bench-{pid}-trivial-relay-1"),
        format!("bench-{pid}-trivial-relay-1-host"),
    ] {
        assert_clean(&RunName::new(&run).unwrap());
    }
}

#[test]
fn fleet_options_are_checked_before_anything_starts() {
    // A bad run name, before the output directory is made.
    let dir = temp_dir("bad-run-name");
    let out = acps(&["run", "grid", "--run", "a_b", "--out", dir.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("--run a_b: "),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(!dir.exists(), "wrote {}", dir.display());
    let cases: [(&[&str], &str); 9] = [
        (&["worker"], "--run is missing: name the run to join"),
        (
            &["run", "grid", "--run", "a_b"],
            "'a_b' must be 1 to 40 characters of letters, digits and '-'",
        ),
        (
            &["run", "grid", "--worker-queue-depth", "0"],
            "invalid value '0' for '--worker-queue-depth <WORKER_QUEUE_DEPTH>': must be an integer in 1..=128",
        ),
        (
            &["worker", "--run", "x", "--queue-depth", "129"],
            "invalid value '129' for '--queue-depth <QUEUE_DEPTH>': must be an integer in 1..=128",
        ),
        (
            &["worker", "--run", "x", "--startup-timeout=-1"],
            "invalid value '-1' for '--startup-timeout <STARTUP_TIMEOUT>': must be a number of seconds in 0..=86400",
        ),
        (&["worker", "--run", "bad/name"], "must be 1 to 40 characters"),
        (
            &["worker", "--run", "x", "--nice", "20"],
            "invalid value '20' for '--nice <N>': must be an integer in 0..=19",
        ),
        (
            &["run", "grid", "--worker-nice", "25"],
            "invalid value '25' for '--worker-nice <WORKER_NICE>': must be an integer in 0..=19",
        ),
        (
            &["bench", "--worker-nice", "20"],
            "invalid value '20' for '--worker-nice <WORKER_NICE>': must be an integer in 0..=19",
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

/// Every numeric setting and option outside its range, by class: values that used to crash
/// (a panic, or an allocation that exhausts memory), finite but absurd ones, tiny, negative (which
/// clap used to take for an option), NaN and infinite ones, and those just outside a bound. Each
/// is refused before anything runs, with exit code 2, naming the option, the value and the range.
#[test]
fn numbers_outside_their_ranges_are_refused_before_anything_runs() {
    let runs = "must be an integer in 1..=1000 (repetitions";
    let episodes = "must be an integer in 1..=10000000 (training episodes";
    let sigma = "--initial-sigma must be a number in 1e-12..=1e12 (a variance in the parameters' units";
    let epsilon = "--epsilon must be a number in 1e-4..=10 (C-REPS's KL bound in nats)";
    let xi = "--xi must be a number in 0..=1e6";
    let cases: &[(&[&str], i32, &str)] = &[
        // Crashed: a capacity overflow, an allocation the allocator aborted, a Duration panic.
        (
            &["experiment", "grid", "--runs", "9223372036854775807"],
            2,
            "--runs must be an integer in 1..=1000",
        ),
        (&["experiment", "grid", "--runs", "100000000"], 2, runs),
        (
            &["worker", "--run", "x", "--startup-timeout", "1e30"],
            2,
            "invalid value '1e30' for '--startup-timeout <STARTUP_TIMEOUT>': must be a number of seconds in 0..=86400",
        ),
        // Huge: ran forever, or could not learn.
        (
            &["experiment", "function", "--episodes", "9223372036854775807"],
            2,
            "--episodes must be an integer in 1..=10000000",
        ),
        (&["experiment", "function", "--xi", "1e308"], 2, xi),
        (&["experiment", "function", "--epsilon", "1e308"], 2, epsilon),
        (&["experiment", "function", "--initial-sigma", "1e300"], 2, sigma),
        (
            &["experiment", "function", "--n-theta", "1000"],
            2,
            "--n-theta must be an integer in 5..=64",
        ),
        (
            &["experiment", "function", "--in-flight", "100000"],
            2,
            "--in-flight must be an integer in 1..=16384",
        ),
        (
            &["experiment", "function", "--runs", "2", "--seed", "9223372036854775807"],
            2,
            "--seed must be an integer in 0..=2^63-1 - (runs - 1)",
        ),
        (
            &["run", "function", "--workers", "130"],
            2,
            "invalid value '130' for '--workers <WORKERS>': must be an integer in 0..=128",
        ),
        (
            &["learn", "--workers", "130"],
            2,
            "invalid value '130' for '--workers <WORKERS>': must be an integer in 0..=128",
        ),
        (&["learn", "--runs", "5000"], 2, "--runs must be an integer in 1..=1000"),
        (
            &["bench", "--scale", "1e9"],
            2,
            "invalid value '1e9' for '--scale <SCALE>': must be a number in (0, 100]",
        ),
        (
            &["bench", "--max-workers", "129"],
            2,
            "invalid value '129' for '--max-workers <MAX_WORKERS>': must be an integer in 1..=128",
        ),
        (
            &["experiment", "toy", "--progress-every", "0.01"],
            2,
            "invalid value '0.01' for '--progress-every <SECONDS>': must be a number of seconds in 0.1..=3600",
        ),
        (
            &["experiment", "toy", "--max-failed-share", "1.5"],
            2,
            "invalid value '1.5' for '--max-failed-share <SHARE>': must be a share in 0..=1",
        ),
        (
            &["bench", "--rounds", "101"],
            2,
            "invalid value '101' for '--rounds <ROUNDS>': must be an integer in 1..=100",
        ),
        (
            &["bench", "--worker-queue-depth", "129"],
            2,
            "'--worker-queue-depth <WORKER_QUEUE_DEPTH>': must be an integer in 1..=128",
        ),
        (
            &["worker", "--run", "x", "--spin-us", "1000001"],
            2,
            "invalid value '1000001' for '--spin-us <SPIN_US>': must be an integer in 0..=1000000",
        ),
        (
            &["experiment", "toy", "--checkpoint-every", "10000001"],
            2,
            "invalid value '10000001' for '--checkpoint-every <N>': must be an integer in 0..=10000000",
        ),
        (
            &["evaluate", "nowhere", "--run", "1000"],
            2,
            "invalid value '1000' for '--run <RUN>': must be an integer in 0..=999",
        ),
        // Every value in range, but more records than any machine holds: refused before running.
        (
            &["experiment", "function", "--runs", "1000", "--episodes", "10000000"],
            2,
            "function: 6 methods x 1000 runs of 10000000 episodes (200002 evaluations on 100 test contexts each) would hold about 28.6 TB in memory, more than the",
        ),
        (
            &[
                "run",
                "grid",
                "--runs",
                "1000",
                "--episodes",
                "10000000",
                "--workers",
                "0",
            ],
            2,
            "available now (MemAvailable in /proc/meminfo): lower runs (--runs), episodes (--episodes) or the number of methods (--method)",
        ),
        // Tiny.
        (&["experiment", "function", "--epsilon", "1e-300"], 2, epsilon),
        (&["experiment", "function", "--initial-sigma", "1e-300"], 2, sigma),
        (&["experiment", "function", "--initial-sigma", "0"], 2, sigma),
        (
            &["bench", "--scale", "0"],
            2,
            "'--scale <SCALE>': must be a number in (0, 100]",
        ),
        // Negative: refused with the range, not with clap's tip to write `-- -1`.
        (
            &["experiment", "toy", "--runs", "-1"],
            2,
            "invalid value '-1' for '--runs <RUNS>': must be an integer in 1..=1000",
        ),
        (
            &["learn", "--runs", "-1"],
            2,
            "invalid value '-1' for '--runs <RUNS>': must be an integer in 1..=1000",
        ),
        (
            &["experiment", "toy", "--episodes", "-5"],
            2,
            "invalid value '-5' for '--episodes <EPISODES>': must be an integer in 1..=10000000",
        ),
        (
            &["experiment", "toy", "--seed", "-1"],
            2,
            "invalid value '-1' for '--seed <SEED>': must be an integer in 0..=2^63-1",
        ),
        (
            &["experiment", "toy", "--in-flight", "-1"],
            2,
            "invalid value '-1' for '--in-flight <IN_FLIGHT>'",
        ),
        (
            &["experiment", "dims", "--n-s", "-2"],
            2,
            "invalid value '-2' for '--n-s <N_S>': must be an integer in 1..=4",
        ),
        (
            &["experiment", "function", "--n-theta", "-3"],
            2,
            "invalid value '-3' for '--n-theta <N_THETA>'",
        ),
        (&["experiment", "toy", "--xi", "-1e-9"], 2, xi),
        (&["experiment", "function", "--epsilon", "-1"], 2, epsilon),
        (
            &["run", "grid", "--workers", "-1"],
            2,
            "invalid value '-1' for '--workers <WORKERS>': must be an integer in 0..=128",
        ),
        (
            &["run", "grid", "--worker-in-flight", "-1"],
            2,
            "invalid value '-1' for '--worker-in-flight",
        ),
        (
            &["run", "grid", "--worker-nice", "-1"],
            2,
            "invalid value '-1' for '--worker-nice <WORKER_NICE>': must be an integer in 0..=19",
        ),
        (
            &["experiment", "toy", "--checkpoint-every", "-1"],
            2,
            "invalid value '-1' for '--checkpoint-every <N>'",
        ),
        (
            &["bench", "--max-workers", "-1"],
            2,
            "invalid value '-1' for '--max-workers <MAX_WORKERS>'",
        ),
        (
            &["bench", "--rounds", "-1"],
            2,
            "invalid value '-1' for '--rounds <ROUNDS>'",
        ),
        (
            &["bench", "--scale", "-1"],
            2,
            "invalid value '-1' for '--scale <SCALE>'",
        ),
        (
            &["worker", "--run", "x", "--in-flight", "-1"],
            2,
            "invalid value '-1' for '--in-flight <IN_FLIGHT>'",
        ),
        (
            &["worker", "--run", "x", "--spin-us", "-1"],
            2,
            "invalid value '-1' for '--spin-us <SPIN_US>'",
        ),
        (
            &["worker", "--run", "x", "--nice", "-1"],
            2,
            "invalid value '-1' for '--nice <N>'",
        ),
        (
            &["worker", "--run", "x", "--startup-timeout", "-1"],
            2,
            "invalid value '-1' for '--startup-timeout",
        ),
        (
            &["evaluate", "nowhere", "--run", "-1"],
            2,
            "invalid value '-1' for '--run <RUN>': must be an integer in 0..=999",
        ),
        // NaN and infinities.
        (&["experiment", "toy", "--xi", "nan"], 2, xi),
        (&["experiment", "function", "--epsilon", "inf"], 2, epsilon),
        (&["experiment", "function", "--initial-sigma", "-inf"], 2, sigma),
        (
            &["bench", "--scale", "NaN"],
            2,
            "invalid value 'NaN' for '--scale <SCALE>'",
        ),
        (
            &["worker", "--run", "x", "--startup-timeout", "inf"],
            2,
            "invalid value 'inf' for '--startup-timeout",
        ),
        // Just outside a bound.
        (&["experiment", "toy", "--runs", "1001"], 2, runs),
        (&["experiment", "toy", "--episodes", "10000001"], 2, episodes),
        (&["experiment", "function", "--epsilon", "0.0000999"], 2, epsilon),
        (&["experiment", "function", "--initial-sigma", "1.1e12"], 2, sigma),
        (&["experiment", "toy", "--xi", "1000000.1"], 2, xi),
        (
            &["worker", "--run", "x", "--startup-timeout", "86400.5"],
            2,
            "must be a number of seconds in 0..=86400",
        ),
        (&["bench", "--scale", "100.01"], 2, "must be a number in (0, 100]"),
        (&["run", "grid", "--workers", "129"], 2, "must be an integer in 0..=128"),
        // The network of hosts.
        (
            &["run", "grid", "--lease", "0.09"],
            2,
            "must be a number of seconds in 0.1..=3600",
        ),
        (
            &["relay", "--connect", "tcp/127.0.0.1:1", "--lease", "3601"],
            2,
            "must be a number of seconds in 0.1..=3600",
        ),
        (
            &["relay", "--connect", "tcp/127.0.0.1:1", "--queue", "0"],
            2,
            "invalid value '0' for '--queue <QUEUE>': must be an integer in 1..=4096",
        ),
        (
            &["relay", "--connect", "tcp/127.0.0.1:1", "--wait-for-learner", "-1"],
            2,
            "must be a number of seconds in 0..=86400",
        ),
        (
            &["relay", "--connect", "udp/127.0.0.1:7447"],
            2,
            "--connect udp/127.0.0.1:7447: endpoint \"udp/127.0.0.1:7447\": protocol \"udp\" is not built in",
        ),
        (
            &["run", "grid", "--listen", "tls/127.0.0.1:7447"],
            2,
            "--listen tls/127.0.0.1:7447: endpoint \"tls/127.0.0.1:7447\": TLS is not built in: Zenoh 1.10's TLS links are unsound",
        ),
        (
            &["run", "grid", "--listen", "127.0.0.1:7447"],
            2,
            "--listen 127.0.0.1:7447: endpoint \"127.0.0.1:7447\": no protocol",
        ),
        (
            &["run", "grid", "--lease", "1"],
            2,
            "--zenoh-config and --lease set up the network of hosts, which only --listen (acps run) or --connect (acps relay) opens",
        ),
        (
            &[
                "relay",
                "--connect",
                "tcp/127.0.0.1:1",
                "--zenoh-config",
                "/nonexistent.json5",
            ],
            2,
            "--zenoh-config /nonexistent.json5: not a readable file",
        ),
        (
            &["relay", "--connect", "tcp/127.0.0.1:1", "--run", "a_b"],
            2,
            "--run a_b",
        ),
        // Relay credentials: a key file that is not there, or none said.
        (
            &[
                "relay",
                "--connect",
                "tcp/127.0.0.1:1",
                "--relay-key",
                "/nonexistent/relay.key",
            ],
            2,
            "--relay-key: relay key /nonexistent/relay.key: no such file (copy the key file the learner made, `relay.key` in its run directory, to this host)",
        ),
        (
            &["relay", "--connect", "tcp/127.0.0.1:1"],
            2,
            "--relay-key FILE is missing: a copy of the relay.key its learner made",
        ),
        (
            &[
                "relay",
                "--connect",
                "tcp/127.0.0.1:1",
                "--relay-key",
                "k",
                "--no-relay-key",
            ],
            2,
            "the argument '--relay-key <FILE>' cannot be used with '--no-relay-key'",
        ),
        // Not a number at all.
        (
            &["experiment", "toy", "--runs", "three"],
            2,
            "invalid value 'three' for '--runs <RUNS>': must be an integer in 1..=1000",
        ),
        (
            &["experiment", "toy", "--xi", "0x10"],
            2,
            "invalid value '0x10' for '--xi <XI>': must be a number in 0..=1e6",
        ),
    ];
    for &(args, code, expected) in cases {
        let out = acps(args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(code), "{args:?}: {stderr}");
        assert!(
            stderr.contains(expected) && !stderr.contains("panicked") && !stderr.contains("tip:"),
            "{args:?}: {stderr}"
        );
    }
}

/// The bounds themselves are accepted: `--save-config` checks every setting and the fleet's
/// options and writes the file without running anything.
#[test]
fn numbers_on_the_bounds_of_their_ranges_are_accepted() {
    let dir = temp_dir("bounds");
    std::fs::create_dir_all(&*dir).unwrap();
    let cases: &[&[&str]] = &[
        &[
            "experiment",
            "function",
            "--runs",
            "1",
            "--episodes",
            "1",
            "--in-flight",
            "1",
            "--n-theta",
            "5",
            "--initial-sigma",
            "1e-12",
            "--epsilon",
            "1e-4",
            "--xi",
            "0",
            "--checkpoint-every",
            "0",
            "--progress-every",
            "0.1",
            "--max-failed-share",
            "0",
        ],
        &[
            "experiment",
            "function",
            "--runs",
            "1000",
            "--episodes",
            "10000000",
            "--in-flight",
            "16384",
            "--n-theta",
            "64",
            "--initial-sigma",
            "1e12",
            "--epsilon",
            "10",
            "--xi",
            "1e6",
            "--checkpoint-every",
            "10000000",
            "--progress-every",
            "3600",
            "--max-failed-share",
            "1",
        ],
        &[
            "run",
            "grid",
            "--workers",
            "128",
            "--worker-queue-depth",
            "128",
            "--worker-nice",
            "19",
            "--runs",
            "1000",
        ],
        &[
            "run",
            "grid",
            "--workers",
            "0",
            "--worker-queue-depth",
            "1",
            "--worker-nice",
            "0",
        ],
    ];
    for (i, args) in cases.iter().enumerate() {
        let saved = dir.join(format!("{i}.toml"));
        let mut args = args.to_vec();
        args.extend(["--save-config", saved.to_str().unwrap()]);
        let out = acps(&args);
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(saved.is_file());
    }
    // xi = 0 (no exploration bonus) also runs: the D-UCB methods are greedy on their means.
    let out = acps(&[
        "experiment",
        "toy",
        "--panel",
        "a",
        "--xi",
        "0",
        "--runs",
        "1",
        "--episodes",
        "30",
        "-q",
        "--out",
        dir.join("xi-0").to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
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

/// A worker's queue and the learner's window have different names now; the old names of the
/// worker's queue still work, with a warning that names the new one.
#[test]
fn the_old_names_of_a_workers_queue_still_work_with_a_warning() {
    let dir = temp_dir("deprecated-queue");
    let args: Vec<String> = [
        "run",
        "function",
        "--method",
        "random",
        "--runs",
        "1",
        "--episodes",
        "50",
        "--workers",
        "1",
        "--worker-in-flight",
        "2",
        "-q",
        "--checkpoint-every",
        "0",
        "--out",
    ]
    .iter()
    .map(|a| a.to_string())
    .chain([dir.to_str().unwrap().to_string()])
    .collect();
    let output = acps_strings(&args);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(
        stderr.contains("warning: --worker-in-flight is deprecated and will be removed: use --worker-queue-depth"),
        "{stderr}"
    );
    let output = acps_strings(&[
        "worker".into(),
        "--in-flight".into(),
        "4".into(),
        "--queue-depth".into(),
        "4".into(),
    ]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("'--in-flight <IN_FLIGHT>' cannot be used with '--queue-depth <QUEUE_DEPTH>'"),
        "{stderr}"
    );
    let output = acps_strings(&[
        "worker".into(),
        "--in-flight".into(),
        "4".into(),
        "--run".into(),
        "no-such-run".into(),
        "--startup-timeout".into(),
        "0".into(),
    ]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("warning: --in-flight is deprecated and will be removed: use --queue-depth"),
        "{stderr}"
    );
}

/// Piped, a run writes plain progress lines (the first report at once, then every
/// --progress-every) and its final line, instead of a terminal's bar; quiet, none.
#[test]
fn a_piped_run_writes_plain_progress_lines() {
    for quiet in [false, true] {
        let dir = temp_dir("piped");
        let mut args: Vec<String> = [
            "experiment",
            "function",
            "--method",
            "random",
            "--runs",
            "2",
            "--episodes",
            "300",
            "--progress-every",
            "0.1",
            "--out",
        ]
        .iter()
        .map(|a| a.to_string())
        .collect();
        args.push(dir.to_str().unwrap().into());
        if quiet {
            args.push("-q".into());
        }
        let output = acps_strings(&args);
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(output.status.success(), "{stderr}");
        let progress = stderr
            .lines()
            .filter(|l| l.starts_with("function: ") && l.contains("/600 episodes, test ln cost "))
            .count();
        let done = stderr
            .lines()
            .filter(|l| l.starts_with("function: done, final test ln cost "))
            .count();
        assert_eq!((progress >= 1, done), (!quiet, usize::from(!quiet)), "{stderr}");
    }
}

#[test]
fn a_closed_output_ends_a_command_quietly() {
    // `acps protocol | head -1` where head has gone before acps writes: its output closed first.
    let dir = temp_dir("closed-output");
    let out = dir.join("function");
    let run: &[&str] = &[
        "experiment",
        "function",
        "--runs",
        "1",
        "--episodes",
        "50",
        "--method",
        "random",
        "--out",
        out.to_str().unwrap(),
    ];
    for args in [&["protocol"][..], &["evaluate", "--help"][..], run] {
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_acps"))
            .args(args)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("acps runs");
        drop(child.stdout.take());
        let output = child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(!stderr.contains("panicked"), "acps {args:?}: {stderr}");
        assert!(output.status.success(), "acps {args:?}: {} {stderr}", output.status);
    }
    assert!(out.join("summary.json").is_file(), "the run's record is whole");
}

#[test]
fn a_full_output_is_an_error_naming_standard_output() {
    let full = std::fs::File::options().write(true).open("/dev/full").unwrap();
    let output = watched().arg("protocol").stdout(full).output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.starts_with("error: writing to standard output: No space left on device"),
        "{stderr}"
    );
}

#[test]
fn help_gives_each_command_one_line_and_usage_shows_the_file_form() {
    let help = succeeded(&acps(&["--help"]));
    let commands: Vec<&str> = help
        .lines()
        .skip_while(|line| *line != "Commands:")
        .skip(1)
        .take_while(|line| !line.is_empty())
        .collect();
    assert!(commands.len() >= 9, "{help}");
    for line in &commands {
        assert!(
            line.len() <= 100,
            "a command's line of {} characters: {line}",
            line.len()
        );
        assert!(!line.contains(" s on "), "a timing claim: {line}");
    }
    for command in ["run", "experiment"] {
        let output = acps(&[command]);
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{stderr}");
        assert!(stderr.contains(&format!("acps {command} --config FILE")), "{stderr}");
    }
}

#[test]
fn a_huge_bad_value_is_shown_cut_not_echoed_whole() {
    let name = "x".repeat(100_000);
    let output = acps(&["experiment", "function", "--method", &name]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{stderr}");
    assert!(stderr.len() < 2000, "{} bytes of error", stderr.len());
    assert!(
        stderr.contains("(100002 characters)") && stderr.contains("--method"),
        "{stderr}"
    );
}
