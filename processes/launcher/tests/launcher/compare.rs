//! `acps compare` on tiny run directories written here, with every expected number computed in
//! the test from the curves it wrote.

use crate::{acps, succeeded, temp_dir};
use acps_reports::compare::{paired_t, wilcoxon};
use std::path::Path;

/// Curves of three runs (seeds 0, 1, 2) evaluated at episodes 0, 100 and 200.
type Curves = [[f64; 3]; 3];

const EPISODES: [u64; 3] = [0, 100, 200];

/// A run directory of `experiment` holding these methods' curves, as `acps experiment` writes it
/// (the fields `acps compare` reads).
fn run_dir(dir: &Path, experiment: &str, retire: bool, methods: &[(&str, Curves)]) {
    std::fs::create_dir_all(dir).unwrap();
    let summary = serde_json::json!({
        "experiment": experiment,
        "metric": "a test score",
        "runs": 3,
        "base_seed": 0,
        "training_episodes": 200,
        "settings": { "retire": if retire { serde_json::json!({ "probe_every": 10 }) } else { serde_json::Value::Null } },
        "methods": {},
    });
    std::fs::write(dir.join("summary.json"), summary.to_string()).unwrap();
    let mut csv = String::from("method,run,seed,episode,score\n");
    for (method, curves) in methods {
        for (run, curve) in curves.iter().enumerate() {
            for (episode, score) in EPISODES.iter().zip(curve) {
                csv.push_str(&format!("{method},{run},{run},{episode},{score}\n"));
            }
        }
    }
    std::fs::write(dir.join("runs.csv"), csv).unwrap();
}

const RANDOM: Curves = [[10.0, 6.0, 4.0], [12.0, 8.0, 5.0], [9.0, 7.0, 3.0]];
const ROUND_ROBIN: Curves = [[10.0, 7.0, 5.0], [12.0, 9.0, 6.0], [9.0, 8.0, 4.0]];
const TEACHER: Curves = [[10.0, 5.0, 2.0], [12.0, 6.0, 3.5], [9.0, 4.0, 2.5]];

fn report(args: &[&str]) -> serde_json::Value {
    serde_json::from_str(&succeeded(&acps(args))).unwrap()
}

/// `acps compare FIRST --with SECOND --json`.
fn paired(first: &Path, second: &Path) -> serde_json::Value {
    report(&[
        "compare",
        first.to_str().unwrap(),
        "--with",
        second.to_str().unwrap(),
        "--json",
    ])
}

fn row<'a>(report: &'a serde_json::Value, method: &str, metric: &str) -> &'a serde_json::Value {
    report["rows"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["method"] == method && r["metric"] == metric)
        .unwrap_or_else(|| panic!("no row {method} {metric} in {report}"))
}

fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

fn close(a: &serde_json::Value, b: f64) {
    let a = a.as_f64().unwrap_or_else(|| panic!("{a} is no number"));
    assert!((a - b).abs() < 1e-12, "{a} != {b}");
}

#[test]
fn compare_pairs_every_method_with_the_best_baseline() {
    let dir = temp_dir("compare");
    run_dir(
        &dir,
        "grid",
        false,
        &[("random", RANDOM), ("round-robin", ROUND_ROBIN), ("alp-gmm", TEACHER)],
    );
    let dir_arg = dir.to_str().unwrap();
    let report = report(&["compare", dir_arg, "--levels", "6,3", "--json"]);
    // Lower is better on the grid: random's finals (4, 5, 3) beat round robin's (5, 6, 4).
    assert_eq!(report["baseline"], "random");
    assert_eq!(report["lower_is_better"], true);
    let final_d: Vec<f64> = (0..3).map(|r| TEACHER[r][2] - RANDOM[r][2]).collect();
    let teacher_final = row(&report, "alp-gmm", "final");
    close(&teacher_final["value"]["mean"], mean(&TEACHER.map(|c| c[2])));
    close(&teacher_final["difference"]["mean"], mean(&final_d));
    close(&teacher_final["wilcoxon"]["p"], wilcoxon(&final_d).p.unwrap());
    close(&teacher_final["t_test"]["p"], paired_t(&final_d).p.unwrap());
    // The area over 0..200 by trapezoids, divided by 200.
    let auc = |c: [f64; 3]| (100.0 * (c[0] + c[1]) / 2.0 + 100.0 * (c[1] + c[2]) / 2.0) / 200.0;
    let auc_d: Vec<f64> = (0..3).map(|r| auc(TEACHER[r]) - auc(RANDOM[r])).collect();
    close(&row(&report, "alp-gmm", "auc")["difference"]["mean"], mean(&auc_d));
    // To 3: the teacher at 200, 200 and never (200 + one interval of 100); random never, never, 200.
    let to_3 = row(&report, "alp-gmm", "episodes to 3");
    assert_eq!(to_3["not_reached"], 1);
    close(&to_3["value"]["mean"], mean(&[200.0, 200.0, 300.0]));
    close(
        &to_3["difference"]["mean"],
        mean(&[200.0 - 300.0, 200.0 - 300.0, 300.0 - 200.0]),
    );
    // The baseline's own rows carry no test.
    assert!(row(&report, "random", "final").get("wilcoxon").is_none());
    // Both tables name every method and the baseline.
    let long = succeeded(&acps(&["compare", dir_arg, "--levels", "6,3"]));
    assert!(long.contains("| alp-gmm | episodes to 3 | 3 |"), "{long}");
    let wide = succeeded(&acps(&["compare", dir_arg, "--levels", "6,3", "--wide"]));
    assert!(wide.contains("| **random** (baseline) |"), "{wide}");
    assert!(
        wide.contains("| method | final | auc | episodes to 6 | episodes to 3 |"),
        "{wide}"
    );
}

#[test]
fn compare_reads_the_direction_and_pairs_a_retiring_run() {
    let (first, second) = (temp_dir("compare-toy"), temp_dir("compare-toy-retire"));
    // Section 4's J: higher is better, so round robin's finals (5, 6, 4) beat random's.
    run_dir(
        &first,
        "toy",
        false,
        &[("random", RANDOM), ("round-robin", ROUND_ROBIN)],
    );
    run_dir(&second, "toy", true, &[("monotonic-progress", TEACHER)]);
    let report = paired(&first, &second);
    assert_eq!(report["baseline"], "round-robin");
    assert_eq!(report["lower_is_better"], false);
    let d: Vec<f64> = (0..3).map(|r| TEACHER[r][2] - ROUND_ROBIN[r][2]).collect();
    let retired = row(&report, "monotonic-progress+retire", "final");
    close(&retired["difference"]["mean"], mean(&d));
    // Differences -3, -2.5 and -1.5: no ties, so the exact test. Every one is negative (W+ = 0),
    // which one of the 2^3 sign patterns gives, as does all positive on the other side: p = 2 / 8.
    assert_eq!(retired["wilcoxon"]["exact"], true);
    close(&retired["wilcoxon"]["p"], 2.0 / 8.0);
}

/// A run of the other learner pairs with the first run's methods under METHOD+c-cmaes.
#[test]
fn compare_pairs_a_run_of_the_other_learner() {
    let (first, second) = (temp_dir("compare-c-reps"), temp_dir("compare-c-cmaes"));
    let shape = ["--runs", "3", "--episodes", "200", "--method", "random", "-q", "--out"];
    succeeded(&acps(
        &[&["experiment", "function"][..], &shape, &[first.to_str().unwrap()]].concat(),
    ));
    let learner = ["--learner", "c-cmaes"];
    succeeded(&acps(
        &[
            &["experiment", "function"][..],
            &learner,
            &shape,
            &[second.to_str().unwrap()],
        ]
        .concat(),
    ));
    let report = paired(&first, &second);
    assert_eq!(report["baseline"], "random");
    assert_eq!(row(&report, "random+c-cmaes", "final")["n"], 3);
}

#[test]
fn compare_names_bad_input() {
    let dir = temp_dir("compare-bad");
    run_dir(&dir, "grid", false, &[("random", RANDOM), ("alp-gmm", TEACHER)]);
    let dir_arg = dir.to_str().unwrap();
    let refused = |args: &[&str]| {
        let out = acps(args);
        assert!(!out.status.success(), "{args:?} succeeded");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let missing = dir.join("nothing");
    let error = refused(&["compare", missing.to_str().unwrap()]);
    assert!(error.contains("nothing/summary.json"), "{error}");
    assert_eq!(error.matches("os error 2").count(), 1, "the reason once: {error}");
    // A directory of panels (`acps experiment toy` writes DIR/a..d) names them.
    let panels = temp_dir("compare-panels");
    for panel in ["a", "b"] {
        run_dir(&panels.join(panel), "toy", false, &[("random", RANDOM)]);
    }
    let error = refused(&["compare", panels.to_str().unwrap()]);
    let first = panels.join("a");
    assert!(
        error.contains("holds no run of its own but 2 panels")
            && error.contains(&format!("`acps compare {}`", first.display())),
        "{error}"
    );
    let error = refused(&["compare", dir_arg, "--baseline", "corners"]);
    assert!(
        error.contains("method 'corners' is not in") && error.contains("alp-gmm, random"),
        "{error}"
    );
    let error = refused(&["compare", dir_arg, "--levels", "5,0"]);
    assert!(error.contains("--levels 0: the scores are distances"), "{error}");
    let error = refused(&["compare", dir_arg, "--levels", "5,x"]);
    assert!(error.contains("--levels x: not a number"), "{error}");
    let other = temp_dir("compare-other");
    run_dir(&other, "function", true, &[("random", RANDOM)]);
    let error = refused(&["compare", dir_arg, "--with", other.to_str().unwrap()]);
    assert!(error.contains("experiment differs (function vs grid)"), "{error}");
    let no_baseline = temp_dir("compare-no-baseline");
    run_dir(&no_baseline, "grid", false, &[("alp-gmm", TEACHER)]);
    let error = refused(&["compare", no_baseline.to_str().unwrap()]);
    assert!(error.contains("none of the baselines"), "{error}");
}
