//! The C-REPS dual (P Alg. 2 line 7) and its solution.
//!
//! With `r_i = R_i - v^T phi_i`, `A_i = r_i / eta` and `phi_bar` the mean feature vector,
//!
//! `g(eta, v) = eta eps + v^T phi_bar + eta log( (1/N) sum_i exp(A_i) )`,
//!
//! `dg/deta = eps + LSE(A) - sum_i p_i A_i` and `dg/dv = phi_bar - sum_i p_i phi_i`, where
//! `LSE` is the log-mean-exp and `p = softmax(A)`. Since `KL(p || uniform) = sum p_i A_i - LSE(A)`,
//! `dg/deta = eps - KL` and `dg/dv` is the feature-matching residual with the sign flipped: at an
//! interior optimum both optimality conditions hold to within the solver's gradient tolerance.
//!
//! As in BOLeRo the returns are not normalised, the solver starts at `eta = 1, v = 1` and uses
//! scipy's default stopping rules (see [`DualOptions`]).

use nalgebra::{DMatrix, DVector, DVectorView};
use serde::{Deserialize, Serialize};

use super::error::{CRepsError, check_at_least_one, check_finite, check_non_negative, check_positive};
use super::solver::minimize;

/// Solver settings for [`solve_dual`]; the defaults are scipy's `fmin_l_bfgs_b` defaults, which
/// BOLeRo uses.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DualOptions {
    /// Stop when the projected gradient's inf-norm is <= `pgtol` (default 1e-5).
    pub pgtol: f64,
    /// Stop when an iteration reduces the objective by a relative amount <= `factr *
    /// f64::EPSILON` (default 1e7, i.e. about 2.2e-9). 0 disables this test.
    pub factr: f64,
    /// Iteration cap (default 15000).
    pub max_iterations: usize,
    /// Number of L-BFGS correction pairs (default 10).
    pub memory: usize,
}

impl Default for DualOptions {
    fn default() -> Self {
        Self {
            pgtol: 1e-5,
            factr: 1e7,
            max_iterations: 15_000,
            memory: 10,
        }
    }
}

/// The minimiser of the dual and the sample weights it implies.
#[derive(Clone, Debug, PartialEq)]
pub struct DualSolution {
    /// The temperature eta (>= `eta_min`).
    pub eta: f64,
    /// The baseline coefficients v (one per feature).
    pub v: DVector<f64>,
    /// `d = softmax((R - Phi v) / eta)`; sums to 1.
    pub weights: DVector<f64>,
    /// `g(eta, v)`.
    pub objective: f64,
    /// `KL(d || uniform)`.
    pub kl: f64,
    /// Solver iterations.
    pub iterations: usize,
    /// Whether a stopping rule of [`DualOptions`] was met (BOLeRo ignores this flag, and so does
    /// the C-REPS update; it is reported for diagnostics).
    pub converged: bool,
}

/// Minimises the C-REPS dual over `eta >= eta_min` and free `v`.
///
/// `phi` holds one feature vector per row (N x n_phi), `returns` the N returns. Errors if the
/// inputs are inconsistent or non-finite, or if the dual is not finite at the start point.
pub fn solve_dual(
    phi: &DMatrix<f64>,
    returns: &[f64],
    epsilon: f64,
    eta_min: f64,
    options: &DualOptions,
) -> Result<DualSolution, CRepsError> {
    check_positive("epsilon", epsilon)?;
    check_positive("eta_min", eta_min)?;
    check_options(options)?;
    if phi.nrows() != returns.len() {
        return Err(CRepsError::LengthMismatch {
            first: "the number of phi rows",
            first_len: phi.nrows(),
            second: "the number of returns",
            second_len: returns.len(),
        });
    }
    if returns.is_empty() {
        return Err(CRepsError::NoSamples);
    }
    check_finite("returns", returns)?;
    check_finite("phi", phi.as_slice())?;

    let dual = Dual::new(phi, returns, epsilon);
    let mut scratch = Scratch::new(phi.nrows(), phi.ncols());
    let n_phi = phi.ncols();
    let mut lower = DVector::from_element(n_phi + 1, f64::NEG_INFINITY);
    lower[0] = eta_min;
    let x0 = DVector::from_element(n_phi + 1, 1.0);
    let mut gradient = DVector::zeros(n_phi + 1);
    let start = dual.evaluate(&x0.zip_map(&lower, f64::max), &mut gradient, &mut scratch);
    if !start.is_finite() || gradient.iter().any(|g| !g.is_finite()) {
        return Err(CRepsError::NonFiniteDual);
    }

    let minimum = minimize(|x, g| dual.evaluate(x, g, &mut scratch), x0, &lower, options);
    let eta = minimum.x[0];
    let v = minimum.x.rows(1, n_phi).into_owned();
    dual.softmax(eta, &v.as_view(), &mut scratch);
    let weights = scratch.p;
    Ok(DualSolution {
        eta,
        kl: kl_to_uniform(weights.as_slice()),
        v,
        weights,
        objective: minimum.f,
        iterations: minimum.iterations,
        converged: minimum.converged,
    })
}

/// `KL(d || uniform) = sum_i d_i ln(N d_i)` for weights `d` that sum to 1 (`0 ln 0 = 0`).
pub fn kl_to_uniform(weights: &[f64]) -> f64 {
    let n = weights.len() as f64;
    weights.iter().filter(|&&d| d > 0.0).map(|&d| d * (n * d).ln()).sum()
}

/// The feature-matching residual `sum_i d_i phi_i - phi_bar` (rows of `phi` are the `phi_i`,
/// `phi_bar` their plain mean); zero at an optimum of the dual.
pub fn feature_matching_residual(phi: &DMatrix<f64>, weights: &[f64]) -> DVector<f64> {
    phi.tr_mul(&DVector::from_column_slice(weights)) - mean_row(phi)
}

fn mean_row(phi: &DMatrix<f64>) -> DVector<f64> {
    phi.row_mean().transpose()
}

/// The dual's data.
struct Dual<'a> {
    phi: &'a DMatrix<f64>,
    returns: DVector<f64>,
    phi_mean: DVector<f64>,
    epsilon: f64,
}

impl<'a> Dual<'a> {
    fn new(phi: &'a DMatrix<f64>, returns: &[f64], epsilon: f64) -> Self {
        Self {
            phi,
            returns: DVector::from_column_slice(returns),
            phi_mean: mean_row(phi),
            epsilon,
        }
    }

    /// Writes `p = softmax((R - Phi v) / eta)` into `scratch.p` and `a = A - max A` (<= 0) into
    /// `scratch.shifted`; returns `max_r = max_i r_i` and `log((1/N) sum exp(a))`, the shifted
    /// log-mean-exp parts.
    fn softmax(&self, eta: f64, v: &DVectorView<f64>, scratch: &mut Scratch) -> (f64, f64) {
        let Scratch {
            baseline, shifted, p, ..
        } = scratch;
        baseline.gemv(1.0, self.phi, v, 0.0);
        let residuals = baseline.as_mut_slice();
        for (b, r) in residuals.iter_mut().zip(self.returns.as_slice()) {
            *b = r - *b;
        }
        // `>=` as in nalgebra's `max`, which this used before: the same bits for every input.
        let max_r = residuals
            .iter()
            .copied()
            .reduce(|a, b| if a >= b { a } else { b })
            .expect("the dual has samples");
        for (a, r) in shifted.iter_mut().zip(residuals.iter()) {
            *a = (r - max_r) / eta;
        }
        let exps = p.as_mut_slice();
        for (e, a) in exps.iter_mut().zip(shifted.iter()) {
            *e = a.exp();
        }
        let total: f64 = exps.iter().sum();
        let log_mean = (total / exps.len() as f64).ln();
        exps.iter_mut().for_each(|e| *e /= total);
        (max_r, log_mean)
    }

    /// g at `x = (eta, v)`; writes the gradient into `gradient`.
    ///
    /// `eta LSE(A) = max_r + eta log_mean` avoids multiplying a huge `max A` back by a tiny eta.
    fn evaluate(&self, x: &DVector<f64>, gradient: &mut DVector<f64>, scratch: &mut Scratch) -> f64 {
        let eta = x[0];
        let v = x.rows(1, x.len() - 1);
        let (max_r, log_mean) = self.softmax(eta, &v, scratch);
        let Scratch {
            shifted, p, matched, ..
        } = scratch;
        // p_i = 0 terms are skipped: their shifted A_i may be -inf.
        let p_dot_a: f64 = p
            .as_slice()
            .iter()
            .zip(shifted.iter())
            .filter(|&(&pi, _)| pi > 0.0)
            .map(|(pi, a)| pi * a)
            .sum();
        gradient[0] = self.epsilon + log_mean - p_dot_a;
        self.phi.tr_mul_to(p, matched);
        for (g, (mean, weighted)) in gradient
            .as_mut_slice()
            .iter_mut()
            .skip(1)
            .zip(self.phi_mean.as_slice().iter().zip(matched.as_slice()))
        {
            *g = mean - weighted;
        }
        eta * self.epsilon + v.dot(&self.phi_mean) + max_r + eta * log_mean
    }
}

/// The buffers of one evaluation of the dual, reused by every evaluation of a solve (tens per
/// C-REPS update): an evaluation allocates nothing, which made an update of the grid problem
/// 2.8% faster (`cargo bench -p acps-bench --bench learner -- creps_update`).
struct Scratch {
    /// `Phi v`, then the residuals `R - Phi v` in place.
    baseline: DVector<f64>,
    /// `A - max A`.
    shifted: Vec<f64>,
    /// The softmax weights.
    p: DVector<f64>,
    /// `Phi^T p`.
    matched: DVector<f64>,
}

impl Scratch {
    fn new(n: usize, n_phi: usize) -> Self {
        Self {
            baseline: DVector::zeros(n),
            shifted: vec![0.0; n],
            p: DVector::zeros(n),
            matched: DVector::zeros(n_phi),
        }
    }
}

fn check_options(options: &DualOptions) -> Result<(), CRepsError> {
    check_non_negative("pgtol", options.pgtol)?;
    check_non_negative("factr", options.factr)?;
    check_at_least_one("max_iterations", options.max_iterations)?;
    check_at_least_one("memory", options.memory)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::StandardNormal;

    fn linspace(a: f64, b: f64, n: usize) -> Vec<f64> {
        (0..n).map(|i| a + (b - a) * i as f64 / (n - 1) as f64).collect()
    }

    /// Rows `(x_i, 1)` or `(x_i^2, x_i, 1)`.
    fn polynomial_features(x: &[f64], degree: i32) -> DMatrix<f64> {
        DMatrix::from_fn(x.len(), degree as usize + 1, |i, j| x[i].powi(degree - j as i32))
    }

    fn tight() -> DualOptions {
        DualOptions {
            pgtol: 1e-9,
            factr: 0.0,
            ..DualOptions::default()
        }
    }

    /// A random problem: `n_features` standard-normal features plus a constant, returns on
    /// the scale `scale`.
    fn random_problem(seed: u64, n: usize, n_features: usize, scale: f64) -> (DMatrix<f64>, Vec<f64>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let phi = DMatrix::from_fn(n, n_features + 1, |_, j| {
            if j == n_features {
                1.0
            } else {
                rng.sample(StandardNormal)
            }
        });
        let returns = (0..n).map(|_| scale * rng.sample::<f64, _>(StandardNormal)).collect();
        (phi, returns)
    }

    #[test]
    fn gradient_matches_central_differences() {
        for seed in 0..5 {
            let (phi, returns) = random_problem(seed, 30, 3, 2.0);
            let dual = Dual::new(&phi, &returns, 0.7);
            let mut rng = ChaCha8Rng::seed_from_u64(100 + seed);
            let x = DVector::from_fn(5, |i, _| {
                if i == 0 {
                    rng.random_range(0.2..3.0)
                } else {
                    rng.random_range(-2.0..2.0)
                }
            });
            let mut buffers = Scratch::new(30, 4);
            let mut gradient = DVector::zeros(5);
            dual.evaluate(&x, &mut gradient, &mut buffers);
            let mut scratch = DVector::zeros(5);
            for i in 0..5 {
                let h = 1e-6;
                let mut up = x.clone();
                up[i] += h;
                let mut down = x.clone();
                down[i] -= h;
                let numeric = (dual.evaluate(&up, &mut scratch, &mut buffers)
                    - dual.evaluate(&down, &mut scratch, &mut buffers))
                    / (2.0 * h);
                assert!(
                    (numeric - gradient[i]).abs() < 1e-7 * (1.0 + numeric.abs()),
                    "seed {seed}, component {i}: analytic {} vs numeric {numeric}",
                    gradient[i]
                );
            }
        }
    }

    #[test]
    fn objective_is_stable_for_tiny_eta_and_huge_returns() {
        let (phi, returns) = random_problem(3, 20, 1, 1e6);
        let dual = Dual::new(&phi, &returns, 0.5);
        let mut gradient = DVector::zeros(3);
        let f = dual.evaluate(
            &DVector::from_vec(vec![1e-8, 0.0, 0.0]),
            &mut gradient,
            &mut Scratch::new(20, 2),
        );
        // eta LSE -> max_i R_i as eta -> 0.
        let max_return = returns.iter().cloned().fold(f64::MIN, f64::max);
        assert!((f - max_return).abs() < 1e-6 * max_return.abs());
        assert!(gradient.iter().all(|g| g.is_finite()));
    }

    /// Notes section 1.2: a NumPy re-run of BOLeRo's dual (scipy L-BFGS-B with defaults).
    #[test]
    fn reproduces_the_reference_solution() {
        let x = linspace(-1.0, 1.0, 11);
        let phi = polynomial_features(&x, 1);
        let returns: Vec<f64> = x.iter().map(|x| (3.0 * x).sin() - x * x).collect();
        let solution = solve_dual(&phi, &returns, 0.5, 1e-8, &DualOptions::default()).unwrap();
        assert!(solution.converged);
        assert!((solution.eta - 0.341885).abs() < 1e-4, "{}", solution.eta);
        assert!((solution.v[0] - 1.227724).abs() < 1e-4, "{}", solution.v);
        // The constant feature's coefficient lies on a flat direction and stays at its start.
        assert!((solution.v[1] - 1.0).abs() < 1e-12, "{}", solution.v);
        assert!((solution.objective - 0.08925233).abs() < 1e-6);
        assert!((solution.kl - 0.5).abs() < 1e-5, "{}", solution.kl);
        let expected = [
            0.1487, 0.04355, 0.02013, 0.01991, 0.04038, 0.1154, 0.2612, 0.2626, 0.08061, 0.007241, 0.000258,
        ];
        for (d, want) in solution.weights.iter().zip(expected) {
            assert!((d - want).abs() < 1e-3, "{} vs {want}", solution.weights);
        }
        assert!((solution.weights.sum() - 1.0).abs() < 1e-12);
        let residual = feature_matching_residual(&phi, solution.weights.as_slice());
        assert!(residual.amax() < 1e-5, "{residual}");
    }

    /// Off the bound, KL = eps and the features are matched: the gradient components are exactly
    /// `eps - KL` and `-residual`. How small they get is limited by the objective's resolution,
    /// not by `pgtol`: a step whose effect on g (~|grad|^2 / curvature) is below ~1e-16 |g|
    /// yields no decrease, and the search stops there; on these problems that is at |grad| of
    /// about 1e-8 (worst seen 1.2e-8), so we allow 1e-7. On the bound the eta-derivative
    /// `eps - KL` must be >= 0 (up to the same tolerance) and nothing is claimed about the
    /// residual: g is nearly piecewise linear in v for eta = 1e-8.
    #[test]
    fn random_problems_satisfy_the_optimality_conditions() {
        let mut off_bound = 0;
        for seed in 0..12 {
            let n = [10, 40, 150][seed as usize % 3];
            let scale = [0.01, 1.0, 100.0][seed as usize / 3 % 3];
            let (phi, returns) = random_problem(seed, n, 2, scale);
            let epsilon = [0.1, 0.5, 1.0, 2.0][seed as usize % 4];
            let solution = solve_dual(&phi, &returns, epsilon, 1e-8, &tight()).unwrap();
            assert!(solution.converged, "seed {seed}");
            if solution.eta > 1e-8 {
                off_bound += 1;
                let residual = feature_matching_residual(&phi, solution.weights.as_slice());
                assert!(residual.amax() <= 1e-7, "seed {seed}: {residual}");
                assert!((solution.kl - epsilon).abs() <= 1e-7, "seed {seed}: {}", solution.kl);
            } else {
                assert!(solution.kl <= epsilon + 1e-7, "seed {seed}: {}", solution.kl);
            }
            // scipy's default stopping rules end close to the tight optimum: they stop once a
            // step reduces g by <= 2.2e-9 relative, and convergence is superlinear by then
            // (largest gap seen: 5e-9 relative).
            let default = solve_dual(&phi, &returns, epsilon, 1e-8, &DualOptions::default()).unwrap();
            let gap = default.objective - solution.objective;
            assert!(
                (-1e-12..1e-7 * solution.objective.abs().max(1.0)).contains(&gap),
                "seed {seed}: gap {gap}"
            );
        }
        assert!(off_bound >= 6, "only {off_bound} problems had eta off its bound");
    }

    /// BOLeRo's `test_baseline_overestimates`: R is exactly representable, the KL bound is
    /// inactive, eta sits on its bound and the baseline covers every return.
    #[test]
    fn baseline_overestimates_when_eta_is_on_its_bound() {
        let x = linspace(0.0, 1.0, 11);
        let phi = polynomial_features(&x, 2);
        let returns: Vec<f64> = x.iter().map(|x| 10.0 * (x - 0.3).powi(2)).collect();
        let solution = solve_dual(&phi, &returns, 1.0, 1e-6, &DualOptions::default()).unwrap();
        assert_eq!(solution.eta, 1e-6);
        let baseline = &phi * &solution.v;
        for (b, r) in baseline.iter().zip(&returns) {
            assert!(b >= r, "baseline {b} < return {r}");
        }
        assert!(solution.weights.iter().all(|&d| d >= 0.0));
        assert!((solution.weights.sum() - 1.0).abs() < 1e-7);
    }

    #[test]
    fn kl_helper_matches_hand_values() {
        assert_eq!(kl_to_uniform(&[0.25; 4]), 0.0);
        assert!((kl_to_uniform(&[1.0, 0.0]) - 2f64.ln()).abs() < 1e-15);
        assert!((kl_to_uniform(&[0.75, 0.25]) - (0.75 * 1.5f64.ln() + 0.25 * 0.5f64.ln())).abs() < 1e-15);
    }

    #[test]
    fn bad_inputs_are_errors_naming_the_argument() {
        let x = linspace(-1.0, 1.0, 11);
        let phi = polynomial_features(&x, 1);
        let returns = vec![0.0; 10];
        let error = solve_dual(&phi, &returns, 0.5, 1e-8, &DualOptions::default()).unwrap_err();
        assert_eq!(
            error.to_string(),
            "the number of phi rows (11) must equal the number of returns (10)"
        );
        let returns = vec![0.0; 11];
        let message = |epsilon, eta_min, options: &DualOptions| {
            solve_dual(&phi, &returns, epsilon, eta_min, options)
                .unwrap_err()
                .to_string()
        };
        let defaults = DualOptions::default();
        assert_eq!(message(-1.0, 1e-8, &defaults), "epsilon must be finite and > 0, got -1");
        assert!(message(0.5, 0.0, &defaults).starts_with("eta_min must be"));
        let bad_pgtol = DualOptions {
            pgtol: f64::NAN,
            ..DualOptions::default()
        };
        assert!(message(0.5, 1e-8, &bad_pgtol).starts_with("pgtol must be"));
        let no_memory = DualOptions {
            memory: 0,
            ..DualOptions::default()
        };
        assert!(message(0.5, 1e-8, &no_memory).starts_with("memory must be"));
        let mut nan_returns = returns.clone();
        nan_returns[3] = f64::NAN;
        let error = solve_dual(&phi, &nan_returns, 0.5, 1e-8, &defaults).unwrap_err();
        assert_eq!(error.to_string(), "returns must be finite, got NaN at index 3");
        let empty = DMatrix::zeros(0, 2);
        assert!(solve_dual(&empty, &[], 0.5, 1e-8, &defaults).is_err());
    }
}
