//! The paper's Section 5.1 contextual function optimisation problem.
//!
//! f(theta, s) = -||A theta - s||_2 * ||s||_2^2 + sum_i s_i with A (n_s x n_theta) uniform in
//! [0, 1] and of full rank n_s, so that the optimum f*(s) = sum_i s_i is reachable everywhere. The
//! first norm is the plain Euclidean norm (the cost is a cone around the optimum), the second one
//! is squared: ||s||^2 makes outer contexts "complex", sum_i s_i gives contexts different maximal
//! rewards. The score of a rollout is the cost |f - f*| = ||A theta - s|| ||s||^2.
//!
//! n_theta is not stated in the paper; the default is 20 (documented in docs/EXPERIMENTS.md).

use crate::{InvalidArgument, check};
use acps_shared::{
    ContextSpace, Environment, EnvironmentSpec, Outcome, Problem, ScoreAggregate, Stream, Task, derive_seed,
    random_unit_vector,
};
use nalgebra::{DMatrix, DVector};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Default number of low-level parameters.
pub const DEFAULT_N_THETA: usize = 20;

/// The name of the function's environment; its parameters are [n_s, n_theta, problem seed].
pub const ENVIRONMENT: &str = "contextual-function";

/// Why [`ContextualFunction::new`] refuses its dimensions.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("contextual function: {0}")]
pub struct ContextualFunctionCreateError(#[from] pub InvalidArgument);

/// The contextual function of one run.
#[derive(Debug, Clone)]
pub struct ContextualFunction {
    a: DMatrix<f64>,
    problem_seed: u64,
    spec: EnvironmentSpec,
}

impl ContextualFunction {
    /// Draw A (n_s x n_theta) uniformly in [0, 1] from `problem_seed` until it has rank n_s.
    pub fn new(n_s: usize, n_theta: usize, problem_seed: u64) -> Result<Self, ContextualFunctionCreateError> {
        check(n_s >= 1, "n_s", ">= 1", n_s)?;
        check(n_theta > n_s, "n_theta", "> n_s", n_theta)?;
        let mut rng = ChaCha8Rng::seed_from_u64(derive_seed(problem_seed, Stream::Problem, 0));
        loop {
            let a = DMatrix::from_fn(n_s, n_theta, |_, _| rng.random::<f64>());
            if a.rank(1e-10) == n_s {
                // A is everything a rollout depends on: its values are the settings.
                let parameters = [n_s as u64, n_theta as u64, problem_seed];
                let spec = EnvironmentSpec::new(ENVIRONMENT, parameters, &a.as_slice()).expect("a valid name");
                return Ok(Self { a, problem_seed, spec });
            }
        }
    }

    /// The matrix A.
    pub fn matrix(&self) -> &DMatrix<f64> {
        &self.a
    }

    /// f(theta, s) and the cost |f - f*|, or `None` for arguments of the wrong size.
    pub fn evaluate(&self, theta: &[f64], s: &[f64]) -> Option<(f64, f64)> {
        if theta.len() != self.a.ncols() || s.len() != self.a.nrows() {
            return None;
        }
        let error = (&self.a * DVector::from_column_slice(theta) - DVector::from_column_slice(s)).norm();
        let complexity: f64 = s.iter().map(|x| x * x).sum();
        let cost = error * complexity;
        Some((s.iter().sum::<f64>() - cost, cost))
    }

    /// Section 5.1.2 for this function (n_s = 2): the 25 training contexts on the grid
    /// {-1, -1/2, 0, 1/2, 1}^2 and 100 test contexts uniform in [-1, 1]^2; the score is
    /// ln(mean cost).
    pub fn grid_problem(&self) -> Result<Problem, ContextualFunctionCreateError> {
        let n_s = self.a.nrows();
        check(n_s == 2, "n_s", "2 for the grid problem", n_s)?;
        let ticks = [-1.0, -0.5, 0.0, 0.5, 1.0];
        let training_contexts = ticks
            .iter()
            .flat_map(|&x| ticks.iter().map(move |&y| vec![x, y]))
            .collect();
        let space = ContextSpace::new_box(vec![-1.0; 2], vec![1.0; 2]).expect("a valid box");
        let mut rng = ChaCha8Rng::seed_from_u64(derive_seed(self.problem_seed, Stream::Problem, 1));
        let test_contexts = (0..100).map(|_| space.sample(&mut rng)).collect();
        Ok(self.problem("function", training_contexts, test_contexts, space))
    }

    /// Section 5.1.3 for this function: 25 training contexts s_k with a uniform random direction
    /// and ||s_k|| = k/25, k = 1..25, and a test set built the same way from another stream; the
    /// continuous space is the unit ball.
    pub fn shell_problem(&self) -> Problem {
        let n_s = self.a.nrows();
        let shells = |index: u64| -> Vec<Vec<f64>> {
            let mut rng = ChaCha8Rng::seed_from_u64(derive_seed(self.problem_seed, Stream::Problem, index));
            (1..=25)
                .map(|k| {
                    random_unit_vector(n_s, &mut rng)
                        .into_iter()
                        .map(|d| d * k as f64 / 25.0)
                        .collect()
                })
                .collect()
        };
        let space = ContextSpace::new_ball(n_s, 1.0).expect("a valid ball");
        self.problem(&format!("dims-{n_s}"), shells(1), shells(2), space)
    }

    fn problem(&self, name: &str, training: Vec<Vec<f64>>, test: Vec<Vec<f64>>, space: ContextSpace) -> Problem {
        Problem {
            name: name.into(),
            training_contexts: training,
            test_contexts: test,
            space,
            theta0: vec![0.0; self.a.ncols()],
            score: ScoreAggregate::LogMean,
            metric: "natural log of the mean cost |f - f*| over the test contexts, exploration off".into(),
            environment: self.spec,
        }
    }
}

impl Environment for ContextualFunction {
    fn spec(&self) -> EnvironmentSpec {
        self.spec
    }

    fn context_dim(&self) -> usize {
        self.a.nrows()
    }

    fn param_dim(&self) -> usize {
        self.a.ncols()
    }

    fn rollout(&mut self, task: &Task) -> Outcome {
        match self.evaluate(&task.theta, &task.context) {
            Some((f, cost)) => Outcome::new(task.id, f, cost),
            None => Outcome::failed(task.id),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_has_full_rank_and_values_in_the_unit_interval() {
        for seed in 0..5 {
            let f = ContextualFunction::new(3, 20, seed).unwrap();
            assert_eq!(f.matrix().rank(1e-10), 3);
            assert!(f.matrix().iter().all(|x| (0.0..1.0).contains(x)));
        }
        assert!(ContextualFunction::new(3, 3, 0).is_err());
    }

    #[test]
    fn the_optimum_is_the_baseline_and_the_cost_scales_with_complexity() {
        let f = ContextualFunction::new(2, 20, 4).unwrap();
        let s = [0.5, -1.0];
        // A least-norm solution of A theta = s reaches the optimum.
        let theta = f.matrix().clone().pseudo_inverse(1e-12).unwrap() * DVector::from_column_slice(&s);
        let (value, cost) = f.evaluate(theta.as_slice(), &s).unwrap();
        assert!((value - (-0.5)).abs() < 1e-9 && cost < 1e-9);
        // theta = 0: the error is ||s||, so the cost is ||s||^3.
        let (value, cost) = f.evaluate(&[0.0; 20], &s).unwrap();
        let norm = 1.25f64.sqrt();
        assert!((cost - norm.powi(3)).abs() < 1e-12);
        assert!((value - (-0.5 - norm.powi(3))).abs() < 1e-12);
        assert!(f.evaluate(&[0.0; 3], &s).is_none());
    }

    #[test]
    fn problem_sets_match_the_paper() {
        let function = ContextualFunction::new(2, 20, 1).unwrap();
        let grid = function.grid_problem().unwrap();
        assert_eq!(grid.environment, function.spec());
        assert_eq!(grid.training_contexts.len(), 25);
        assert!(grid.training_contexts.contains(&vec![-1.0, 0.5]));
        assert_eq!(grid.test_contexts.len(), 100);
        assert!(grid.test_contexts.iter().all(|s| grid.space.contains(s)));
        for n_s in 1..=4 {
            let p = ContextualFunction::new(n_s, 20, 1).unwrap().shell_problem();
            for (k, s) in p.training_contexts.iter().enumerate() {
                let norm = s.iter().map(|x| x * x).sum::<f64>().sqrt();
                assert!((norm - (k + 1) as f64 / 25.0).abs() < 1e-12);
            }
            assert_ne!(p.training_contexts, p.test_contexts);
        }
        let error = ContextualFunction::new(3, 20, 1).unwrap().grid_problem().unwrap_err();
        assert!(
            error.to_string().contains("n_s must be 2 for the grid problem, got 3"),
            "{error}"
        );
    }

    #[test]
    fn the_spec_names_the_instance() {
        let spec = |n_s, n_theta, seed| ContextualFunction::new(n_s, n_theta, seed).unwrap().spec();
        assert_eq!(spec(2, 20, 5), spec(2, 20, 5));
        assert_eq!(
            (spec(2, 20, 5).name(), spec(2, 20, 5).parameters()),
            (ENVIRONMENT, [2, 20, 5])
        );
        assert_ne!(spec(2, 20, 5).settings(), spec(2, 20, 6).settings(), "another matrix A");
        assert_ne!(spec(2, 20, 5).settings(), spec(2, 21, 5).settings());
    }
}
