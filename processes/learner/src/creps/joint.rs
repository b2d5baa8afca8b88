//! Self-paced contextual RL's joint dual (SPRL, Klink et al., CoRL 2019): the C-REPS dual
//! extended by the distribution of the contexts, solved to its optimum whatever the units of the
//! returns.
//!
//! Besides the returns `R_i` and the feature rows `phi_i` of the samples' contexts `c_i`, SPRL
//! knows each sample's log-ratio `a_i = ln mu(c_i) - ln q(c_i)` of the target context density
//! `mu` over the current one `q`. With `s` the returns' standard deviation and `A = alpha s` the
//! weight of the new context distribution's KL to the target, the dual is
//!
//! `g(eta, eta_c, v) = eta eps + eta ln( (1/N) sum_i exp((R_i - phi_i^T v) / eta) )`
//! `                 + eta_c eps_c + T ln( (1/N) sum_i exp((A a_i + phi_i^T v) / T) )`,
//! `T = A + eta_c`,
//!
//! over `eta >= eta_min s`, `eta_c >= eta_min s` and free `v`. It implies two weightings of the
//! samples: the policy's `d = softmax((R - Phi v) / eta)` and the contexts'
//! `w = softmax((A a + Phi v) / T)`. Its gradient is
//!
//! - `dg/deta = eps - KL(d || uniform)` and `dg/deta_c = eps_c - KL(w || uniform)`, so each KL
//!   bound holds with equality at the optimum unless its temperature sits on its bound;
//! - `dg/dv = Phi^T w - Phi^T d`: the weighted features of the policy match those of the new
//!   context distribution (not the sample mean, as in plain C-REPS: there is no `v^T phi_bar`
//!   term).
//!
//! # How it is solved
//! As the C-REPS dual (module [`dual`](super::dual)), with whose pieces it is built:
//!
//! 1. **The flat directions and the units go.** A constant added to the baseline `Phi v` cancels
//!    between the two terms, so `v` is replaced by coordinates `u` in the orthonormal basis `B`
//!    of the centred features. With `R = m + s R~`, both temperatures and the baseline in units
//!    of s, and `a` centred (which shifts `g` by `A mean(a)`), `g = m + A mean(a) + s g~`, `g~`
//!    being the same dual on `R~` with `A` replaced by `alpha`. `alpha` is relative to s, so the
//!    whole solve is invariant to `R -> a R + b`, a > 0. (The returns are first recentred on
//!    their midrange, exactly, so that a shift of many standard deviations keeps their digits
//!    through the standardisation.)
//! 2. **Projected Newton with the exact Hessian.** `g~` is jointly convex (each term is the
//!    perspective of a log-mean-exp); with the log-weights `z_d = (R~ - B u) / eta~` and
//!    `z_w = (alpha a + B u) / T~`, its Hessian is `(1/eta~) Cov_d([z_d, B])` on `(eta~, u)` plus
//!    `(1/T~) Cov_w([-z_w, B])` on `(eta_c~, u)`. A temperature on its bound whose gradient is
//!    positive is held there; the others take the Newton step, through the Schur complement on
//!    the temperatures (see `Model`), each kept within a factor 8 and clamped to its bound, with
//!    u re-minimised in the quadratic model for the clamped temperatures. While u is far from
//!    its optimum for the current temperatures (the dual is exponential in u), the temperatures
//!    wait for it, as in `solve_dual`. A backtracking line search on `g~` does the rest (a step
//!    may change no log-weight by more than 1000 through u).
//!
//! It stops when the projected gradient of `g~` (dimensionless) has an inf-norm of at most
//! [`DualOptions::tolerance`], or of what double precision allows at the temperatures reached,
//! or at the iteration cap (then not converged). On the C-REPS test data sets with a Gaussian
//! context density against a uniform target, a solve takes 6-25 Newton steps when both KL
//! bounds are active and up to about 40 (rarely more) when eta must follow the path to its
//! bound.

use nalgebra::{DMatrix, DVector};

use crate::stop::{Never, Stop};

use super::dual::{
    CENTRING, DualOptions, DualValue, ETA_STEP_FACTOR, MAX_LOG_WEIGHT_CHANGE, ROUNDING, Scratch, Softmax, Standardised,
    backtrack, check_data, check_eta_min, check_options, factor_regularised, kl_to_uniform, standardise,
};
use super::error::{
    DualEvaluateError, DualSolveError, InvalidValue, check_finite, check_len, check_non_negative, check_positive,
};

/// The context side of SPRL's joint dual.
#[derive(Clone, Debug, PartialEq)]
pub struct ContextTerm<'a> {
    /// Per sample: `ln mu(c_i) - ln q(c_i)`, the log-ratio of the target context density over
    /// the current one at the sample's context; finite (a constant offset changes nothing but
    /// the objective).
    pub log_ratio: &'a [f64],
    /// The weight of `KL(new context distribution || target)`, relative to the returns' standard
    /// deviation; finite and >= 0. At 0 the context weights come from the baseline alone.
    pub alpha: f64,
    /// Bound on `KL(w || uniform)` of the context weights, finite and > 0.
    pub epsilon: f64,
}

/// The minimiser of the joint dual and the two sample weightings it implies.
#[derive(Clone, Debug, PartialEq)]
pub struct JointDualSolution {
    /// The policy's temperature eta, in the returns' units (>= `eta_min` times their standard
    /// deviation).
    pub eta: f64,
    /// Whether eta sits on its lower bound (the policy's KL bound is then slack).
    pub eta_at_bound: bool,
    /// The contexts' temperature eta_c, in the returns' units (>= `eta_min` times their standard
    /// deviation).
    pub eta_context: f64,
    /// Whether eta_c sits on its lower bound (the contexts' KL bound is then slack).
    pub eta_context_at_bound: bool,
    /// Baseline coefficients v (one per feature), in the returns' units; the minimum-norm v (the
    /// dual is flat along the constant feature and any combination constant over the samples).
    pub v: DVector<f64>,
    /// The policy's weights `d = softmax((R - Phi v) / eta)`; sum to 1.
    pub weights: DVector<f64>,
    /// The contexts' weights `w = softmax((A a + Phi v) / (A + eta_c))`; sum to 1.
    pub context_weights: DVector<f64>,
    /// `KL(d || uniform)` (= epsilon when eta is off its bound).
    pub kl: f64,
    /// `KL(w || uniform)` (= the context epsilon when eta_c is off its bound).
    pub context_kl: f64,
    /// `g(eta, eta_c, v)`, in the returns' units.
    pub objective: f64,
    /// The inf-norm of the standardised dual's projected gradient at the returned point.
    pub optimality: f64,
    /// Newton iterations.
    pub iterations: usize,
    /// Whether the optimality reached the tolerance (or what double precision allows at the
    /// temperatures reached) within the iteration cap.
    pub converged: bool,
}

/// Minimises SPRL's joint dual over `eta >= eta_min s`, `eta_c >= eta_min s` and free `v`, s
/// being the standard deviation of `returns`.
///
/// `phi` holds one feature vector per row (N x n_phi), `returns` the N returns and `context`
/// the log-ratios, alpha and the bound of the context side. Errors if the inputs are inconsistent
/// or not finite, or a setting is out of its range. Returns that are all equal (to rounding) carry
/// no preference: both weightings are then uniform, both temperatures 0 and on their bounds.
///
/// ```
/// use acps_learner::creps::{ContextTerm, DualOptions, solve_joint_dual};
/// use nalgebra::DMatrix;
///
/// // Features (s, 1) of six contexts; the target density prefers large s.
/// let s = [-1.0, -0.6, -0.2, 0.2, 0.6, 1.0];
/// let phi = DMatrix::from_fn(6, 2, |i, j| if j == 0 { s[i] } else { 1.0 });
/// let returns = [-3.0, -1.0, 0.0, -2.0, -0.5, -1.5];
/// let log_ratio: Vec<f64> = s.iter().map(|s| 2.0 * s).collect();
/// let context = ContextTerm { log_ratio: &log_ratio, alpha: 1.0, epsilon: 0.1 };
/// let solution = solve_joint_dual(&phi, &returns, &context, 0.5, 1e-5, &DualOptions::default()).unwrap();
/// assert!(solution.converged && !solution.eta_at_bound && !solution.eta_context_at_bound);
/// assert!((solution.kl - 0.5).abs() < 1e-9);
/// assert!((solution.context_kl - 0.1).abs() < 1e-9);
/// // The policy's weighted features match the new context distribution's.
/// let (d, w) = (phi.tr_mul(&solution.weights), phi.tr_mul(&solution.context_weights));
/// assert!((d - w).amax() < 1e-9);
/// ```
pub fn solve_joint_dual(
    phi: &DMatrix<f64>,
    returns: &[f64],
    context: &ContextTerm,
    epsilon: f64,
    eta_min: f64,
    options: &DualOptions,
) -> Result<JointDualSolution, DualSolveError> {
    check_data(phi, returns)?;
    if returns.is_empty() {
        return Err(DualSolveError::NoSamples);
    }
    let Ok(solution) = solve_joint_valid(phi, returns, context, epsilon, eta_min, options, Never);
    Ok(solution?)
}

/// [`solve_joint_dual`] on data known to be consistent and finite (a memory's); the context
/// term and the settings are checked.
pub(crate) fn solve_joint_valid<S: Stop>(
    phi: &DMatrix<f64>,
    returns: &[f64],
    context: &ContextTerm,
    epsilon: f64,
    eta_min: f64,
    options: &DualOptions,
    stop: S,
) -> Result<Result<JointDualSolution, InvalidValue>, S::Halt> {
    let checked = check_positive("epsilon", epsilon)
        .and_then(|()| check_context(context, returns.len()))
        .and_then(|()| check_eta_min(eta_min))
        .and_then(|()| check_options(options));
    if let Err(invalid) = checked {
        return Ok(Err(invalid));
    }
    let (n, original) = (returns.len(), returns);
    // Returns equal to rounding at their own magnitude carry no preference, as in `solve_dual`.
    let (returns, midrange) = recentre(returns);
    let Some(policy) = standardise(original).and_then(|_| Standardised::new(phi, &returns, epsilon)) else {
        // Equal returns: A = 0, and v = 0 with both temperatures at 0 gives the least value, m.
        let uniform = DVector::from_element(n, 1.0 / n as f64);
        return Ok(Ok(JointDualSolution {
            eta: 0.0,
            eta_at_bound: true,
            eta_context: 0.0,
            eta_context_at_bound: true,
            v: DVector::zeros(phi.ncols()),
            weights: uniform.clone(),
            context_weights: uniform,
            kl: 0.0,
            context_kl: 0.0,
            objective: midrange + returns.iter().sum::<f64>() / n as f64,
            optimality: 0.0,
            iterations: 0,
            converged: true,
        }));
    };
    let problem = Joint::new(policy, context);
    let newton = problem.minimise(eta_min, options, stop)?;
    let scale = problem.policy.scale;
    Ok(Ok(JointDualSolution {
        eta: scale * newton.point.temperatures[0],
        eta_at_bound: newton.point.temperatures[0] <= eta_min,
        eta_context: scale * newton.point.temperatures[1],
        eta_context_at_bound: newton.point.temperatures[1] <= eta_min,
        v: &problem.policy.to_v * &newton.point.u * scale,
        kl: kl_to_uniform(newton.weights.as_slice()),
        context_kl: kl_to_uniform(newton.context_weights.as_slice()),
        weights: newton.weights,
        context_weights: newton.context_weights,
        objective: midrange + problem.policy.mean + scale * (problem.offset + newton.point.value),
        converged: newton.optimality <= problem.attainable(options.tolerance, &newton.point),
        optimality: newton.optimality,
        iterations: newton.iterations,
    }))
}

/// The joint dual `g(eta, eta_c, v)` and its gradient `(dg/deta, dg/deta_c, dg/dv_0, ...,
/// dg/dv_{n_phi - 1})` at one point, in the returns' units (computed with shifted log-sum-exps,
/// so tiny temperatures and huge returns stay finite). `A = alpha s` uses the returns' standard
/// deviation s, as [`solve_joint_dual`] does.
///
/// ```
/// use acps_learner::creps::{ContextTerm, DualOptions, evaluate_joint_dual, solve_joint_dual};
/// use nalgebra::DMatrix;
///
/// let phi = DMatrix::from_row_slice(4, 2, &[0.0, 1.0, 1.0, 1.0, 2.0, 1.0, 3.0, 1.0]);
/// let returns = [1.0, 3.0, 2.0, 0.0];
/// let context = ContextTerm { log_ratio: &[0.5, 0.0, -0.5, -1.0], alpha: 1.0, epsilon: 0.02 };
/// let optimum = solve_joint_dual(&phi, &returns, &context, 0.3, 1e-5, &DualOptions::default()).unwrap();
/// let at = evaluate_joint_dual(&phi, &returns, &context, 0.3, optimum.eta, optimum.eta_context, optimum.v.as_slice())
///     .unwrap();
/// assert!(!optimum.eta_at_bound && !optimum.eta_context_at_bound);
/// assert!((at.value - optimum.objective).abs() < 1e-12);
/// // The optimum: both KL bounds met and the features matched.
/// assert!(at.gradient.amax() < 1e-9);
/// ```
pub fn evaluate_joint_dual(
    phi: &DMatrix<f64>,
    returns: &[f64],
    context: &ContextTerm,
    epsilon: f64,
    eta: f64,
    eta_context: f64,
    v: &[f64],
) -> Result<DualValue, DualEvaluateError> {
    check_positive("epsilon", epsilon)?;
    check_positive("eta", eta)?;
    check_positive("eta_context", eta_context)?;
    check_data(phi, returns)?;
    if returns.is_empty() {
        return Err(DualEvaluateError::NoSamples);
    }
    check_context(context, returns.len())?;
    check_len("the length of v", v.len(), "the number of phi columns", phi.ncols())?;
    check_finite("v", v)?;
    let n = returns.len();
    let scale = standardise(&recentre(returns).0).map_or(0.0, |(_, _, scale)| scale);
    let weight = context.alpha * scale;
    let temperature = weight + eta_context;
    let v = DVector::from_column_slice(v);
    let baseline = phi * &v;
    let mut policy = Softmax::new(n);
    let (max_r, log_mean) = policy.compute(&(DVector::from_column_slice(returns) - &baseline), eta);
    let mut contexts = Softmax::new(n);
    let log_ratio = DVector::from_column_slice(context.log_ratio);
    let (max_c, log_mean_c) = contexts.compute(&(log_ratio * weight + &baseline), temperature);
    let mut gradient = DVector::zeros(2 + phi.ncols());
    gradient[0] = epsilon - policy.kl(log_mean);
    gradient[1] = context.epsilon - contexts.kl(log_mean_c);
    gradient
        .rows_mut(2, phi.ncols())
        .copy_from(&(phi.tr_mul(&contexts.p) - phi.tr_mul(&policy.p)));
    Ok(DualValue {
        value: eta * epsilon
            + max_r
            + eta * log_mean
            + eta_context * context.epsilon
            + max_c
            + temperature * log_mean_c,
        gradient,
    })
}

/// The returns less their midrange, and the midrange: `g` is shift-equivariant (`R + b` gives
/// `g + b`, the same weights), and returns shifted far from 0 relative to their spread (say by
/// 1e10 standard deviations) keep their digits in the standardisation only when it starts
/// near their centre. Each difference is exact when the spread is small against the shift, and
/// rounded relative to the spread otherwise; none overflows.
fn recentre(returns: &[f64]) -> (Vec<f64>, f64) {
    let (low, high) = returns
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &r| (l.min(r), h.max(r)));
    let midrange = if returns.is_empty() {
        0.0
    } else {
        low / 2.0 + high / 2.0
    };
    (returns.iter().map(|r| r - midrange).collect(), midrange)
}

fn check_context(context: &ContextTerm, n: usize) -> Result<(), InvalidValue> {
    check_len(
        "the length of context.log_ratio",
        context.log_ratio.len(),
        "the number of returns",
        n,
    )?;
    check_finite("context.log_ratio", context.log_ratio)?;
    check_non_negative("context.alpha", context.alpha)?;
    check_positive("context.epsilon", context.epsilon)
}

/// The joint dual on standardised returns, in the basis of the policy's standardised dual.
struct Joint {
    /// The policy's term (standardised returns, basis, units).
    policy: Standardised,
    /// `alpha (a - mean a)`.
    log_ratio: DVector<f64>,
    /// `alpha mean(a)`: `g = m + s (offset + g~)`.
    offset: f64,
    alpha: f64,
    /// The context epsilon.
    epsilon: f64,
}

impl Joint {
    fn new(policy: Standardised, context: &ContextTerm) -> Self {
        let mean = context.log_ratio.iter().sum::<f64>() / context.log_ratio.len() as f64;
        let log_ratio = DVector::from_iterator(
            context.log_ratio.len(),
            context.log_ratio.iter().map(|a| context.alpha * (a - mean)),
        );
        Self {
            policy,
            log_ratio,
            offset: context.alpha * mean,
            alpha: context.alpha,
            epsilon: context.epsilon,
        }
    }

    /// The optimality a solve can reach at `point`: the log-weights are known to the rounding of
    /// their numerators divided by the temperatures.
    fn attainable(&self, tolerance: f64, point: &JointPoint) -> f64 {
        let context_rounding = ROUNDING * (1.0 + self.log_ratio.amax());
        tolerance
            .max(ROUNDING / point.temperatures[0])
            .max(context_rounding / point.temperature(self.alpha))
    }

    /// Projected Newton (see the module documentation).
    fn minimise<S: Stop>(&self, eta_min: f64, options: &DualOptions, stop: S) -> Result<JointNewton, S::Halt> {
        let n = self.log_ratio.len();
        let k = self.policy.rank();
        let mut scratch = (Scratch::new(n, k), Scratch::new(n, k));
        let start = self.start(eta_min);
        let mut current = self.evaluate(start.0, start.1, &mut scratch);
        let mut steps = 0;
        let optimality = loop {
            let optimality = current.optimality(eta_min);
            if optimality <= self.attainable(options.tolerance, &current) || steps >= options.max_iterations {
                break optimality;
            }
            stop.check()?;
            steps += 1;
            // The scratch holds the evaluation of `current`: the start, or the step accepted last.
            let hessian = self.hessian(&current, &mut scratch);
            let model = Model::new(&current, &hessian, self.alpha, eta_min);
            // Should the Newton step find no decrease, the same step with both temperatures'
            // changes shortened alike, then steepest descent, are tried before the point counts
            // as optimal.
            let found = self
                .search(&current, &model.clamped(), &mut scratch)
                .or_else(|| self.search(&current, &model.shortened(), &mut scratch))
                .or_else(|| self.search(&current, &model.descent(), &mut scratch));
            match found {
                Some(next) => current = next,
                None => {
                    // No decrease along a descent direction: the optimum to rounding. The
                    // scratch holds the last trial, so evaluate the point again for its weights.
                    current = self.evaluate(current.temperatures, current.u, &mut scratch);
                    break current.optimality(eta_min);
                }
            }
        };
        Ok(JointNewton {
            weights: scratch.0.softmax.p.clone(),
            context_weights: scratch.1.softmax.p.clone(),
            point: current,
            optimality,
            iterations: steps,
        })
    }

    /// The policy dual's start (the least-squares baseline and its eta), and the eta_c at which
    /// the context weights of that baseline would have KL = epsilon_c to second order.
    fn start(&self, eta_min: f64) -> ([f64; 2], DVector<f64>) {
        let (eta, u) = self.policy.start(eta_min);
        let numerators = &self.log_ratio + &self.policy.basis * &u;
        let centred = numerators.add_scalar(-numerators.mean());
        let spread = (centred.norm_squared() / centred.len() as f64).sqrt();
        let eta_context = (spread / (2.0 * self.epsilon).sqrt() - self.alpha).max(eta_min);
        ([eta, eta_context], u)
    }

    /// The dual, its gradient and both weightings (left in the scratch) at one point.
    fn evaluate(&self, temperatures: [f64; 2], u: DVector<f64>, scratch: &mut (Scratch, Scratch)) -> JointPoint {
        let policy = self.policy.evaluate(temperatures[0], u, &mut scratch.0);
        let contexts = &mut scratch.1;
        let temperature = self.alpha + temperatures[1];
        contexts.residuals.copy_from(&self.log_ratio);
        contexts.residuals.gemv(1.0, &self.policy.basis, &policy.u, 1.0);
        let (max_c, log_mean) = contexts.softmax.compute(&contexts.residuals, temperature);
        contexts
            .matched
            .gemv_tr(1.0, &self.policy.basis, &contexts.softmax.p, 0.0);
        JointPoint {
            temperatures,
            value: policy.value + temperatures[1] * self.epsilon + max_c + temperature * log_mean,
            gradient_temperatures: [policy.gradient_eta, self.epsilon - contexts.softmax.kl(log_mean)],
            gradient_u: policy.gradient_u + &contexts.matched,
            u: policy.u,
        }
    }

    /// The Hessian on `(eta~, eta_c~, u)` at the point last evaluated: the policy dual's
    /// `(1/eta~) Cov_d([z_d, B])` on `(eta~, u)`, and the same covariance of the context weights,
    /// `(1/T~) Cov_w([z_w, B])`, with the sign of its cross terms turned (their log-weights grow
    /// with u, not fall) on `(eta_c~, u)`.
    fn hessian(&self, point: &JointPoint, scratch: &mut (Scratch, Scratch)) -> DMatrix<f64> {
        let k = point.u.len();
        let policy = scratch.0.hessian(&self.policy.basis, point.temperatures[0]);
        let contexts = scratch.1.hessian(&self.policy.basis, point.temperature(self.alpha));
        let mut hessian = DMatrix::zeros(2 + k, 2 + k);
        hessian[(0, 0)] = policy[(0, 0)];
        hessian[(1, 1)] = contexts[(0, 0)];
        for j in 0..k {
            hessian[(0, 2 + j)] = policy[(0, 1 + j)];
            hessian[(2 + j, 0)] = policy[(1 + j, 0)];
            hessian[(1, 2 + j)] = -contexts[(0, 1 + j)];
            hessian[(2 + j, 1)] = -contexts[(1 + j, 0)];
        }
        let mut h_uu = hessian.view_mut((2, 2), (k, k));
        h_uu += policy.view((1, 1), (k, k));
        h_uu += contexts.view((1, 1), (k, k));
        hessian
    }

    /// A backtracking line search along the straight segment from `point` to `step` (first
    /// shortened so that no log-weight moves by more than [`MAX_LOG_WEIGHT_CHANGE`] through u);
    /// `None` for a step that is no descent direction. The scratch then holds the evaluation of
    /// the point returned.
    fn search(&self, point: &JointPoint, step: &JointStep, scratch: &mut (Scratch, Scratch)) -> Option<JointPoint> {
        let change = [
            step.temperatures[0] - point.temperatures[0],
            step.temperatures[1] - point.temperatures[1],
        ];
        let slope = point.gradient_temperatures[0] * change[0]
            + point.gradient_temperatures[1] * change[1]
            + point.gradient_u.dot(&step.u);
        if slope.is_nan() || slope >= 0.0 {
            return None;
        }
        let coldest = point.temperatures[0].min(point.temperature(self.alpha));
        let stretch = (&self.policy.basis * &step.u).amax() / coldest;
        let first = (MAX_LOG_WEIGHT_CHANGE / stretch).min(1.0);
        backtrack(point.value, slope, first, |fraction| {
            let temperatures = if fraction == 1.0 {
                step.temperatures
            } else {
                [
                    point.temperatures[0] + fraction * change[0],
                    point.temperatures[1] + fraction * change[1],
                ]
            };
            let trial = self.evaluate(temperatures, &point.u + &step.u * fraction, scratch);
            (trial.value, trial)
        })
    }
}

/// One evaluated point of the standardised joint dual.
struct JointPoint {
    /// `(eta~, eta_c~)`.
    temperatures: [f64; 2],
    u: DVector<f64>,
    value: f64,
    /// `(eps - KL(d), eps_c - KL(w))`.
    gradient_temperatures: [f64; 2],
    /// `B^T w - B^T d`.
    gradient_u: DVector<f64>,
}

impl JointPoint {
    /// The context weights' temperature `T~ = alpha + eta_c~`.
    fn temperature(&self, alpha: f64) -> f64 {
        alpha + self.temperatures[1]
    }

    /// Whether temperature `i` is held on its bound: there, and the dual would decrease below it.
    fn held(&self, i: usize, eta_min: f64) -> bool {
        self.temperatures[i] <= eta_min && self.gradient_temperatures[i] > 0.0
    }

    fn optimality(&self, eta_min: f64) -> f64 {
        (0..2)
            .filter(|&i| !self.held(i, eta_min))
            .map(|i| self.gradient_temperatures[i].abs())
            .fold(self.gradient_u.amax(), f64::max)
    }
}

/// A trial step: the new temperatures and the change of u.
struct JointStep {
    temperatures: [f64; 2],
    u: DVector<f64>,
}

/// The quadratic model at a point, reduced to the free temperatures through the Schur complement.
///
/// With `z = H_uu^-1 g_u` and `W = H_uu^-1 H_ut`, minimising the model over u for given changes
/// `dt` of the free temperatures leaves `h(dt) = (g_t - H_tu z)^T dt + dt^T S dt / 2`,
/// `S = H_tt - H_tu W`, with `du = -z - W dt`; its minimiser `dt*` with the matching du is the
/// Newton step.
struct Model<'a> {
    point: &'a JointPoint,
    alpha: f64,
    eta_min: f64,
    /// `-z`.
    u_step: DVector<f64>,
    /// `W`, k x 2 (zero columns for held temperatures).
    coupling: DMatrix<f64>,
    /// `dt*` (0 for held temperatures, and for both while u is far from its optimum); infinite
    /// where the model has no curvature.
    newton: [f64; 2],
}

impl<'a> Model<'a> {
    fn new(point: &'a JointPoint, hessian: &DMatrix<f64>, alpha: f64, eta_min: f64) -> Self {
        let k = point.u.len();
        let scale = 1.0 / point.temperatures[0].min(point.temperature(alpha));
        let factor = factor_regularised(hessian.view((2, 2), (k, k)).into_owned(), scale);
        // Without a factor (no shift made H_uu positive definite): steepest descent in u.
        let z = factor
            .as_ref()
            .map_or_else(|| point.gradient_u.clone(), |f| f.solve(&point.gradient_u));
        let free: Vec<usize> = (0..2).filter(|&i| !point.held(i, eta_min)).collect();
        let mut coupling = DMatrix::zeros(k, 2);
        let mut newton = [0.0; 2];
        // While the Newton decrement of u exceeds CENTRING times the colder temperature, the
        // model is poor (the dual is exponential in u / temperature): the temperatures wait.
        let centred = point.gradient_u.dot(&z) <= CENTRING / scale;
        if centred && !free.is_empty() {
            for &i in &free {
                let column = hessian.view((2, i), (k, 1)).into_owned();
                let solved = factor
                    .as_ref()
                    .map_or_else(|| DMatrix::zeros(k, 1), |f| f.solve(&column));
                coupling.set_column(i, &solved.column(0));
            }
            let m = free.len();
            let schur = DMatrix::from_fn(m, m, |a, b| {
                let (i, j) = (free[a], free[b]);
                hessian[(i, j)] - hessian.view((i, 2), (1, k)).transpose().dot(&coupling.column(j))
            });
            let reduced = DVector::from_fn(m, |a, _| {
                let i = free[a];
                point.gradient_temperatures[i] - hessian.view((i, 2), (1, k)).transpose().dot(&z)
            });
            match factor_regularised(schur, scale) {
                Some(f) => {
                    let step = f.solve(&reduced);
                    for (a, &i) in free.iter().enumerate() {
                        newton[i] = -step[a];
                    }
                }
                None => {
                    for (a, &i) in free.iter().enumerate() {
                        newton[i] = -reduced[a].signum() * f64::INFINITY;
                    }
                }
            }
        }
        Self {
            point,
            alpha,
            eta_min,
            u_step: -z,
            coupling,
            newton,
        }
    }

    /// The step for temperature changes `change`, u re-minimised in the model.
    fn step(&self, change: [f64; 2]) -> JointStep {
        let t = self.point.temperatures;
        JointStep {
            temperatures: [t[0] + change[0], t[1] + change[1]],
            u: &self.u_step - &self.coupling * DVector::from_column_slice(&change),
        }
    }

    /// The range temperature `i` may move within in one step.
    fn range(&self, i: usize) -> (f64, f64) {
        let t = self.point.temperatures[i];
        ((t / ETA_STEP_FACTOR).max(self.eta_min), t * ETA_STEP_FACTOR)
    }

    /// The Newton step with each temperature clamped to its range (so onto its bound).
    fn clamped(&self) -> JointStep {
        let change = [0, 1].map(|i| {
            let (low, high) = self.range(i);
            let t = self.point.temperatures[i];
            // A temperature at its bound may sit slightly below the range's low end.
            (t + self.newton[i]).clamp(low.min(t), high) - t
        });
        self.step(change)
    }

    /// The Newton step with both temperature changes shortened by the same factor until both
    /// are within their ranges: the model decreases along it whatever S's off-diagonal.
    fn shortened(&self) -> JointStep {
        let fraction = (0..2)
            .filter(|&i| self.newton[i] != 0.0)
            .map(|i| {
                let (low, high) = self.range(i);
                let t = self.point.temperatures[i];
                let room = if self.newton[i] > 0.0 {
                    high - t
                } else {
                    (low - t).min(0.0)
                };
                (room / self.newton[i]).clamp(0.0, 1.0)
            })
            .fold(1.0, f64::min);
        self.step(self.newton.map(|d| if d == 0.0 { 0.0 } else { fraction * d }))
    }

    /// Steepest descent: log-weight changes of the gradient's size, with the free temperatures
    /// moved by their gradient relative to their size.
    fn descent(&self) -> JointStep {
        let point = self.point;
        let coldest = point.temperatures[0].min(point.temperature(self.alpha));
        let change = [0, 1].map(|i| {
            if point.held(i, self.eta_min) {
                return 0.0;
            }
            let (low, high) = self.range(i);
            let t = point.temperatures[i];
            (t * (1.0 - point.gradient_temperatures[i])).clamp(low.min(t), high) - t
        });
        JointStep {
            temperatures: [point.temperatures[0] + change[0], point.temperatures[1] + change[1]],
            u: -&point.gradient_u * coldest,
        }
    }
}

/// The result of [`Joint::minimise`], in standardised units.
struct JointNewton {
    point: JointPoint,
    weights: DVector<f64>,
    context_weights: DVector<f64>,
    optimality: f64,
    iterations: usize,
}

#[cfg(test)]
mod tests;
