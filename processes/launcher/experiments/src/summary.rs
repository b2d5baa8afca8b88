//! The summary of an experiment (`summary.json`) and the results of its runs: what the run
//! directory's records, the pictures and `acps compare` read.

use acps_learner::creps::PolicySnapshot;
use acps_learner::{Episode, LearnerStats, UpdateRecord};
use acps_shared::Problem;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// How the scores of a problem of the user's read, as its problem file says; recorded in the
/// summary and in every policy file. The learner maximises the workers' rewards either way.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct UserProblem {
    /// The scores' unit (may be empty).
    pub unit: String,
    /// Whether lower scores are better (costs, errors), as in all the paper's problems but the
    /// Section 4 model.
    pub lower_is_better: bool,
}

/// Whether lower scores are better: a problem file says so itself; of the paper's problems every
/// score is a cost or a distance except Section 4's J (`toy`), which its learner raises towards
/// J_opt. `acps compare` takes the direction from here.
pub fn lower_is_better(experiment: &str, user_problem: Option<&UserProblem>) -> bool {
    match user_problem {
        Some(user) => user.lower_is_better,
        None => experiment != "toy",
    }
}

/// Whether the scores are distances from the throwing targets, in cm (the paper's grid and
/// dartboard; not a problem file's, whatever it is called).
pub fn scores_are_distances(experiment: &str, user_problem: Option<&UserProblem>) -> bool {
    user_problem.is_none() && matches!(experiment, "grid" | "dartboard")
}

/// The result of one learner run.
#[derive(Debug)]
pub struct RunResult {
    /// The run's seed (problem instance and learner).
    pub seed: u64,
    /// The problem the run learned, with the environment it is defined for.
    pub problem: Problem,
    /// The final upper-level policy, if the problem has policy parameters.
    pub policy: Option<PolicySnapshot>,
    /// Episodes at which the policy was evaluated.
    pub eval_episodes: Vec<u64>,
    /// The evaluation scores (`None` if every rollout of an evaluation failed).
    pub scores: Vec<Option<f64>>,
    /// The consumed training episodes.
    pub episodes: Vec<Episode>,
    /// Every C-REPS update with its report.
    pub updates: Vec<UpdateRecord>,
    /// Counters.
    pub stats: LearnerStats,
    /// The instance's optimal score.
    pub optimal_score: Option<f64>,
    /// Evaluation rollouts of the run, and how many of them failed.
    pub evaluation_rollouts: (u64, u64),
    /// The outcome of every test context in the last evaluation.
    pub final_outcomes: Vec<Option<acps_shared::Outcome>>,
}

/// Per-method statistics over runs, in the summary.json contract.
#[derive(Debug, Serialize)]
pub struct MethodSummary {
    /// Training episodes at which the policy was evaluated.
    pub episodes: Vec<u64>,
    /// Mean score over runs at each evaluation.
    pub mean: Vec<Option<f64>>,
    /// Standard error of that mean.
    pub sem: Vec<Option<f64>>,
    /// Mean of the last evaluation.
    pub final_mean: Option<f64>,
    /// Its standard error.
    pub final_sem: Option<f64>,
    /// The last evaluation of every run (run r has seed base_seed + r), to see what the SEM is
    /// made of.
    pub final_scores: Vec<Option<f64>>,
    /// Per run, the most consecutive episodes spent on one training context: a bandit locked on
    /// one context shows as a long stay (round robin: 1; continuous contexts do not count).
    pub longest_stay: Vec<usize>,
    /// The selected training context (index) of every episode of run 0 (null: continuous).
    pub selections_run0: Vec<Option<usize>>,
    /// Fraction of the first `selection_window` episodes spent in each training context,
    /// averaged over runs.
    pub selection_ratio: Vec<f64>,
    /// Summed counters over runs.
    pub updates: u64,
    /// Summed rejected C-REPS updates over runs.
    pub rejected_updates: u64,
    /// Summed failed training rollouts over runs.
    pub failed_episodes: u64,
    /// Summed evaluation rollouts over runs (every test context of every evaluation).
    pub evaluation_rollouts: u64,
    /// Summed failed evaluation rollouts over runs: left out of the test means.
    pub failed_evaluation_rollouts: u64,
    /// Problem-specific results.
    #[serde(flatten)]
    pub detail: serde_json::Map<String, serde_json::Value>,
}

/// The summary.json of an experiment.
#[derive(Debug, Serialize)]
pub struct Summary {
    /// Experiment name.
    pub experiment: String,
    /// What the numbers mean.
    pub metric: String,
    /// For a problem file's problem: the scores' unit and direction.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub user_problem: Option<UserProblem>,
    /// Runs per method.
    pub runs: usize,
    /// Seed of run 0.
    pub base_seed: u64,
    /// Training episodes per run.
    pub training_episodes: u64,
    /// Tasks in flight.
    pub in_flight: usize,
    /// Episodes counted in `selection_ratio`.
    pub selection_window: usize,
    /// The training contexts (indices in `selections_run0` refer to these).
    pub training_contexts: Vec<Vec<f64>>,
    /// Mean over runs of the best achievable score, when the problem knows it (Section 4's
    /// J_opt = 10 + sum_s b_s); absent otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub j_opt_mean: Option<f64>,
    /// Recorded settings.
    pub settings: serde_json::Value,
    /// The lowest score of any evaluated policy, when the experiment asks for it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub best_policy: Option<BestPolicy>,
    /// Results per method.
    pub methods: BTreeMap<String, MethodSummary>,
    /// Every run of every method (keyed like `methods`), for the run directory's tables and
    /// policies; not part of summary.json.
    #[serde(skip)]
    pub run_results: BTreeMap<String, Vec<RunResult>>,
}

/// The best policy generated in all runs of all methods, as the paper's Fig. 8 reference: the
/// lowest score over every evaluation (not only the final ones) of every run, so it is the
/// minimum of `runs.csv`'s scores. Ties go to the first method, run and episode.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BestPolicy {
    /// Its evaluation score.
    pub score: f64,
    /// The method whose run generated it.
    pub method: String,
    /// The run (index from 0) ...
    pub run: usize,
    /// ... and its seed.
    pub seed: u64,
    /// The training episode after which it was evaluated; the run's final policy, saved in
    /// `policies/`, when this is the last evaluation.
    pub episode: u64,
}

impl BestPolicy {
    /// The lowest evaluation score in `runs` (method name, that method's runs); `None` when no
    /// evaluation has a score.
    pub(crate) fn find<'a>(runs: impl IntoIterator<Item = (&'a str, &'a [RunResult])>) -> Option<Self> {
        let mut best: Option<Self> = None;
        for (method, results) in runs {
            for (run, result) in results.iter().enumerate() {
                for (&episode, score) in result.eval_episodes.iter().zip(&result.scores) {
                    let Some(score) = *score else { continue };
                    if best.as_ref().is_none_or(|b| score < b.score) {
                        best = Some(Self {
                            score,
                            method: method.to_string(),
                            run,
                            seed: result.seed,
                            episode,
                        });
                    }
                }
            }
        }
        best
    }
}

/// A method whose share of failed rollouts is larger than a run accepts.
#[derive(Debug, Clone, PartialEq)]
pub struct Failures {
    /// The method.
    pub method: String,
    /// Its failed and all training rollouts over runs.
    pub training: (u64, u64),
    /// Its failed and all evaluation rollouts over runs.
    pub evaluation: (u64, u64),
}

impl Failures {
    /// The share of all its rollouts that failed.
    pub fn share(&self) -> f64 {
        let all = self.training.1 + self.evaluation.1;
        (self.training.0 + self.evaluation.0) as f64 / all.max(1) as f64
    }
}

impl std::fmt::Display for Failures {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}: {} of {} training and {} of {} evaluation rollouts failed ({:.1}%)",
            self.method,
            self.training.0,
            self.training.1,
            self.evaluation.0,
            self.evaluation.1,
            100.0 * self.share()
        )
    }
}

impl Summary {
    /// Every method with a failed rollout, with its counts.
    pub fn failures(&self) -> Vec<Failures> {
        self.methods
            .iter()
            .map(|(method, m)| Failures {
                method: method.clone(),
                training: (m.failed_episodes, self.training_episodes * self.runs as u64),
                evaluation: (m.failed_evaluation_rollouts, m.evaluation_rollouts),
            })
            .filter(|f| f.training.0 + f.evaluation.0 > 0)
            .collect()
    }

    /// Write `dir/summary.json`, creating `dir`.
    pub fn write(&self, dir: &Path) -> std::io::Result<()> {
        std::fs::create_dir_all(dir)?;
        // Streamed: a long run's selections make the text large.
        let mut out = std::io::BufWriter::new(std::fs::File::create(dir.join("summary.json"))?);
        serde_json::to_writer_pretty(&mut out, self).map_err(std::io::Error::other)?;
        std::io::Write::flush(&mut out)
    }
}

/// Arithmetic mean.
pub fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

/// Standard error of the mean (sample standard deviation / sqrt(n)); 0 for a single value.
pub fn standard_error(values: &[f64]) -> f64 {
    let n = values.len() as f64;
    if values.len() < 2 {
        return 0.0;
    }
    let m = mean(values);
    (values.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn standard_error_matches_the_textbook_formula() {
        // Sample std of [1, 2, 3, 4] is sqrt(5/3); SEM = that / 2.
        assert!((standard_error(&[1.0, 2.0, 3.0, 4.0]) - (5.0f64 / 3.0).sqrt() / 2.0).abs() < 1e-15);
        assert_eq!(standard_error(&[3.0]), 0.0);
    }
}
