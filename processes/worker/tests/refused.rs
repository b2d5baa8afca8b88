//! A worker refused by the learner, or refusing a task, stops with a message naming both sides;
//! one whose environment returns more than the wire carries stops naming the limit; one whose
//! factory has no environment stops with the factory's error. A worker with batches hands its
//! environment every queued task at once, and stops when the outcomes do not match them.

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
    factory: impl EnvironmentFactory + Send + 'static,
    answer: impl FnMut(&WorkerMessage) -> (Answer, Vec<WireTask>),
) -> Result<WorkerReport, WorkerError> {
    let options = WorkerOptions {
        name: "refused".into(),
        ..WorkerOptions::default()
    };
    with_options(test, options, factory, answer)
}

/// [`against_stand_in`] with the worker's `options`.
fn with_options(
    test: &str,
    options: WorkerOptions,
    mut factory: impl EnvironmentFactory + Send + 'static,
    mut answer: impl FnMut(&WorkerMessage) -> (Answer, Vec<WireTask>),
) -> Result<WorkerReport, WorkerError> {
    let run = RunName::new(&format!("{test}-{}", std::process::id())).unwrap();
    let worker = {
        let run = run.clone();
        std::thread::spawn(move || acps_worker::serve(&run, &options, &mut factory, &AtomicBool::new(false)))
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
                "this worker serves {} = \"2.0\"; the run's jobs need {} = \"1.0\" and 1 other",
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

/// Rollouts that return their task's id as reward, recording each batch's size; with `drop`,
/// a batch's last outcome is left out.
struct Batched {
    spec: EnvironmentSpec,
    sizes: std::sync::Arc<std::sync::Mutex<Vec<usize>>>,
    drop: bool,
}

impl Environment for Batched {
    fn spec(&self) -> EnvironmentSpec {
        self.spec
    }

    fn context_dim(&self) -> usize {
        1
    }

    fn param_dim(&self) -> usize {
        1
    }

    fn rollout(&mut self, task: &Task) -> Outcome {
        Outcome::new(task.id, task.id as f64, 0.0)
    }

    fn rollout_batch(&mut self, tasks: &[Task]) -> Vec<Outcome> {
        self.sizes.lock().unwrap().push(tasks.len());
        let keep = tasks.len() - usize::from(self.drop);
        tasks[..keep].iter().map(|task| self.rollout(task)).collect()
    }
}

/// Five tasks (ids 10..15) in the first answer, then the end of the run once their outcomes
/// came back; the batch sizes and the outcomes the worker delivered, in order.
fn five_tasks_then_stop(test: &str, drop: bool) -> (Result<WorkerReport, WorkerError>, Vec<usize>, Vec<u64>) {
    let sizes = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let environment = Batched {
        spec: spec(1.0),
        sizes: sizes.clone(),
        drop,
    };
    let options = WorkerOptions {
        name: "batches".into(),
        queue_depth: 8,
        batches: true,
        ..WorkerOptions::default()
    };
    let mut handed_out = false;
    let mut delivered = Vec::new();
    let result = with_options(test, options, Single(environment), |message| {
        for outcome in &message.outcomes[..message.count as usize] {
            assert_eq!(outcome.reward, outcome.task_id as f64, "each outcome is its task's");
            delivered.push(outcome.task_id);
        }
        if handed_out {
            // The run ends once the five came back (or the worker stopped); until then,
            // requests get no tasks.
            let done = delivered.len() >= 5;
            return (
                Answer::new(if done { Response::Stop } else { Response::Task }, 42),
                vec![],
            );
        }
        handed_out = true;
        let tasks = (10..15)
            .map(|id| {
                let task = Task {
                    id,
                    kind: TaskKind::Train,
                    seed: id,
                    context: vec![0.0],
                    theta: vec![0.0],
                };
                WireTask::new(0, &task, spec(1.0)).unwrap()
            })
            .collect();
        (Answer::new(Response::Task, 42), tasks)
    });
    let sizes = sizes.lock().unwrap().clone();
    (result, sizes, delivered)
}

#[test]
fn a_worker_with_batches_hands_every_queued_task_to_one_call() {
    let (result, sizes, delivered) = five_tasks_then_stop("batches", false);
    let report = result.unwrap();
    assert_eq!(report.rollouts, 5);
    assert_eq!(sizes, vec![5], "one call for the five queued tasks");
    assert_eq!(delivered, vec![10, 11, 12, 13, 14]);
}

#[test]
fn a_batch_whose_outcomes_do_not_match_its_tasks_stops_the_worker() {
    let (result, sizes, delivered) = five_tasks_then_stop("batch-short", true);
    let error = result.unwrap_err();
    assert!(matches!(error, WorkerError::Batch { job: 0, .. }), "{error:?}");
    assert_eq!(
        error.to_string(),
        "a batch of job 0: rollout_batch returned 4 outcomes for 5 tasks; the worker stops, and the learner hands its tasks to another worker"
    );
    assert_eq!(sizes, vec![5]);
    assert!(
        delivered.is_empty(),
        "no outcome of the broken batch went out: {delivered:?}"
    );
}
