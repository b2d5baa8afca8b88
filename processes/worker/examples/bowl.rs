//! The worker of `experiments/bowl.toml`, a problem of your own in a problem file: the learner
//! (`acps run --config experiments/bowl.toml --worker-command PATH`) starts this program W
//! times, and each copy serves the run named in `ACPS_RUN`. Its Python twin computes the same
//! bits, so the arithmetic and its order are part of the example.
//!
//! ```sh
//! cargo build --release -p acps-worker --example bowl
//! cargo run --release -p acps -- run --config experiments/bowl.toml --worker-command target/release/examples/bowl --workers 2
//! ```
//!
//! `BOWL_SETTINGS=TEXT` declares other settings than the problem file's ("bowl v1"), and
//! `BOWL_UNNAMED=1` no environment at all: the learner then refuses the worker, naming both
//! sides' environments. `--batch` serves batches: every queued task in one `rollout_batch`
//! call (here the trait's default, one after another: the same bits).

use acps_shared::{Environment, EnvironmentSpec, Outcome, Task};
use acps_worker::{RunName, Single, WorkerOptions};
use std::sync::atomic::AtomicBool;

/// The settings text of `experiments/bowl.toml`'s `[problem.environment]`.
const SETTINGS: &str = "bowl v1";

/// theta should be the context, scaled: theta_i = s_(i mod d) (i + 1) / n.
struct Bowl {
    spec: EnvironmentSpec,
}

impl Environment for Bowl {
    fn spec(&self) -> EnvironmentSpec {
        self.spec
    }

    fn context_dim(&self) -> usize {
        2
    }

    fn param_dim(&self) -> usize {
        4
    }

    fn rollout(&mut self, task: &Task) -> Outcome {
        let (context, theta) = (&task.context, &task.theta);
        if context.is_empty() {
            return Outcome::failed(task.id);
        }
        let (d, n) = (context.len(), theta.len());
        let mut total = 0.0;
        for (i, t) in theta.iter().enumerate() {
            let c = context[i % d] * (i + 1) as f64 / n as f64;
            let e = t - c;
            total += e * e;
        }
        Outcome::new(task.id, -total, total.sqrt())
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Some(run) = RunName::from_env()? else {
        return Err(
            "ACPS_RUN is not set: this worker is started by `acps run ... --worker-command`, or with ACPS_RUN=RUN"
                .into(),
        );
    };
    let spec = if std::env::var_os("BOWL_UNNAMED").is_some() {
        EnvironmentSpec::unnamed()
    } else {
        let settings = std::env::var("BOWL_SETTINGS").unwrap_or_else(|_| SETTINGS.to_string());
        EnvironmentSpec::from_text("bowl", [0, 0, 0], &settings)?
    };
    let index = std::env::var("ACPS_WORKER_INDEX").unwrap_or_default();
    let batches = std::env::args().any(|arg| arg == "--batch");
    let defaults = WorkerOptions::default();
    let options = WorkerOptions {
        name: format!("bowl-{index}-{}", std::process::id()),
        // A deeper queue lets batches form.
        queue_depth: if batches { 16 } else { defaults.queue_depth },
        batches,
        ..defaults
    };
    let report = acps_worker::serve(&run, &options, &mut Single(Bowl { spec }), &AtomicBool::new(false))?;
    eprintln!("{}: {:?} after {} rollouts", options.name, report.exit, report.rollouts);
    Ok(())
}
