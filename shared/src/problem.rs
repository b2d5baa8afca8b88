//! What the learner needs to know about a problem, independent of who simulates it.

use crate::{ContextSpace, Environment, EnvironmentSpec};
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
    /// The environment the problem is defined for: rollouts of any other are refused.
    pub environment: EnvironmentSpec,
}

/// An environment that is not the one a problem is defined for.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("problem '{problem}' is defined for environment {expected}, not for {found}")]
pub struct EnvironmentMatchError {
    /// The problem's name.
    pub problem: String,
    /// The problem's environment (boxed, as the error path is rare and results stay small).
    pub expected: Box<EnvironmentSpec>,
    /// The environment offered.
    pub found: Box<EnvironmentSpec>,
}

impl Problem {
    /// Dimension of the contexts.
    pub fn context_dim(&self) -> usize {
        self.space.dim()
    }

    /// Refuse an environment other than the problem's.
    pub fn check_environment(&self, environment: &dyn Environment) -> Result<(), EnvironmentMatchError> {
        let found = environment.spec();
        if found == self.environment {
            Ok(())
        } else {
            Err(EnvironmentMatchError {
                problem: self.name.clone(),
                expected: Box::new(self.environment),
                found: Box::new(found),
            })
        }
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

    /// An environment that is only its spec.
    struct Named(EnvironmentSpec);

    impl Environment for Named {
        fn spec(&self) -> EnvironmentSpec {
            self.0
        }

        fn context_dim(&self) -> usize {
            1
        }

        fn param_dim(&self) -> usize {
            0
        }

        fn rollout(&mut self, task: &crate::Task) -> crate::Outcome {
            crate::Outcome::failed(task.id)
        }
    }

    #[test]
    fn another_environment_is_refused_naming_both() {
        let spec = |dt: f64| EnvironmentSpec::new("arm", [0; 3], &dt).unwrap();
        let problem = Problem {
            name: "reach".into(),
            training_contexts: vec![vec![0.0]],
            test_contexts: vec![],
            space: ContextSpace::new_box(vec![0.0], vec![1.0]).unwrap(),
            theta0: vec![],
            score: ScoreAggregate::Mean,
            metric: "none".into(),
            environment: spec(0.01),
        };
        assert_eq!(problem.check_environment(&Named(spec(0.01))), Ok(()));
        let error = problem.check_environment(&Named(spec(0.02))).unwrap_err();
        assert_eq!(
            error.to_string(),
            format!(
                "problem 'reach' is defined for environment {}, not for {}",
                spec(0.01),
                spec(0.02)
            )
        );
    }
}
