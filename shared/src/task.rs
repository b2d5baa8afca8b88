//! Tasks, outcomes and the environment trait.

use crate::EnvironmentSpec;
use serde::{Deserialize, Serialize};

/// Why a task exists.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum TaskKind {
    /// A training rollout: explorative parameters, the outcome feeds the learner.
    Train,
    /// A rollout of the greedy policy (exploration off) on a test context, for the learning curve.
    Evaluate,
    /// A rollout of the initial greedy policy on a training context before learning starts: it
    /// gives each context's first-visit baseline for the intrinsic rewards.
    Baseline,
}

/// One rollout to perform: parameters `theta` in `context`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Task {
    /// Position in the learner's task sequence; outcomes are consumed in this order.
    pub id: u64,
    /// Why the task exists.
    pub kind: TaskKind,
    /// Seed for everything random inside the rollout.
    pub seed: u64,
    /// The task context s.
    pub context: Vec<f64>,
    /// The low-level policy parameters theta.
    pub theta: Vec<f64>,
}

/// Whether a rollout produced a usable return.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum OutcomeStatus {
    /// The return and score are finite and meaningful.
    Ok,
    /// The simulation failed (non-finite state, explosion, violated limit); the return is not used.
    Failed,
}

/// The result of one task.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Outcome {
    /// The id of the task this answers.
    pub task_id: u64,
    /// Whether `reward` and `score` can be used.
    pub status: OutcomeStatus,
    /// The return r(s, theta) the learner maximises.
    pub reward: f64,
    /// The problem's evaluation measure for this rollout (for example a cost or a distance);
    /// the problem says how scores of a test set are aggregated.
    pub score: f64,
    /// Problem-defined extra numbers, for example where a thrown ball landed.
    pub diagnostics: Vec<f64>,
}

impl Outcome {
    /// A successful outcome. Non-finite values are turned into a failed outcome, so that a NaN
    /// can never reach the learner as a return.
    pub fn new(task_id: u64, reward: f64, score: f64) -> Self {
        let status = if reward.is_finite() && score.is_finite() {
            OutcomeStatus::Ok
        } else {
            OutcomeStatus::Failed
        };
        Self {
            task_id,
            status,
            reward,
            score,
            diagnostics: Vec::new(),
        }
    }

    /// The same outcome with `diagnostics` attached.
    pub fn with_diagnostics(mut self, diagnostics: Vec<f64>) -> Self {
        self.diagnostics = diagnostics;
        self
    }

    /// A failed outcome.
    pub fn failed(task_id: u64) -> Self {
        Self {
            task_id,
            status: OutcomeStatus::Failed,
            reward: f64::NAN,
            score: f64::NAN,
            diagnostics: Vec::new(),
        }
    }

    /// True when the outcome carries a usable return.
    pub fn is_ok(&self) -> bool {
        self.status == OutcomeStatus::Ok
    }
}

/// Something that performs rollouts. Implementations must be deterministic given the task
/// (its seed included), unless they document otherwise.
pub trait Environment: Send {
    /// What the environment is: its name, the hash of the settings that change its rollouts, and
    /// the numbers it was built from. Learners refuse an environment whose spec is not their
    /// problem's, and workers check it for every task they perform, so return a value computed
    /// when the environment was built.
    fn spec(&self) -> EnvironmentSpec;
    /// Dimension of the context s.
    fn context_dim(&self) -> usize;
    /// Dimension of the low-level parameters theta.
    fn param_dim(&self) -> usize;
    /// Perform one rollout. Never panics on bad numbers: a failed simulation is a failed outcome.
    fn rollout(&mut self, task: &Task) -> Outcome;

    /// Perform `tasks`, returning one outcome per task in their order: a vectorised simulator
    /// overrides it to step them together. A worker with `WorkerOptions::batches` hands it every
    /// queued task of this environment at once (up to 64); the default performs them one by one.
    fn rollout_batch(&mut self, tasks: &[Task]) -> Vec<Outcome> {
        tasks.iter().map(|task| self.rollout(task)).collect()
    }

    /// What the environment carries from one rollout to the next, encoded exactly (every bit of
    /// a float), for a checkpoint. Empty, the default, for environments whose rollouts depend
    /// on the task only.
    fn save_state(&self) -> Vec<u8> {
        Vec::new()
    }

    /// Continue from a state saved by [`save_state`](Environment::save_state) of an environment
    /// built the same way. The default accepts only the empty state.
    fn restore_state(&mut self, state: &[u8]) -> Result<(), EnvironmentRestoreError> {
        if state.is_empty() {
            Ok(())
        } else {
            Err(EnvironmentRestoreError::Length {
                expected: 0,
                got: state.len(),
            })
        }
    }
}

/// A boxed environment is one: a worker serves `Box<dyn Environment>` as it serves any other.
impl<E: Environment + ?Sized> Environment for Box<E> {
    fn spec(&self) -> EnvironmentSpec {
        (**self).spec()
    }

    fn context_dim(&self) -> usize {
        (**self).context_dim()
    }

    fn param_dim(&self) -> usize {
        (**self).param_dim()
    }

    fn rollout(&mut self, task: &Task) -> Outcome {
        (**self).rollout(task)
    }

    fn rollout_batch(&mut self, tasks: &[Task]) -> Vec<Outcome> {
        (**self).rollout_batch(tasks)
    }

    fn save_state(&self) -> Vec<u8> {
        (**self).save_state()
    }

    fn restore_state(&mut self, state: &[u8]) -> Result<(), EnvironmentRestoreError> {
        (**self).restore_state(state)
    }
}

/// A saved state that [`Environment::restore_state`] refuses.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EnvironmentRestoreError {
    /// The state has another length than this environment's states: it was saved by another
    /// kind of environment (0 bytes: this environment keeps no state).
    #[error("a saved environment state of {got} bytes, but this environment's state has {expected}")]
    Length {
        /// The length of this environment's states.
        expected: usize,
        /// The length of the saved state.
        got: usize,
    },
    /// The state has a fitting length but contents this environment cannot continue from; the
    /// environment says why.
    #[error("the saved environment state does not fit: {0}")]
    Invalid(String),
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Stateless;

    impl Environment for Stateless {
        fn spec(&self) -> EnvironmentSpec {
            EnvironmentSpec::new("stateless", [0; 3], &()).unwrap()
        }
        fn context_dim(&self) -> usize {
            1
        }
        fn param_dim(&self) -> usize {
            0
        }
        fn rollout(&mut self, task: &Task) -> Outcome {
            Outcome::new(task.id, 0.0, 0.0)
        }
    }

    #[test]
    fn a_stateless_environment_accepts_only_the_empty_state() {
        let mut environment = Stateless;
        assert_eq!(environment.restore_state(&environment.save_state()), Ok(()));
        assert_eq!(
            environment.restore_state(&[1, 2]),
            Err(EnvironmentRestoreError::Length { expected: 0, got: 2 })
        );
    }

    #[test]
    fn non_finite_values_make_a_failed_outcome() {
        assert!(Outcome::new(0, 1.0, 2.0).is_ok());
        assert!(!Outcome::new(0, f64::NAN, 2.0).is_ok());
        assert!(!Outcome::new(0, 1.0, f64::INFINITY).is_ok());
        assert!(!Outcome::failed(3).is_ok());
    }
}
