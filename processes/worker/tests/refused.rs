//! A worker told by the learner that it belongs to another run stops with a message naming both.

use acps_shared::{Environment, EnvironmentSpec, Outcome, Task};
use acps_wire::ipc::{self, RunName};
use acps_wire::wire::{Answer, Response};
use acps_worker::{Single, WorkerError, WorkerOptions};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

/// Rollouts that return zero.
struct Zero;

impl Environment for Zero {
    fn spec(&self) -> EnvironmentSpec {
        EnvironmentSpec::new("zero", [0; 3], &()).unwrap()
    }

    fn context_dim(&self) -> usize {
        1
    }

    fn param_dim(&self) -> usize {
        1
    }

    fn rollout(&mut self, task: &Task) -> Outcome {
        Outcome::new(task.id, 0.0, 0.0)
    }
}

#[test]
fn a_refused_worker_stops_and_says_why() {
    let run = RunName::new(&format!("refused-{}", std::process::id())).unwrap();
    let worker = {
        let run = run.clone();
        std::thread::spawn(move || {
            let options = WorkerOptions {
                name: "refused".into(),
                ..WorkerOptions::default()
            };
            acps_worker::serve(&run, &options, &mut Single(Zero), &AtomicBool::new(false))
        })
    };
    {
        // A stand-in learner that refuses every request with identity 42.
        let node = ipc::node(&run, "fake-learner").unwrap();
        let services = ipc::open_services(&node).unwrap();
        let server = ipc::task_server(&run, &services.tasks).unwrap();
        let start = Instant::now();
        while !worker.is_finished() {
            while let Some(request) = server.receive().unwrap() {
                ipc::reply(&request, Answer::new(Response::Refused, 42), &[]).unwrap();
            }
            assert!(start.elapsed() < Duration::from_secs(20), "the worker never asked");
            std::thread::sleep(Duration::from_millis(5));
        }
    }
    match worker.join().unwrap() {
        Err(WorkerError::Refused { run: name, reason }) => {
            assert_eq!(name, run.as_str());
            assert!(reason.contains("000000000000002a"), "{reason}");
        }
        other => panic!("expected a refusal, got {other:?}"),
    }
    ipc::remove_run_files(&run).unwrap();
    assert!(ipc::leftover_files(&run).is_empty());
}
