//! Cost of one request-response round trip through the fleet's task service, in one process
//! (no wake-ups), by the number of connected workers: iceoryx2 looks for returned chunks on
//! every connection's channels whenever the learner loans an answer.

use acps_shared::EnvironmentSpec;
use acps_shared::{Task, TaskKind};
use acps_wire::ipc::{self, RunName};
use acps_wire::wire::{Answer, Response, WireTask, WorkerMessage};
use criterion::{Criterion, criterion_group, criterion_main};

fn round_trip(c: &mut Criterion) {
    let task = Task {
        id: 0,
        kind: TaskKind::Train,
        seed: 0,
        context: vec![0.0; 2],
        theta: vec![0.0; 21],
    };
    let spec = EnvironmentSpec::new("bench", [0; 3], &()).unwrap();
    let tasks = [WireTask::new(0, &task, spec).unwrap()];
    for workers in [1, 8, 64] {
        let run = RunName::new(&format!("bench-rt-{}-{workers}", std::process::id())).unwrap();
        {
            let node = ipc::node(&run, "bench").unwrap();
            let services = ipc::open_services(&node).unwrap();
            let server = ipc::task_server(&run, &services.tasks).unwrap();
            let clients: Vec<_> = (0..workers)
                .map(|_| services.tasks.client_builder().create().unwrap())
                .collect();
            let mut next = 0;
            c.bench_function(&format!("task_round_trip_{workers}_workers"), |b| {
                b.iter(|| {
                    next = (next + 1) % workers;
                    let pending = clients[next]
                        .send_copy(WorkerMessage::request(0, 1, acps_shared::Serves::Any))
                        .unwrap();
                    let request = server.receive().unwrap().unwrap();
                    ipc::reply(&request, Answer::new(Response::Task, 0), &tasks).unwrap();
                    drop(request);
                    pending.receive().unwrap().unwrap().payload().len()
                })
            });
        }
        ipc::remove_run_files(&run).unwrap();
    }
}

criterion_group!(benches, round_trip);
criterion_main!(benches);
