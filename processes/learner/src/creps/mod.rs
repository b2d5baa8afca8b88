//! Contextual relative entropy policy search (C-REPS; P Algorithm 2 and Appendix A), with the
//! implementation choices of BOLeRo's `CREPSOptimizer` where the paper is silent, and a dual
//! solved to its optimum in any reward units.
//!
//! The policy `N(theta | W^T phi(s), Sigma)` ([`LinearGaussianPolicy`]) starts at `W = 0` except
//! for the constant feature's coefficients, which are `theta0` (so the initial mean is `theta0`
//! in every context), and `Sigma = initial_sigma I`. Rollouts are [`record`](CReps::record)ed into
//! a [`MemoryConfig`] memory; after every `update_every` recorded rollouts an [`update`] runs on
//! the whole memory (so the first update sees `update_every` samples, as in BOLeRo):
//!
//! 1. [`solve_dual`]: minimise the dual over `eta >= eta_min std(R)` and `v`, exactly (a Newton
//!    method on standardised returns, see the module [`dual`]), and take
//!    `d = softmax((R - Phi v) / eta)`. The update is invariant to `R -> a R + b`, a > 0.
//! 2. [`LinearGaussianPolicy::fit`]: weighted maximum likelihood with ridge `lambda`.
//!
//! Every update returns an [`UpdateReport`]: eta, the achieved KL, the effective sample size,
//! the dual's value and optimality, the solver's iterations and the resulting exploration. A
//! failed update (a singular regression, a non-finite or non-positive-semi-definite covariance)
//! is reported with its [`Rejection`] and leaves the policy unchanged.
//!
//! One file per piece, each importing only pieces before it in this list: `error` (every
//! operation's error type, and [`Rejection`]); `features` ([`FeatureMap`]); `memory`
//! ([`MemoryConfig`]); [`dual`] (the dual and its solver); [`joint`] (SPRL's dual with a context
//! distribution, Klink et al. 2019); `policy` ([`LinearGaussianPolicy`] and its weighted fit);
//! `update` (one update and its [`UpdateReport`]); this module's learner, [`CReps`], with
//! [`PacedContexts`], what SPRL's selector hands it; and `snapshot` (a learned policy as plain
//! data, [`PolicySnapshot`]).
//!
//! [`update`] runs one update on rollouts of your own, without a memory or a learner:
//!
//! ```
//! use acps_learner::creps::{Batch, FeatureMap, LinearGaussianPolicy, UpdateSettings, update};
//! use nalgebra::DMatrix;
//! use rand::SeedableRng;
//!
//! // theta in R^2 should equal (s, -s); start at W = 0, Sigma = I.
//! let mut policy = LinearGaussianPolicy::new(DMatrix::zeros(2, 2), DMatrix::identity(2, 2)).unwrap();
//! let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
//! for _ in 0..30 {
//!     let (mut contexts, mut thetas, mut returns) = (vec![], vec![], vec![]);
//!     for i in 0..40 {
//!         let s = i as f64 / 40.0;
//!         let theta = policy.sample(&FeatureMap::Affine.apply(&[s]), &mut rng);
//!         returns.push(-(theta[0] - s).powi(2) - (theta[1] + s).powi(2));
//!         contexts.push(vec![s]);
//!         thetas.push(theta.as_slice().to_vec());
//!     }
//!     let batch = Batch::from_contexts(&FeatureMap::Affine, &contexts, &thetas, &returns).unwrap();
//!     let settings = UpdateSettings { epsilon: 1.0, ..Default::default() };
//!     let (next, report) = update(&policy, &batch, &settings).unwrap();
//!     assert!(report.rejected.is_none() && report.optimality <= 1e-10);
//!     policy = next;
//! }
//! let mean = policy.mean(&FeatureMap::Affine.apply(&[0.5]));
//! assert!((mean[0] - 0.5).abs() < 0.05 && (mean[1] + 0.5).abs() < 0.05);
//! ```

pub mod dual;
mod error;
mod features;
pub mod joint;
mod memory;
mod policy;
mod snapshot;
mod update;

pub(crate) use policy::{GaussianKl, bound_by_kl, log_det, scale_rows, tr_mul_stopping};

pub use dual::{
    DEFAULT_ETA_MIN, DualOptions, DualSolution, DualValue, ETA_MIN_RANGE, TOLERANCE_RANGE, effective_sample_size,
    evaluate_dual, feature_matching_residual, kl_to_uniform, solve_dual,
};
pub use error::{
    BatchCreateError, CRepsCreateError, CRepsRestoreError, CRepsUpdateError, DualEvaluateError, DualSolveError,
    FeatureMapValidateError, InvalidValue, PolicyCreateError, PolicyFitError, Rejection,
};
pub use features::{CustomFeatures, FeatureFn, FeatureMap};
pub use joint::{ContextTerm, JointDualSolution, evaluate_joint_dual, solve_joint_dual};
pub use memory::{MemoryConfig, MemoryFitError};
pub use policy::LinearGaussianPolicy;
pub use snapshot::{PolicySnapshot, PolicySnapshotRestoreError, RestoredPolicy};
pub use update::{Batch, ContextReport, UpdateReport, UpdateSettings, update, update_paced};

use nalgebra::{DMatrix, DVector};
use rand::RngCore;
use serde::{Deserialize, Serialize};

pub(crate) use error::{check_at_least_one, check_finite, check_non_negative, check_positive, check_range};
use memory::{Memory, Sample};
use update::{update_paced_stopping, update_stopping};

use crate::stop::{Never, Stop};

/// C-REPS settings. [`Default`] is BOLeRo's `CREPSOptimizer`; the paper's three settings are
/// [`paper_function`](Self::paper_function), [`paper_dims`](Self::paper_dims) and
/// [`paper_throwing`](Self::paper_throwing).
///
/// Only `initial_sigma` has units (those of theta, squared): the update is invariant to the
/// returns' units (see the module docs), so the other defaults hold for any problem. Set
/// `initial_sigma` to the exploration variance wanted around theta0.
///
/// ```
/// use acps_learner::creps::{CRepsConfig, FeatureMap, MemoryConfig};
///
/// let config = CRepsConfig {
///     features: FeatureMap::Quadratic,
///     initial_sigma: 0.1,
///     ..CRepsConfig::default()
/// };
/// assert_eq!(config.memory, MemoryConfig::SlidingWindow { capacity: 100 });
/// // The paper's PA-10 setting for 25 targets keeps the best 12 throws of each.
/// assert_eq!(CRepsConfig::paper_throwing(25).memory, MemoryConfig::BestPerTask { per_task: 12 });
/// ```
#[derive(Clone, Debug)]
pub struct CRepsConfig {
    /// Bound on the KL divergence between successive sample weightings, finite and > 0.
    pub epsilon: f64,
    /// Lower bound of eta relative to the standard deviation of the returns in the update,
    /// within [`ETA_MIN_RANGE`] (P suggests 1e-6..1e-4 in reward units; BOLeRo 1e-8).
    pub eta_min: f64,
    /// Ridge lambda of the weighted least squares, finite and >= 0 (P and BOLeRo: 1e-4).
    pub ridge: f64,
    /// An update runs after every `update_every` recorded rollouts, >= 1.
    pub update_every: usize,
    /// Which rollouts an update uses.
    pub memory: MemoryConfig,
    /// The context features of the policy mean.
    pub features: FeatureMap,
    /// `Sigma_0 = initial_sigma I`, finite and > 0.
    pub initial_sigma: f64,
}

impl Default for CRepsConfig {
    /// BOLeRo's `CREPSOptimizer` defaults (epsilon 2, ridge 1e-4, an update every 25 rollouts
    /// on a sliding window of 100, Sigma_0 = I), [`FeatureMap::default`] (affine) and
    /// [`DEFAULT_ETA_MIN`].
    fn default() -> Self {
        Self {
            epsilon: 2.0,
            eta_min: DEFAULT_ETA_MIN,
            ridge: 1e-4,
            update_every: 25,
            memory: MemoryConfig::default(),
            features: FeatureMap::default(),
            initial_sigma: 1.0,
        }
    }
}

impl CRepsConfig {
    /// Updates on disjoint batches: an update every `batch` rollouts on exactly those rollouts
    /// (BOLeRo's `n_samples_per_update` with an update per batch), with `epsilon` and the other
    /// settings at their defaults.
    ///
    /// ```
    /// use acps_learner::creps::{CRepsConfig, MemoryConfig};
    ///
    /// let config = CRepsConfig::batches(1.0, 1000);
    /// assert_eq!((config.update_every, config.memory), (1000, MemoryConfig::SlidingWindow { capacity: 1000 }));
    /// ```
    pub fn batches(epsilon: f64, batch: usize) -> Self {
        Self {
            epsilon,
            update_every: batch,
            memory: MemoryConfig::SlidingWindow { capacity: batch },
            ..Self::default()
        }
    }

    /// The paper's Sec. 5.1.2 (Fig. 4): epsilon 2, the last 50 rollouts, an update every 25,
    /// quadratic features, Sigma_0 = I.
    pub fn paper_function() -> Self {
        Self {
            memory: MemoryConfig::SlidingWindow { capacity: 50 },
            features: FeatureMap::Quadratic,
            ..Self::default()
        }
    }

    /// The paper's Sec. 5.1.3 (Fig. 6) for `n_s`-dimensional contexts: epsilon 1, the last
    /// 25 n_s^2 rollouts, an update every 13 n_s^2, quadratic features, Sigma_0 = I.
    pub fn paper_dims(n_s: usize) -> Self {
        let n2 = n_s * n_s;
        Self {
            epsilon: 1.0,
            update_every: 13 * n2,
            memory: MemoryConfig::SlidingWindow { capacity: 25 * n2 },
            features: FeatureMap::Quadratic,
            ..Self::default()
        }
    }

    /// The paper's Sec. 5.2.2 (the PA-10 throws) for `tasks` training contexts: epsilon 0.5, an
    /// update every 50 on the best 300/K rollouts per task ([`MemoryConfig::best_per_task`]),
    /// polar-quadratic features of 2-D contexts, Sigma_0 = 0.02 I.
    pub fn paper_throwing(tasks: usize) -> Self {
        Self {
            epsilon: 0.5,
            update_every: 50,
            memory: MemoryConfig::best_per_task(300, tasks),
            features: FeatureMap::PolarQuadratic,
            initial_sigma: 0.02,
            ..Self::default()
        }
    }
}

/// Everything of a [`CReps`] that changes while it learns (for checkpoints): the policy's W,
/// Sigma and sampling factor, the sample memory and the update schedule's position.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CRepsState {
    weights: DMatrix<f64>,
    covariance: DMatrix<f64>,
    sampling_factor: DMatrix<f64>,
    memory: Memory,
    since_update: usize,
    dropped: usize,
}

impl CRepsState {
    /// The contexts of the remembered rollouts.
    pub(crate) fn contexts(&self) -> impl Iterator<Item = &[f64]> {
        self.memory.samples().map(|sample| sample.context.as_slice())
    }

    /// The first remembered rollout's context, to forge in tests.
    #[cfg(test)]
    pub(crate) fn first_context_mut(&mut self) -> Option<&mut Vec<f64>> {
        self.memory.first_mut().map(|sample| &mut sample.context)
    }
}

/// A context distribution that moves with the policy, in one dual (SPRL, Klink et al. 2019):
/// [`CReps::record_paced`] asks it for the context side of every update and hands it the context
/// weights to refit itself with. The self-paced selector implements it; a learner core drives it
/// through [`ContextSelector::paced`](crate::selection::ContextSelector::paced).
pub trait PacedContexts {
    /// The context side of the update on the rollouts in memory, whose contexts are
    /// `contexts` (in memory order): `alpha`, relative to the returns' standard deviation, and
    /// `ln mu(c_i) - ln q(c_i)` per context, finite. Called once per update, in update order;
    /// changes nothing, since an update may be stopped half-way
    /// ([`Learner::tell_until`](crate::Learner::tell_until)).
    fn terms(&self, contexts: &[&[f64]]) -> PacedTerms;

    /// Called after every update that ran to its end: refit the distribution to `contexts`
    /// weighted by `weights` (which sum to 1), moving it by at most `epsilon` (the update's KL
    /// bound) from where it is; `weights` is `None` when the update was rejected, and the
    /// distribution stays.
    fn refit(&mut self, contexts: &[&[f64]], weights: Option<&[f64]>, epsilon: f64);
}

/// What [`PacedContexts::terms`] returns.
#[derive(Clone, Debug, PartialEq)]
pub struct PacedTerms {
    /// The weight of the new distribution's KL to the target, relative to the returns'
    /// standard deviation, >= 0.
    pub alpha: f64,
    /// `ln mu(c_i) - ln q(c_i)` per context: target over current density.
    pub log_ratio: Vec<f64>,
}

/// A C-REPS learner: a contextual Gaussian policy, its sample memory and its update schedule.
#[derive(Clone, Debug)]
pub struct CReps {
    config: CRepsConfig,
    context_dim: usize,
    n_tasks: usize,
    policy: LinearGaussianPolicy,
    memory: Memory,
    since_update: usize,
    dropped: usize,
}

impl CReps {
    /// A learner for `context_dim`-dimensional contexts, initial mean `theta0` and `n_tasks`
    /// training contexts (the buckets of [`MemoryConfig::BestPerTask`]). Every field of `config`
    /// and every argument is validated.
    pub fn new(
        config: CRepsConfig,
        context_dim: usize,
        theta0: &[f64],
        n_tasks: usize,
    ) -> Result<Self, CRepsCreateError> {
        check_positive("epsilon", config.epsilon)?;
        dual::check_eta_min(config.eta_min)?;
        check_non_negative("ridge", config.ridge)?;
        check_at_least_one("update_every", config.update_every)?;
        match config.memory {
            MemoryConfig::SlidingWindow { capacity } => check_at_least_one("capacity", capacity)?,
            MemoryConfig::BestPerTask { per_task } => check_at_least_one("per_task", per_task)?,
        }
        check_positive("initial_sigma", config.initial_sigma)?;
        check_at_least_one("n_tasks", n_tasks)?;
        check_at_least_one("theta0 length (n_theta)", theta0.len())?;
        check_finite("theta0", theta0)?;
        config.features.validate(context_dim, theta0)?;

        let n_phi = config.features.dim(context_dim);
        let mut weights = DMatrix::zeros(n_phi, theta0.len());
        if let Some(constant) = config.features.constant_index(context_dim) {
            weights.row_mut(constant).copy_from_slice(theta0);
        }
        let covariance = DMatrix::identity(theta0.len(), theta0.len()) * config.initial_sigma;
        let policy = LinearGaussianPolicy::new(weights, covariance)
            .expect("W is finite (theta0 was checked) and Sigma_0 = initial_sigma I with a checked initial_sigma");
        let memory = Memory::new(&config.memory, n_tasks);
        Ok(Self {
            config,
            context_dim,
            n_tasks,
            policy,
            memory,
            since_update: 0,
            dropped: 0,
        })
    }

    /// `theta ~ N(W^T phi(s), Sigma)`, as `W^T phi(s) + L z` with `z` drawn in order from `rng`.
    ///
    /// # Panics
    /// If `context.len() != context_dim`.
    pub fn sample(&self, context: &[f64], rng: &mut dyn RngCore) -> Vec<f64> {
        let features = self.features(context);
        self.policy.sample(&features, rng).data.into()
    }

    /// The mean `W^T phi(s)` (exploration off).
    ///
    /// # Panics
    /// If `context.len() != context_dim`.
    pub fn greedy(&self, context: &[f64]) -> Vec<f64> {
        self.policy.mean(&self.features(context)).data.into()
    }

    /// Stores one rollout of training task `task` and, after every `update_every` stored
    /// rollouts, runs an update on the memory and returns its report.
    ///
    /// A rollout with a non-finite reward, theta, context or feature vector is not stored, does
    /// not count towards `update_every` and returns `None`; [`dropped`](CReps::dropped) counts
    /// them. (The learner filters failed rollouts before they get here, so this is a guard.)
    ///
    /// # Panics
    /// If `task >= n_tasks`, `context.len() != context_dim` or `theta.len() != n_theta`.
    pub fn record(&mut self, task: usize, context: &[f64], theta: &[f64], reward: f64) -> Option<UpdateReport> {
        let Ok(report) = self.record_stopping(task, context, theta, reward, None, Never);
        report
    }

    /// [`record`](CReps::record), with the updates it triggers moving `paced` together with the
    /// policy ([`update_paced`]) when it is given.
    ///
    /// # Panics
    /// As [`record`](CReps::record); and if `paced` returns log-ratios of another length than
    /// the memory's or values out of range (a bug of the implementation).
    pub fn record_paced(
        &mut self,
        task: usize,
        context: &[f64],
        theta: &[f64],
        reward: f64,
        paced: Option<&mut dyn PacedContexts>,
    ) -> Option<UpdateReport> {
        let Ok(report) = self.record_stopping(task, context, theta, reward, paced, Never);
        report
    }

    /// [`record_paced`](CReps::record_paced), asking `stop` between the steps of the update
    /// it triggers (Ctrl-C, [`Learner::tell_until`](crate::Learner::tell_until)): a stopped
    /// update leaves the learner (and `paced`) as it was before this rollout, which is not
    /// stored.
    pub(crate) fn record_stopping<S: Stop>(
        &mut self,
        task: usize,
        context: &[f64],
        theta: &[f64],
        reward: f64,
        paced: Option<&mut dyn PacedContexts>,
        stop: S,
    ) -> Result<Option<UpdateReport>, S::Halt> {
        assert!(
            task < self.n_tasks,
            "task {task} out of range, n_tasks is {}",
            self.n_tasks
        );
        self.policy.assert_params(theta);
        let features = self.features(context);
        let finite = reward.is_finite()
            && theta.iter().all(|t| t.is_finite())
            && context.iter().all(|s| s.is_finite())
            && features.iter().all(|f| f.is_finite());
        if !finite {
            self.dropped += 1;
            return Ok(None);
        }
        let sample = Sample {
            context: context.to_vec(),
            features,
            theta: DVector::from_column_slice(theta),
            reward,
        };
        let pushed = self.memory.push(task, sample);
        if self.since_update + 1 < self.config.update_every {
            self.since_update += 1;
            return Ok(None);
        }
        match self.update(paced, stop) {
            Ok(report) => {
                self.since_update = 0;
                Ok(Some(report))
            }
            Err(halt) => {
                self.memory.undo(task, pushed);
                Err(halt)
            }
        }
    }

    /// The current policy.
    pub fn policy(&self) -> &LinearGaussianPolicy {
        &self.policy
    }

    /// The configuration.
    pub fn config(&self) -> &CRepsConfig {
        &self.config
    }

    /// The context dimension.
    pub fn context_dim(&self) -> usize {
        self.context_dim
    }

    /// The number of rollouts currently in memory.
    pub fn memory_len(&self) -> usize {
        self.memory.len()
    }

    /// The number of rollouts [`record`](CReps::record) refused because of non-finite values.
    pub fn dropped(&self) -> usize {
        self.dropped
    }

    /// The learning state, for a checkpoint. The sampling factor is saved as it is rather than
    /// recomputed on restore, so sampling continues bit for bit.
    pub fn state(&self) -> CRepsState {
        CRepsState {
            weights: self.policy.weights().clone(),
            covariance: self.policy.covariance().clone(),
            sampling_factor: self.policy.sampling_factor().clone(),
            memory: self.memory.clone(),
            since_update: self.since_update,
            dropped: self.dropped,
        }
    }

    /// Continue from `state`, saved by [`state`](CReps::state) of a learner built with the same
    /// configuration and dimensions. A state of other dimensions or another memory is refused
    /// and leaves the learner unchanged.
    pub fn restore(&mut self, state: CRepsState) -> Result<(), CRepsRestoreError> {
        let (n_phi, n_theta) = (self.policy.n_features(), self.policy.n_params());
        let shape = |m: &DMatrix<f64>| (m.nrows(), m.ncols());
        if shape(&state.weights) != (n_phi, n_theta)
            || shape(&state.covariance) != (n_theta, n_theta)
            || shape(&state.sampling_factor) != (n_theta, n_theta)
        {
            return Err(CRepsRestoreError::Shape {
                weights: shape(&state.weights),
                covariance: shape(&state.covariance),
                factor: shape(&state.sampling_factor),
                expected_weights: (n_phi, n_theta),
                expected_covariance: (n_theta, n_theta),
            });
        }
        state
            .memory
            .check_fits(&self.memory, self.context_dim, n_phi, n_theta)
            .map_err(CRepsRestoreError::Memory)?;
        if state.since_update >= self.config.update_every {
            return Err(CRepsRestoreError::Schedule {
                since_update: state.since_update,
                update_every: self.config.update_every,
            });
        }
        let finite = |values: &[f64]| values.iter().all(|x| x.is_finite());
        if !state.memory.samples().all(|sample| {
            finite(&sample.context)
                && finite(sample.features.as_slice())
                && finite(sample.theta.as_slice())
                && sample.reward.is_finite()
        }) {
            return Err(CRepsRestoreError::Values {
                what: "a remembered rollout",
            });
        }
        self.policy = LinearGaussianPolicy::from_saved(state.weights, state.covariance, state.sampling_factor)
            .map_err(|what| CRepsRestoreError::Values { what })?;
        self.memory = state.memory;
        self.since_update = state.since_update;
        self.dropped = state.dropped;
        Ok(())
    }

    fn features(&self, context: &[f64]) -> DVector<f64> {
        self.config.features.apply_sized(context, self.context_dim)
    }

    /// The settings of its updates.
    pub fn update_settings(&self) -> UpdateSettings {
        UpdateSettings {
            epsilon: self.config.epsilon,
            eta_min: self.config.eta_min,
            ridge: self.config.ridge,
            dual: DualOptions::default(),
        }
    }

    /// One C-REPS update on everything in memory, moving `paced` with the policy when given;
    /// a stopped one changes nothing.
    fn update<S: Stop>(&mut self, paced: Option<&mut dyn PacedContexts>, stop: S) -> Result<UpdateReport, S::Halt> {
        let samples: Vec<&Sample> = self.memory.samples().collect();
        let features = stack_rows(samples.iter().map(|s| &s.features), self.policy.n_features());
        let thetas = stack_rows(samples.iter().map(|s| &s.theta), self.policy.n_params());
        let returns: Vec<f64> = samples.iter().map(|s| s.reward).collect();
        // The memory holds finite samples of this policy's widths and the settings were checked
        // by `new`, so the update cannot fail (a paced distribution's terms are its own bugs).
        let batch = Batch::of_valid(features, thetas, returns);
        let settings = self.update_settings();
        let (policy, report) = match paced {
            None => update_stopping(&self.policy, &batch, &settings, stop)?
                .expect("the memory fits the policy and the settings were checked"),
            Some(paced) => {
                let contexts: Vec<&[f64]> = samples.iter().map(|s| s.context.as_slice()).collect();
                let terms = paced.terms(&contexts);
                let term = ContextTerm {
                    log_ratio: &terms.log_ratio,
                    alpha: terms.alpha,
                    epsilon: settings.epsilon,
                };
                let (policy, report, weights) = update_paced_stopping(&self.policy, &batch, &term, &settings, stop)?
                    .unwrap_or_else(|e| panic!("a paced distribution's terms are out of range: {e}"));
                let refit = report.rejected.is_none().then_some(weights.as_slice());
                paced.refit(&contexts, refit, settings.epsilon);
                (policy, report)
            }
        };
        self.policy = policy;
        Ok(report)
    }
}

/// One row per vector. Row by row because every sample is an allocation of its own: each is read
/// once instead of once per column, which missed the cache in a fleet's learner.
fn stack_rows<'a>(rows: impl ExactSizeIterator<Item = &'a DVector<f64>>, width: usize) -> DMatrix<f64> {
    let mut matrix = DMatrix::zeros(rows.len(), width);
    for (i, row) in rows.enumerate() {
        matrix.row_mut(i).tr_copy_from(row);
    }
    matrix
}

#[cfg(test)]
mod tests;
