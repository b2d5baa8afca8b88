//! A simulator of your own, learned in this process with ask/tell: the learner hands out tasks
//! (a context and parameters), you perform them and tell it the outcomes.
//!
//! ```sh
//! cargo run --release -p acps-fleet --example ask_tell
//! ```

mod cannon;

use acps_learner::{Learner, LearnerConfig, SelectorConfig};
use acps_shared::Environment;
use cannon::{Cannon, CannonSettings};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut cannon = Cannon::new(CannonSettings::default());
    let config = LearnerConfig {
        episodes: 1500,
        ..LearnerConfig::default()
    };
    // D-UCB with the monotonic-progress reward chooses which target and wind to practise.
    let mut learner = Learner::with_selector(config, cannon.problem(), &SelectorConfig::monotonic_progress())?;
    while let Some(task) = learner.ask() {
        // Your simulator here: any code that turns a task into an outcome.
        let outcome = cannon.rollout(&task);
        learner.tell(outcome)?;
    }
    let scores: Vec<f64> = learner.evaluations().iter().filter_map(|e| e.score).collect();
    let (first, last) = (scores[0], scores[scores.len() - 1]);
    println!(
        "mean miss {first:.3} m before learning, {last:.3} m after {} episodes",
        learner.episodes().len()
    );
    if let Some(policy) = learner.policy() {
        let theta = policy.greedy(&[7.0, 0.0]);
        println!(
            "at a 7 m target in no wind: elevation {:.3} rad, speed {:.2} m/s, spin {:.3}",
            theta[0], theta[1], theta[2]
        );
    }
    Ok(())
}
