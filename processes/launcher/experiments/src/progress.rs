//! What a running experiment shows: training episodes done of all, the latest test score
//! averaged over the runs, rollouts per second and, for fleets, the live workers; and, once it
//! is done, the final scores in the same words and unit.

use crate::summary::{Summary, UserProblem, mean};
use acps_learner::LearningProgress;
use indicatif::{HumanDuration, ProgressBar, ProgressState, ProgressStyle};
use std::io::IsTerminal;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

/// How an experiment's score reads: its name and unit (with a leading space, or empty).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ScoreFormat {
    /// For example "test error".
    pub name: &'static str,
    /// For example " cm".
    pub unit: String,
}

impl ScoreFormat {
    /// The score of one of the paper's experiments, by name.
    fn of_paper(experiment: &str) -> Self {
        let (name, unit) = match experiment {
            "grid" | "dartboard" => ("test error", " cm"),
            "function" | "dims" => ("test ln cost", ""),
            "toy" => ("test J", ""),
            _ => ("test score", ""),
        };
        Self {
            name,
            unit: unit.to_string(),
        }
    }

    /// The score of experiment `name`, in the unit a problem file gives its scores (`user`).
    pub fn of(name: &str, user: Option<&UserProblem>) -> Self {
        match user {
            None => Self::of_paper(name),
            Some(user) if user.unit.is_empty() => Self::of_paper(""),
            Some(user) => Self {
                name: "test score",
                unit: format!(" {}", user.unit),
            },
        }
    }

    /// `score` with its unit, to two decimals.
    fn value(&self, score: Option<f64>) -> String {
        score.map_or("-".to_string(), |score| format!("{score:.2}{}", self.unit))
    }

    /// A method's final line: "final test error 4.05 cm ± 0.27 cm (mean ± SEM over 4 runs)".
    pub fn final_line(&self, mean: Option<f64>, sem: Option<f64>, runs: usize) -> String {
        match (mean, sem) {
            (Some(mean), Some(sem)) => format!(
                "final {} {mean:.3}{unit} ± {sem:.3}{unit} (mean ± SEM over {runs} runs)",
                self.name,
                unit = self.unit
            ),
            _ => format!(
                "final {}: none (every rollout of the last evaluation failed)",
                self.name
            ),
        }
    }
}

/// What an [`Observer`] is told of a running experiment.
#[derive(Debug, Clone, PartialEq)]
pub struct ProgressReport<'a> {
    /// The experiment's name.
    pub experiment: &'a str,
    /// Training episodes done, over all its runs.
    pub episodes: u64,
    /// Training episodes in all.
    pub total: u64,
    /// What the line shows beside them: the latest test score and the rollouts per second,
    /// or, once done, the final score.
    pub message: &'a str,
    /// Whether the experiment is done (the last report).
    pub done: bool,
}

/// Who watches a run's progress besides its line (a notebook's progress bar, a user's log): told
/// at most every [`OBSERVE_EVERY`], and once more when an experiment is done. It is called from
/// the threads that run the jobs.
pub type Observer = Arc<dyn Fn(&ProgressReport<'_>) + Send + Sync>;

/// The least time between two reports to an [`Observer`] (a notebook redraws no faster).
pub const OBSERVE_EVERY: Duration = Duration::from_millis(100);

/// A progress line for an experiment: a live bar on a terminal, a plain line every few seconds
/// when stderr is a file or a pipe (a log), nothing when quiet; and reports to an [`Observer`].
pub struct Progress {
    bar: ProgressBar,
    score: ScoreFormat,
    /// When stderr is not a terminal: the interval of the plain lines and when the last was
    /// written (none yet: the first report is written at once).
    lines: Option<(Duration, Mutex<Option<Instant>>)>,
    /// The observer and when it was last told.
    observer: Option<(Observer, Mutex<Option<Instant>>)>,
    /// The rollouts it was last shown.
    rollouts: AtomicU64,
}

/// The time left, once there is something to estimate it from (not "eta 0s" at the start) and
/// until the run is done.
fn eta(state: &ProgressState, out: &mut dyn std::fmt::Write) {
    if state.pos() > 0 && state.len().is_some_and(|len| state.pos() < len) {
        let _ = write!(out, " (eta {:#})", HumanDuration(state.eta()));
    }
}

/// How often a run's progress is written as a plain line when stderr is not a terminal, unless
/// set (`--progress-every`).
pub const PROGRESS_EVERY: Duration = Duration::from_secs(5);

impl Progress {
    /// A progress line for `experiment` (its name), of `total` training episodes over all its
    /// runs; nothing is drawn when `quiet`.
    pub fn new(experiment: &str, total: u64, quiet: bool) -> Self {
        Self::every(experiment, total, quiet, PROGRESS_EVERY)
    }

    /// [`Progress::new`], writing a plain line every `every` when stderr is not a terminal.
    pub fn every(experiment: &str, total: u64, quiet: bool, every: Duration) -> Self {
        let terminal = std::io::stderr().is_terminal();
        let lines = (!quiet && !terminal).then(|| (every, Mutex::new(None)));
        let bar = if quiet || !terminal {
            // Hidden, it still keeps the position, length and message the plain lines show.
            let bar = ProgressBar::hidden();
            bar.set_length(total);
            bar.set_prefix(experiment.to_string());
            bar
        } else {
            // The length is known from the start: no "0/0" bar drawn full before the first report.
            // The message comes last and is cut to the terminal's width: at 80 columns the line
            // keeps the test error; wider ones also show the rollouts/s and workers.
            let bar = ProgressBar::new(total)
                .with_style(
                    ProgressStyle::with_template(
                        "{prefix} [{bar:16}] {human_pos}/{human_len}, {elapsed}{eta}: {wide_msg}",
                    )
                    .expect("a valid template")
                    .with_key("eta", eta)
                    .progress_chars("=> "),
                )
                .with_prefix(experiment.to_string())
                .with_message("starting");
            bar.enable_steady_tick(Duration::from_millis(250));
            bar
        };
        Self {
            bar,
            score: ScoreFormat::of_paper(experiment),
            lines,
            observer: None,
            rollouts: AtomicU64::new(0),
        }
    }

    /// The same progress, reported to `observer` too.
    pub fn observed(self, observer: Option<Observer>) -> Self {
        Self {
            observer: observer.map(|observer| (observer, Mutex::new(None))),
            ..self
        }
    }

    /// Tell the observer, if there is one and it is due (always when `done`).
    fn report(&self, episodes: u64, message: &str, done: bool) {
        let Some((observer, last)) = &self.observer else {
            return;
        };
        {
            let mut last = last.lock().unwrap_or_else(PoisonError::into_inner);
            let now = Instant::now();
            if !done && last.is_some_and(|last| now.duration_since(last) < OBSERVE_EVERY) {
                return;
            }
            *last = Some(now);
        }
        observer(&ProgressReport {
            experiment: &self.bar.prefix(),
            episodes,
            total: self.bar.length().unwrap_or(episodes),
            message,
            done,
        });
    }

    /// A progress line for experiment `name` of `total` episodes, in the unit a problem file
    /// gives its scores (`user`).
    pub fn of(name: &str, total: u64, user: Option<&UserProblem>, quiet: bool, every: Duration) -> Self {
        Self {
            score: ScoreFormat::of(name, user),
            ..Self::every(name, total, quiet, every)
        }
    }

    /// Show `learning`, with `rollouts` done so far and, for fleets, the live `workers`.
    pub fn show(&self, learning: &LearningProgress, rollouts: u64, workers: Option<usize>) {
        self.rollouts.store(rollouts, Ordering::Relaxed);
        self.bar.set_length(learning.total_episodes);
        self.bar.set_position(learning.episodes);
        let rate = rollouts as f64 / self.bar.elapsed().as_secs_f64().max(1e-3);
        let mut message = format!(
            "{} {}, {rate:.0} rollouts/s",
            self.score.name,
            self.score.value(learning.score)
        );
        if let Some(workers) = workers {
            message += &format!(", {workers} workers");
        }
        if let Some((every, last)) = &self.lines {
            let mut last = last.lock().unwrap_or_else(PoisonError::into_inner);
            let now = Instant::now();
            if last.is_none_or(|last| now.duration_since(last) >= *every) {
                *last = Some(now);
                eprintln!(
                    "{}: {}/{} episodes, {message}, {:.1} s",
                    self.bar.prefix(),
                    learning.episodes,
                    learning.total_episodes,
                    self.bar.elapsed().as_secs_f64()
                );
            }
        }
        self.report(learning.episodes, &message, false);
        self.bar.set_message(message);
    }

    /// End the line with the final score of all runs, the mean the summary's lines break down
    /// per method.
    pub fn finish(&self, summary: &Summary) {
        let finals: Vec<f64> = summary
            .methods
            .values()
            .flat_map(|method| method.final_scores.iter().flatten().copied())
            .collect();
        let score = (!finals.is_empty()).then(|| mean(&finals));
        let of = match summary.methods.len() {
            1 => String::new(),
            methods => format!(" (mean of {methods} methods)"),
        };
        self.bar.set_position(self.bar.length().unwrap_or(0));
        let message = format!("final {} {}{of}", self.score.name, self.score.value(score));
        self.report(self.bar.position(), &message, true);
        if self.lines.is_some() {
            eprintln!(
                "{}: done, {message}, {:.1} s",
                self.bar.prefix(),
                self.bar.elapsed().as_secs_f64()
            );
        }
        self.bar.finish_with_message(message);
        if !self.bar.is_hidden() {
            // The bar stays; what is printed next starts below it.
            eprintln!();
        }
    }

    /// Rollouts done so far (the last count shown) and the seconds since the line was made.
    pub fn done(&self) -> (u64, f64) {
        (self.rollouts.load(Ordering::Relaxed), self.bar.elapsed().as_secs_f64())
    }

    /// Remove the line (the run failed or was stopped).
    pub fn abandon(&self) {
        self.bar.finish_and_clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn final_lines_carry_the_unit_and_name_the_sem() {
        let cm = ScoreFormat::of_paper("grid");
        assert_eq!(
            cm.final_line(Some(4.0451), Some(0.2724), 4),
            "final test error 4.045 cm ± 0.272 cm (mean ± SEM over 4 runs)"
        );
        let none = ScoreFormat::of_paper("function");
        assert_eq!(
            none.final_line(Some(-2.5), Some(0.125), 20),
            "final test ln cost -2.500 ± 0.125 (mean ± SEM over 20 runs)"
        );
        assert!(
            cm.final_line(None, None, 4)
                .contains("every rollout of the last evaluation failed")
        );
    }
}
