//! The C-REPS dual (P Alg. 2 line 7), solved to its optimum whatever the units of the returns.
//!
//! With `phi_bar` the mean feature vector, the dual is
//!
//! `g(eta, v) = eta eps + v^T phi_bar + eta log( (1/N) sum_i exp((R_i - v^T phi_i) / eta) )`
//!
//! over `eta >= eta_min` and free `v`; the sample weights are `d = softmax((R - Phi v) / eta)`.
//! Its gradient is `dg/deta = eps - KL(d || uniform)` and `dg/dv = phi_bar - sum_i d_i phi_i`, so
//! at the optimum the KL bound holds with equality (unless eta sits on its bound) and the
//! weighted features match the sample mean.
//!
//! # How it is solved
//! 1. **The flat directions go.** `g` depends on `v` only through the centred baseline
//!    `(Phi - 1 phi_bar^T) v`: the constant feature, and any combination of features that is
//!    constant over the samples, change nothing. So `v` is replaced by coordinates `u` in an
//!    orthonormal basis of the centred features' column space (a thin SVD, rank-revealing),
//!    scaled to unit root mean square. The problem no longer depends on how the features are
//!    scaled or how ill-conditioned they are (polar-quadratic features of the PA-10 targets:
//!    ~1e7).
//! 2. **The units go.** With `R = m + s R~` (m the mean and s the standard deviation of the
//!    returns), `eta = s eta~` and a baseline scaled by s, `g = m + s g~(eta~, u)`, where `g~` is
//!    the same dual on the standardised returns `R~`. The weights depend on `(eta~, u)` only, and
//!    the bound is relative too (`eta >= eta_min s`), so the whole update is invariant to
//!    `R -> a R + b`, a > 0.
//! 3. **Newton with the exact Hessian.** `g~` is jointly convex, with Hessian
//!    `(1/eta~) Cov_d([A, Q])`, the `d`-weighted covariance of the scaled residuals
//!    `A_i = (R~_i - q_i^T u) / eta~` and the basis rows `q_i`: 1 + rank(features) variables, cheap
//!    to form and to factorise. Each step eliminates u through the Schur complement, takes the
//!    Newton step on `h(eta~) = min_u g~`, whose derivative is `eps - KL`, and moves u with it
//!    (see `Step::new`). Where the dual is far from its quadratic model (it is exponential in
//!    u / eta~) the steps are kept short: eta~ moves by at most a factor 8 and waits while u is
//!    far from its optimum for the current eta~, and a backtracking line search on `g~` does the
//!    rest (a step may change no sample's log-weight by more than 1000 through u, a guard against
//!    unbounded steps where the Hessian is nearly singular). When the KL bound is slack, eta~
//!    thus follows the path of optima down to its bound, like an interior-point method, and
//!    stops exactly on it.
//!
//! It stops when the projected gradient of `g~` (dimensionless: `eps - KL` for eta~, zero when
//! eta~ is on its bound and the KL bound is slack, and the feature-matching residual in the
//! basis for u) has an inf-norm of at most [`DualOptions::tolerance`], or of what double
//! precision allows at that eta~, `1e-15 / eta~` (the rounding of the residuals, divided by
//! eta~, is the precision of the log-weights). A solve takes 5-10 Newton steps when the KL bound
//! is active and 15-40 when eta~ must follow the path to a bound of 1e-5.

use nalgebra::{Cholesky, DMatrix, DVector, Dyn, SVD};
use serde::{Deserialize, Serialize};

use crate::stop::{Never, Stop};

use super::error::{
    DualEvaluateError, DualSolveError, InvalidValue, check_at_least_one, check_finite, check_len, check_positive,
    check_range,
};

/// The largest factor by which one step on the path may raise or lower eta.
pub(super) const ETA_STEP_FACTOR: f64 = 8.0;

/// Step halvings of one backtracking line search before the point counts as optimal.
pub(super) const MAX_HALVINGS: usize = 40;

/// The largest change of a sample's log-weight `(R~_i - q_i^T u) / eta` through u that a step
/// may try: where the weights sit on too few samples to span every direction of u, the Newton
/// step along a direction without curvature is unbounded. Only a guard: good steps change
/// log-weights by up to a few hundred (when eta falls by 8 on a steep path), so a smaller bound
/// slowed those solves down, sometimes past the iteration cap; the line search shortens what is
/// too long.
pub(super) const MAX_LOG_WEIGHT_CHANGE: f64 = 1000.0;

/// The Newton decrement of u, in units of eta, above which eta waits for u (see [`Step::new`]).
pub(super) const CENTRING: f64 = 0.1;

/// The default `eta_min`, relative to the returns' standard deviation: within the paper's
/// 1e-6..1e-4, and large enough that the log-weights keep 10 significant digits there.
pub const DEFAULT_ETA_MIN: f64 = 1e-5;

/// Accepted `eta_min` (relative to the returns' standard deviation): below 1e-8 the log-weights
/// carry less than 7 significant digits (see `ROUNDING`); above 1 the floor would override
/// the KL bound for any epsilon above about 0.5.
pub const ETA_MIN_RANGE: (f64, f64) = (1e-8, 1.0);

/// The rounding of a standardised residual: the log-weights `residual / eta~`, and with them the
/// gradient, are known to about `ROUNDING / eta~`.
pub(super) const ROUNDING: f64 = 1e-15;

/// Accepted [`DualOptions::tolerance`]: below 1e-14 rounding can keep the gradient above it.
pub const TOLERANCE_RANGE: (f64, f64) = (1e-14, 1e-3);

/// Solver settings for [`solve_dual`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DualOptions {
    /// Stop when the projected gradient of the standardised dual has an inf-norm of at most this
    /// (default 1e-10), within [`TOLERANCE_RANGE`].
    pub tolerance: f64,
    /// Iteration cap (default 100; a solve takes 5-45 Newton steps). A solve that reaches it is
    /// reported as not converged.
    pub max_iterations: usize,
}

impl Default for DualOptions {
    fn default() -> Self {
        Self {
            tolerance: 1e-10,
            max_iterations: 100,
        }
    }
}

/// The minimiser of the dual and the sample weights it implies.
#[derive(Clone, Debug, PartialEq)]
pub struct DualSolution {
    /// The temperature eta, in the returns' units (>= `eta_min` times their standard deviation).
    pub eta: f64,
    /// Whether eta sits on its lower bound (the KL bound is then slack: even the greediest
    /// weighting the features allow stays within epsilon).
    pub eta_at_bound: bool,
    /// Baseline coefficients v (one per feature), in the returns' units. The dual is flat along
    /// the constant feature (and any combination of features constant over the samples); the
    /// minimum-norm v is returned.
    pub v: DVector<f64>,
    /// `d = softmax((R - Phi v) / eta)`; sums to 1.
    pub weights: DVector<f64>,
    /// `g(eta, v)`, in the returns' units.
    pub objective: f64,
    /// `KL(d || uniform)` (= epsilon when eta is off its bound).
    pub kl: f64,
    /// The inf-norm of the standardised dual's projected gradient at the returned point.
    pub optimality: f64,
    /// Newton iterations.
    pub iterations: usize,
    /// Whether the optimality reached the tolerance (or, for eta below 1e-5 times the returns'
    /// standard deviation, what double precision allows there) within the iteration cap.
    pub converged: bool,
}

/// The dual's value and gradient at one point, from [`evaluate_dual`].
#[derive(Clone, Debug, PartialEq)]
pub struct DualValue {
    /// `g(eta, v)`.
    pub value: f64,
    /// `(dg/deta, dg/dv_0, ..., dg/dv_{n_phi - 1})`.
    pub gradient: DVector<f64>,
}

/// Minimises the C-REPS dual over `eta >= eta_min s` and free `v`, s being the standard
/// deviation of `returns`.
///
/// `phi` holds one feature vector per row (N x n_phi), `returns` the N returns. Errors if the
/// inputs are inconsistent or not finite, or a setting is out of its range. Returns that are all
/// equal (to rounding) carry no preference: the weights are then uniform, eta is 0 and on its
/// bound.
///
/// ```
/// use acps_learner::creps::{DualOptions, solve_dual};
/// use nalgebra::DMatrix;
///
/// // Features (s, 1) of five contexts, and returns in any units.
/// let phi = DMatrix::from_row_slice(5, 2, &[-1.0, 1.0, -0.5, 1.0, 0.0, 1.0, 0.5, 1.0, 1.0, 1.0]);
/// let returns = [-3.0, -1.0, 0.0, -2.0, -0.5];
/// let solution = solve_dual(&phi, &returns, 0.5, 1e-8, &DualOptions::default()).unwrap();
/// assert!(solution.converged && !solution.eta_at_bound);
/// assert!((solution.kl - 0.5).abs() < 1e-9);
/// assert!((solution.weights.sum() - 1.0).abs() < 1e-12);
/// ```
pub fn solve_dual(
    phi: &DMatrix<f64>,
    returns: &[f64],
    epsilon: f64,
    eta_min: f64,
    options: &DualOptions,
) -> Result<DualSolution, DualSolveError> {
    check_data(phi, returns)?;
    if returns.is_empty() {
        return Err(DualSolveError::NoSamples);
    }
    let Ok(solution) = solve_valid(phi, returns, epsilon, eta_min, options, Never);
    Ok(solution?)
}

/// [`solve_dual`] on data known to be consistent and finite (a [`Batch`](super::Batch)'s).
pub(crate) fn solve_valid<S: Stop>(
    phi: &DMatrix<f64>,
    returns: &[f64],
    epsilon: f64,
    eta_min: f64,
    options: &DualOptions,
    stop: S,
) -> Result<Result<DualSolution, InvalidValue>, S::Halt> {
    let checked = check_positive("epsilon", epsilon)
        .and_then(|()| check_eta_min(eta_min))
        .and_then(|()| check_options(options));
    if let Err(invalid) = checked {
        return Ok(Err(invalid));
    }
    let n = returns.len();
    let Some(problem) = Standardised::new(phi, returns, epsilon) else {
        // Equal returns: any eta gives uniform weights with v = 0, and g = m + eta eps is least
        // at eta = 0.
        return Ok(Ok(DualSolution {
            eta: 0.0,
            eta_at_bound: true,
            v: DVector::zeros(phi.ncols()),
            weights: DVector::from_element(n, 1.0 / n as f64),
            objective: returns.iter().sum::<f64>() / n as f64,
            kl: 0.0,
            optimality: 0.0,
            iterations: 0,
            converged: true,
        }));
    };
    let newton = problem.minimise(eta_min, options, stop)?;
    let weights = newton.weights;
    Ok(Ok(DualSolution {
        eta: problem.scale * newton.eta,
        eta_at_bound: newton.eta <= eta_min,
        v: &problem.to_v * &newton.u * problem.scale,
        kl: kl_to_uniform(weights.as_slice()),
        weights,
        objective: problem.mean + problem.scale * newton.value,
        optimality: newton.optimality,
        iterations: newton.iterations,
        converged: newton.optimality <= attainable(options.tolerance, newton.eta),
    }))
}

/// The dual `g(eta, v)` and its gradient at one point, in the returns' units (computed with a
/// shifted log-sum-exp, so a tiny eta and huge returns stay finite).
///
/// ```
/// use acps_learner::creps::{DualOptions, evaluate_dual, solve_dual};
/// use nalgebra::DMatrix;
///
/// let phi = DMatrix::from_row_slice(4, 2, &[0.0, 1.0, 1.0, 1.0, 2.0, 1.0, 3.0, 1.0]);
/// let returns = [1.0, 3.0, 2.0, 0.0];
/// let optimum = solve_dual(&phi, &returns, 0.3, 1e-5, &DualOptions::default()).unwrap();
/// assert!(!optimum.eta_at_bound);
/// let at_optimum = evaluate_dual(&phi, &returns, 0.3, optimum.eta, optimum.v.as_slice()).unwrap();
/// assert!((at_optimum.value - optimum.objective).abs() < 1e-12);
/// // The optimum: KL = epsilon and the features matched.
/// assert!(at_optimum.gradient.amax() < 1e-9);
/// ```
pub fn evaluate_dual(
    phi: &DMatrix<f64>,
    returns: &[f64],
    epsilon: f64,
    eta: f64,
    v: &[f64],
) -> Result<DualValue, DualEvaluateError> {
    check_positive("epsilon", epsilon)?;
    check_positive("eta", eta)?;
    check_data(phi, returns)?;
    if returns.is_empty() {
        return Err(DualEvaluateError::NoSamples);
    }
    check_len("the length of v", v.len(), "the number of phi columns", phi.ncols())?;
    check_finite("v", v)?;
    let v = DVector::from_column_slice(v);
    let residuals = DVector::from_column_slice(returns) - phi * &v;
    let mut softmax = Softmax::new(returns.len());
    let (max_r, log_mean) = softmax.compute(&residuals, eta);
    let phi_mean = phi.row_mean().transpose();
    let mut gradient = DVector::zeros(1 + phi.ncols());
    gradient[0] = epsilon - softmax.kl(log_mean);
    gradient
        .rows_mut(1, phi.ncols())
        .copy_from(&(&phi_mean - phi.tr_mul(&softmax.p)));
    Ok(DualValue {
        value: eta * epsilon + v.dot(&phi_mean) + max_r + eta * log_mean,
        gradient,
    })
}

/// `KL(d || uniform) = sum_i d_i ln(N d_i)` for weights `d` that sum to 1 (`0 ln 0 = 0`).
pub fn kl_to_uniform(weights: &[f64]) -> f64 {
    let n = weights.len() as f64;
    weights.iter().filter(|&&d| d > 0.0).map(|&d| d * (n * d).ln()).sum()
}

/// The effective sample size `1 / sum_i d_i^2` of weights `d` that sum to 1: N for uniform
/// weights, 1 when one sample carries all the weight.
pub fn effective_sample_size(weights: &[f64]) -> f64 {
    1.0 / weights.iter().map(|d| d * d).sum::<f64>()
}

/// The feature-matching residual `sum_i d_i phi_i - phi_bar` (rows of `phi` are the `phi_i`,
/// `phi_bar` their plain mean); zero at an optimum of the dual.
pub fn feature_matching_residual(phi: &DMatrix<f64>, weights: &[f64]) -> DVector<f64> {
    phi.tr_mul(&DVector::from_column_slice(weights)) - phi.row_mean().transpose()
}

/// The optimality a solve can reach at `eta~`.
fn attainable(tolerance: f64, eta: f64) -> f64 {
    tolerance.max(ROUNDING / eta)
}

pub(crate) fn check_eta_min(eta_min: f64) -> Result<(), InvalidValue> {
    check_range("eta_min", eta_min, ETA_MIN_RANGE)
}

pub(super) fn check_options(options: &DualOptions) -> Result<(), InvalidValue> {
    check_range("tolerance", options.tolerance, TOLERANCE_RANGE)?;
    check_at_least_one("max_iterations", options.max_iterations)
}

/// Consistent, finite data (perhaps empty: each caller has its own error for that).
pub(super) fn check_data(phi: &DMatrix<f64>, returns: &[f64]) -> Result<(), InvalidValue> {
    check_len(
        "the number of phi rows",
        phi.nrows(),
        "the number of returns",
        returns.len(),
    )?;
    check_finite("returns", returns)?;
    check_finite("phi", phi.as_slice())
}

/// Softmax weights of `r / eta`, computed after subtracting `max r`.
pub(super) struct Softmax {
    /// `(r_i - max r) / eta` (<= 0).
    pub(super) shifted: DVector<f64>,
    /// The weights.
    pub(super) p: DVector<f64>,
}

impl Softmax {
    pub(super) fn new(n: usize) -> Self {
        Self {
            shifted: DVector::zeros(n),
            p: DVector::zeros(n),
        }
    }

    /// Fills the weights of `residuals / eta`; returns `max r` and `log((1/N) sum exp(shifted))`,
    /// so that `eta LSE(r / eta) = max r + eta log_mean` without multiplying a huge `max r / eta`
    /// back by a tiny eta.
    pub(super) fn compute(&mut self, residuals: &DVector<f64>, eta: f64) -> (f64, f64) {
        let max_r = residuals.max();
        for ((a, p), r) in self.shifted.iter_mut().zip(self.p.iter_mut()).zip(residuals.iter()) {
            *a = (r - max_r) / eta;
            *p = a.exp();
        }
        let total = self.p.sum();
        self.p /= total;
        (max_r, (total / residuals.len() as f64).ln())
    }

    /// `sum_i p_i a_i`, skipping `p_i = 0` terms (whose `a_i` may be -inf).
    pub(super) fn mean_shifted(&self) -> f64 {
        self.p
            .iter()
            .zip(self.shifted.iter())
            .filter(|&(&p, _)| p > 0.0)
            .map(|(p, a)| p * a)
            .sum()
    }

    /// `KL(p || uniform) = sum_i p_i a_i - log_mean`.
    pub(super) fn kl(&self, log_mean: f64) -> f64 {
        self.mean_shifted() - log_mean
    }
}

/// The dual on standardised returns in an orthonormal basis of the centred features.
pub(super) struct Standardised {
    pub(super) epsilon: f64,
    /// `(R - m) / s`.
    pub(super) returns: DVector<f64>,
    /// N x k, orthogonal columns with mean 0 and root mean square 1 spanning the centred
    /// features' columns.
    pub(super) basis: DMatrix<f64>,
    /// m.
    pub(super) mean: f64,
    /// s.
    pub(super) scale: f64,
    /// n_phi x k: `v = s to_v u` is the minimum-norm v whose centred baseline is `s basis u`.
    pub(super) to_v: DMatrix<f64>,
}

impl Standardised {
    /// `None` when the returns are all equal to rounding.
    pub(super) fn new(phi: &DMatrix<f64>, returns: &[f64], epsilon: f64) -> Option<Self> {
        let (returns, mean, scale) = standardise(returns)?;
        let (basis, to_v) = centred_basis(phi);
        Some(Self {
            epsilon,
            returns,
            basis,
            mean,
            scale,
            to_v,
        })
    }

    pub(super) fn rank(&self) -> usize {
        self.basis.ncols()
    }

    /// Path following on eta with Newton steps (see the module documentation).
    fn minimise<S: Stop>(&self, eta_min: f64, options: &DualOptions, stop: S) -> Result<Newton, S::Halt> {
        let mut scratch = Scratch::new(self.returns.len(), self.rank());
        let mut steps = 0;
        let (eta, u) = self.start(eta_min);
        let mut current = self.evaluate(eta, u, &mut scratch);
        let optimality = loop {
            let optimality = current.optimality(eta_min);
            if optimality <= attainable(options.tolerance, current.eta) || steps >= options.max_iterations {
                break optimality;
            }
            stop.check()?;
            steps += 1;
            // The scratch holds the evaluation of `current`: the start, or the step accepted last.
            let hessian = scratch.hessian(&self.basis, current.eta);
            let newton = Step::new(&current, &hessian, eta_min);
            // Should the Newton step find no decrease, steepest descent in u (log-weight
            // changes of the gradient's size) is tried before the point counts as optimal.
            let descent = || Step {
                eta: current.eta,
                u: -&current.gradient_u * current.eta,
            };
            let found = self
                .search(&current, &newton, &mut scratch)
                .or_else(|| self.search(&current, &descent(), &mut scratch));
            match found {
                Some(next) => current = next,
                None => {
                    // No decrease along a descent direction: the optimum to rounding. The
                    // scratch holds the last trial, so evaluate the point again for its weights.
                    current = self.evaluate(current.eta, current.u, &mut scratch);
                    break current.optimality(eta_min);
                }
            }
        };
        Ok(Newton {
            weights: scratch.softmax.p.clone(),
            eta: current.eta,
            u: current.u,
            value: current.value,
            optimality,
            iterations: steps,
        })
    }

    /// A backtracking line search along `step` from `point`: the first of the step (shortened
    /// so that no sample's log-weight moves by more than [`MAX_LOG_WEIGHT_CHANGE`] through u),
    /// its half, quarter, ... that decreases the dual sufficiently (Armijo), or does not
    /// increase it when the decrease is below what the objective can resolve. The scratch then
    /// holds its evaluation.
    fn search(&self, point: &Point, step: &Step, scratch: &mut Scratch) -> Option<Point> {
        let slope = point.gradient_eta * (step.eta - point.eta) + point.gradient_u.dot(&step.u);
        let stretch = (&self.basis * &step.u).amax() / point.eta;
        let first = (MAX_LOG_WEIGHT_CHANGE / stretch).min(1.0);
        backtrack(point.value, slope, first, |fraction| {
            let eta = if fraction == 1.0 {
                step.eta
            } else {
                point.eta + fraction * (step.eta - point.eta)
            };
            let trial = self.evaluate(eta, &point.u + &step.u * fraction, scratch);
            (trial.value, trial)
        })
    }

    /// The least-squares baseline, and the eta at which the weights of its residuals `e` would
    /// have KL = epsilon to second order (`KL ~ Var(e) / (2 eta^2)`).
    pub(super) fn start(&self, eta_min: f64) -> (f64, DVector<f64>) {
        let n = self.returns.len() as f64;
        let u = self.basis.tr_mul(&self.returns) / n;
        let residuals = &self.returns - &self.basis * &u;
        let spread = (residuals.norm_squared() / n).sqrt();
        ((spread / (2.0 * self.epsilon).sqrt()).max(eta_min), u)
    }

    pub(super) fn evaluate(&self, eta: f64, u: DVector<f64>, scratch: &mut Scratch) -> Point {
        scratch.residuals.copy_from(&self.returns);
        scratch.residuals.gemv(-1.0, &self.basis, &u, 1.0);
        let (max_r, log_mean) = scratch.softmax.compute(&scratch.residuals, eta);
        scratch.matched.gemv_tr(1.0, &self.basis, &scratch.softmax.p, 0.0);
        Point {
            eta,
            value: eta * self.epsilon + max_r + eta * log_mean,
            gradient_eta: self.epsilon - scratch.softmax.kl(log_mean),
            gradient_u: -&scratch.matched,
            u,
        }
    }
}

/// `(R - m) / s`, m and s: the returns standardised by their mean and population standard
/// deviation, or `None` when they are all equal to rounding.
pub(super) fn standardise(returns: &[f64]) -> Option<(DVector<f64>, f64, f64)> {
    let n = returns.len();
    // Dividing by the largest magnitude first keeps squares finite for any finite returns.
    let largest = returns.iter().fold(0.0f64, |m, r| m.max(r.abs()));
    if largest == 0.0 {
        return None;
    }
    let unit = DVector::from_iterator(n, returns.iter().map(|r| r / largest));
    let unit_mean = unit.mean();
    let centred = unit.add_scalar(-unit_mean);
    let unit_std = (centred.norm_squared() / n as f64).sqrt();
    // Entries are in [-1, 1], each rounded by up to one ulp: a smaller spread is rounding.
    if unit_std <= 4.0 * f64::EPSILON {
        return None;
    }
    Some((centred / unit_std, unit_mean * largest, unit_std * largest))
}

/// A backtracking line search: `trial(fraction)` evaluates the point a `fraction` of the way
/// along a step whose directional derivative (the step's `slope`) is taken at a point of value
/// `value`, starting at `first` and halving up to [`MAX_HALVINGS`] times. Returns the first trial
/// that decreases the value sufficiently (Armijo), or does not increase it when the decrease is
/// below what the value can resolve.
pub(super) fn backtrack<P>(value: f64, slope: f64, first: f64, mut trial: impl FnMut(f64) -> (f64, P)) -> Option<P> {
    let resolution = 1e-14 * (1.0 + value.abs());
    let mut fraction = first;
    for _ in 0..MAX_HALVINGS {
        let (trial_value, point) = trial(fraction);
        let sufficient = trial_value <= value + 1e-4 * fraction * slope;
        let unresolved = -fraction * slope <= resolution && trial_value <= value + resolution;
        if sufficient || unresolved {
            return Some(point);
        }
        fraction /= 2.0;
    }
    None
}

/// An orthogonal basis of the column space of `phi - 1 phi_bar^T`, scaled to root mean square 1
/// per column (N x k), and the n_phi x k map from coordinates in it to the minimum-norm v. Left
/// singular vectors whose singular value is below `max(N, n_phi) eps sigma` are left out as
/// rounding (numpy's rank rule), with sigma the larger of the centred matrix's largest singular
/// value and `sqrt(N) max |phi|`: centring a constant column leaves rounding of that size.
fn centred_basis(phi: &DMatrix<f64>) -> (DMatrix<f64>, DMatrix<f64>) {
    let (n, n_phi) = phi.shape();
    let mean = phi.row_mean();
    let mut centred = phi.clone();
    for mut row in centred.row_iter_mut() {
        row -= &mean;
    }
    let svd = SVD::new(centred, true, true);
    let (left, right) = (svd.u.expect("requested"), svd.v_t.expect("requested").transpose());
    let reference = svd.singular_values.max().max((n as f64).sqrt() * phi.amax());
    let cutoff = n.max(n_phi) as f64 * f64::EPSILON * reference;
    let kept: Vec<usize> = (0..svd.singular_values.len())
        .filter(|&j| svd.singular_values[j] > cutoff)
        .collect();
    let root_n = (n as f64).sqrt();
    let basis = DMatrix::from_fn(n, kept.len(), |i, j| left[(i, kept[j])] * root_n);
    let to_v = DMatrix::from_fn(n_phi, kept.len(), |i, j| {
        right[(i, kept[j])] * root_n / svd.singular_values[kept[j]]
    });
    (basis, to_v)
}

/// Buffers of one solve, reused by every evaluation.
pub(super) struct Scratch {
    pub(super) residuals: DVector<f64>,
    pub(super) softmax: Softmax,
    /// `basis^T p`.
    pub(super) matched: DVector<f64>,
    /// `sqrt(p_i) ([A_i, q_i] - their weighted mean)`, N x (1 + k).
    centred: DMatrix<f64>,
}

impl Scratch {
    pub(super) fn new(n: usize, k: usize) -> Self {
        Self {
            residuals: DVector::zeros(n),
            softmax: Softmax::new(n),
            matched: DVector::zeros(k),
            centred: DMatrix::zeros(n, 1 + k),
        }
    }

    /// `(1/eta) Cov_p([A, q])` at the point last evaluated.
    pub(super) fn hessian(&mut self, basis: &DMatrix<f64>, eta: f64) -> DMatrix<f64> {
        let p = &self.softmax.p;
        let mean_a = self.softmax.mean_shifted();
        let k = self.matched.len();
        for i in 0..p.len() {
            let root = p[i].sqrt();
            if root == 0.0 {
                self.centred.row_mut(i).fill(0.0);
                continue;
            }
            self.centred[(i, 0)] = root * (self.softmax.shifted[i] - mean_a);
            for j in 0..k {
                self.centred[(i, j + 1)] = root * (basis[(i, j)] - self.matched[j]);
            }
        }
        self.centred.tr_mul(&self.centred) / eta
    }
}

/// One evaluated point of the standardised dual.
pub(super) struct Point {
    pub(super) eta: f64,
    pub(super) u: DVector<f64>,
    pub(super) value: f64,
    /// `eps - KL`.
    pub(super) gradient_eta: f64,
    /// `-basis^T p`.
    pub(super) gradient_u: DVector<f64>,
}

impl Point {
    /// Whether eta is held on its bound: there, and the dual would decrease below it.
    fn eta_held(&self, eta_min: f64) -> bool {
        self.eta <= eta_min && self.gradient_eta > 0.0
    }

    fn optimality(&self, eta_min: f64) -> f64 {
        let eta_part = if self.eta_held(eta_min) {
            0.0
        } else {
            self.gradient_eta.abs()
        };
        self.gradient_u.amax().max(eta_part)
    }
}

/// A Newton step: the new eta and the change of u.
struct Step {
    eta: f64,
    u: DVector<f64>,
}

impl Step {
    /// The Newton step from `point`, through the Schur complement on eta.
    ///
    /// With `z = H_uu^-1 g_u` and `w = H_uu^-1 H_ue`, minimising the quadratic model over u for a
    /// given change `d` of eta leaves `h(d) = (g_e - H_eu z) d + S d^2 / 2`, `S = H_ee - H_eu w`
    /// (exactly h''(eta) when u is optimal), with `du = -z - w d`. While the Newton decrement of
    /// u, `g_u^T z`, exceeds [`CENTRING`] eta the model is poor (the dual is exponential in
    /// u / eta), so eta stays and only u moves; else eta takes the Newton step on `h`, kept
    /// within a factor [`ETA_STEP_FACTOR`] and above `eta_min`.
    fn new(point: &Point, hessian: &DMatrix<f64>, eta_min: f64) -> Self {
        let eta = point.eta;
        let k = point.u.len();
        let h_uu = hessian.view((1, 1), (k, k)).into_owned();
        let h_ue = hessian.view((1, 0), (k, 1)).column(0).into_owned();
        let factor = factor_regularised(h_uu, 1.0 / eta);
        // Without a factor (no shift made H_uu positive definite): steepest descent in u.
        let z = factor
            .as_ref()
            .map_or_else(|| point.gradient_u.clone(), |f| f.solve(&point.gradient_u));
        let decrement = point.gradient_u.dot(&z);
        if decrement > CENTRING * eta || point.eta_held(eta_min) {
            return Self { eta, u: -z };
        }
        let w = factor.map_or_else(|| DVector::zeros(k), |f| f.solve(&h_ue));
        let curvature = hessian[(0, 0)] - h_ue.dot(&w);
        let slope = point.gradient_eta - h_ue.dot(&z);
        let newton = if curvature > 0.0 {
            eta - slope / curvature
        } else if slope > 0.0 {
            0.0
        } else {
            f64::INFINITY
        };
        let target = newton.clamp(eta / ETA_STEP_FACTOR, eta * ETA_STEP_FACTOR).max(eta_min);
        Self {
            eta: target,
            u: -z - w * (target - eta),
        }
    }
}

/// The Cholesky factor of `H`, with `1e-12 scale` added to the diagonal, and more, tenfold, until
/// `H` is positive definite with a finite factor (a Hessian whose weights sit on too few samples
/// to span every direction); `scale` is the Hessian's natural size, `1/eta`.
pub(super) fn factor_regularised(hessian: DMatrix<f64>, scale: f64) -> Option<Cholesky<f64, Dyn>> {
    let mut shift = 0.0;
    for _ in 0..30 {
        let mut shifted = hessian.clone();
        for i in 0..shifted.nrows() {
            shifted[(i, i)] += shift;
        }
        let factor = Cholesky::new(shifted).filter(|f| f.l_dirty().iter().all(|x| x.is_finite()));
        if factor.is_some() {
            return factor;
        }
        shift = if shift == 0.0 { 1e-12 * scale } else { shift * 10.0 };
    }
    None
}

/// The result of [`Standardised::minimise`], in standardised units.
struct Newton {
    eta: f64,
    u: DVector<f64>,
    value: f64,
    weights: DVector<f64>,
    optimality: f64,
    iterations: usize,
}

#[cfg(test)]
pub(super) mod tests;
