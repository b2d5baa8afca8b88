//! The same simulator served by this program's learner to two worker processes, which are this
//! very program started again: a worker finds the run to join in `ACPS_RUN`, which the fleet
//! sets. The result is bit for bit the in-process one.
//!
//! ```sh
//! cargo run --release -p acps-fleet --example fleet
//! ```

mod cannon;

use acps_fleet::{Fleet, FleetJob, FleetProgress, RunName};
use acps_learner::{Learner, LearnerConfig, SelectorConfig, run_in_process};
use acps_worker::{Single, WorkerOptions};
use cannon::{Cannon, CannonSettings};
use std::process::Command;
use std::sync::atomic::AtomicBool;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let cannon = Cannon::new(CannonSettings::default());
    // Started by the fleet: be a worker.
    if let Some(run) = RunName::from_env()? {
        let report = acps_worker::serve(
            &run,
            &WorkerOptions::default(),
            &mut Single(cannon),
            &AtomicBool::new(false),
        )?;
        eprintln!(
            "worker {}: {:?} after {} rollouts",
            std::process::id(),
            report.exit,
            report.rollouts
        );
        return Ok(());
    }
    let learner = || {
        let config = LearnerConfig {
            episodes: 1500,
            // Two training tasks in flight keep both workers busy.
            in_flight: 2,
            ..LearnerConfig::default()
        };
        Learner::with_selector(config, cannon.problem(), &SelectorConfig::monotonic_progress())
    };
    let mut jobs = vec![FleetJob::new(learner()?)?];
    let mut fleet = Fleet::builder(RunName::new(&format!("cannon-{}", std::process::id()))?)
        .spawn_workers(2, |_| {
            Command::new(std::env::current_exe().expect("this program's path"))
        })
        .ctrl_c(true)
        .start()?;
    let mut shown = 0;
    let report = fleet.serve(&mut jobs, &mut |progress: &FleetProgress| {
        if progress.learning.episodes >= shown + 500 {
            shown = progress.learning.episodes;
            println!("{shown} episodes, {} workers", progress.workers);
        }
    })?;
    let served = jobs.remove(0).into_learner();
    println!(
        "served {} outcomes for {} episodes; mean miss {:.3} m",
        report.outcomes,
        served.episodes().len(),
        served.latest_score().unwrap_or(f64::NAN)
    );
    // The same learner driven in this process.
    let mut reference = learner()?;
    run_in_process(&mut reference, &mut cannon.clone())?;
    let same = format!("{:?}", served.episodes()) == format!("{:?}", reference.episodes());
    println!(
        "{}",
        if same {
            "identical to the in-process run"
        } else {
            "DIFFERENT from the in-process run"
        }
    );
    Ok(())
}
