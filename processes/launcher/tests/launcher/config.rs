//! Experiment files: the shipped ones validate and match the command-line defaults, bad files are
//! refused with file, line and accepted range, and a run's resolved file re-runs it bit for bit.

use crate::{acps, temp_dir};
use acps_experiments::file::LoadedFile;
use acps_experiments::plan::Plan;
use acps_experiments::settings::{ExperimentFile, ExperimentName, SimName};
use std::path::{Path, PathBuf};

fn succeeds(args: &[&str]) {
    let out = acps(args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn shipped() -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|entry| entry.unwrap().path())
        .filter(|path| path.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    files
}

#[test]
fn every_shipped_file_validates_sets_every_key_and_matches_the_defaults() {
    let files = shipped();
    let stems: Vec<String> = files
        .iter()
        .map(|f| f.file_stem().unwrap().to_str().unwrap().to_string())
        .collect();
    for expected in [
        "toy-fig2a",
        "toy-fig2b",
        "toy-fig2c",
        "toy-fig2d",
        "toy-fig3",
        "function-fig4",
        "dims-fig6-ns1",
        "dims-fig6-ns2",
        "dims-fig6-ns3",
        "dims-fig6-ns4",
        "grid-fig8",
        "grid-fig8-rapier",
        "dartboard-fig10",
        "bolero-sphere",
        "bolero-rosenbrock",
    ] {
        assert!(
            stems.iter().any(|s| s == expected),
            "experiments/{expected}.toml missing"
        );
    }
    for path in &files {
        let file = LoadedFile::read(path).unwrap_or_else(|e| panic!("{e}"));
        let plan = Plan::new(Some(&file), &ExperimentFile::default()).unwrap_or_else(|e| panic!("{e}"));
        if file.values.problem.is_some() {
            // A problem of your own (bowl.toml), tested in `problems`.
            continue;
        }
        // Every setting is written out, so the file documents the whole run.
        assert_eq!(plan.resolved(), file.values, "{} is not fully resolved", path.display());
        // Only what selects the figure differs from what `acps experiment NAME` runs; the
        // comparisons of issue 22 (beyond-*.toml) choose their methods and retirement too, and
        // snap where the problem takes only its training contexts, but keep every other setting
        // of the figure and the teachers' defaults (self-paced's chosen on tuning seeds).
        let v = &file.values;
        let stem = path.file_stem().unwrap().to_str().unwrap();
        let comparison = stem.starts_with("beyond-");
        let selection = ExperimentFile {
            experiment: v.experiment,
            panel: v.panel,
            n_s: v.n_s,
            sim: v.sim.filter(|&s| s == SimName::Rapier),
            fig3_learning_factors: v.fig3_learning_factors.filter(|&f| f),
            methods: v.methods.clone().filter(|_| comparison),
            retire: v.retire.filter(|_| comparison),
            snap: v.snap.filter(|_| comparison),
            ..ExperimentFile::default()
        };
        let defaults = Plan::new(None, &selection).unwrap().resolved();
        assert_eq!(defaults, file.values, "{} differs from the defaults", path.display());
        if comparison {
            let name = format!("{:?}", v.experiment.unwrap()).to_lowercase();
            let expected = [
                format!("beyond-{name}"),
                format!("beyond-{name}-retire"),
                format!("beyond-{name}-self-paced"),
            ];
            assert!(
                expected.iter().any(|e| e == stem),
                "{stem}: expected one of {expected:?}"
            );
            assert_eq!(v.retire == Some(true), stem.ends_with("-retire"), "{stem}");
            continue;
        }
        let expected_stem = match v.experiment.unwrap() {
            ExperimentName::Toy if v.fig3_learning_factors == Some(true) => "toy-fig3".to_string(),
            ExperimentName::Toy => format!("toy-fig2{}", v.panel.unwrap()),
            ExperimentName::Function => "function-fig4".into(),
            ExperimentName::Dims => format!("dims-fig6-ns{}", v.n_s.unwrap()),
            ExperimentName::Grid if v.sim == Some(SimName::Rapier) => "grid-fig8-rapier".into(),
            ExperimentName::Grid => "grid-fig8".into(),
            ExperimentName::Dartboard => "dartboard-fig10".into(),
            ExperimentName::Sphere => "bolero-sphere".into(),
            ExperimentName::Rosenbrock => "bolero-rosenbrock".into(),
        };
        assert_eq!(path.file_stem().unwrap().to_str().unwrap(), expected_stem);
    }
}

#[test]
fn bad_files_are_refused_with_file_line_and_range() {
    let dir = temp_dir("bad");
    std::fs::create_dir_all(&*dir).unwrap();
    let cases = [
        (
            "experiment = \"toy\"\nruns = 2\nwokers = 4\n",
            ":3: unknown field `wokers`, expected one of `experiment`",
        ),
        (
            "experiment = \"grid\"\n# a comment\nepisodes = \"300\"\n",
            ":3: episodes must be an integer in 1..=10000000 (training episodes per run, each kept in memory: about 300 bytes per episode and run), got \"300\"",
        ),
        (
            "experiment = \"dims\"\nn_s = 7\n",
            ":2: n_s must be an integer in 1..=4, got 7",
        ),
        (
            "experiment = \"function\"\nruns = 0\n",
            ":2: runs must be an integer in 1..=1000 (repetitions with seeds seed ..= seed + runs - 1, all in memory at once), got 0",
        ),
        (
            "experiment = \"function\"\nepsilon = nan\n",
            ":2: epsilon must be a number in 1e-4..=10 (C-REPS's KL bound in nats), got nan",
        ),
        (
            "experiment = \"dartboard\"\n\nxi = inf\n",
            ":3: xi must be a number in 0..=1e6 (D-UCB's exploration bonus is 2 B sqrt(xi ln n / N_i)), got inf",
        ),
        (
            "experiment = \"grid\"\ninitial_sigma = -0.5\n",
            ":2: initial_sigma must be a number in 1e-12..=1e12 (a variance in the parameters' units: standard deviations 1e-6 to 1e6), got -0.5",
        ),
        (
            "experiment = \"grid\"\nn_theta = 10\n",
            ":2: n_theta applies to function, dims, sphere, rosenbrock only, not to the grid experiment",
        ),
        // Values that crashed (capacity overflow) or were accepted though nothing can learn with
        // them: refused with the key's range.
        (
            "experiment = \"grid\"\nruns = 9223372036854775807\n",
            ":2: runs must be an integer in 1..=1000",
        ),
        (
            "experiment = \"toy\"\nepisodes = 9223372036854775807\n",
            ":2: episodes must be an integer in 1..=10000000",
        ),
        (
            "experiment = \"toy\"\nxi = 1e308\n",
            ":2: xi must be a number in 0..=1e6",
        ),
        (
            "experiment = \"function\"\nepsilon = 1e-300\n",
            ":2: epsilon must be a number in 1e-4..=10 (C-REPS's KL bound in nats), got 1e-300",
        ),
        (
            "experiment = \"function\"\ninitial_sigma = 1e300\n",
            ":2: initial_sigma must be a number in 1e-12..=1e12",
        ),
    ];
    for (i, (text, expected)) in cases.into_iter().enumerate() {
        let path = dir.join(format!("bad-{i}.toml"));
        std::fs::write(&path, text).unwrap();
        let out = acps(&["experiment", "--config", path.to_str().unwrap(), "-q"]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{text:?}: {stderr}");
        let expected = format!("{}{expected}", path.display());
        assert!(
            stderr.contains(&expected) && !stderr.contains("panicked"),
            "{text:?}:\n{stderr}"
        );
    }
    // Nothing ran: no run directory appeared.
    assert!(!Path::new("runs/bad-0").exists());
}

/// The file's settings without its comment lines.
fn settings(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .filter(|line| !line.starts_with('#'))
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn a_saved_or_written_config_reruns_bit_for_bit() {
    let dir = temp_dir("rerun");
    std::fs::create_dir_all(&*dir).unwrap();
    let cases: [&[&str]; 2] = [
        &[
            "toy",
            "--panel",
            "c",
            "--runs",
            "2",
            "--episodes",
            "60",
            "--seed",
            "7",
            "--xi",
            "0.001",
        ],
        &[
            "function",
            "--runs",
            "2",
            "--episodes",
            "120",
            "--method",
            "monotonic-progress",
            "--method",
            "random",
            "--n-theta",
            "7",
            "--epsilon",
            "1.3",
            "--initial-sigma",
            "0.3",
            "--memory",
            "best-per-task",
            "--first-visit",
            "zero",
            "--in-flight",
            "3",
        ],
    ];
    for (i, args) in cases.into_iter().enumerate() {
        let first = dir.join(format!("{i}-first"));
        let rerun = dir.join(format!("{i}-rerun"));
        let saved = dir.join(format!("{i}-saved.toml"));
        let from_saved = dir.join(format!("{i}-from-saved"));
        let run = |extra: &[&str], out: &Path| {
            let mut all = vec!["experiment"];
            all.extend_from_slice(extra);
            all.extend(["-q", "--out", out.to_str().unwrap()]);
            succeeds(&all);
        };
        run(args, &first);
        let written = first.join("config.toml");
        run(&["--config", written.to_str().unwrap()], &rerun);
        let mut save = args.to_vec();
        save.extend(["--save-config", saved.to_str().unwrap()]);
        run(&save, &dir.join("unused"));
        assert!(!dir.join("unused").exists(), "--save-config does not run");
        run(&["--config", saved.to_str().unwrap()], &from_saved);

        let summary = std::fs::read(first.join("summary.json")).unwrap();
        for other in [&rerun, &from_saved] {
            assert_eq!(std::fs::read(other.join("summary.json")).unwrap(), summary, "{args:?}");
            assert_eq!(settings(&other.join("config.toml")), settings(&written));
        }
        assert_eq!(settings(&saved), settings(&written));
        // A different seed on top of the file changes the results: the rerun really read the file.
        // (Into the rerun's directory, which it replaces when asked.)
        run(
            &["--config", written.to_str().unwrap(), "--seed", "1", "--force"],
            &rerun,
        );
        assert_ne!(std::fs::read(rerun.join("summary.json")).unwrap(), summary);
        assert!(settings(&rerun.join("config.toml")).contains("seed = 1\n"));
    }
    // A saved file is never replaced.
    let out = acps(&[
        "experiment",
        "toy",
        "--save-config",
        dir.join("0-saved.toml").to_str().unwrap(),
    ]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("exists; remove it or choose another name"));
}

#[test]
fn an_experiment_is_named_or_read_from_a_file_not_both() {
    let neither = acps(&["experiment", "-q"]);
    assert!(String::from_utf8_lossy(&neither.stderr).contains("<NAME>"));
    let both = acps(&["experiment", "toy", "--config", "experiments/toy-fig2a.toml"]);
    assert!(String::from_utf8_lossy(&both.stderr).contains("cannot be used with '--config <FILE>'"));
    let missing = acps(&["experiment", "--config", "no/such/file.toml"]);
    assert!(String::from_utf8_lossy(&missing.stderr).contains("no/such/file.toml: cannot read"));
    for out in [neither, both, missing] {
        assert!(!out.status.success());
    }
}
