//! Experiment files and options as the settings table checks them: errors name the file, line,
//! key and range (or the option), bounds are accepted, options override files, resolved files
//! re-run their experiments, and the teachers' keys apply only with their methods.

use acps_experiments::file::LoadedFile;
use acps_experiments::plan::Plan;
use acps_experiments::settings::ExperimentName::{Dartboard, Dims, Function, Grid, Toy};
use acps_experiments::settings::{ExperimentFile, FirstVisitName};
use acps_learner::{Method, SearchConfig, SelectorConfig};
use std::path::Path;

fn error(text: &str) -> String {
    let file = LoadedFile::parse(Path::new("e.toml"), text.to_string());
    match file {
        Err(e) => e.to_string(),
        Ok(file) => match Plan::new(Some(&file), &ExperimentFile::default()) {
            Err(e) => e.to_string(),
            Ok(_) => panic!("{text} was accepted"),
        },
    }
}

#[test]
fn file_errors_name_line_key_and_range() {
    let cases = [
        ("experiment = \"toy\"\nrunz = 3\n", "e.toml:2: unknown field `runz`"),
        (
            "experiment = \"toy\"\nruns = 2\nruns = 3\n",
            "e.toml:3: duplicate key `runs`: each key may be set once",
        ),
        (
            "experiment = \"toy\"\n\nruns = \"3\"\n",
            "e.toml:3: runs must be an integer in 1..=1000 (repetitions with seeds seed ..= seed + runs - 1, all in memory at once), got \"3\"",
        ),
        (
            "experiment = \"toy\"\nruns = 0\n",
            "e.toml:2: runs must be an integer in 1..=1000 (repetitions with seeds seed ..= seed + runs - 1, all in memory at once), got 0",
        ),
        (
            "experiment = \"toy\"\nxi = nan\n",
            "e.toml:2: xi must be a number in 0..=1e6 (D-UCB's exploration bonus is 2 B sqrt(xi ln n / N_i)), got nan",
        ),
        (
            "experiment = \"grid\"\nepsilon = -inf\n",
            "e.toml:2: epsilon must be a number in 1e-4..=10 (C-REPS's KL bound in nats), got -inf",
        ),
        (
            "experiment = \"toy\"\nepsilon = 1.0\n",
            "e.toml:2: epsilon applies to function, dims, grid, dartboard, sphere, rosenbrock, [problem] tables only, not to the toy experiment",
        ),
        (
            "experiment = \"dims\"\nn_s = 5\n",
            "e.toml:2: n_s must be an integer in 1..=4, got 5",
        ),
        (
            "experiment = \"toy\"\npanel = \"e\"\n",
            "e.toml:2: panel must be one of a, b, c, d, got \"e\"",
        ),
        (
            "experiment = \"function\"\nmethods = [\n  \"random\",\n  \"monotonic\",\n]\n",
            "e.toml:4: methods must be a non-empty list of distinct methods",
        ),
        (
            "experiment = \"function\"\nmethods = [\"random\", \"random\"]\n",
            "got [\"random\", \"random\"]",
        ),
        (
            "experiment = \"function\"\nmethods = []\n",
            "e.toml:2: methods must be a non-empty",
        ),
        (
            "experiment = \"function\"\nn_theta = 65\n",
            "e.toml:2: n_theta must be an integer in 5..=64",
        ),
        (
            "experiment = \"function\"\nin_flight = 16385\n",
            "e.toml:2: in_flight must be an integer in 1..=16384",
        ),
        (
            "experiment = \"function\"\nruns = 2\nseed = 9223372036854775807\n",
            "e.toml:3: seed must be an integer in 0..=2^63-1 - (runs - 1)",
        ),
        (
            "experiment = \"throw\"\n",
            "e.toml:1: experiment must be one of toy, function",
        ),
        ("runs = 2\n", "e.toml: experiment must be set"),
        ("experiment = \"toy\"\nruns = \n", "e.toml:2:"),
        (
            "experiment = \"toy\"\n[fleet]\nworkers = 2\n",
            "e.toml:2: unknown field `fleet`",
        ),
    ];
    for (text, expected) in cases {
        let message = error(text);
        assert!(
            message.starts_with(expected) || message.contains(expected),
            "{text:?}: {message}"
        );
    }
}

/// Every numeric key, just outside its range and absurdly far outside it (the values a
/// program could not run with: too large to allocate, finite but meaningless, negative).
#[test]
fn numbers_outside_their_ranges_are_refused() {
    let cases = [
        ("toy", "runs = 1001", "runs must be an integer in 1..=1000"),
        ("grid", "runs = 9223372036854775807", "got 9223372036854775807"),
        ("grid", "runs = -1", "runs must be an integer in 1..=1000"),
        (
            "toy",
            "episodes = 10000001",
            "episodes must be an integer in 1..=10000000",
        ),
        ("toy", "episodes = 9223372036854775807", "episodes must be an integer"),
        ("toy", "episodes = 0", "episodes must be an integer"),
        ("toy", "seed = -1", "seed must be an integer in 0..=2^63-1"),
        ("toy", "in_flight = 0", "in_flight must be an integer in 1..=16384"),
        ("dims", "n_theta = 4", "n_theta must be an integer in 5..=64"),
        ("dims", "n_s = 0", "n_s must be an integer in 1..=4"),
        (
            "function",
            "initial_sigma = 1e300",
            "initial_sigma must be a number in 1e-12..=1e12",
        ),
        ("function", "initial_sigma = 1e-300", "got 1e-300"),
        ("function", "initial_sigma = 9.9e-13", "got 9.9e-13"),
        ("function", "initial_sigma = 0.0", "got 0.0"),
        ("function", "initial_sigma = inf", "got inf"),
        ("grid", "epsilon = 1e308", "epsilon must be a number in 1e-4..=10"),
        ("grid", "epsilon = 1e-300", "got 1e-300"),
        ("grid", "epsilon = 10.000001", "got 10.000001"),
        ("grid", "epsilon = 0.0", "got 0.0"),
        ("toy", "xi = 1e308", "xi must be a number in 0..=1e6"),
        ("toy", "xi = 1000001.0", "got 1000001.0"),
        ("toy", "xi = -1e-9", "got -1e-9"),
    ];
    for (experiment, line, expected) in cases {
        let text = format!("experiment = \"{experiment}\"\n{line}\n");
        let message = error(&text);
        assert!(
            message.starts_with("e.toml:2: ") && message.contains(expected),
            "{text:?}: {message}"
        );
    }
}

#[test]
fn numbers_on_the_bounds_of_their_ranges_are_accepted() {
    for text in [
        "experiment = \"function\"\nruns = 1\nepisodes = 1\ninitial_sigma = 1e-12\nepsilon = 1e-4\nxi = 0.0\nn_theta = 5\n",
        "experiment = \"function\"\nruns = 1000\nepisodes = 10000000\ninitial_sigma = 1e12\nepsilon = 10.0\nxi = 1e6\nn_theta = 64\nin_flight = 16384\n",
    ] {
        let file = LoadedFile::parse(Path::new("e.toml"), text.into()).unwrap();
        assert!(Plan::new(Some(&file), &ExperimentFile::default()).is_ok(), "{text}");
    }
}

#[test]
fn options_name_the_flag_and_override_the_file() {
    let file = LoadedFile::parse(Path::new("e.toml"), "experiment = \"toy\"\nruns = 0\n".into()).unwrap();
    let cli = ExperimentFile {
        runs: Some(3),
        ..Default::default()
    };
    let plan = Plan::new(Some(&file), &cli).unwrap();
    assert_eq!(plan.resolved().runs, Some(3));
    let cli = ExperimentFile {
        epsilon: Some(f64::NAN),
        ..Default::default()
    };
    let message = Plan::new(Some(&file), &cli).err().unwrap().to_string();
    assert_eq!(
        message,
        "--epsilon applies to function, dims, grid, dartboard, sphere, rosenbrock, [problem] tables only, not to the toy experiment"
    );
    let cli = ExperimentFile {
        experiment: Some(Grid),
        xi: Some(f64::INFINITY),
        ..Default::default()
    };
    let message = Plan::new(None, &cli).err().unwrap().to_string();
    assert_eq!(
        message,
        "--xi must be a number in 0..=1e6 (D-UCB's exploration bonus is 2 B sqrt(xi ln n / N_i)), got inf"
    );
}

/// The resolved file's xi and first-visit rule are read from the recorded settings; they
/// must be what the D-UCB methods run with, by default and when set.
#[test]
fn resolved_d_ucb_settings_are_the_methods() {
    for name in [Toy, Function, Dims, Grid, Dartboard] {
        for (xi, first_visit) in [(None, None), (Some(0.5), Some(FirstVisitName::Zero))] {
            let cli = ExperimentFile {
                experiment: Some(name),
                xi,
                first_visit,
                ..Default::default()
            };
            for job in Plan::new(None, &cli).unwrap().jobs(Path::new("out")) {
                let bandits: Vec<_> = job
                    .experiment
                    .methods
                    .iter()
                    .filter_map(|m| match m {
                        SelectorConfig::Bandit(bandit) => Some(bandit),
                        _ => None,
                    })
                    .collect();
                assert!(!bandits.is_empty(), "{name:?}");
                for bandit in bandits {
                    assert_eq!(job.config.xi, Some(bandit.ducb.xi), "{name:?}");
                    let rule = serde_json::to_value(bandit.first_visit).unwrap();
                    assert_eq!(serde_json::to_value(job.config.first_visit).unwrap(), rule, "{name:?}");
                }
                if let Some(xi) = xi {
                    assert_eq!(job.config.xi, Some(xi));
                }
            }
        }
    }
}

#[test]
fn resolved_files_rerun_their_jobs_and_panels_share_their_defaults() {
    for name in [Toy, Function, Dims, Grid, Dartboard] {
        let plan = Plan::new(
            None,
            &ExperimentFile {
                experiment: Some(name),
                ..Default::default()
            },
        )
        .unwrap();
        let resolved = plan.resolved();
        let jobs = plan.jobs(Path::new("out"));
        // The resolved file re-runs every panel and dimension as it was.
        let text = resolved.to_toml("").unwrap();
        let file = LoadedFile::parse(Path::new("r.toml"), text).unwrap();
        let again = Plan::new(Some(&file), &ExperimentFile::default())
            .unwrap()
            .jobs(Path::new("out"));
        assert_eq!(again.len(), jobs.len());
        for (job, again) in jobs.iter().zip(&again) {
            assert_eq!(job.config, again.config, "{name:?}");
            // Only what differs between dims' dimensions is left to their defaults.
            let differs = ExperimentFile {
                panel: resolved.panel,
                n_s: resolved.n_s,
                ..job.config.clone()
            };
            let grows = name == Dims;
            assert_eq!(differs.memory_size != resolved.memory_size, grows, "{name:?}");
            assert_eq!(differs.update_every != resolved.update_every, grows, "{name:?}");
            let shared = ExperimentFile {
                memory_size: resolved.memory_size,
                update_every: resolved.update_every,
                ..differs
            };
            assert_eq!(shared, resolved, "{name:?}");
            // And a job's own file re-runs it.
            let text = job.config.to_toml("# header\n").unwrap();
            let again = LoadedFile::parse(Path::new("r.toml"), text).unwrap();
            assert_eq!(again.values, job.config);
            let replan = Plan::new(Some(&again), &ExperimentFile::default()).unwrap();
            assert_eq!(replan.resolved(), job.config, "{name:?}");
        }
    }
}

#[test]
fn teacher_keys_are_checked_against_their_ranges_each_other_and_the_methods() {
    let cases = [
        (
            "methods = [\"random\"]\nfit_rate = 300\n",
            "e.toml:3: fit_rate applies only when methods lists alp-gmm",
        ),
        (
            "methods = [\"monotonic-progress\"]\nrandom_share = 0.5\n",
            "e.toml:3: random_share applies only when methods lists absolute-progress or alp-gmm",
        ),
        (
            "ema_slow = 0.01\n",
            "e.toml:2: ema_slow applies only when methods lists absolute-progress",
        ),
        (
            "methods = [\"alp-gmm\"]\nrandom_share = 1.5\n",
            "e.toml:3: random_share must be a number in 0..=1 (the share of contexts drawn uniformly), got 1.5",
        ),
        (
            "methods = [\"alp-gmm\"]\nfit_rate = 99\n",
            "e.toml:3: fit_rate must be an integer in 10 * max_components (10 unless set) ..=100000 (10 points per component of the largest mixture), got 99",
        ),
        (
            "methods = [\"alp-gmm\"]\nmax_components = 3\nfit_rate = 29\n",
            "e.toml:4: fit_rate must be",
        ),
        ("methods = [\"alp-gmm\"]\nfit_rate = 100001\n", "got 100001"),
        (
            "methods = [\"alp-gmm\"]\nmax_components = 21\n",
            "e.toml:3: max_components must be an integer in 2..=20, got 21",
        ),
        ("methods = [\"alp-gmm\"]\nmax_components = 1\n", "got 1"),
        (
            "methods = [\"random\"]\nzeta = 0.5\n",
            "e.toml:3: zeta applies only when methods lists self-paced",
        ),
        (
            "methods = [\"self-paced\"]\nzeta = 0.0\n",
            "e.toml:3: zeta must be a number in (0, 100] (alpha KL(q || target) as a share of the returns' standard deviation), got 0.0",
        ),
        (
            "methods = [\"self-paced\"]\nalpha_offset = -1\n",
            "e.toml:3: alpha_offset must be an integer in 0..=1000000",
        ),
        (
            "methods = [\"alp-gmm\"]\nsnap = 1\n",
            "e.toml:3: snap must be true or false, got 1",
        ),
        (
            "retire = \"yes\"\n",
            "e.toml:2: retire must be true or false, got \"yes\"",
        ),
        (
            "methods = [\"absolute-progress\"]\nema_fast = 0.04\n",
            "e.toml:3: ema_fast must be a number in (0, 1], above ema_slow (0.05 unless set), got 0.04",
        ),
        (
            "methods = [\"absolute-progress\"]\nema_slow = 0.2\n",
            "e.toml:3: ema_slow must be a number in (0, 1), below ema_fast (0.1 unless set), got 0.2",
        ),
        (
            "methods = [\"absolute-progress\"]\nema_fast = 1.5\nema_slow = 0.5\n",
            "got 1.5",
        ),
        ("methods = [\"absolute-progress\"]\nema_slow = 0.0\n", "got 0.0"),
        ("methods = [\"absolute-progress\"]\nema_fast = nan\n", "got nan"),
    ];
    for (keys, expected) in cases {
        let text = format!("experiment = \"function\"\n{keys}");
        let message = error(&text);
        let found = if expected.starts_with("e.toml:") {
            message.starts_with(expected)
        } else {
            message.starts_with("e.toml:") && message.ends_with(expected)
        };
        assert!(found, "{text:?}: {message}");
    }
    // The bounds themselves are accepted.
    for keys in [
        "methods = [\"alp-gmm\", \"absolute-progress\"]\nrandom_share = 0.0\nema_fast = 1.0\nmax_components = 2\nfit_rate = 20\n",
        "methods = [\"alp-gmm\"]\nrandom_share = 1.0\nmax_components = 20\nfit_rate = 100000\n",
        "methods = [\"absolute-progress\"]\nema_fast = 0.3\nema_slow = 0.29\n",
    ] {
        let text = format!("experiment = \"function\"\n{keys}");
        let file = LoadedFile::parse(Path::new("e.toml"), text.clone()).unwrap();
        assert!(Plan::new(Some(&file), &ExperimentFile::default()).is_ok(), "{text}");
    }
    let cli = ExperimentFile {
        experiment: Some(Grid),
        fit_rate: Some(300),
        ..Default::default()
    };
    let message = Plan::new(None, &cli).err().unwrap().to_string();
    assert_eq!(message, "--fit-rate applies only when methods lists alp-gmm");
}

/// The teachers run with the values of their keys (else their defaults), the summary records
/// them, and the resolved file reads them back.
#[test]
fn teachers_run_with_their_keys_and_resolve_to_them() {
    use acps_learner::SelectorConfig as S;
    let every = ExperimentFile {
        experiment: Some(Function),
        methods: Some(vec![
            Method::AbsoluteProgress,
            Method::AlpGmm,
            Method::Diversity,
            Method::SelfPaced,
        ]),
        retire: Some(true),
        random_share: Some(0.3),
        ema_fast: Some(0.4),
        ema_slow: Some(0.2),
        fit_rate: Some(120),
        max_components: Some(4),
        snap: Some(true),
        zeta: Some(2.5),
        alpha_offset: Some(7),
        ..Default::default()
    };
    let plan = Plan::new(None, &every).unwrap();
    let job = plan.jobs(Path::new("out")).swap_remove(0);
    let [
        S::AbsoluteProgress(progress),
        S::AlpGmm { config, snap },
        S::Bandit(bandit),
        S::SelfPaced(paced),
    ] = job.experiment.methods.as_slice()
    else {
        panic!("{:?}", job.experiment.methods)
    };
    assert_eq!(
        (progress.rates.fast, progress.rates.slow, progress.random_share),
        (0.4, 0.2, 0.3)
    );
    assert!(progress.retire.is_some() && bandit.retire.is_some());
    assert_eq!(
        (config.fit_rate, config.max_components, config.random_share, *snap),
        (120, 4, 0.3, true)
    );
    assert_eq!((paced.zeta, paced.offset), (2.5, 7));
    let resolved = plan.resolved();
    // The teachers' keys read back as set (the other keys hold the experiment's defaults).
    let teachers = ExperimentFile {
        experiment: resolved.experiment,
        methods: resolved.methods.clone(),
        retire: resolved.retire,
        random_share: resolved.random_share,
        ema_fast: resolved.ema_fast,
        ema_slow: resolved.ema_slow,
        fit_rate: resolved.fit_rate,
        max_components: resolved.max_components,
        snap: resolved.snap,
        zeta: resolved.zeta,
        alpha_offset: resolved.alpha_offset,
        ..Default::default()
    };
    assert_eq!(teachers, every);
    let text = resolved.to_toml("").unwrap();
    let again = LoadedFile::parse(Path::new("r.toml"), text).unwrap();
    assert_eq!(
        Plan::new(Some(&again), &ExperimentFile::default()).unwrap().resolved(),
        resolved
    );
    // Unset, the paper's methods do not retire, and nothing of the teachers is written.
    let paper = Plan::new(
        None,
        &ExperimentFile {
            experiment: Some(Grid),
            ..Default::default()
        },
    )
    .unwrap();
    let resolved = paper.resolved();
    assert_eq!(resolved.retire, Some(false));
    assert_eq!(
        (resolved.random_share, resolved.fit_rate, resolved.snap),
        (None, None, None)
    );
    for job in paper.jobs(Path::new("out")) {
        assert!(job.experiment.settings["retire"].is_null());
        for method in &job.experiment.methods {
            assert!(!matches!(method, S::Bandit(b) if b.retire.is_some()));
        }
    }
}

/// D-UCB's B and gamma, C-REPS's memory, update interval and ridge, and the evaluation interval
/// reach what runs, in a file and as options, and the resolved file says so.
#[test]
fn d_ucb_c_reps_and_evaluation_settings_reach_the_learner() {
    use acps_learner::creps::MemoryConfig;
    let text = "experiment = \"grid\"\nmethods = [\"monotonic-progress\", \"random\"]\nb = 0.5\ngamma = 0.9\nmemory_size = 50\nupdate_every = 10\nridge = 0.01\neval_every = 7\n";
    let file = LoadedFile::parse(Path::new("e.toml"), text.into()).unwrap();
    let plan = Plan::new(Some(&file), &ExperimentFile::default()).unwrap();
    let job = plan.jobs(Path::new("out")).swap_remove(0);
    let SelectorConfig::Bandit(bandit) = &job.experiment.methods[0] else {
        panic!("{:?}", job.experiment.methods)
    };
    assert_eq!((bandit.ducb.b, bandit.ducb.gamma), (0.5, 0.9));
    let Some(SearchConfig::CReps(creps)) = &job.experiment.learner.search else {
        panic!("C-REPS is the default learner")
    };
    // The grid's best-per-task memory: 50 rollouts over 25 targets, 2 each.
    assert_eq!(creps.memory, MemoryConfig::BestPerTask { per_task: 2 });
    assert_eq!((creps.update_every, creps.ridge), (10, 0.01));
    assert_eq!(job.experiment.learner.eval_every, 7);
    assert_eq!(job.experiment.settings["ducb"]["b"], 0.5);
    let resolved = plan.resolved();
    assert_eq!(
        (
            resolved.b,
            resolved.gamma,
            resolved.memory_size,
            resolved.update_every,
            resolved.ridge,
            resolved.eval_every
        ),
        (Some(0.5), Some(0.9), Some(50), Some(10), Some(0.01), Some(7))
    );
    // Options override the file, and a window takes the size as it is.
    let cli = ExperimentFile {
        memory: Some(acps_experiments::settings::Memory::Window),
        memory_size: Some(30),
        b: Some(2.0),
        ..Default::default()
    };
    let job = Plan::new(Some(&file), &cli)
        .unwrap()
        .jobs(Path::new("out"))
        .swap_remove(0);
    let Some(SearchConfig::CReps(creps)) = &job.experiment.learner.search else {
        panic!("C-REPS is the default learner")
    };
    assert_eq!(creps.memory, MemoryConfig::SlidingWindow { capacity: 30 });
    let SelectorConfig::Bandit(bandit) = &job.experiment.methods[0] else {
        unreachable!()
    };
    assert_eq!(bandit.ducb.b, 2.0);
    // Section 4's two bounds become one when B is set, and the resolved file holds it; unset,
    // they stay two and the resolved file leaves B to them.
    for (b, expected) in [(Some(0.5), [0.5, 0.5]), (None, [1.0, 0.25])] {
        let cli = ExperimentFile {
            experiment: Some(Toy),
            panel: Some('a'),
            methods: Some(vec![Method::BestReward, Method::MonotonicProgress]),
            b,
            ..Default::default()
        };
        let plan = Plan::new(None, &cli).unwrap();
        let job = plan.jobs(Path::new("out")).swap_remove(0);
        let bounds: Vec<f64> = job
            .experiment
            .methods
            .iter()
            .map(|m| match m {
                SelectorConfig::Bandit(bandit) => bandit.ducb.b,
                other => panic!("{other:?}"),
            })
            .collect();
        assert_eq!(bounds, expected);
        assert_eq!(plan.resolved().b, b);
    }
}

#[test]
fn d_ucb_and_c_reps_settings_are_refused_outside_their_ranges() {
    let cases = [
        ("b = 0.0", "b must be a number in 1e-12..=1e12"),
        ("b = inf", "got inf"),
        ("gamma = 0.0", "gamma must be a number in (0, 1]"),
        ("gamma = 1.5", "got 1.5"),
        ("memory_size = 1", "memory_size must be an integer in 2..=100000"),
        ("update_every = 0", "update_every must be an integer in 1..=100000"),
        ("ridge = -1e-9", "ridge must be a number in 0..=1e6"),
        ("eval_every = 0", "eval_every must be an integer in 1..=10000000"),
    ];
    for (line, expected) in cases {
        let text = format!("experiment = \"function\"\n{line}\n");
        let message = error(&text);
        assert!(
            message.starts_with("e.toml:2: ") && message.contains(expected),
            "{text:?}: {message}"
        );
    }
    let message = error("experiment = \"toy\"\nupdate_every = 5\n");
    assert!(
        message.contains(
            "update_every applies to function, dims, grid, dartboard, sphere, rosenbrock, [problem] tables only"
        ),
        "{message}"
    );
}

/// A problem run only by methods that draw from the continuous box needs no training contexts;
/// a method that chooses among them does, and says so.
#[test]
fn training_contexts_are_required_only_by_methods_that_choose_among_them() {
    let table = "[problem]\nname = \"boxed\"\ntest_contexts = [[0.5], [-0.5]]\ncontext_low = [-1.0]\ncontext_high = [1.0]\ntheta0 = [0.0]\n";
    let file = |methods: &str| LoadedFile::parse(Path::new("p.toml"), format!("methods = {methods}\n{table}")).unwrap();
    for methods in [
        "[\"random-continuous\"]",
        "[\"random-continuous\", \"self-paced\", \"alp-gmm\"]",
    ] {
        let plan = Plan::new(Some(&file(methods)), &ExperimentFile::default()).unwrap();
        let job = plan.jobs(Path::new("out")).swap_remove(0);
        // The learners of every (method, run) start: the test contexts stand in for the training
        // contexts.
        assert_eq!(job.experiment.jobs().unwrap().len(), job.experiment.methods.len() * 20);
        // The resolved file leaves them out and re-runs the same.
        let resolved = plan.resolved();
        assert_eq!(resolved.problem.as_ref().unwrap().training_contexts, None);
        let again = LoadedFile::parse(Path::new("r.toml"), resolved.to_toml("").unwrap()).unwrap();
        assert_eq!(
            Plan::new(Some(&again), &ExperimentFile::default()).unwrap().resolved(),
            resolved
        );
    }
    for methods in ["[\"random\"]", "[\"random-continuous\", \"monotonic-progress\"]"] {
        let message = Plan::new(Some(&file(methods)), &ExperimentFile::default())
            .err()
            .unwrap()
            .to_string();
        assert!(
            message.starts_with("p.toml:2: problem.training_contexts must be set"),
            "{message}"
        );
    }
    // Unset methods are the default monotonic progress and random, which need them.
    let message = Plan::new(
        Some(&LoadedFile::parse(Path::new("p.toml"), table.into()).unwrap()),
        &ExperimentFile::default(),
    )
    .err()
    .unwrap()
    .to_string();
    assert!(message.contains("problem.training_contexts must be set"), "{message}");
}

/// `learner = "c-cmaes"` runs C-CMA-ES with the experiment's features and initial exploration
/// and the population asked for; C-REPS' own keys are refused with it, and its population
/// without it, each naming the key and the learner.
#[test]
fn the_learner_setting_chooses_c_cmaes_and_refuses_the_other_learners_keys() {
    let text = "experiment = \"function\"\nlearner = \"c-cmaes\"\npopulation = 60\ninitial_sigma = 0.5\n";
    let file = LoadedFile::parse(Path::new("e.toml"), text.into()).unwrap();
    let plan = Plan::new(Some(&file), &ExperimentFile::default()).unwrap();
    let job = plan.jobs(Path::new("out")).swap_remove(0);
    let Some(SearchConfig::CCmaes(ccmaes)) = &job.experiment.learner.search else {
        panic!("{:?}", job.experiment.learner.search)
    };
    assert_eq!((ccmaes.population, ccmaes.initial_sigma), (Some(60), 0.5));
    assert!(matches!(ccmaes.features, acps_learner::creps::FeatureMap::Quadratic));
    assert!(job.experiment.settings.get("creps").is_none());
    assert_eq!(job.experiment.settings["ccmaes"]["population"], 60);
    let resolved = plan.resolved();
    assert_eq!(
        (
            resolved.learner,
            resolved.population,
            resolved.epsilon,
            resolved.memory_size
        ),
        (
            Some(acps_experiments::settings::LearnerName::CCmaes),
            Some(60),
            None,
            None
        )
    );
    // Unset: 4 + floor(3 ln 22) (2 * 6 - 1) for 20 parameters and the 6 quadratic features of a
    // 2-D context.
    let text = "experiment = \"function\"\nlearner = \"c-cmaes\"\n";
    let file = LoadedFile::parse(Path::new("e.toml"), text.into()).unwrap();
    let resolved = Plan::new(Some(&file), &ExperimentFile::default()).unwrap().resolved();
    assert_eq!(resolved.population, Some(103));

    let text = "experiment = \"function\"\nlearner = \"c-cmaes\"\nepsilon = 1.0\n";
    let file = LoadedFile::parse(Path::new("e.toml"), text.into()).unwrap();
    let error = Plan::new(Some(&file), &ExperimentFile::default())
        .err()
        .unwrap()
        .to_string();
    assert!(
        error.contains("e.toml:3: epsilon is a setting of learner c-reps only, and the learner is c-cmaes"),
        "{error}"
    );
    let cli = ExperimentFile {
        experiment: Some(Function),
        population: Some(60),
        ..Default::default()
    };
    let error = Plan::new(None, &cli).err().unwrap().to_string();
    assert!(
        error.contains("--population is a setting of learner c-cmaes only, and the learner is c-reps"),
        "{error}"
    );
    let cli = ExperimentFile {
        experiment: Some(Function),
        learner: Some(acps_experiments::settings::LearnerName::CCmaes),
        population: Some(1),
        ..Default::default()
    };
    let error = Plan::new(None, &cli).err().unwrap().to_string();
    assert!(
        error.contains("--population must be an integer in 2..=100000"),
        "{error}"
    );
    // A learner that does not exist is refused with the file's line and the two there are.
    let text = "experiment = \"grid\"\nlearner = \"cmaes\"\n";
    let error = LoadedFile::parse(Path::new("e.toml"), text.into())
        .err()
        .unwrap()
        .to_string();
    assert!(
        error.contains("e.toml:2: learner must be c-reps or c-cmaes, got \"cmaes\""),
        "{error}"
    );
}
