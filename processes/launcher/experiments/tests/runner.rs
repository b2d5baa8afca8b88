//! The runner's refusals, through the library's public API: an environment that is not its
//! problem's, runs whose every rollout of a kind failed, methods the environment cannot serve,
//! and runs with more failed rollouts than they accept.

use acps_experiments::experiment::{Instance, RunError};
use acps_experiments::paper;
use acps_experiments::progress::Progress;
use acps_experiments::settings::ExperimentFile;
use acps_models::contextual_function::ContextualFunction;
use acps_shared::Environment;

#[test]
fn an_instance_whose_environment_is_not_its_problems_is_refused_in_process() {
    let options = ExperimentFile {
        runs: Some(1),
        episodes: Some(10),
        ..Default::default()
    };
    let mut experiment = paper::function(&options);
    // The problem of seed s with the function of seed s + 1, as a user's wiring might do.
    experiment.instance = Box::new(|seed| Instance {
        problem: ContextualFunction::new(2, 20, seed).unwrap().grid_problem().unwrap(),
        environment: Some(Box::new(ContextualFunction::new(2, 20, seed + 1).unwrap())),
        optimal_score: None,
        keeps_state: false,
    });
    let expected = ContextualFunction::new(2, 20, 0).unwrap().spec();
    let found = ContextualFunction::new(2, 20, 1).unwrap().spec();
    let error = experiment.run(&Progress::new("function", 0, true)).unwrap_err();
    assert!(matches!(error, RunError::Environment(_)), "{error}");
    assert_eq!(
        error.to_string(),
        format!("problem 'function' is defined for environment {expected}, not for {found}")
    );
}

/// The contextual function, failing every rollout of a task `fails` picks.
struct Failing {
    function: ContextualFunction,
    fails: Box<dyn Fn(&acps_shared::Task) -> bool + Send>,
}

impl Environment for Failing {
    fn spec(&self) -> acps_shared::EnvironmentSpec {
        self.function.spec()
    }

    fn context_dim(&self) -> usize {
        self.function.context_dim()
    }

    fn param_dim(&self) -> usize {
        self.function.param_dim()
    }

    fn rollout(&mut self, task: &acps_shared::Task) -> acps_shared::Outcome {
        if (self.fails)(task) {
            acps_shared::Outcome::failed(task.id)
        } else {
            self.function.rollout(task)
        }
    }
}

#[test]
fn a_run_whose_every_rollout_of_a_kind_failed_is_refused() {
    use acps_shared::TaskKind;
    let cases = [
        (
            TaskKind::Train,
            "experiment 'function', method random, run 1 (seed 4): every one of its 20 training rollouts failed, so it learnt nothing; the first at episode 0, context (",
        ),
        (
            TaskKind::Evaluate,
            "experiment 'function', method random, run 1 (seed 4): every rollout of its 3 evaluations failed, so no score was measured; the first at test context (",
        ),
    ];
    for (kind, expected) in cases {
        let options = ExperimentFile {
            runs: Some(2),
            seed: Some(3),
            episodes: Some(20),
            methods: Some(vec![acps_learner::Method::Random]),
            ..Default::default()
        };
        let mut experiment = paper::function(&options);
        experiment.learner.eval_every = 10;
        // Only run 1 (seed 4) fails: the error names that run.
        experiment.instance = Box::new(move |seed| {
            let function = ContextualFunction::new(2, 20, seed).unwrap();
            Instance {
                problem: function.grid_problem().unwrap(),
                environment: Some(Box::new(Failing {
                    function,
                    fails: Box::new(move |task| seed == 4 && task.kind == kind),
                })),
                optimal_score: None,
                keeps_state: false,
            }
        });
        let error = experiment.run(&Progress::new("function", 0, true)).unwrap_err();
        assert!(matches!(error, RunError::AllFailed { run: 1, .. }), "{error}");
        assert!(error.to_string().starts_with(expected), "{kind:?}: {error}");
    }
}

#[test]
fn a_method_the_environment_cannot_serve_is_refused_before_the_run() {
    let options = ExperimentFile {
        runs: Some(1),
        episodes: Some(10),
        methods: Some(vec![acps_learner::Method::RandomContinuous]),
        ..Default::default()
    };
    let toy = paper::toy(paper::toy_panel('a').unwrap(), &options);
    let error = toy.jobs().err().unwrap();
    assert!(
        error
            .to_string()
            .starts_with("method random-continuous draws contexts from the continuous space, but experiment 'toy' takes only its training contexts"),
        "{error}"
    );
    // The same method on an experiment whose environment takes any context in the space.
    assert!(paper::function(&options).jobs().is_ok());
}

/// Failed rollouts are counted by kind in the summary and said in a warning; beyond the share a
/// run accepts, the run ends with an error that names the method and its counts, after the run
/// directory is written.
#[test]
fn failed_rollouts_are_counted_and_too_many_end_the_run_with_an_error() {
    use acps_experiments::run_dir::{RunDir, RunDirError};
    use std::sync::atomic::AtomicBool;
    let settings = ExperimentFile {
        experiment: Some(acps_experiments::settings::ExperimentName::Function),
        runs: Some(2),
        episodes: Some(200),
        methods: Some(vec![acps_learner::Method::Random]),
        ..Default::default()
    };
    let out = std::env::temp_dir().join(format!("acps-failures-{}", std::process::id()));
    for (above, max_share, refused) in [(0.0, 0.25, true), (0.0, 0.9, false), (2.0, 0.0, false)] {
        let mut run = RunDir::plan(None, &settings, Some(out.clone())).unwrap();
        run.max_failed_share = max_share;
        run.checkpoint_every = 0;
        run.jobs[0].experiment.instance = Box::new(move |seed| {
            let function = ContextualFunction::new(2, 20, seed).unwrap();
            Instance {
                problem: function.grid_problem().unwrap(),
                environment: Some(Box::new(Failing {
                    function,
                    fails: Box::new(move |task| task.context[0] > above),
                })),
                optimal_score: None,
                keeps_state: false,
            }
        });
        run.prepare().unwrap();
        let outcome = run.in_process(true, &AtomicBool::new(false), &|_, _| Ok(()));
        let summary: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
        let random = &summary["methods"]["random"];
        let (failed, evaluations) = (
            random["failed_evaluation_rollouts"].as_u64().unwrap(),
            random["evaluation_rollouts"].as_u64().unwrap(),
        );
        // 2 runs x 5 evaluations (episodes 0, 50, .., 200) of 100 test contexts.
        assert_eq!(evaluations, 2 * 5 * 100);
        // About half the contexts have a positive first coordinate; none is above 2.
        let failing = above < 1.0;
        assert_eq!(failed > 0 && random["failed_episodes"].as_u64().unwrap() > 0, failing);
        match outcome {
            Err(RunDirError::TooManyFailed { failures, .. }) => {
                assert!(refused, "{failures}");
                assert_eq!(failures.method, "random");
                assert_eq!(failures.evaluation, (failed, evaluations));
                assert!(failures.share() > max_share);
            }
            Ok(_) => assert!(!refused),
            Err(other) => panic!("{other}"),
        }
        std::fs::remove_dir_all(&out).unwrap();
    }
}
