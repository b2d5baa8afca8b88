//! Embedding a worker in your own program: serve a running fleet from a background thread with
//! an environment of your own, and stop it when you like.
//!
//! Start a learner that waits for workers, then this program:
//!
//! ```sh
//! cargo run --release -p acps -- run function --workers 0 --run demo &
//! cargo run --release -p acps-worker --example embedded -- demo
//! ```
//!
//! Here the environment is the crate's spec-driven factory wrapped to count rollouts; any type
//! implementing `acps_shared::Environment` can be served with `acps_worker::Single`.

use acps_shared::Environment;
use acps_shared::ipc::RunName;
use acps_shared::wire::EnvironmentSpec;
use acps_worker::{EnvironmentFactory, ModelFactory, WorkerOptions};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// The host's view of the work done: a counter it can read while the worker runs.
struct Counting {
    inner: ModelFactory,
    rollouts: Arc<AtomicU64>,
}

impl EnvironmentFactory for Counting {
    fn environment(&mut self, spec: &EnvironmentSpec) -> Result<&mut dyn Environment, String> {
        self.rollouts.fetch_add(1, Ordering::Relaxed);
        self.inner.environment(spec)
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let run = RunName::new(&std::env::args().nth(1).ok_or("usage: embedded RUN_NAME")?)?;
    let stop = Arc::new(AtomicBool::new(false));
    let rollouts = Arc::new(AtomicU64::new(0));
    let worker = {
        let (stop, rollouts) = (stop.clone(), rollouts.clone());
        // iceoryx2 ports are not Send: the worker creates its own node on its own thread.
        std::thread::spawn(move || {
            let mut factory = Counting {
                inner: ModelFactory::default(),
                rollouts,
            };
            acps_worker::serve(&run, &WorkerOptions::default(), &mut factory, &stop)
        })
    };
    // The host goes on with its own work; here it reports progress until the worker is done.
    while !worker.is_finished() {
        std::thread::sleep(std::time::Duration::from_millis(500));
        println!("{} rollouts so far", rollouts.load(Ordering::Relaxed));
    }
    let report = worker.join().map_err(|_| "the worker thread panicked")??;
    println!("worker stopped: {:?} after {} rollouts", report.exit, report.rollouts);
    Ok(())
}
