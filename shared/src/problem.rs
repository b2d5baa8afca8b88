//! What the learner needs to know about a problem, independent of who simulates it.

use crate::ContextSpace;
use serde::{Deserialize, Serialize};

/// How the scores of an evaluation's rollouts (one per test context) become one number.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ScoreAggregate {
    /// The sum (the Section 4 model's J = sum_s r(s)).
    Sum,
    /// The arithmetic mean (for example the mean distance to the targets).
    Mean,
    /// The natural log of the mean (Section 5.1's log cost).
    LogMean,
}

impl ScoreAggregate {
    /// Aggregate `scores`; `None` when there are none.
    pub fn apply(self, scores: &[f64]) -> Option<f64> {
        if scores.is_empty() {
            return None;
        }
        let sum: f64 = scores.iter().sum();
        let mean = sum / scores.len() as f64;
        Some(match self {
            Self::Sum => sum,
            Self::Mean => mean,
            Self::LogMean => mean.ln(),
        })
    }
}

/// A contextual learning problem as the learner sees it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Problem {
    /// Short name, used in run directories.
    pub name: String,
    /// The K training contexts the selector chooses among.
    pub training_contexts: Vec<Vec<f64>>,
    /// The contexts the greedy policy is evaluated on.
    pub test_contexts: Vec<Vec<f64>>,
    /// The continuous context space (for continuous baselines and SAGG-RIAC).
    pub space: ContextSpace,
    /// The initial low-level parameters theta_0 (empty when the problem has no policy to learn).
    pub theta0: Vec<f64>,
    /// How evaluation scores aggregate.
    pub score: ScoreAggregate,
    /// What the aggregated score means, for people reading results.
    pub metric: String,
}

impl Problem {
    /// Dimension of the contexts.
    pub fn context_dim(&self) -> usize {
        self.space.dim()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aggregates() {
        let scores = [1.0, 2.0, 3.0, 6.0];
        assert_eq!(ScoreAggregate::Sum.apply(&scores), Some(12.0));
        assert_eq!(ScoreAggregate::Mean.apply(&scores), Some(3.0));
        assert_eq!(ScoreAggregate::LogMean.apply(&scores), Some(3.0f64.ln()));
        assert_eq!(ScoreAggregate::Mean.apply(&[]), None);
    }
}
