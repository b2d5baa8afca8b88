//! The run directory's tables, policies and pictures, and `acps evaluate` replaying a saved
//! policy.

use crate::{TempDir, acps, temp_dir, watched};
use std::path::Path;
use std::process::Output;

fn stdout(out: &Output) -> String {
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout.clone()).unwrap()
}

/// The error message of a command that must be refused (exit code 2), under the watchdog: a
/// command that blocks (on a FIFO, say) fails instead of hanging the test.
fn refusal(args: &[&str]) -> String {
    let out = watched().args(args).output().unwrap();
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
    stderr
}

fn experiment(name: &str, method: &str, episodes: &str) -> TempDir {
    let dir = temp_dir(name);
    let out = acps(&[
        "experiment",
        name,
        "--runs",
        "1",
        "--episodes",
        episodes,
        "--seed",
        "3",
        "--method",
        method,
        "-q",
        "--out",
        dir.to_str().unwrap(),
    ]);
    stdout(&out);
    dir
}

/// One short grid run (0.04 s), a test's own.
fn grid() -> TempDir {
    experiment("grid", "monotonic-progress", "200")
}

fn summary(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap()
}

/// The rows of a CSV file after checking its header.
fn csv(path: &Path, header: &str) -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(header), "{}", path.display());
    lines
        .map(|l| l.split(',').map(str::to_string).collect::<Vec<_>>())
        .collect()
}

fn number(field: &str) -> f64 {
    field.parse().unwrap_or_else(|_| panic!("'{field}' is not a number"))
}

#[test]
fn the_csv_tables_repeat_summary_json() {
    let dir = grid();
    let s = summary(&dir);
    let m = &s["methods"]["monotonic-progress"];
    let episodes = m["episodes"].as_array().unwrap();
    assert_eq!(episodes.len(), 3, "evaluations at 0, 100 and 200");

    let curves = csv(&dir.join("curves.csv"), "method,episode,mean,sem");
    assert_eq!(curves.len(), episodes.len());
    for (i, row) in curves.iter().enumerate() {
        assert_eq!(row[0], "monotonic-progress");
        assert_eq!(number(&row[1]), episodes[i].as_f64().unwrap());
        assert_eq!(number(&row[2]), m["mean"][i].as_f64().unwrap());
        assert_eq!(number(&row[3]), m["sem"][i].as_f64().unwrap());
    }

    // One run: its scores are the mean curve.
    let runs = csv(&dir.join("runs.csv"), "method,run,seed,episode,score");
    assert_eq!(runs.len(), episodes.len());
    for (i, row) in runs.iter().enumerate() {
        assert_eq!((row[1].as_str(), row[2].as_str()), ("0", "3"));
        assert_eq!(number(&row[4]), m["mean"][i].as_f64().unwrap());
    }

    let selections = csv(&dir.join("selections.csv"), "method,episode,arm,s0,s1,reward");
    let chosen = m["selections_run0"].as_array().unwrap();
    assert_eq!(selections.len(), 200);
    let contexts = s["training_contexts"].as_array().unwrap();
    for (t, row) in selections.iter().enumerate() {
        assert_eq!(number(&row[1]), t as f64);
        let arm = chosen[t].as_u64().unwrap() as usize;
        assert_eq!(row[2], arm.to_string());
        assert_eq!(number(&row[3]), contexts[arm][0].as_f64().unwrap());
        assert_eq!(number(&row[4]), contexts[arm][1].as_f64().unwrap());
        assert!(number(&row[5]) < 0.0, "grid rewards are -||s - b||^2");
    }

    // An update every 50 rollouts, each solved to the optimum: KL = epsilon off the bound.
    let updates = csv(&dir.join("updates.csv"), acps_experiments::records::UPDATES_HEADER);
    assert_eq!(
        updates.len() as u64,
        m["updates"].as_u64().unwrap() + m["rejected_updates"].as_u64().unwrap()
    );
    assert_eq!(updates.len(), 4);
    let epsilon = s["settings"]["creps"]["epsilon"].as_f64().unwrap();
    for (k, row) in updates.iter().enumerate() {
        let column = |name: &str| {
            acps_experiments::records::UPDATES_HEADER
                .split(',')
                .position(|h| h == name)
        };
        let field = |name: &str| row[column(name).unwrap()].as_str();
        assert_eq!((field("method"), field("run")), ("monotonic-progress", "0"));
        assert_eq!(number(field("update")), k as f64);
        assert_eq!(number(field("episode")), 50.0 * (k + 1) as f64);
        assert_eq!(number(field("epsilon")), epsilon);
        assert_eq!(field("rejected"), "", "update {k} was applied");
        let samples = number(field("samples"));
        assert!(samples >= 25.0 && samples <= 50.0 * (k + 1) as f64, "{row:?}");
        assert!(
            number(field("optimality")) <= 1e-10 && number(field("iterations")) >= 1.0,
            "{row:?}"
        );
        let kl = number(field("kl"));
        if field("eta_at_bound") == "false" {
            assert!((kl - epsilon).abs() < 1e-8, "{row:?}");
        } else {
            assert!(kl <= epsilon, "{row:?}");
        }
        let ess = number(field("ess"));
        assert!(ess >= 1.0 && ess <= samples, "{row:?}");
        assert!(
            number(field("eta")) > 0.0 && number(field("trace_sigma")) > 0.0,
            "{row:?}"
        );
        // 21 parameters: the mean of the eigenvalues bounds their geometric mean (AM-GM).
        let (logdet, trace) = (number(field("logdet_sigma")), number(field("trace_sigma")));
        assert!(
            logdet.is_finite() && logdet <= 21.0 * (trace / 21.0).ln() + 1e-9,
            "{row:?}"
        );
    }
}

#[test]
fn every_picture_is_written_as_svg_and_png() {
    let dir = grid();
    for stem in ["curves", "selections", "selections-time", "throw", "updates"] {
        let png = std::fs::read(dir.join(format!("{stem}.png"))).unwrap();
        assert!(png.starts_with(b"\x89PNG\r\n\x1a\n"), "{stem}.png");
        assert!(png.len() > 5_000, "{stem}.png has only {} bytes", png.len());
        let svg = std::fs::read_to_string(dir.join(format!("{stem}.svg"))).unwrap();
        assert!(svg.starts_with("<svg"), "{stem}.svg");
    }
    // 200 episodes in 50 bins, as the title says.
    let heatmap = std::fs::read_to_string(dir.join("selections-time.svg")).unwrap();
    assert!(heatmap.contains("monotonic-progress") && heatmap.contains("each bin of 4 training episodes"));
}

#[test]
fn the_policy_file_describes_the_final_policy() {
    let dir = grid();
    let s = summary(&dir);
    let path = dir.join("policies/monotonic-progress-run0.json");
    let policy: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    assert_eq!(policy["format"], "acps-policy-2");
    // The environment the problem is defined for, which a replay must rebuild exactly.
    let environment = &policy["problem"]["environment"];
    assert_eq!(
        (environment["name"].as_str(), &environment["parameters"]),
        (Some("throw-grid"), &serde_json::json!([0, 0, 0]))
    );
    assert_eq!(environment["settings"].as_str().map(str::len), Some(16));
    assert_eq!(
        (policy["experiment"].as_str(), policy["run"].as_u64()),
        (Some("grid"), Some(0))
    );
    assert_eq!(policy["seed"], 3);
    assert_eq!(policy["final_score"], s["methods"]["monotonic-progress"]["final_mean"]);
    assert_eq!(policy["problem"]["test_contexts"].as_array().unwrap().len(), 16);
    assert_eq!(policy["policy"]["features"], "polar-quadratic");
    let weights = policy["policy"]["weights"].as_array().unwrap();
    assert_eq!(weights.len(), 6);
    assert!(weights.iter().all(|row| row.as_array().unwrap().len() == 21));
    // The C-REPS updates (one per 50 rollouts) moved the mean away from theta_0.
    assert!(
        weights
            .iter()
            .flat_map(|r| r.as_array().unwrap())
            .any(|w| w.as_f64().unwrap() != 0.0)
    );
    assert_eq!(policy["policy"]["covariance"].as_array().unwrap().len(), 21);
}

#[test]
fn the_grid_summary_names_the_best_policy_of_all_runs() {
    let dir = temp_dir("best-policy");
    #[rustfmt::skip]
    let args = ["experiment", "grid", "--runs", "2", "--episodes", "300", "--seed", "5",
        "--method", "round-robin", "--method", "best-reward", "-q", "--out", dir.to_str().unwrap()];
    stdout(&acps(&args));
    let s = summary(&dir);
    let best = &s["best_policy"];
    let score = best["score"].as_f64().expect("the grid summary names its best policy");

    // It is the lowest score any evaluation of any run reached, and runs.csv shows where.
    let runs = csv(&dir.join("runs.csv"), "method,run,seed,episode,score");
    assert_eq!(runs.len(), 2 * 2 * 4, "2 methods x 2 runs x evaluations at 0..=300");
    let lowest = runs.iter().map(|r| number(&r[4])).fold(f64::INFINITY, f64::min);
    assert_eq!(score, lowest);
    let row = runs
        .iter()
        .find(|r| number(&r[4]) == score)
        .expect("a row holds the best score");
    assert_eq!(best["method"].as_str(), Some(row[0].as_str()));
    assert_eq!(best["run"].as_u64().unwrap().to_string(), row[1]);
    assert_eq!(best["seed"].as_u64().unwrap().to_string(), row[2]);
    assert_eq!(best["episode"].as_u64().unwrap().to_string(), row[3]);
    assert_eq!(best["seed"].as_u64(), Some(5 + best["run"].as_u64().unwrap()));
    for (method, m) in s["methods"].as_object().unwrap() {
        assert!(score <= m["final_mean"].as_f64().unwrap(), "{method}");
    }
    assert!(score < 92.0, "300 episodes improve on the initial throw's 92 cm");

    // Per run: the final score, as in runs.csv, and the longest stay on one context.
    for (method, m) in s["methods"].as_object().unwrap() {
        let finals: Vec<f64> = runs
            .iter()
            .filter(|r| &r[0] == method && r[3] == "300")
            .map(|r| number(&r[4]))
            .collect();
        let summarised: Vec<f64> = m["final_scores"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(summarised, finals, "{method}");
    }
    assert_eq!(s["methods"]["round-robin"]["longest_stay"], serde_json::json!([1, 1]));

    // The curves draw it as Fig. 8's reference line.
    let svg = std::fs::read_to_string(dir.join("curves.svg")).unwrap();
    assert!(
        svg.contains(&format!("best policy ({score:.2} cm)")),
        "no reference line in curves.svg"
    );
    // ... and, as the paper's Fig. 8, beside a zoom on the second half of training.
    assert!(svg.contains("the second half, zoomed"), "no zoomed panel in curves.svg");

    // Problems without that reference have none, and no zoomed panel.
    let function = temp_dir("no-best-policy");
    #[rustfmt::skip]
    let args = ["experiment", "function", "--runs", "1", "--episodes", "50", "--method", "random", "-q",
        "--out", function.to_str().unwrap()];
    stdout(&acps(&args));
    assert!(summary(&function).get("best_policy").is_none());
    let svg = std::fs::read_to_string(function.join("curves.svg")).unwrap();
    assert!(!svg.contains("zoomed"));
}

/// The value after `label` on the line that starts with it.
fn value_after<'a>(text: &'a str, label: &str) -> &'a str {
    let line = text
        .lines()
        .find(|l| l.starts_with(label))
        .unwrap_or_else(|| panic!("no '{label}' in\n{text}"));
    line[label.len()..].split_whitespace().next().unwrap()
}

#[test]
fn evaluate_reproduces_the_learners_final_test_score() {
    let dir = grid();
    let s = summary(&dir);
    let text = stdout(&acps(&["evaluate", dir.to_str().unwrap()]));
    assert_eq!(
        text.lines().filter(|l| l.starts_with("  target (")).count(),
        16,
        "{text}"
    );
    let score = value_after(
        &text,
        "test-set score (mean distance to the test targets in cm, exploration off):",
    );
    assert_eq!(
        number(score),
        s["methods"]["monotonic-progress"]["final_mean"].as_f64().unwrap(),
        "{text}"
    );
    assert!(text.contains("error (cm): mean "), "{text}");
}

#[test]
fn evaluate_names_the_simulator_and_its_settings() {
    let rapier = temp_dir("rapier");
    #[rustfmt::skip]
    let args = ["experiment", "grid", "--sim", "rapier", "--runs", "1", "--episodes", "50",
        "--method", "round-robin", "-q", "--out", rapier.to_str().unwrap()];
    stdout(&acps(&args));
    let cases: [(TempDir, &str); 3] = [
        (
            grid(),
            "simulator: analytic (the PA-10's commanded joint state at release, closed-form flight); environment throw-grid [0, 0, 0] (settings ",
        ),
        (
            rapier,
            "simulator: rapier (the PA-10 as a rapier3d multibody tracking the throw with joint motors: step 0.008 s, 32 solver iterations, motor stiffness 1e10 1/s^2, damping 1e7 1/s; closed-form flight after release); environment throw-grid [1, 0, 0] (settings ",
        ),
        (
            experiment("function", "random", "20"),
            "simulator: the contextual function of n_s = 2, n_theta = 20, problem seed 3; environment contextual-function [2, 20, 3] (settings ",
        ),
    ];
    for (dir, expected) in cases {
        let text = stdout(&acps(&["evaluate", dir.to_str().unwrap()]));
        assert!(text.lines().nth(1).unwrap().starts_with(expected), "{text}");
    }
}

#[test]
fn a_method_that_cannot_work_on_the_experiment_is_refused_before_running() {
    let dir = temp_dir("toy-continuous");
    std::fs::create_dir_all(&*dir).unwrap();
    let file = dir.join("toy.toml");
    std::fs::write(
        &file,
        "experiment = \"toy\"\nmethods = [\"round-robin\", \"random-continuous\"]\n",
    )
    .unwrap();
    let out = dir.join("out");
    let (out, file) = (out.to_str().unwrap(), file.to_str().unwrap());
    let cases: [&[&str]; 2] = [
        &["experiment", "toy", "--method", "random-continuous", "--out", out],
        &["experiment", "--config", file, "--out", out],
    ];
    for args in cases {
        let error = refusal(args);
        assert!(
            error.contains("method random-continuous draws contexts from the continuous space, but experiment 'toy' takes only its training contexts; choose a method that selects among them"),
            "{args:?}: {error}"
        );
        assert!(!Path::new(out).exists(), "{args:?} wrote {out}");
    }
}

#[test]
fn evaluate_reproduces_a_function_run() {
    let dir = experiment("function", "random", "100");
    let s = summary(&dir);
    let text = stdout(&acps(&[
        "evaluate",
        dir.to_str().unwrap(),
        "--method",
        "random",
        "--run",
        "0",
    ]));
    assert_eq!(text.lines().filter(|l| l.starts_with("  context (")).count(), 100);
    let score = value_after(
        &text,
        "test-set score (natural log of the mean cost |f - f*| over the test contexts, exploration off):",
    );
    assert_eq!(number(score), s["methods"]["random"]["final_mean"].as_f64().unwrap());
}

#[test]
fn evaluate_throws_at_chosen_targets_and_renders() {
    let dir = grid();
    let picture = dir.join("chosen.png");
    let text = stdout(&acps(&[
        "evaluate",
        dir.to_str().unwrap(),
        "--target",
        "-3.25,-3.25",
        "--target",
        "-4.6,-3.1",
        "--render",
        picture.to_str().unwrap(),
    ]));
    let throws: Vec<&str> = text.lines().filter(|l| l.starts_with("  target (")).collect();
    assert_eq!(throws.len(), 2, "{text}");
    assert!(throws[1].starts_with("  target (-4.6000, -3.1000): landed ("), "{text}");
    assert!(!text.contains("test-set score"), "targets were given: {text}");
    // The first target is also the first test target: the same throw as in the test-set replay.
    let test_set = stdout(&acps(&["evaluate", dir.to_str().unwrap()]));
    assert_eq!(
        test_set.lines().find(|l| l.starts_with("  target (")),
        Some(throws[0]),
        "{text}\n{test_set}"
    );
    let png = std::fs::read(picture).unwrap();
    assert!(png.starts_with(b"\x89PNG") && png.len() > 5_000);
}

#[test]
fn evaluate_refuses_bad_targets_with_the_accepted_range() {
    let grid = grid();
    let dir = grid.to_str().unwrap();
    let error = refusal(&["evaluate", dir, "--target", "-9,-4"]);
    assert!(
        error.contains("--target -9,-4: outside the grid problem's context space, which takes coordinate 0 in [-5, -3], coordinate 1 in [-5, -3]"),
        "{error}"
    );
    let error = refusal(&["evaluate", dir, "--target", "NaN,-4"]);
    assert!(
        error.contains("target coordinates must be finite, got 'NaN'"),
        "{error}"
    );
    let error = refusal(&["evaluate", dir, "--target", "-4,-4,1"]);
    assert!(
        error.contains("the grid problem's targets have 2 coordinates"),
        "{error}"
    );
    let error = refusal(&["evaluate", dir, "--target", "-4;-4"]);
    assert!(error.contains("is not a number; write the target as X,Y"), "{error}");
    let error = refusal(&["evaluate", dir, "--render", "throw.jpg"]);
    assert!(
        error.contains("--render throw.jpg: the file name must end in .svg or .png"),
        "{error}"
    );
}

#[test]
fn evaluate_refuses_what_is_not_a_policy_of_the_run_directory() {
    let grid = grid();
    let dir = grid.to_str().unwrap();
    let other = temp_dir("not-policies");
    std::fs::create_dir_all(other.join("policies")).unwrap();
    let fifo = other.join("fifo");
    let made = |path: &Path| {
        let status = std::process::Command::new("mkfifo").arg(path).status().unwrap();
        assert!(status.success(), "mkfifo {}", path.display());
    };
    made(&fifo);
    // A FIFO among the policies, as --method could name it.
    made(&grid.join("policies/fifo-run0.json"));
    let empty = other.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    // A copy of the run whose policy says it is another method's.
    let relabelled = other.join("relabelled");
    std::fs::create_dir_all(relabelled.join("policies")).unwrap();
    let original = std::fs::read_to_string(grid.join("policies/monotonic-progress-run0.json")).unwrap();
    std::fs::write(
        relabelled.join("policies/monotonic-progress-run0.json"),
        original.replace("\"method\": \"monotonic-progress\"", "\"method\": \"diversity\""),
    )
    .unwrap();
    let at = |path: &Path| path.to_str().unwrap().to_string();
    let cases: Vec<(Vec<String>, String)> = vec![
        (
            vec![dir.into(), "--method".into(), "diversity".into()],
            format!(
                "--method diversity: {dir}/policies holds no policy file of that method for run 0; --method must be one of [fifo, monotonic-progress]"
            ),
        ),
        // A path is not a method: it cannot reach a file outside DIR/policies.
        (
            vec![dir.into(), "--method".into(), "../../x".into()],
            "--method ../../x: ".into(),
        ),
        (
            vec![dir.into(), "--run".into(), "4".into()],
            "holds no policy file of run 4 (--run); --run must be one of [0]".into(),
        ),
        (
            vec![dir.into(), "--method".into(), "fifo".into()],
            format!("{dir}/policies/fifo-run0.json is a named pipe (FIFO), not a policy file"),
        ),
        (vec![at(&empty)], "has no policies/ directory".into()),
        (
            vec![at(&other)],
            "policies holds no policy file (METHOD-runR.json)".into(),
        ),
        (
            vec![at(&other.join("missing"))],
            "missing does not exist; give a run directory".into(),
        ),
        (
            vec!["/dev/zero".into()],
            "/dev/zero is a character device, not a run directory or a policy file".into(),
        ),
        (
            vec![at(&fifo)],
            format!(
                "{} is a named pipe (FIFO), not a run directory or a policy file",
                fifo.display()
            ),
        ),
        (
            vec![at(&relabelled)],
            "monotonic-progress-run0.json: method \"diversity\" and run 0 are not the ones the file's name says".into(),
        ),
    ];
    for (args, expected) in cases {
        let mut all = vec!["evaluate"];
        all.extend(args.iter().map(String::as_str));
        let error = refusal(&all);
        assert!(error.contains(&expected), "{args:?}: {error}");
    }
}

#[test]
fn evaluate_refuses_edited_policy_files_naming_the_file_and_field() {
    let grid = grid();
    let function = experiment("function", "random", "20");
    let broken = temp_dir("broken");
    std::fs::create_dir_all(&*broken).unwrap();
    let file = broken.join("policy.json");
    type Edit = fn(&mut serde_json::Value);
    // (run directory, edit of its policy, message after the file's name)
    let cases: [(&Path, Edit, &str); 20] = [
        (
            &grid,
            |p| p["policy"]["weights"].as_array_mut().unwrap().truncate(5),
            "policy weights: must have 6 rows, got 5",
        ),
        // The row that is short is the one blamed, also when it is the first.
        (
            &grid,
            |p| p["policy"]["weights"][0].as_array_mut().unwrap().truncate(20),
            "policy weights: every row must have 21 entries (n_theta), row 0 has 20 (n_theta: problem.theta0 has 21 entries)",
        ),
        (
            &grid,
            |p| p["policy"]["covariance"][3][4] = 1e3.into(),
            "policy covariance: covariance must be",
        ),
        (
            &grid,
            |p| p["format"] = "acps-policy-0".into(),
            "format must be \"acps-policy-2\", got \"acps-policy-0\"",
        ),
        (
            &grid,
            |p| p["problem"]["theta0"].as_array_mut().unwrap().truncate(20),
            "policy weights: every row must have 20 entries (n_theta), row 0 has 21 (n_theta: problem.theta0 has 20 entries)",
        ),
        (
            &grid,
            |p| p["problem"]["space"]["Box"]["low"] = serde_json::json!([-3.0, -3.0]),
            "problem.space is not a context space: context box: low and high must have the same non-zero length and finite low[i] < high[i]; got low [-3.0, -3.0], high [-3.0, -3.0]",
        ),
        (
            &grid,
            |p| p["problem"]["space"]["Box"] = serde_json::json!({"low": [-3.0, -3.0], "high": [-5.0, -5.0]}),
            "problem.space is not a context space: context box: low and high must have the same non-zero length and finite low[i] < high[i]; got low [-3.0, -3.0], high [-5.0, -5.0]",
        ),
        (
            &grid,
            |p| p["problem"]["space"]["Box"]["high"] = serde_json::json!([-2.0, -3.0]),
            "problem.space is coordinate 0 in [-5, -2], coordinate 1 in [-5, -3], but the grid experiment's run of seed 3 has coordinate 0 in [-5, -3], coordinate 1 in [-5, -3]",
        ),
        (
            &grid,
            |p| p["problem"]["test_contexts"] = serde_json::json!([]),
            "problem.test_contexts must hold at least one context, got none",
        ),
        (
            &grid,
            |p| p["problem"]["training_contexts"][2] = serde_json::json!([-4.0]),
            "problem.training_contexts must be finite with 2 entries (the space's dimension), got [-4.0] at index 2",
        ),
        (
            &grid,
            |p| p["problem"]["test_contexts"][3] = serde_json::json!([-4.0, -4.0]),
            "problem.test_contexts[3] is (-4,-4), but the grid experiment's run of seed 3 has (",
        ),
        // Relabelled as another experiment, or its problem as another problem.
        (
            &grid,
            |p| p["experiment"] = "dartboard".into(),
            "problem.environment.name \"throw-grid\" is not the dartboard experiment's environment \"throw-dartboard\"",
        ),
        (
            &grid,
            |p| p["experiment"] = "function".into(),
            "problem.environment.name \"throw-grid\" is not the function experiment's environment \"contextual-function\"",
        ),
        (
            &grid,
            |p| p["problem"]["name"] = "dartboard".into(),
            "problem.name is \"dartboard\", but the grid experiment's run of seed 3 has \"grid\"",
        ),
        (
            &grid,
            |p| p["experiment"] = "toy".into(),
            "experiment \"toy\" learns no policy",
        ),
        (
            &grid,
            |p| p["experiment"] = "bowl".into(),
            "experiment must be one of function, dims, grid, dartboard, sphere, rosenbrock (the experiments acps simulates; a problem of your own has a user_problem field), got \"bowl\"",
        ),
        (
            &grid,
            |p| p["problem"]["environment"]["parameters"] = serde_json::json!([7, 0, 0]),
            "problem.environment.parameters [7, ..] must start with 0 (analytic) or 1 (rapier), the simulator",
        ),
        // A run whose environment this build builds with other settings (another time step, say).
        (
            &grid,
            |p| p["problem"]["environment"]["settings"] = "0123456789abcdef".into(),
            "problem 'grid' is defined for environment throw-grid [0, 0, 0] (settings 0123456789abcdef), not for throw-grid [0, 0, 0] (settings ",
        ),
        (
            &function,
            |p| p["seed"] = 4.into(),
            "problem.environment.parameters [n_s, n_theta, problem seed] = [2, 20, 3] must be the problem's context dimension 2, its n_theta 20 (theta0's entries, more than n_s) and the run's seed 4",
        ),
        (
            &function,
            |p| p["problem"]["environment"]["parameters"] = serde_json::json!([2, 100000, 3]),
            "[n_s, n_theta, problem seed] = [2, 100000, 3] must be the problem's context dimension 2, its n_theta 20",
        ),
    ];
    let text = |dir: &Path| {
        let name = if dir == &*grid { "monotonic-progress" } else { "random" };
        std::fs::read_to_string(dir.join(format!("policies/{name}-run0.json"))).unwrap()
    };
    std::fs::write(&file, &text(&grid)[..text(&grid).len() / 2]).unwrap();
    let error = refusal(&["evaluate", file.to_str().unwrap()]);
    assert!(
        error.contains(&format!("{}: not an acps policy file", file.display())),
        "{error}"
    );
    for (dir, edit, expected) in cases {
        let mut policy: serde_json::Value = serde_json::from_str(&text(dir)).unwrap();
        edit(&mut policy);
        std::fs::write(&file, policy.to_string()).unwrap();
        let error = refusal(&["evaluate", file.to_str().unwrap()]);
        assert!(error.contains(&format!("{}: ", file.display())), "{error}");
        assert!(error.contains(expected), "{expected}\n{error}");
    }
}

/// The README's run-directory section, where every file's fields are documented.
fn readme_run_directory() -> String {
    let readme = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../README.md")).unwrap();
    let start = readme
        .find("### Run directory")
        .expect("README has a run-directory section");
    let end = readme[start..]
        .find("**Replaying a policy.**")
        .map_or(readme.len(), |e| start + e);
    readme[start..end].to_string()
}

#[test]
fn every_field_of_summary_json_and_run_json_is_documented_in_the_readme() {
    let section = readme_run_directory();
    let undocumented = |value: &serde_json::Value| -> Vec<String> {
        value
            .as_object()
            .unwrap()
            .keys()
            .filter(|key| !section.contains(&format!("`{key}`")))
            .cloned()
            .collect()
    };
    for (dir, method) in [
        (grid(), "monotonic-progress"),
        (experiment("dartboard", "random", "60"), "random"),
    ] {
        let summary = summary(&dir);
        assert_eq!(undocumented(&summary), Vec::<String>::new(), "summary.json");
        assert_eq!(
            undocumented(&summary["methods"][method]),
            Vec::<String>::new(),
            "a method's"
        );
        if summary["best_policy"].is_object() {
            assert_eq!(
                undocumented(&summary["best_policy"]),
                Vec::<String>::new(),
                "best_policy"
            );
        }
        let report: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("run.json")).unwrap()).unwrap();
        assert_eq!(undocumented(&report), Vec::<String>::new(), "run.json");
    }
}
