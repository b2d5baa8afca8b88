//! A worker embedded in a host program: the host keeps its own main thread and serves a run from
//! a thread of its choice, and stops the worker when it likes. Here the host also runs the
//! learner, so that the example needs nothing else; a worker joins a learner in another process
//! the same way, by the run's name.
//!
//! ```sh
//! cargo run --release -p acps-fleet --example embedded
//! ```

mod cannon;

use acps_fleet::{Fleet, FleetJob, FleetProgress, RunName};
use acps_learner::{Learner, LearnerConfig, SelectorConfig};
use acps_worker::{Single, WorkerOptions};
use cannon::{Cannon, CannonSettings};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let cannon = Cannon::new(CannonSettings::default());
    let run = RunName::new(&format!("embedded-{}", std::process::id()))?;
    // A fleet that starts no worker processes: it serves whoever joins.
    let mut fleet = Fleet::builder(run.clone()).start()?;
    let stop = Arc::new(AtomicBool::new(false));
    // The host's simulator thread. iceoryx2's ports stay on the thread that made them, so the
    // worker creates its own.
    let worker = {
        let (run, stop, cannon) = (run.clone(), stop.clone(), cannon.clone());
        std::thread::spawn(move || {
            let options = WorkerOptions {
                name: "host-thread".into(),
                ..WorkerOptions::default()
            };
            acps_worker::serve(&run, &options, &mut Single(cannon), &stop)
        })
    };
    let config = LearnerConfig {
        episodes: 600,
        ..LearnerConfig::default()
    };
    let learner = Learner::with_selector(config, cannon.problem(), &SelectorConfig::monotonic_progress())?;
    let mut jobs = vec![FleetJob::new(learner)?];
    let report = fleet.serve(&mut jobs, &mut |_: &FleetProgress| {})?;
    // The run is over, so the worker stops by itself; `stop` would end it earlier.
    let worked = worker.join().map_err(|_| "the worker thread panicked")??;
    println!(
        "the host's worker thread: {:?} after {} rollouts; the learner took {} outcomes",
        worked.exit, worked.rollouts, report.outcomes
    );
    Ok(())
}
