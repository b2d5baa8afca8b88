//! The runner's refusals, through the library's public API: an environment that is not its
//! problem's, runs whose every rollout of a kind failed, methods the environment cannot serve.

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

/// The contextual function, failing every rollout of one kind in the instance of one seed.
struct Failing {
    function: ContextualFunction,
    fails: Option<acps_shared::TaskKind>,
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
        if Some(task.kind) == self.fails {
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
                    fails: (seed == 4).then_some(kind),
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
