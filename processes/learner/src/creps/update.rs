//! One C-REPS update on given rollouts, and the report of what it did.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use super::dual::{DualOptions, effective_sample_size, solve_valid};
use super::error::{
    BatchCreateError, CRepsUpdateError, Rejection, check_finite, check_len, check_non_negative, check_positive,
};
use super::joint::{ContextTerm, solve_joint_valid};
use super::{FeatureMap, LinearGaussianPolicy};
use crate::stop::{Never, Stop};

/// The settings of one update.
#[derive(Clone, Debug, PartialEq)]
pub struct UpdateSettings {
    /// Bound on `KL(d || uniform)` of the sample weights, finite and > 0.
    pub epsilon: f64,
    /// Lower bound of eta relative to the standard deviation of the returns, within
    /// [`ETA_MIN_RANGE`](super::ETA_MIN_RANGE).
    pub eta_min: f64,
    /// Ridge lambda of the weighted least squares, finite and >= 0.
    pub ridge: f64,
    /// How exactly the dual is solved.
    pub dual: DualOptions,
}

impl Default for UpdateSettings {
    /// BOLeRo's `CREPSOptimizer`: epsilon 2, ridge 1e-4; and [`DEFAULT_ETA_MIN`](super::DEFAULT_ETA_MIN).
    fn default() -> Self {
        Self {
            epsilon: 2.0,
            eta_min: super::DEFAULT_ETA_MIN,
            ridge: 1e-4,
            dual: DualOptions::default(),
        }
    }
}

/// What one update did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UpdateReport {
    /// The number of samples the update ran on.
    pub samples: usize,
    /// The KL bound.
    pub epsilon: f64,
    /// The dual's temperature, in the returns' units (0 when all returns are equal).
    pub eta: f64,
    /// Whether eta sits on its lower bound, so the KL bound was slack.
    pub eta_at_bound: bool,
    /// `KL(d || uniform)` of the sample weights (= epsilon when eta is off its bound).
    pub kl: f64,
    /// The effective sample size `1 / sum d_i^2` of the weights (N when uniform).
    pub ess: f64,
    /// The dual's value at its optimum, in the returns' units.
    pub dual: f64,
    /// The inf-norm of the standardised dual's projected gradient where the solver stopped.
    pub optimality: f64,
    /// Newton iterations of the dual solve.
    pub iterations: usize,
    /// `ln det Sigma` of the policy in force after the update (the new one, or the old one when
    /// rejected); -inf when Sigma is singular.
    pub logdet_sigma: f64,
    /// `trace Sigma` of that policy: the total exploration variance.
    pub trace_sigma: f64,
    /// Why the update was rejected; `None` when the new policy was applied.
    pub rejected: Option<Rejection>,
    /// What the update did to the context distribution, for an update with one
    /// ([`update_paced`]); `None` for plain C-REPS.
    #[serde(default)]
    pub context: Option<ContextReport>,
}

/// The context side of an [`update_paced`] (SPRL).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ContextReport {
    /// The weight of the new context distribution's KL to the target, relative to the returns'
    /// standard deviation.
    pub alpha: f64,
    /// The context weights' temperature, in the returns' units.
    pub eta: f64,
    /// Whether it sits on its lower bound, so the context KL bound was slack.
    pub eta_at_bound: bool,
    /// `KL(w || uniform)` of the context weights.
    pub kl: f64,
    /// The effective sample size of the context weights.
    pub ess: f64,
    /// How far the policy's fit was pulled back towards the old policy to keep its mean KL
    /// within epsilon (0: not at all); `None` when the update was rejected before the fit.
    pub nu: Option<f64>,
}

/// Rollouts to update on, one row each: features `phi(s_i)`, parameters `theta_i`, returns
/// `R_i`, all finite.
#[derive(Clone, Debug, PartialEq)]
pub struct Batch {
    features: DMatrix<f64>,
    thetas: DMatrix<f64>,
    returns: Vec<f64>,
}

impl Batch {
    /// A batch from feature rows (N x n_phi), parameter rows (N x n_theta) and N returns.
    pub fn new(features: DMatrix<f64>, thetas: DMatrix<f64>, returns: Vec<f64>) -> Result<Self, BatchCreateError> {
        let n = returns.len();
        check_len(
            "the number of feature rows",
            features.nrows(),
            "the number of returns",
            n,
        )?;
        check_len("the number of theta rows", thetas.nrows(), "the number of returns", n)?;
        if returns.is_empty() {
            return Err(BatchCreateError::NoSamples);
        }
        check_finite("features", features.as_slice())?;
        check_finite("thetas", thetas.as_slice())?;
        check_finite("returns", &returns)?;
        Ok(Self::of_valid(features, thetas, returns))
    }

    /// A batch of rows known to be consistent and finite (a C-REPS memory's: `record` keeps
    /// non-finite rollouts out), without checking them again.
    pub(crate) fn of_valid(features: DMatrix<f64>, thetas: DMatrix<f64>, returns: Vec<f64>) -> Self {
        Self {
            features,
            thetas,
            returns,
        }
    }

    /// A batch from contexts, mapped through `features`, with their parameters and returns.
    pub fn from_contexts(
        features: &FeatureMap,
        contexts: &[Vec<f64>],
        thetas: &[Vec<f64>],
        returns: &[f64],
    ) -> Result<Self, BatchCreateError> {
        let context_dim = contexts.first().map_or(0, Vec::len);
        let n_theta = thetas.first().map_or(0, Vec::len);
        for context in contexts {
            check_len("a context's length", context.len(), "the first context's", context_dim)?;
        }
        for theta in thetas {
            check_len("a theta's length", theta.len(), "the first theta's", n_theta)?;
        }
        check_len(
            "the number of contexts",
            contexts.len(),
            "the number of thetas",
            thetas.len(),
        )?;
        for context in contexts {
            check_finite("contexts", context)?;
        }
        features.validate(context_dim, &[])?;
        let n_phi = features.dim(context_dim);
        let mut phi = DMatrix::zeros(contexts.len(), n_phi);
        for (i, context) in contexts.iter().enumerate() {
            phi.row_mut(i).tr_copy_from(&features.apply(context));
        }
        let thetas = DMatrix::from_fn(thetas.len(), n_theta, |i, j| thetas[i][j]);
        Self::new(phi, thetas, returns.to_vec())
    }

    /// N.
    pub fn len(&self) -> usize {
        self.returns.len()
    }

    /// Always false: a batch has at least one rollout.
    pub fn is_empty(&self) -> bool {
        self.returns.is_empty()
    }
}

/// One C-REPS update of `policy` on `batch` (P Alg. 2 lines 7-17): solve the dual, weight the
/// rollouts, fit the new policy by weighted maximum likelihood. Returns the policy to continue
/// with (the new one, or `policy` itself when the update is rejected) and the report.
///
/// Errors only for settings out of range or a batch whose widths do not fit the policy; what the
/// data makes impossible (a singular regression, an overflowing covariance) is a rejection in
/// the report.
///
/// ```
/// use acps_learner::creps::{Batch, FeatureMap, LinearGaussianPolicy, UpdateSettings, update};
/// use nalgebra::DMatrix;
///
/// // A 1-D policy theta ~ N(w s + b, 1), W = 0, and five rollouts in which theta = s did best.
/// let policy = LinearGaussianPolicy::new(DMatrix::zeros(2, 1), DMatrix::identity(1, 1)).unwrap();
/// let contexts: Vec<Vec<f64>> = vec![vec![0.0], vec![0.5], vec![1.0], vec![0.5], vec![0.0]];
/// let thetas: Vec<Vec<f64>> = vec![vec![0.1], vec![0.4], vec![0.2], vec![-0.9], vec![1.0]];
/// let returns: Vec<f64> = contexts.iter().zip(&thetas).map(|(s, t)| -(t[0] - s[0]).powi(2)).collect();
/// let batch = Batch::from_contexts(&FeatureMap::Affine, &contexts, &thetas, &returns).unwrap();
/// let (policy, report) = update(&policy, &batch, &UpdateSettings { epsilon: 0.5, ..Default::default() }).unwrap();
/// assert_eq!(report.rejected, None);
/// assert!((report.kl - 0.5).abs() < 1e-8);
/// assert!(report.ess < 5.0 && policy.covariance()[(0, 0)] < 1.0);
/// ```
pub fn update(
    policy: &LinearGaussianPolicy,
    batch: &Batch,
    settings: &UpdateSettings,
) -> Result<(LinearGaussianPolicy, UpdateReport), CRepsUpdateError> {
    let Ok(updated) = update_stopping(policy, batch, settings, Never);
    updated
}

/// [`update`], asking `stop` between its steps.
pub(crate) fn update_stopping<S: Stop>(
    policy: &LinearGaussianPolicy,
    batch: &Batch,
    settings: &UpdateSettings,
    stop: S,
) -> Result<Result<(LinearGaussianPolicy, UpdateReport), CRepsUpdateError>, S::Halt> {
    if let Err(error) = check_update(policy, batch, settings) {
        return Ok(Err(error));
    }
    let dual = match solve_valid(
        &batch.features,
        &batch.returns,
        settings.epsilon,
        settings.eta_min,
        &settings.dual,
        stop,
    )? {
        Ok(dual) => dual,
        Err(invalid) => return Ok(Err(invalid.into())),
    };
    let solved = Solved {
        eta: dual.eta,
        eta_at_bound: dual.eta_at_bound,
        kl: dual.kl,
        weights: dual.weights.as_slice(),
        objective: dual.objective,
        optimality: dual.optimality,
        iterations: dual.iterations,
        converged: dual.converged,
    };
    let fitter = |weights: &[f64]| policy.fit_weighted(&batch.features, &batch.thetas, weights, settings.ridge, stop);
    Ok(Ok(fit(policy, batch, settings, &solved, fitter)?))
}

/// One update of `policy` together with a context distribution (SPRL, Klink et al. 2019): the
/// joint dual ([`solve_joint_dual`](super::solve_joint_dual)) with `context` weights the rollouts
/// for the policy and their contexts for the distribution. As in the original, the policy's fit
/// is bounded too: weighted maximum likelihood pulled back towards `policy` until the mean KL
/// from it over the rollouts' contexts is at most epsilon (without that bound, weights that match
/// the features of a context distribution moving away from the rollouts' make the covariance
/// grow without end). Returns the policy to continue with, the report (with its
/// [`ContextReport`]) and the context weights (which sum to 1), for the caller to refit its
/// distribution with when the update is not rejected.
pub fn update_paced(
    policy: &LinearGaussianPolicy,
    batch: &Batch,
    context: &ContextTerm,
    settings: &UpdateSettings,
) -> Result<(LinearGaussianPolicy, UpdateReport, Vec<f64>), CRepsUpdateError> {
    let Ok(updated) = update_paced_stopping(policy, batch, context, settings, Never);
    updated
}

/// What [`update_paced`] returns.
type Paced = (LinearGaussianPolicy, UpdateReport, Vec<f64>);

/// [`update_paced`], asking `stop` between its steps.
pub(crate) fn update_paced_stopping<S: Stop>(
    policy: &LinearGaussianPolicy,
    batch: &Batch,
    context: &ContextTerm,
    settings: &UpdateSettings,
    stop: S,
) -> Result<Result<Paced, CRepsUpdateError>, S::Halt> {
    if let Err(error) = check_update(policy, batch, settings) {
        return Ok(Err(error));
    }
    let joint = match solve_joint_valid(
        &batch.features,
        &batch.returns,
        context,
        settings.epsilon,
        settings.eta_min,
        &settings.dual,
        stop,
    )? {
        Ok(joint) => joint,
        Err(invalid) => return Ok(Err(invalid.into())),
    };
    let solved = Solved {
        eta: joint.eta,
        eta_at_bound: joint.eta_at_bound,
        kl: joint.kl,
        weights: joint.weights.as_slice(),
        objective: joint.objective,
        optimality: joint.optimality,
        iterations: joint.iterations,
        converged: joint.converged,
    };
    let mut nu = None;
    let fitter = |weights: &[f64]| {
        let fitted = policy.fit_bounded(
            &batch.features,
            &batch.thetas,
            weights,
            settings.ridge,
            settings.epsilon,
            stop,
        )?;
        Ok(fitted.map(|(next, pull)| {
            nu = Some(pull);
            next
        }))
    };
    let (next, mut report) = fit(policy, batch, settings, &solved, fitter)?;
    report.context = Some(ContextReport {
        alpha: context.alpha,
        eta: joint.eta_context,
        eta_at_bound: joint.eta_context_at_bound,
        kl: joint.context_kl,
        ess: effective_sample_size(joint.context_weights.as_slice()),
        nu,
    });
    Ok(Ok((next, report, joint.context_weights.as_slice().to_vec())))
}

/// The settings in range and a batch of the policy's widths.
fn check_update(
    policy: &LinearGaussianPolicy,
    batch: &Batch,
    settings: &UpdateSettings,
) -> Result<(), CRepsUpdateError> {
    check_positive("epsilon", settings.epsilon)?;
    check_non_negative("ridge", settings.ridge)?;
    check_len(
        "the number of feature columns",
        batch.features.ncols(),
        "the policy's n_phi",
        policy.n_features(),
    )?;
    check_len(
        "the number of theta columns",
        batch.thetas.ncols(),
        "the policy's n_theta",
        policy.n_params(),
    )?;
    Ok(())
}

/// What a dual solve gave the policy's fit, whichever dual it was.
struct Solved<'a> {
    eta: f64,
    eta_at_bound: bool,
    kl: f64,
    weights: &'a [f64],
    objective: f64,
    optimality: f64,
    iterations: usize,
    converged: bool,
}

/// Fit the policy to the weighted rollouts with `fitter` (or reject the update) and report; a
/// paced update adds its context report once its fit has told it nu.
fn fit<H>(
    policy: &LinearGaussianPolicy,
    batch: &Batch,
    settings: &UpdateSettings,
    dual: &Solved,
    fitter: impl FnOnce(&[f64]) -> Result<Result<LinearGaussianPolicy, Rejection>, H>,
) -> Result<(LinearGaussianPolicy, UpdateReport), H> {
    let fitted = if batch.len() < 2 {
        Err(Rejection::TooFewSamples)
    } else if !dual.converged {
        Err(Rejection::DualNotSolved)
    } else {
        fitter(dual.weights)?
    };
    let (next, rejected) = match fitted {
        Ok(next) => (next, None),
        Err(rejection) => (policy.clone(), Some(rejection)),
    };
    let report = UpdateReport {
        samples: batch.len(),
        epsilon: settings.epsilon,
        eta: dual.eta,
        eta_at_bound: dual.eta_at_bound,
        kl: dual.kl,
        ess: effective_sample_size(dual.weights),
        dual: dual.objective,
        optimality: dual.optimality,
        iterations: dual.iterations,
        logdet_sigma: next.log_det_covariance(),
        trace_sigma: next.covariance().trace(),
        rejected,
        context: None,
    };
    Ok((next, report))
}
