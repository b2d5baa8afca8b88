//! The paper's Section 4 artificial model of a contextual learning process.
//!
//! Ten discrete contexts s = 0..9, each with a hidden competence l_s (starting at 0). The true
//! reward is r(s) = 1 / (1 + exp(-0.1 l_s + 4)) + b_s with a per-context baseline
//! b_s ~ N(0, sigma_b^2); the agent observes r(s) + N(0, sigma_r^2). Practising context s_t
//! raises every competence: l_s += w_{s_t} 0.5^|s - s_t|, where the learning factors w are a
//! random permutation of {0.1^2, 0.2^2, ..., 1.0^2}.
//!
//! Choices the paper leaves open (see the project notes, algorithms.md section 5):
//! - competence is updated *before* the reward of the practised context is read, so a rollout
//!   sees the learning it caused;
//! - competence is not clipped at 100 (the logistic is 0.9975 there, so it hardly matters);
//! - evaluation and baseline rollouts read the noise-free r(s) and do not learn;
//! - the model has no policy parameters: theta is empty.

use crate::{InvalidArgument, check};
use acps_shared::{
    ContextSpace, Environment, EnvironmentRestoreError, EnvironmentSpec, Outcome, Problem, ScoreAggregate, Stream,
    Task, TaskKind, derive_seed,
};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// Number of contexts in the model.
pub const CONTEXTS: usize = 10;

/// The name of the model's environment (it is never built from a spec: it keeps state).
pub const ENVIRONMENT: &str = "learning-model";

/// Noise levels of the model (the four panels of Fig. 2 vary these).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LearningModelConfig {
    /// Standard deviation of the observation noise, sigma_r >= 0.
    pub sigma_r: f64,
    /// Standard deviation of the per-context reward baselines, sigma_b >= 0.
    pub sigma_b: f64,
}

/// Why [`LearningModel::new`] or [`LearningModel::with_learning_factors`] refuses a parameter.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("learning model: {0}")]
pub struct LearningModelCreateError(#[from] pub InvalidArgument);

/// One instance of the model: baselines and learning factors drawn from a seed.
#[derive(Debug, Clone)]
pub struct LearningModel {
    config: LearningModelConfig,
    baselines: [f64; CONTEXTS],
    learning_factors: [f64; CONTEXTS],
    competence: [f64; CONTEXTS],
    spec: EnvironmentSpec,
}

impl LearningModel {
    /// A model whose baselines and learning-factor permutation come from `problem_seed`.
    pub fn new(config: LearningModelConfig, problem_seed: u64) -> Result<Self, LearningModelCreateError> {
        check(
            config.sigma_r.is_finite() && config.sigma_r >= 0.0,
            "sigma_r",
            "finite and >= 0",
            config.sigma_r,
        )?;
        check(
            config.sigma_b.is_finite() && config.sigma_b >= 0.0,
            "sigma_b",
            "finite and >= 0",
            config.sigma_b,
        )?;
        let mut rng = ChaCha8Rng::seed_from_u64(derive_seed(problem_seed, Stream::Problem, 0));
        let mut learning_factors: [f64; CONTEXTS] = std::array::from_fn(|i| ((i + 1) as f64 / 10.0).powi(2));
        learning_factors.shuffle(&mut rng);
        let baseline_noise = Normal::new(0.0, config.sigma_b).expect("sigma_b was checked to be finite and >= 0");
        let baselines = std::array::from_fn(|_| baseline_noise.sample(&mut rng));
        Ok(Self {
            config,
            baselines,
            learning_factors,
            competence: [0.0; CONTEXTS],
            spec: Self::describe(&config, &baselines, &learning_factors),
        })
    }

    /// The spec of an instance: its noise levels, baselines and learning factors (the
    /// competences are its state, which starts at zero).
    fn describe(
        config: &LearningModelConfig,
        baselines: &[f64; CONTEXTS],
        learning_factors: &[f64; CONTEXTS],
    ) -> EnvironmentSpec {
        EnvironmentSpec::new(ENVIRONMENT, [0; 3], &(config, baselines, learning_factors)).expect("a valid name")
    }

    /// Replace the drawn learning factors, for example by the permutation of the paper's Fig. 3.
    pub fn with_learning_factors(
        mut self,
        learning_factors: [f64; CONTEXTS],
    ) -> Result<Self, LearningModelCreateError> {
        let valid = learning_factors.iter().all(|w| w.is_finite() && *w >= 0.0);
        check(
            valid,
            "learning_factors",
            "finite and >= 0",
            format!("{learning_factors:?}"),
        )?;
        self.learning_factors = learning_factors;
        self.spec = Self::describe(&self.config, &self.baselines, &learning_factors);
        Ok(self)
    }

    /// The problem the learner sees in this instance: the ten contexts are both training and
    /// test set, and the score of an evaluation is J = sum_s r(s).
    pub fn problem(&self) -> Problem {
        let contexts: Vec<Vec<f64>> = (0..CONTEXTS).map(|s| vec![s as f64]).collect();
        Problem {
            name: "learning-model".into(),
            training_contexts: contexts.clone(),
            test_contexts: contexts,
            space: ContextSpace::new_box(vec![-0.5], vec![CONTEXTS as f64 - 0.5]).expect("a valid box"),
            theta0: Vec::new(),
            score: ScoreAggregate::Sum,
            metric: "J = sum over the 10 contexts of the noise-free reward r(s)".into(),
            environment: self.spec,
        }
    }

    /// The noise-free reward of context `s` at the current competence.
    pub fn true_reward(&self, s: usize) -> f64 {
        1.0 / (1.0 + (-0.1 * self.competence[s] + 4.0).exp()) + self.baselines[s]
    }

    /// J = sum_s r(s), noise-free.
    pub fn performance(&self) -> f64 {
        (0..CONTEXTS).map(|s| self.true_reward(s)).sum()
    }

    /// The upper bound J_opt = 10 + sum_s b_s.
    pub fn optimal_performance(&self) -> f64 {
        CONTEXTS as f64 + self.baselines.iter().sum::<f64>()
    }

    /// The learning factors w_s.
    pub fn learning_factors(&self) -> &[f64; CONTEXTS] {
        &self.learning_factors
    }

    /// The hidden competences l_s.
    pub fn competence(&self) -> &[f64; CONTEXTS] {
        &self.competence
    }

    fn practise(&mut self, practised: usize) {
        let w = self.learning_factors[practised];
        for (s, l) in self.competence.iter_mut().enumerate() {
            *l += w * 0.5f64.powi((s as i32 - practised as i32).abs());
        }
    }
}

/// The context index a task names, if it is one of the ten.
fn context_index(context: &[f64]) -> Option<usize> {
    match context {
        [s] if s.is_finite() && s.fract() == 0.0 && (0.0..CONTEXTS as f64).contains(s) => Some(*s as usize),
        _ => None,
    }
}

impl Environment for LearningModel {
    fn spec(&self) -> EnvironmentSpec {
        self.spec
    }

    fn context_dim(&self) -> usize {
        1
    }

    fn param_dim(&self) -> usize {
        0
    }

    fn rollout(&mut self, task: &Task) -> Outcome {
        let Some(s) = context_index(&task.context) else {
            return Outcome::failed(task.id);
        };
        if task.kind != TaskKind::Train {
            let r = self.true_reward(s);
            return Outcome::new(task.id, r, r);
        }
        self.practise(s);
        let r = self.true_reward(s);
        let mut rng = ChaCha8Rng::seed_from_u64(task.seed);
        let noise = Normal::new(0.0, self.config.sigma_r).expect("sigma_r was checked to be finite and >= 0");
        Outcome::new(task.id, r + noise.sample(&mut rng), r)
    }

    /// The competences, which training rollouts raise: ten little-endian f64.
    fn save_state(&self) -> Vec<u8> {
        self.competence.iter().flat_map(|l| l.to_le_bytes()).collect()
    }

    fn restore_state(&mut self, state: &[u8]) -> Result<(), EnvironmentRestoreError> {
        if state.len() != 8 * CONTEXTS {
            return Err(EnvironmentRestoreError::Length {
                expected: 8 * CONTEXTS,
                got: state.len(),
            });
        }
        for (l, bytes) in self.competence.iter_mut().zip(state.chunks_exact(8)) {
            *l = f64::from_le_bytes(bytes.try_into().expect("chunks of 8 bytes"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn task(id: u64, kind: TaskKind, s: f64) -> Task {
        Task {
            id,
            kind,
            seed: id,
            context: vec![s],
            theta: vec![],
        }
    }

    #[test]
    fn learning_factors_are_a_permutation_of_the_squares() {
        for seed in 0..5 {
            let model = LearningModel::new(
                LearningModelConfig {
                    sigma_r: 0.0,
                    sigma_b: 0.0,
                },
                seed,
            )
            .unwrap();
            let mut w = model.learning_factors().to_vec();
            w.sort_by(f64::total_cmp);
            for (i, w) in w.iter().enumerate() {
                assert!((w - ((i + 1) as f64 / 10.0).powi(2)).abs() < 1e-15);
            }
        }
    }

    #[test]
    fn practice_transfers_with_distance_and_rewards_follow_the_logistic() {
        let mut model = LearningModel::new(
            LearningModelConfig {
                sigma_r: 0.0,
                sigma_b: 0.0,
            },
            3,
        )
        .unwrap()
        .with_learning_factors([0.5; CONTEXTS])
        .unwrap();
        assert_eq!(model.problem().environment, model.spec());
        let drawn = LearningModel::new(model.config, 3).unwrap();
        assert_ne!(
            drawn.spec(),
            model.spec(),
            "other learning factors, another environment"
        );
        let untrained = 1.0 / (1.0 + 4f64.exp());
        assert!((model.true_reward(0) - untrained).abs() < 1e-15);
        let outcome = model.rollout(&task(0, TaskKind::Train, 4.0));
        assert_eq!(model.competence()[4], 0.5);
        assert_eq!(model.competence()[2], 0.125);
        assert_eq!(model.competence()[9], 0.5 * 0.5f64.powi(5));
        // The reward is read after the update.
        assert_eq!(outcome.reward, model.true_reward(4));
        assert!(outcome.reward > untrained);
    }

    #[test]
    fn evaluation_does_not_learn_and_is_noise_free() {
        let mut model = LearningModel::new(
            LearningModelConfig {
                sigma_r: 0.5,
                sigma_b: 0.2,
            },
            1,
        )
        .unwrap();
        let before = model.performance();
        let outcomes: Vec<_> = (0..CONTEXTS)
            .map(|s| model.rollout(&task(s as u64, TaskKind::Evaluate, s as f64)))
            .collect();
        assert_eq!(model.performance(), before);
        let j: f64 = outcomes.iter().map(|o| o.score).sum();
        assert!((j - before).abs() < 1e-12);
        assert!(outcomes.iter().all(|o| o.reward == o.score));
    }

    #[test]
    fn observation_noise_has_the_configured_spread() {
        let mut model = LearningModel::new(
            LearningModelConfig {
                sigma_r: 0.01,
                sigma_b: 0.0,
            },
            1,
        )
        .unwrap()
        .with_learning_factors([0.0; CONTEXTS])
        .unwrap();
        let truth = model.true_reward(0);
        let noise: Vec<f64> = (0..4000)
            .map(|i| model.rollout(&task(i, TaskKind::Train, 0.0)).reward - truth)
            .collect();
        let mean = noise.iter().sum::<f64>() / noise.len() as f64;
        let std = (noise.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / noise.len() as f64).sqrt();
        assert!(
            mean.abs() < 0.001 && (std - 0.01).abs() < 0.0005,
            "mean {mean}, std {std}"
        );
    }

    #[test]
    fn optimum_and_bad_input() {
        let model = LearningModel::new(
            LearningModelConfig {
                sigma_r: 0.0,
                sigma_b: 0.2,
            },
            9,
        )
        .unwrap();
        let b_sum: f64 = (0..CONTEXTS)
            .map(|s| model.true_reward(s) - 1.0 / (1.0 + 4f64.exp()))
            .sum();
        assert!((model.optimal_performance() - (10.0 + b_sum)).abs() < 1e-12);
        assert!(
            LearningModel::new(
                LearningModelConfig {
                    sigma_r: -1.0,
                    sigma_b: 0.0
                },
                0
            )
            .is_err()
        );
        let mut model = model;
        assert!(!model.rollout(&task(0, TaskKind::Train, 10.0)).is_ok());
        assert!(!model.rollout(&task(0, TaskKind::Train, 1.5)).is_ok());
    }
}
