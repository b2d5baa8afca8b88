//! What a running experiment shows: training episodes done of all, the latest test score
//! averaged over the runs, rollouts per second and, for fleets, the live workers.

use crate::experiment::Experiment;
use acps_learner::LearningProgress;
use indicatif::{ProgressBar, ProgressStyle};
use std::time::Duration;

/// A progress line for an experiment, hidden when quiet.
pub struct Progress {
    bar: ProgressBar,
    score: ScoreFormat,
}

/// How the score of an experiment reads on the progress line: a name and a unit.
type ScoreFormat = (&'static str, String);

fn score_format(experiment: &str) -> ScoreFormat {
    let (name, unit) = match experiment {
        "grid" | "dartboard" => ("test error", " cm"),
        "function" | "dims" => ("test ln cost", ""),
        "toy" => ("test J", ""),
        _ => ("test score", ""),
    };
    (name, unit.to_string())
}

impl Progress {
    /// A progress line for `experiment`; nothing is drawn when `quiet`.
    pub fn new(experiment: &str, quiet: bool) -> Self {
        let bar = if quiet {
            ProgressBar::hidden()
        } else {
            let bar = ProgressBar::new(0);
            bar.set_style(
                ProgressStyle::with_template(
                    "{prefix} [{bar:25}] {human_pos}/{human_len} episodes, {msg}, {elapsed} (eta {eta})",
                )
                .expect("a valid template")
                .progress_chars("=> "),
            );
            bar.set_prefix(experiment.to_string());
            bar.set_message("starting");
            bar.enable_steady_tick(Duration::from_millis(250));
            bar
        };
        Self {
            bar,
            score: score_format(experiment),
        }
    }

    /// A progress line for `experiment`, in the unit a problem file gives its scores.
    pub fn of(experiment: &Experiment, quiet: bool) -> Self {
        let mut progress = Self::new(&experiment.name, quiet);
        if let Some(user) = &experiment.user_problem {
            let unit = if user.unit.is_empty() {
                String::new()
            } else {
                format!(" {}", user.unit)
            };
            progress.score = ("test score", unit);
        }
        progress
    }

    /// Show `learning`, with `rollouts` done so far and, for fleets, the live `workers`.
    pub fn show(&self, learning: &LearningProgress, rollouts: u64, workers: Option<usize>) {
        self.bar.set_length(learning.total_episodes);
        self.bar.set_position(learning.episodes);
        self.bar.set_message(self.message(learning, rollouts, workers));
    }

    fn message(&self, learning: &LearningProgress, rollouts: u64, workers: Option<usize>) -> String {
        let rate = rollouts as f64 / self.bar.elapsed().as_secs_f64().max(1e-3);
        let (name, unit) = &self.score;
        let score = learning
            .score
            .map_or("-".to_string(), |score| format!("{score:.2}{unit}"));
        let mut message = format!("{name} {score}, {rate:.0} rollouts/s");
        if let Some(workers) = workers {
            message += &format!(", {workers} workers");
        }
        message
    }

    /// Remove the line.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}
