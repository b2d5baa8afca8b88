//! Problem files: a `[problem]` table of the user's, checked key by key, and served through the
//! fleet to workers the user provides (here processes/worker/examples/bowl.rs).

use crate::{TempDir, acps, assert_clean, run_name, succeeded, temp_dir, watched};
use acps_experiments::file::LoadedFile;
use acps_experiments::plan::Plan;
use acps_experiments::settings::ExperimentFile;
use acps_shared::EnvironmentSpec;
use acps_wire::ipc;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;
use std::time::SystemTime;

/// The shipped example problem.
pub(crate) fn bowl_toml() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments/bowl.toml")
}

/// The bowl example's worker, in this test's target directory: `cargo test --workspace` builds
/// the examples; a test of this package alone builds it here when it is missing or older than
/// its source.
pub(crate) fn bowl_worker() -> &'static Path {
    static BOWL: OnceLock<PathBuf> = OnceLock::new();
    BOWL.get_or_init(|| {
        let profile_dir = Path::new(env!("CARGO_BIN_EXE_acps")).parent().unwrap();
        let path = profile_dir.join("examples").join("bowl");
        let source = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worker/examples/bowl.rs");
        let modified = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
        if modified(&path).unwrap_or(SystemTime::UNIX_EPOCH) < modified(&source).unwrap() {
            let mut cargo = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
            cargo
                .args(["build", "-q", "-p", "acps-worker", "--example", "bowl", "--target-dir"])
                .arg(profile_dir.parent().unwrap());
            if profile_dir.ends_with("release") {
                cargo.arg("--release");
            }
            let status = cargo.status().unwrap();
            assert!(status.success(), "building the bowl example failed");
        }
        path
    })
}

/// The bowl worker's command line for --worker-command, with environment variables `vars`.
pub(crate) fn worker_command(vars: &str) -> String {
    format!("env {vars} '{}'", bowl_worker().display())
}

/// `acps run` of `config` on `workers` started from `command`, under a watchdog.
/// One bowl run long enough to be killed while it learns, with a checkpoint after every update.
pub(crate) const LONG_BOWL: [&str; 8] = [
    "--runs",
    "1",
    "--method",
    "monotonic-progress",
    "--episodes",
    "20000",
    "--checkpoint-every",
    "1",
];

/// Wait until the run writing to `out` has written a checkpoint (with [`LONG_BOWL`]: learning
/// has begun) and `also` holds; fails if that takes two minutes or the run ends first.
pub(crate) fn wait_for_learning(learner: &mut std::process::Child, out: &Path, also: impl Fn() -> bool) {
    let start = std::time::Instant::now();
    while !(crate::fleet::has_checkpoint(&out.join("checkpoints")) && also()) {
        assert!(
            start.elapsed() < std::time::Duration::from_secs(120),
            "no checkpoint appeared"
        );
        assert!(
            learner.try_wait().unwrap().is_none(),
            "the run ended before a checkpoint"
        );
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
}

pub(crate) fn run(config: &Path, command: &str, workers: &str, test: &str, out: &Path, extra: &[&str]) -> Output {
    let run = run_name(test);
    let output = watched()
        .args(["run", "--config"])
        .arg(config)
        .args(["--worker-command", command, "--workers", workers, "--run", run.as_str()])
        .args(extra)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    assert_clean(&run);
    output
}

fn summary(dir: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(dir.join("summary.json")).unwrap()).unwrap()
}

/// The message `text` (a file named e.toml) is refused with.
fn refusal(text: &str) -> String {
    let file = match LoadedFile::parse(Path::new("e.toml"), text.to_string()) {
        Ok(file) => file,
        Err(error) => return error.to_string(),
    };
    match Plan::new(Some(&file), &ExperimentFile::default()) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(error) => error.to_string(),
    }
}

#[test]
fn bad_problem_files_are_refused_naming_file_line_key_and_range() {
    // A valid table; every case changes one thing.
    let valid = "runs = 1\n[problem]\ntraining_contexts = [[0.0, 0.0], [1.0, 1.0]]\ntheta0 = [0.0, 0.0]\n";
    // So is one with numbers on the bounds of their ranges.
    let bounds = valid
        .replace("theta0 = [0.0, 0.0]", "theta0 = [1e6, -1e6]")
        .replace("[[0.0, 0.0], [1.0, 1.0]]", "[[-1e6, 0.0], [1e6, 1.0]]");
    for text in [valid.to_string(), bounds] {
        let file = LoadedFile::parse(Path::new("e.toml"), text.clone()).unwrap();
        assert!(Plan::new(Some(&file), &ExperimentFile::default()).is_ok(), "{text}");
    }
    let with = |line: &str| format!("{valid}{line}\n");
    let contexts = |points: &str| valid.replace("[[0.0, 0.0], [1.0, 1.0]]", points);
    let cases = [
        (
            format!("experiment = \"grid\"\n{valid}"),
            "e.toml:3: problem and experiment exclude each other",
        ),
        (
            format!("n_s = 2\n{valid}"),
            "e.toml:1: n_s applies to dims only, not to a [problem] table",
        ),
        (
            format!("sim = \"rapier\"\n{valid}"),
            "e.toml:1: sim applies to grid, dartboard only, not to a [problem] table",
        ),
        (
            format!("fig3_learning_factors = true\n{valid}"),
            "e.toml:1: fig3_learning_factors applies to toy only",
        ),
        (
            valid.replace("theta0 = [0.0, 0.0]\n", ""),
            "e.toml:2: problem.theta0 must be set: a list of 1 to 64 numbers in -1e6..=1e6",
        ),
        (
            valid.replace("[0.0, 0.0]\n", "[]\n"),
            "e.toml:4: problem.theta0 must be a list of 1 to 64 numbers in -1e6..=1e6 (the initial parameters), got []",
        ),
        (
            valid.replace("theta0 = [0.0, 0.0]", &format!("theta0 = {:?}", vec![0.0; 65])),
            "e.toml:4: problem.theta0 must be a list of 1 to 64",
        ),
        (
            valid.replace("theta0 = [0.0, 0.0]", "theta0 = [0.0, nan]"),
            "e.toml:4: problem.theta0 must be a list of 1 to 64 numbers in -1e6..=1e6 (the initial parameters), got [0.0, nan]",
        ),
        (
            valid.replace("theta0 = [0.0, 0.0]", "theta0 = [0.0, \"x\"]"),
            "e.toml:4: problem.theta0 must be a list of 1 to 64 numbers in -1e6..=1e6 (the initial parameters), got \"x\"",
        ),
        (
            valid.replace("theta0 = [0.0, 0.0]", "theta0 = [0.0, -1000001.0]"),
            "e.toml:4: problem.theta0 must be a list of 1 to 64 numbers in -1e6..=1e6 (the initial parameters), got [0.0, -1000001.0]",
        ),
        (
            valid.replace("theta0 = [0.0, 0.0]", "theta0 = [1e300]"),
            "e.toml:4: problem.theta0 must be a list of 1 to 64 numbers in -1e6..=1e6 (the initial parameters), got [1e300]",
        ),
        (
            contexts("[]"),
            "e.toml:3: problem.training_contexts must be a non-empty list of at most 100,000 points",
        ),
        (
            contexts("[[0.0, 0.0], [1.0, 1e7]]"),
            "e.toml:3: problem.training_contexts must be a non-empty list of at most 100,000 points (a grid's limit), each of 1 to 8 coordinates in -1e6..=1e6 (as many as context_low's), inside the context box, got point 1 [1.0, 10000000.0]",
        ),
        (
            with("test_grid = { low = [-1e300, 0.0], high = [1e300, 1.0], points = [2, 2] }"),
            "e.toml:5: problem.test_grid must be a table { low = [..], high = [..], points = [..] } of 1 to 8 dimensions: low <= high in -1e6..=1e6",
        ),
        (
            with("context_low = [-2e6, 0.0]\ncontext_high = [1.0, 1.0]"),
            "e.toml:5: problem.context_low must be a list of 1 to 8 numbers in -1e6..=1e6, one per context dimension (default: the lower corner of the contexts' bounding box), got [-2e6, 0.0]",
        ),
        (
            valid.replace("training_contexts = [[0.0, 0.0], [1.0, 1.0]]\n", ""),
            "e.toml:2: problem.training_contexts must be set",
        ),
        (
            with("training_grid = { low = [0.0], high = [1.0], points = [2] }"),
            "e.toml:5: problem.training_grid and problem.training_contexts exclude each other",
        ),
        (
            with(&format!("test_contexts = {:?}", vec![[0.5, 0.5]; 100_001])),
            "e.toml:5: problem.test_contexts must be a non-empty list of at most 100,000 points (a grid's limit), each of 1 to 8 coordinates in -1e6..=1e6 (as many as context_low's), inside the context box, got 100001 points",
        ),
        (
            contexts("[[0.0, 0.0], [1.0]]"),
            "e.toml:3: problem.training_contexts must be a non-empty list of at most 100,000 points (a grid's limit), each of 1 to 8 coordinates in -1e6..=1e6 (as many as context_low's), inside the context box, got point 1 [1.0] of 1 coordinates, not 2",
        ),
        (
            contexts("[[0.0, inf]]"),
            "e.toml:3: problem.training_contexts must be a non-empty list of at most 100,000 points (a grid's limit), each of 1 to 8 coordinates in -1e6..=1e6 (as many as context_low's), inside the context box, got point 0 [0.0, inf]",
        ),
        (
            contexts(&format!("[{:?}, {:?}]", vec![0.0; 9], vec![1.0; 9])),
            "e.toml:3: problem.training_contexts must be a non-empty list of at most 100,000 points (a grid's limit), each of 1 to 8 coordinates in -1e6..=1e6 (as many as context_low's), inside the context box, got 9-D contexts",
        ),
        (
            with("context_low = [0.0, 0.0]\ncontext_high = [0.5, 2.0]"),
            "e.toml:3: problem.training_contexts must be a non-empty list of at most 100,000 points (a grid's limit), each of 1 to 8 coordinates in -1e6..=1e6 (as many as context_low's), inside the context box, got point 1 [1.0, 1.0], outside the context box [0.0, 0.0] .. [0.5, 2.0]",
        ),
        (
            with("context_low = [0.0, 0.0]\ncontext_high = [1.0, 1.0]\ntest_contexts = [[0.5, 0.5], [0.5, -0.5]]"),
            "e.toml:7: problem.test_contexts must be a non-empty list of at most 100,000 points (a grid's limit), each of 1 to 8 coordinates in -1e6..=1e6 (as many as context_low's), inside the context box, got point 1 [0.5, -0.5], outside the context box [0.0, 0.0] .. [1.0, 1.0]",
        ),
        (
            with("test_grid = { low = [0.0, 0.0], high = [1.0, 1.0], points = [0, 2] }"),
            "e.toml:5: problem.test_grid must be a table { low = [..], high = [..], points = [..] } of 1 to 8 dimensions: low <= high in -1e6..=1e6, points >= 1 per dimension and at most 100000 in all, inside the context box, got { low = [0.0, 0.0], high = [1.0, 1.0], points = [0, 2] }",
        ),
        (
            with("test_grid = { low = [0.0, 0.0], high = [1.0, 1.0], points = [-1, 2] }"),
            "e.toml:5: problem.test_grid must be a table { low = [..], high = [..], points = [..] } of 1 to 8 dimensions",
        ),
        (
            with("test_grid = { low = [0.0, 0.0], high = [1.0, 1.0], points = [1, 1], step = 2 }"),
            "e.toml:5: problem.test_grid must be a table { low = [..], high = [..], points = [..] } of 1 to 8 dimensions: low <= high in -1e6..=1e6, points >= 1 per dimension and at most 100000 in all, inside the context box, got step",
        ),
        (
            with("context_low = [0.0, 0.0]\ncontext_high = [1.0, 1.0, 1.0]"),
            "e.toml:6: problem.context_high must be a list of numbers in -1e6..=1e6, one per context dimension, each above context_low's (default: the upper corner of the contexts' bounding box), got [1.0, 1.0, 1.0]",
        ),
        (
            with("context_low = [0.0, 1.0]\ncontext_high = [1.0, 1.0]"),
            "e.toml:6: problem.context_high must be a list of numbers in -1e6..=1e6, one per context dimension, each above context_low's",
        ),
        (
            with("context_low = [0.0, 0.0]"),
            "e.toml:2: problem.context_high must be set",
        ),
        (
            contexts("[[0.0, 0.0], [1.0, 0.0]]"),
            "e.toml:2: problem.context_low must be a list of 1 to 8 numbers in -1e6..=1e6, one per context dimension (default: the lower corner of the contexts' bounding box), got nothing, and every context has coordinate 1 = 0: set context_low and context_high",
        ),
        (
            contexts("[[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]") + "features = \"polar\"\n",
            "e.toml:5: problem.features must be one of affine, quadratic, polar (2-D contexts only), got \"polar\" for 3-D contexts",
        ),
        (
            with("features = \"cubic\""),
            "e.toml:5: problem.features must be one of affine, quadratic, polar (2-D contexts only), got \"cubic\"",
        ),
        (
            with("score = \"median\""),
            "e.toml:5: problem.score must be one of sum, mean, log-mean, got \"median\"",
        ),
        (
            with("metric = \" \""),
            "e.toml:5: problem.metric must be a text that is not blank, got \" \"",
        ),
        (
            with("name = \"my bowl\""),
            "e.toml:5: problem.name must be 1 to 32 characters of ASCII letters, digits, '-', '_' and '.' (default: the file's name without .toml), got \"my bowl\"",
        ),
        (with("wokers = 2"), "e.toml:5: unknown field `wokers`, expected one of"),
        (
            with("[problem.environment]\nname = \"a b\"\nsettings = \"\""),
            "e.toml:6: problem.environment.name must be 1 to 32 characters of ASCII letters, digits, '-', '_' and '.', got \"a b\"",
        ),
        (
            with("[problem.environment]\nname = \"bowl\""),
            "e.toml:5: problem.environment.settings must be set: a text",
        ),
        (
            with("[problem.environment]\nname = \"bowl\"\nsettings = \"v1\"\nparameters = [1, 2]"),
            "e.toml:8: problem.environment.parameters must be three integers in 0..=2^63-1, got [1, 2]",
        ),
        (
            with("[problem.environment]\nname = \"bowl\"\nsettings = \"v1\"\nparameters = [0, 0, 0, 7]"),
            "e.toml:8: problem.environment.parameters must be three integers in 0..=2^63-1, got [0, 0, 0, 7]",
        ),
        (
            with("[problem.environment]\nname = \"bowl\"\nsettings = \"v1\"\nparameters = [1, -2, 3]"),
            "e.toml:8: problem.environment.parameters must be three integers in 0..=2^63-1, got -2",
        ),
    ];
    for (text, expected) in cases {
        let message = refusal(&text);
        assert!(message.starts_with(expected), "{text}\n{message}\nexpected: {expected}");
    }
    // A long value is shown by its start and length, not echoed whole.
    let long = format!("{:?}", vec![0.0; 65]);
    let message = refusal(&valid.replace("theta0 = [0.0, 0.0]", &format!("theta0 = {long}")));
    assert!(
        message.ends_with(&format!("got {} ... ({} characters)", &long[..120], long.len())),
        "{message}"
    );
    // The default name is the file's stem, which must be a valid name too.
    let file = LoadedFile::parse(Path::new("my bowl.toml"), valid.into()).unwrap();
    let message = Plan::new(Some(&file), &ExperimentFile::default())
        .err()
        .unwrap()
        .to_string();
    assert!(
        message.starts_with("my bowl.toml:2: problem.name must be 1 to 32 characters")
            && message.ends_with("got \"my bowl\" (the file's name: set problem.name)"),
        "{message}"
    );
}

#[test]
fn files_too_large_or_not_regular_are_refused_without_reading_them() {
    let dir = temp_dir("file-limits");
    std::fs::create_dir_all(&*dir).unwrap();
    let large = dir.join("large.toml");
    // A valid start, then comments beyond the limit: refused by its size, before parsing.
    let mut text = String::from("runs = 1\n");
    while text.len() as u64 <= acps_experiments::file::MAX_FILE_BYTES {
        text += "# padding padding padding padding padding padding padding padding padding\n";
    }
    std::fs::write(&large, &text).unwrap();
    let fifo = dir.join("fifo.toml");
    let made = Command::new("mkfifo").arg(&fifo).status().unwrap();
    assert!(made.success());
    for (file, reason) in [
        (&large, format!("{} bytes, more than the 16 MiB", text.len())),
        (&fifo, "not a regular file".to_string()),
    ] {
        // Under the watchdog: reading the FIFO would block for ever.
        let output = watched()
            .args(["run", "--config", file.to_str().unwrap(), "--workers", "0"])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{stderr}");
        assert!(
            stderr.contains(&format!("{}: cannot read", file.display())) && stderr.contains(&reason),
            "{stderr}"
        );
    }
}

#[test]
fn a_bad_problem_file_is_refused_before_workers_start_or_the_directory_is_written() {
    let dir = temp_dir("bad-problem");
    std::fs::create_dir_all(&*dir).unwrap();
    let file = dir.join("bad.toml");
    std::fs::write(&file, "[problem]\ntraining_contexts = [[0.0], [1.0]]\ntheta0 = []\n").unwrap();
    let out = dir.join("out");
    let output = acps(&[
        "run",
        "--config",
        file.to_str().unwrap(),
        "--worker-command",
        "false",
        "--out",
        out.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(
        stderr.contains(&format!("{}:3: problem.theta0 must be", file.display())),
        "{stderr}"
    );
    assert!(!out.exists(), "the output directory was written");
}

#[test]
fn a_problem_is_refused_in_process_and_without_workers() {
    let config = bowl_toml();
    let config = config.to_str().unwrap();
    let dir = temp_dir("refused-commands");
    let out = dir.join("out");
    let out = out.to_str().unwrap();
    let output = acps(&["experiment", "--config", config, "--out", out]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(
        stderr.contains(
            "problem 'bowl' is a problem of your own, simulated by your workers: use `acps run --config FILE --worker-command CMD` (or --workers 0 and start them yourself)"
        ),
        "{stderr}"
    );
    let output = acps(&["run", "--config", config, "--workers", "2", "--out", out]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(
        stderr.contains("problem 'bowl' needs your workers: --worker-command CMD or --workers 0"),
        "{stderr}"
    );
    for (workers, command, says) in [
        (
            "2",
            " ",
            "--worker-command must be a command that starts your worker, got \" \"",
        ),
        ("0", "my-worker", "with --workers 0 it would start none"),
    ] {
        let output = acps(&[
            "run",
            "--config",
            config,
            "--workers",
            workers,
            "--worker-command",
            command,
            "--out",
            out,
        ]);
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(!output.status.success() && stderr.contains(says), "{stderr}");
    }
    assert!(!dir.exists(), "a refused command wrote {}", dir.display());
}

#[test]
fn the_bowl_learns_on_its_workers_and_two_workers_give_one_workers_bits() {
    let dir = temp_dir("bowl");
    let two = dir.join("two");
    let command = worker_command("");
    succeeded(&run(&bowl_toml(), &command, "2", "bowl-2", &two, &["-q"]));
    // The resolved file re-runs it: on one worker, the same bits.
    let one = dir.join("one");
    succeeded(&run(&two.join("config.toml"), &command, "1", "bowl-1", &one, &["-q"]));
    let bits = |dir: &Path| std::fs::read(dir.join("summary.json")).unwrap();
    assert_eq!(bits(&two), bits(&one));
    let summary = summary(&two);
    assert_eq!(summary["experiment"], "bowl");
    assert_eq!(summary["metric"], "distance to the target");
    assert_eq!(summary["user_problem"]["lower_is_better"], true);
    for (method, result) in summary["methods"].as_object().unwrap() {
        let first = result["mean"][0].as_f64().unwrap();
        let last = result["final_mean"].as_f64().unwrap();
        assert!(last < first / 2.0, "{method} did not learn: {first} -> {last}");
        for run in 0..2 {
            let policy = two.join("policies").join(format!("{method}-run{run}.json"));
            let policy: serde_json::Value = serde_json::from_slice(&std::fs::read(policy).unwrap()).unwrap();
            assert_eq!(policy["policy"]["features"], "affine");
            assert_eq!(policy["problem"]["theta0"], serde_json::json!([0.0, 0.0, 0.0, 0.0]));
            assert_eq!(policy["problem"]["training_contexts"].as_array().unwrap().len(), 9);
            assert_eq!(policy["user_problem"]["unit"], "");
        }
    }
    for picture in ["curves", "selections", "selections-time", "updates"] {
        for extension in ["svg", "png"] {
            assert!(
                two.join(format!("{picture}.{extension}")).is_file(),
                "{picture}.{extension}"
            );
        }
    }
    for paper_only in ["throw.svg", "board.svg"] {
        assert!(!two.join(paper_only).exists(), "{paper_only}");
    }
    let curves = std::fs::read_to_string(two.join("curves.svg")).unwrap();
    assert!(curves.contains("distance to the target") && curves.contains("lower is better"));
    // acps cannot replay the user's simulator: it says where the policy is.
    let output = acps(&["evaluate", two.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(
        stderr.contains("problem 'bowl' is a problem of your own, which acps cannot simulate")
            && stderr.contains("acps_worker.Policy.load(path).mean(context)"),
        "{stderr}"
    );
}

/// The spec the bowl worker declares with settings `settings`.
pub(crate) fn bowl_spec(settings: &str) -> EnvironmentSpec {
    EnvironmentSpec::from_text("bowl", [0, 0, 0], settings).unwrap()
}

/// A refused run's stderr: it ends when no worker is left.
pub(crate) fn refused(output: &Output) -> String {
    assert!(!output.status.success(), "{}", String::from_utf8_lossy(&output.stdout));
    String::from_utf8_lossy(&output.stderr).into_owned()
}

#[test]
fn started_workers_that_never_connect_stop_the_run_naming_their_command() {
    // What a Python worker stuck at an import looks like: a process that runs and never asks.
    let dir = temp_dir("stuck");
    let output = run(
        &bowl_toml(),
        "sleep 3600",
        "1",
        "stuck",
        &dir.join("out"),
        &["-q", "--worker-startup-timeout", "1"],
    );
    assert_eq!(
        output.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains(
            "connected within 1 s: 1 started worker processes (`sh -c 'exec sleep 3600'`) ran but none asked for tasks"
        ) && stderr.contains("raise --worker-startup-timeout"),
        "{stderr}"
    );
    // The same run resumed would hang the same way: no --resume is offered.
    assert!(!stderr.contains("--resume"), "{stderr}");
    assert!(!dir.join("out").join("summary.json").exists());
}

#[test]
fn a_worker_of_other_settings_is_refused_and_the_run_says_so() {
    let dir = temp_dir("bowl-v2");
    let output = run(
        &bowl_toml(),
        &worker_command("BOWL_SETTINGS='bowl v2'"),
        "1",
        "bowl-v2",
        &dir.join("out"),
        &["-q"],
    );
    let stderr = refused(&output);
    // Both sides' settings texts, beside their hashes.
    let reason = format!(
        "it serves environment {} = \"bowl v2\"; the jobs need {} = \"bowl v1\"",
        bowl_spec("bowl v2"),
        bowl_spec("bowl v1")
    );
    assert!(
        stderr.contains("refused a worker") && stderr.contains(&reason),
        "{stderr}"
    );
    assert!(stderr.contains("no worker can go on"), "{stderr}");
    // The run ends on the refusal, and does not offer a --resume that would meet it again.
    assert!(
        stderr.contains(&format!("the learner refused a worker: {reason}")),
        "{stderr}"
    );
    assert!(!stderr.contains("--resume"), "{stderr}");
    assert!(!dir.join("out").join("summary.json").exists());
}

/// `experiments/bowl.toml` without its environment table and with fewer episodes, in `dir`.
fn unnamed_bowl(dir: &TempDir) -> PathBuf {
    std::fs::create_dir_all(&**dir).unwrap();
    let text = std::fs::read_to_string(bowl_toml()).unwrap();
    let (text, _) = text.split_once("[problem.environment]").unwrap();
    let path = dir.join("unnamed.toml");
    std::fs::write(&path, text.replace("episodes = 400", "episodes = 60")).unwrap();
    path
}

#[test]
fn a_problem_without_an_environment_admits_only_workers_that_declare_none() {
    let dir = temp_dir("unnamed");
    let file = unnamed_bowl(&dir);
    let out = dir.join("admitted");
    succeeded(&run(
        &file,
        &worker_command("BOWL_UNNAMED=1"),
        "1",
        "unnamed",
        &out,
        &["-q"],
    ));
    assert!(out.join("summary.json").is_file());
    let output = run(
        &file,
        &worker_command(""),
        "1",
        "unnamed-bowl",
        &dir.join("refused"),
        &["-q"],
    );
    let stderr = refused(&output);
    let reason = format!(
        "it serves environment {} = \"bowl v1\"; the jobs need no named environment",
        bowl_spec("bowl v1")
    );
    assert!(stderr.contains(&reason), "{stderr}");
}

#[test]
fn a_killed_problem_run_resumes_to_the_uninterrupted_result() {
    let dir = temp_dir("bowl-resume");
    let command = worker_command("");
    let shape = [LONG_BOWL.as_slice(), &["-q"]].concat();
    let reference = dir.join("reference");
    succeeded(&run(&bowl_toml(), &command, "2", "resume-ref", &reference, &shape));
    let out = dir.join("killed");
    let name = run_name("resume");
    let mut learner = Command::new(env!("CARGO_BIN_EXE_acps"))
        .args(["run", "--config"])
        .arg(bowl_toml())
        .args(["--worker-command", &command, "--workers", "2", "--run", name.as_str()])
        .args(&shape)
        .arg("--out")
        .arg(&out)
        .spawn()
        .unwrap();
    // SIGKILL once learning has begun: a checkpoint is written after every update.
    wait_for_learning(&mut learner, &out, || true);
    let _ = learner.kill();
    let _ = learner.wait();
    assert!(!out.join("summary.json").exists(), "killed before the end");
    // Its workers notice and leave.
    let start = std::time::Instant::now();
    while ipc::live_nodes(&name).map_or(true, |alive| alive > 0) {
        assert!(
            start.elapsed() < std::time::Duration::from_secs(60),
            "the killed run's workers stay"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let mut resume = shape.to_vec();
    resume.extend(["--resume", out.to_str().unwrap()]);
    succeeded(&run(&bowl_toml(), &command, "2", "resume", &out, &resume));
    assert_eq!(
        std::fs::read(out.join("summary.json")).unwrap(),
        std::fs::read(reference.join("summary.json")).unwrap()
    );
}
