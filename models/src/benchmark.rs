//! BOLeRo's contextual benchmark functions (`benchmarks/ccmaes/objective.py`, the comparison
//! of C-CMA-ES with C-REPS of Abdolmaleki et al. 2017, Sec. 6.1), written from their
//! definitions: the cost of `x = theta + G s` with `G ~ N(0, 1)^(n_theta x n_s)`, contexts
//! uniform in `[1, 2]^n_s` and the initial parameters `theta0 ~ N(0, I)`, both drawn per run.
//!
//! - the sphere: `f(x) = ||x||^2`, optimum 0 at `theta = -G s` (affine in s);
//! - Rosenbrock: `f(x) = sum_i 100 (x_{i+1} - x_i^2)^2 + (1 - x_i)^2`, optimum 0 at
//!   `theta = 1 - G s`.
//!
//! The reward is `-f`, the score of a rollout its cost `f`. BOLeRo uses 20 parameters, a 2-D
//! context for the sphere and a 1-D one for Rosenbrock.

use crate::{InvalidArgument, check};
use acps_shared::{
    ContextSpace, Environment, EnvironmentSpec, Outcome, Problem, ScoreAggregate, Stream, Task, derive_seed,
};
use nalgebra::{DMatrix, DVector};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// The name of the sphere's environment; its parameters are [n_s, n_theta, problem seed].
pub const SPHERE_ENVIRONMENT: &str = "contextual-sphere";
/// The name of Rosenbrock's environment; its parameters are [n_s, n_theta, problem seed].
pub const ROSENBROCK_ENVIRONMENT: &str = "contextual-rosenbrock";

/// Which of the two functions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Objective {
    /// `||x||^2`.
    Sphere,
    /// `sum_i 100 (x_{i+1} - x_i^2)^2 + (1 - x_i)^2`.
    Rosenbrock,
}

impl Objective {
    /// The problem's and the experiment's name.
    pub fn name(self) -> &'static str {
        match self {
            Objective::Sphere => "sphere",
            Objective::Rosenbrock => "rosenbrock",
        }
    }

    /// The environment's name.
    pub fn environment(self) -> &'static str {
        match self {
            Objective::Sphere => SPHERE_ENVIRONMENT,
            Objective::Rosenbrock => ROSENBROCK_ENVIRONMENT,
        }
    }

    /// `f(x)`, 0 at the optimum.
    fn cost(self, x: &DVector<f64>) -> f64 {
        match self {
            Objective::Sphere => x.norm_squared(),
            Objective::Rosenbrock => x
                .as_slice()
                .windows(2)
                .map(|w| 100.0 * (w[1] - w[0] * w[0]).powi(2) + (1.0 - w[0]).powi(2))
                .sum(),
        }
    }
}

/// Why [`ContextualBenchmark::new`] refuses its dimensions.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("contextual benchmark: {0}")]
pub struct BenchmarkCreateError(#[from] pub InvalidArgument);

/// One run's instance of a contextual benchmark function.
#[derive(Debug, Clone)]
pub struct ContextualBenchmark {
    objective: Objective,
    g: DMatrix<f64>,
    theta0: Vec<f64>,
    problem_seed: u64,
    spec: EnvironmentSpec,
}

impl ContextualBenchmark {
    /// Draw G (n_theta x n_s) and theta0 (n_theta) from N(0, 1) with `problem_seed`.
    pub fn new(
        objective: Objective,
        n_s: usize,
        n_theta: usize,
        problem_seed: u64,
    ) -> Result<Self, BenchmarkCreateError> {
        check(n_s >= 1, "n_s", ">= 1", n_s)?;
        check(n_theta >= 2, "n_theta", ">= 2", n_theta)?;
        let mut rng = ChaCha8Rng::seed_from_u64(derive_seed(problem_seed, Stream::Problem, 0));
        let g = DMatrix::from_fn(n_theta, n_s, |_, _| StandardNormal.sample(&mut rng));
        let theta0 = (0..n_theta).map(|_| StandardNormal.sample(&mut rng)).collect();
        let parameters = [n_s as u64, n_theta as u64, problem_seed];
        // G is everything a rollout depends on: its values are the settings.
        let spec = EnvironmentSpec::new(objective.environment(), parameters, &g.as_slice()).expect("a valid name");
        Ok(Self {
            objective,
            g,
            theta0,
            problem_seed,
            spec,
        })
    }

    /// The function.
    pub fn objective(&self) -> Objective {
        self.objective
    }

    /// The matrix G.
    pub fn matrix(&self) -> &DMatrix<f64> {
        &self.g
    }

    /// The cost `f(theta + G s)`, or `None` for arguments of the wrong size.
    pub fn cost(&self, theta: &[f64], s: &[f64]) -> Option<f64> {
        if theta.len() != self.g.nrows() || s.len() != self.g.ncols() {
            return None;
        }
        let x = DVector::from_column_slice(theta) + &self.g * DVector::from_column_slice(s);
        Some(self.objective.cost(&x))
    }

    /// The problem: the continuous space `[1, 2]^n_s` (BOLeRo draws its contexts from it), for
    /// the selectors that choose among training contexts the grid of 5 values per dimension,
    /// and 50 test contexts uniform in the space; theta0 as drawn; the score is the natural log
    /// of the mean cost over the test contexts.
    pub fn problem(&self) -> Problem {
        let n_s = self.g.ncols();
        let ticks = [1.0, 1.25, 1.5, 1.75, 2.0];
        let mut training_contexts: Vec<Vec<f64>> = vec![Vec::new()];
        for _ in 0..n_s {
            training_contexts = training_contexts
                .into_iter()
                .flat_map(|prefix| {
                    ticks.iter().map(move |&t| {
                        let mut context = prefix.clone();
                        context.push(t);
                        context
                    })
                })
                .collect();
        }
        let space = ContextSpace::new_box(vec![1.0; n_s], vec![2.0; n_s]).expect("a valid box");
        let mut rng = ChaCha8Rng::seed_from_u64(derive_seed(self.problem_seed, Stream::Problem, 1));
        let test_contexts = (0..50).map(|_| space.sample(&mut rng)).collect();
        Problem {
            name: self.objective.name().into(),
            training_contexts,
            test_contexts,
            space,
            theta0: self.theta0.clone(),
            score: ScoreAggregate::LogMean,
            metric: format!(
                "natural log of the mean cost over the test contexts, f(theta + G s) of the contextual {}, exploration off",
                self.objective.name()
            ),
            environment: self.spec,
        }
    }
}

impl Environment for ContextualBenchmark {
    fn spec(&self) -> EnvironmentSpec {
        self.spec
    }

    fn context_dim(&self) -> usize {
        self.g.ncols()
    }

    fn param_dim(&self) -> usize {
        self.g.nrows()
    }

    fn rollout(&mut self, task: &Task) -> Outcome {
        match self.cost(&task.theta, &task.context) {
            Some(cost) => Outcome::new(task.id, -cost, cost),
            None => Outcome::failed(task.id),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_optimum_lies_where_the_definitions_put_it() {
        for objective in [Objective::Sphere, Objective::Rosenbrock] {
            let f = ContextualBenchmark::new(objective, 2, 20, 3).unwrap();
            let s = [1.3, 1.9];
            let shift = f.matrix() * DVector::from_column_slice(&s);
            let optimum: Vec<f64> = match objective {
                Objective::Sphere => (-&shift).as_slice().to_vec(),
                Objective::Rosenbrock => shift.iter().map(|g| 1.0 - g).collect(),
            };
            assert!(f.cost(&optimum, &s).unwrap() < 1e-20);
            let mut off = optimum.clone();
            off[4] += 0.1;
            assert!(f.cost(&off, &s).unwrap() > 1e-3);
        }
        // Rosenbrock in two dimensions at x = 0: 100 (0 - 0)^2 + (1 - 0)^2 = 1.
        assert_eq!(Objective::Rosenbrock.cost(&DVector::from_vec(vec![0.0, 0.0])), 1.0);
        assert_eq!(Objective::Sphere.cost(&DVector::from_vec(vec![3.0, 4.0])), 25.0);
    }

    #[test]
    fn each_seed_draws_its_own_instance_and_the_spec_says_which() {
        let a = ContextualBenchmark::new(Objective::Sphere, 2, 20, 1).unwrap();
        let b = ContextualBenchmark::new(Objective::Sphere, 2, 20, 2).unwrap();
        assert_ne!(a.matrix(), b.matrix());
        assert_ne!(a.spec(), b.spec());
        let again = ContextualBenchmark::new(Objective::Sphere, 2, 20, 1).unwrap();
        assert_eq!((a.matrix(), a.spec()), (again.matrix(), again.spec()));
        let rosenbrock = ContextualBenchmark::new(Objective::Rosenbrock, 2, 20, 1).unwrap();
        assert_ne!(rosenbrock.spec(), a.spec());
    }

    #[test]
    fn the_problem_is_bolero_s_box_with_a_grid_for_discrete_selectors() {
        let p = ContextualBenchmark::new(Objective::Sphere, 2, 20, 0).unwrap().problem();
        assert_eq!(
            (p.training_contexts.len(), p.test_contexts.len(), p.theta0.len()),
            (25, 50, 20)
        );
        assert!(
            p.training_contexts
                .iter()
                .chain(&p.test_contexts)
                .all(|s| p.space.contains(s))
        );
        assert!(p.training_contexts.contains(&vec![1.25, 2.0]));
        let p = ContextualBenchmark::new(Objective::Rosenbrock, 1, 20, 0)
            .unwrap()
            .problem();
        assert_eq!(
            p.training_contexts,
            vec![vec![1.0], vec![1.25], vec![1.5], vec![1.75], vec![2.0]]
        );
        assert!(ContextualBenchmark::new(Objective::Sphere, 0, 20, 0).is_err());
    }

    #[test]
    fn a_rollout_returns_minus_the_cost_and_fails_on_wrong_sizes() {
        let mut f = ContextualBenchmark::new(Objective::Sphere, 1, 3, 0).unwrap();
        let task = |theta: Vec<f64>| Task {
            id: 7,
            kind: acps_shared::TaskKind::Train,
            context: vec![1.5],
            theta,
            seed: 0,
        };
        let outcome = f.rollout(&task(vec![0.0; 3]));
        let cost = f.cost(&[0.0; 3], &[1.5]).unwrap();
        assert_eq!((outcome.reward, outcome.score), (-cost, cost));
        assert!(!f.rollout(&task(vec![0.0; 2])).is_ok());
    }
}
