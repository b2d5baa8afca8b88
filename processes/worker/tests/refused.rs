//! A worker refused by the learner, or refusing a task, stops with a message naming both sides;
//! one whose environment returns more than the wire carries stops naming the limit; one whose
//! factory has no environment stops with the factory's error.

use acps_shared::{Environment, EnvironmentSpec, Outcome, Serves, Task, TaskKind};
use acps_wire::ipc::{self, RunName};
use acps_wire::wire::{Answer, MAX_DIAGNOSTICS, Refusal, Response, WireTask, WorkerMessage};
use acps_worker::{EnvironmentFactory, EnvironmentProvideError, Single, WorkerError, WorkerOptions, WorkerReport};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

/// Rollouts that return zero, with as many diagnostics as `.1` says.
struct Zero(EnvironmentSpec, usize);

/// The spec of an environment that differs from others of its name by `setting`.
fn spec(setting: f64) -> EnvironmentSpec {
    EnvironmentSpec::new("zero", [0; 3], &setting).unwrap()
}

impl Environment for Zero {
    fn spec(&self) -> EnvironmentSpec {
        self.0
    }

    fn context_dim(&self) -> usize {
        1
    }

    fn param_dim(&self) -> usize {
        1
    }

    fn rollout(&mut self, task: &Task) -> Outcome {
        Outcome::new(task.id, 0.0, 0.0).with_diagnostics(vec![0.0; self.1])
    }
}

/// Serve `factory`'s environments to a stand-in learner of a run named after `test` that answers every
/// request with `answer`, until the worker stops (within 20 s, or the test fails).
fn against_stand_in(
    test: &str,
    mut factory: impl EnvironmentFactory + Send + 'static,
    answer: impl Fn(&WorkerMessage) -> (Answer, Vec<WireTask>),
) -> Result<WorkerReport, WorkerError> {
    let run = RunName::new(&format!("{test}-{}", std::process::id())).unwrap();
    let worker = {
        let run = run.clone();
        std::thread::spawn(move || {
            let options = WorkerOptions {
                name: "refused".into(),
                ..WorkerOptions::default()
            };
            acps_worker::serve(&run, &options, &mut factory, &AtomicBool::new(false))
        })
    };
    {
        let node = ipc::node(&run, "stand-in").unwrap();
        let services = ipc::open_services(&node).unwrap();
        let server = ipc::task_server(&run, &services.tasks).unwrap();
        let start = Instant::now();
        while !worker.is_finished() {
            while let Some(request) = server.receive().unwrap() {
                let (header, tasks) = answer(request.payload());
                // A worker that stopped may no longer take the answer.
                let _ = ipc::reply(&request, header, &tasks);
            }
            assert!(start.elapsed() < Duration::from_secs(20), "the worker did not stop");
            std::thread::sleep(Duration::from_millis(5));
        }
    }
    let result = worker.join().unwrap();
    ipc::remove_run_files(&run).unwrap();
    assert!(ipc::leftover_files(&run).is_empty());
    result
}

#[test]
fn a_worker_of_another_run_stops_and_says_why() {
    let refuse = |_: &WorkerMessage| (Answer::refused(Refusal::Run, 42, Some(spec(1.0)), 1), vec![]);
    match against_stand_in("refused-run", Single(Zero(spec(1.0), 0)), refuse) {
        Err(WorkerError::Refused { reason, .. }) => assert!(reason.contains("000000000000002a"), "{reason}"),
        other => panic!("expected a refusal, got {other:?}"),
    }
}

#[test]
fn a_worker_serving_an_environment_no_job_needs_names_both() {
    let refuse = |message: &WorkerMessage| {
        assert_eq!(message.serves(), Ok(acps_shared::Serves::One(spec(2.0))));
        (Answer::refused(Refusal::Environment, 42, Some(spec(1.0)), 2), vec![])
    };
    match against_stand_in("refused-environment", Single(Zero(spec(2.0), 0)), refuse) {
        Err(WorkerError::Refused { reason, .. }) => assert_eq!(
            reason,
            format!(
                "this worker serves {}; the run's jobs need {} and 1 other",
                spec(2.0),
                spec(1.0)
            )
        ),
        other => panic!("expected a refusal, got {other:?}"),
    }
}

/// A task of job 3 that needs `environment`.
fn task_in(environment: EnvironmentSpec) -> WireTask {
    let task = Task {
        id: 9,
        kind: TaskKind::Train,
        seed: 0,
        context: vec![0.0],
        theta: vec![0.0],
    };
    WireTask::new(3, &task, environment).unwrap()
}

#[test]
fn single_refuses_a_task_of_another_environment() {
    let hand_out = |_: &WorkerMessage| (Answer::new(Response::Task, 42), vec![task_in(spec(1.0))]);
    let error = against_stand_in("refused-task", Single(Zero(spec(2.0), 0)), hand_out).unwrap_err();
    assert!(
        matches!(
            &error,
            WorkerError::TaskRefused { job: 3, task_id: 9, needed, provided }
                if **needed == spec(1.0) && **provided == spec(2.0)
        ),
        "{error:?}"
    );
    let message = error.to_string();
    assert!(
        message.contains(&spec(1.0).to_string()) && message.contains(&spec(2.0).to_string()),
        "{message}"
    );
}

#[test]
fn an_outcome_with_more_diagnostics_than_the_wire_carries_stops_the_worker() {
    let hand_out = |_: &WorkerMessage| (Answer::new(Response::Task, 42), vec![task_in(spec(1.0))]);
    let error = against_stand_in("diagnostics", Single(Zero(spec(1.0), MAX_DIAGNOSTICS + 1)), hand_out).unwrap_err();
    assert!(
        matches!(error, WorkerError::OutcomeTooLarge { job: 3, task_id: 9, .. }),
        "{error}"
    );
    assert_eq!(
        error.to_string(),
        format!(
            "task 9 of job 3: the outcome cannot be sent: an outcome's diagnostics has {} values, the wire carries at most {MAX_DIAGNOSTICS} (MAX_DIAGNOSTICS)",
            MAX_DIAGNOSTICS + 1
        )
    );
}

/// A factory whose every build fails.
struct Broken;

impl EnvironmentFactory for Broken {
    fn serves(&self) -> Serves {
        Serves::Any
    }

    fn environment(&mut self, _: &EnvironmentSpec) -> Result<&mut dyn Environment, EnvironmentProvideError> {
        Err(EnvironmentProvideError::new(std::io::Error::other("no simulator here")))
    }
}

#[test]
fn a_factory_without_the_environment_stops_the_worker_with_its_own_error() {
    let hand_out = |_: &WorkerMessage| (Answer::new(Response::Task, 42), vec![task_in(spec(1.0))]);
    let error = against_stand_in("no-environment", Broken, hand_out).unwrap_err();
    assert!(
        matches!(error, WorkerError::Environment { job: 3, task_id: 9, .. }),
        "{error}"
    );
    assert_eq!(error.to_string(), "task 9 of job 3: no environment");
    let source = std::error::Error::source(&error).expect("the factory's error");
    assert_eq!(source.to_string(), "no simulator here");
}
