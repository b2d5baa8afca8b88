//! Contextual CMA-ES (Abdolmaleki, Price, Lau, Reis and Neumann, IJCAI 2017): the second
//! upper-level learner beside [`creps`](crate::creps), with the same policy class.
//!
//! The policy is `N(theta | W^T phi(s), sigma^2 C)`: the [`LinearGaussianPolicy`] of C-REPS with
//! its covariance split into a global step size `sigma` and a shape `C`, as in CMA-ES. It starts
//! as C-REPS does: `W = 0` except for the constant feature's coefficients, which are `theta0`,
//! and `sigma^2 C = initial_sigma I` (`C = I`). Rollouts are [`record`](CCmaes::record)ed; every
//! `population` rollouts (a generation, lambda) one update runs on exactly those:
//!
//! 1. **Baseline.** The returns, standardised, are fitted by ridge regression on the baseline's
//!    own context features `psi(s)`; the advantages are the residuals. They make ranks fair
//!    across contexts whose returns differ in level.
//! 2. **Weights.** The best `mu = lambda / 2` advantages get CMA-ES's weights
//!    `ln((lambda + 1) / 2) - ln i`, normalised (equal advantages share their ranks' weights);
//!    the rest 0.
//! 3. **Mean.** `W` by weighted ridge regression of the parameters on `phi(s)`.
//! 4. **Paths and covariance.** The shift of the mean at the generation's average features, in
//!    units of `sigma` and of its own spread under random selection, drives the conjugate path
//!    `p_sigma` and the path `p_c`; `C` gets the rank-one update from `p_c` and the rank-mu
//!    update from the residuals `(theta_i - W_old^T phi(s_i)) / sigma` of the old mean, each in
//!    its own context.
//! 5. **Step size.** `sigma` by cumulative step-size adaptation on `||p_sigma||`.
//!
//! Only the ranks of the advantages are used, and the baseline absorbs a shift of the returns,
//! so an update is invariant to `R -> a R + b`, a > 0 (up to rounding of the standardisation).
//! The constants are Hansen's ("The CMA Evolution Strategy: A Tutorial", 2016) with the
//! dimension `n = n_theta + n_s`, and each can be set ([`Rates`]). Every choice the paper leaves
//! open is in `docs/CHOICES.md`.
//!
//! ```
//! use acps_learner::ccmaes::{CCmaes, CCmaesConfig};
//! use rand::SeedableRng;
//!
//! // theta in R^2 should be (s, -s) for s in [0, 1]; start at theta0 = 0 with Sigma_0 = I.
//! let mut learner = CCmaes::new(CCmaesConfig::default(), 1, &[0.0, 0.0]).unwrap();
//! let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
//! for episode in 0..3000 {
//!     let s = (episode % 17) as f64 / 16.0;
//!     let theta = learner.sample(&[s], &mut rng);
//!     let reward = -(theta[0] - s).powi(2) - (theta[1] + s).powi(2);
//!     learner.record(&[s], &theta, reward);
//! }
//! let mean = learner.greedy(&[0.5]);
//! assert!((mean[0] - 0.5).abs() < 1e-3 && (mean[1] + 0.5).abs() < 1e-3, "{mean:?}");
//! ```

mod generation;

use nalgebra::{DMatrix, DVector};
use rand::RngCore;
use serde::{Deserialize, Serialize};

use crate::creps::{
    FeatureMap, FeatureMapValidateError, InvalidValue, LinearGaussianPolicy, PolicySnapshot, Rejection,
    check_at_least_one, check_finite, check_non_negative, check_positive, check_range,
};
use generation::Generation;

use crate::stop::{Never, Stop};

/// C-CMA-ES settings. [`Default`] is the original's: the population (generalised to any
/// features) and every rate from the problem's dimensions, affine policy features, a quadratic
/// baseline.
///
/// Like C-REPS', only `initial_sigma` has units (those of theta, squared).
///
/// ```
/// use acps_learner::ccmaes::{CCmaesConfig, Rates};
/// use acps_learner::creps::FeatureMap;
///
/// let config = CCmaesConfig { initial_sigma: 0.1, ..CCmaesConfig::default() };
/// // 20 parameters, a 2-D context and its 3 affine features: 4 + floor(3 ln 22) (2 * 3 - 1) = 49,
/// // the original's 4 + floor(3 ln 22) (1 + 2 * 2).
/// assert_eq!(config.population(20, 2), 49);
/// // Its 6 quadratic features need more rollouts: 4 + 9 (2 * 6 - 1) = 103.
/// let quadratic = CCmaesConfig { features: FeatureMap::Quadratic, ..CCmaesConfig::default() };
/// assert_eq!(quadratic.population(20, 2), 103);
/// assert_eq!(config.rates, Rates::default());
/// ```
#[derive(Clone, Debug)]
pub struct CCmaesConfig {
    /// Rollouts per generation, lambda; `None` for `4 + floor(3 ln(n_theta + n_s)) (2 n_phi - 1)`,
    /// the original's `(1 + 2 n_s)` for its affine features (n_phi = n_s + 1) extended to any
    /// features: the mean's regression weighs the best half of a generation, and with the
    /// original's count for quadratic features it fitted noise (docs/CHOICES.md). At least
    /// enough for both regressions: `lambda / 2 >= n_phi` and `lambda > n_psi`.
    pub population: Option<usize>,
    /// `sigma_0^2 C_0 = initial_sigma I` (C_0 = I), finite and > 0: the exploration variance
    /// around theta0, as C-REPS' setting of the same name.
    pub initial_sigma: f64,
    /// The context features of the policy mean.
    pub features: FeatureMap,
    /// The context features of the baseline the advantages are taken from (default
    /// [`FeatureMap::Quadratic`], as BOLeRo's `baseline_degree = 2`).
    pub baseline: FeatureMap,
    /// Ridge of both regressions, relative to each feature's scale (its entry on the diagonal of
    /// the normal matrix; for the mean's regression the largest over the generations so far),
    /// so it does not depend on the features' units; within [0, 1]. The mean's
    /// regression fits the change of W, so the ridge holds back directions of W that a
    /// generation's contexts barely determine: a selector that practises two nearby contexts
    /// would otherwise extrapolate their noise to every other. Default 1e-5, chosen on tuning
    /// seeds 1000-1004 of the grid (docs/CHOICES.md).
    pub ridge: f64,
    /// The learning rates; `None` fields take the original's defaults.
    pub rates: Rates,
}

impl Default for CCmaesConfig {
    fn default() -> Self {
        Self {
            population: None,
            initial_sigma: 1.0,
            features: FeatureMap::Affine,
            baseline: FeatureMap::Quadratic,
            ridge: 1e-5,
            rates: Rates::default(),
        }
    }
}

impl CCmaesConfig {
    /// lambda for `n_theta` parameters and `n_s`-dimensional contexts: the setting, or the
    /// default for these features.
    pub fn population(&self, n_theta: usize, n_s: usize) -> usize {
        self.population.unwrap_or_else(|| {
            let n = (n_theta + n_s) as f64;
            let n_phi = self.features.dim(n_s);
            4 + (3.0 * n.ln()).floor() as usize * (2 * n_phi).saturating_sub(1)
        })
    }
}

/// CMA-ES's learning rates; each `None` takes its default from Hansen's tutorial with
/// `n = n_theta + n_s` and the weights' `mu_eff`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Rates {
    /// Learning rate of the conjugate path `p_sigma`, within (0, 1]; default
    /// `(mu_eff + 2) / (n + mu_eff + 5)`.
    pub c_sigma: Option<f64>,
    /// Damping of the step size, finite and > 0; default
    /// `1 + 2 max(0, sqrt((mu_eff - 1) / (n + 1)) - 1) + c_sigma`.
    pub d_sigma: Option<f64>,
    /// Learning rate of the path `p_c`, within (0, 1]; default
    /// `(4 + mu_eff / n) / (n + 4 + 2 mu_eff / n)`.
    pub c_c: Option<f64>,
    /// Rate of the rank-one update, within [0, 1] with `c_1 + c_mu < 1` (or = 1 when the
    /// population's best half outnumbers n_theta); default `2 / ((n + 1.3)^2 + mu_eff)`.
    pub c_1: Option<f64>,
    /// Rate of the rank-mu update, within [0, 1] with `c_1 + c_mu < 1` (or = 1 when the
    /// population's best half outnumbers n_theta); default
    /// `min(1 - c_1, 2 (mu_eff - 2 + 1 / mu_eff) / ((n + 2)^2 + mu_eff))`, which is `1 - c_1`
    /// from a population of about `4 (n + 2)^2`.
    pub c_mu: Option<f64>,
}

/// Why [`CCmaes::new`] refuses its configuration or arguments.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CCmaesCreateError {
    /// A setting, theta0 or the context dimension is outside its range.
    #[error(transparent)]
    Invalid(#[from] InvalidValue),
    /// A feature map does not fit the context dimension or theta0.
    #[error(transparent)]
    Features(#[from] FeatureMapValidateError),
    /// The population is too small for one of the two regressions.
    #[error(
        "population must be >= {needed} for these features, got {population}: the mean's regression weights the best population / 2 rollouts and needs {n_phi} of them (its features), the baseline needs more rollouts than its {n_psi} features"
    )]
    Population {
        /// The population asked for.
        population: usize,
        /// The smallest that works.
        needed: usize,
        /// The policy's feature count.
        n_phi: usize,
        /// The baseline's feature count.
        n_psi: usize,
    },
    /// `c_1 + c_mu` is over 1, so the old shape would keep a negative weight; or 1 while the
    /// best half of a generation is too few to make C positive definite alone.
    #[error(
        "rates c_1 + c_mu must be < 1, or 1 when the best half of a generation (mu = {mu}) outnumbers the {n_theta} parameters (the old C keeps weight 1 - c_1 - c_mu; without it C is the mu best steps' alone, positive definite only if they span the parameters), got {c_1} + {c_mu}"
    )]
    RatesSum {
        /// The rank-one rate.
        c_1: f64,
        /// The rank-mu rate.
        c_mu: f64,
        /// The rollouts of a generation that weigh in (half the population).
        mu: usize,
        /// The parameters.
        n_theta: usize,
    },
}

/// Why [`CCmaes::restore`] refuses a state.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CCmaesRestoreError {
    /// A matrix, vector or the generation's rollouts do not have this learner's dimensions.
    #[error("C-CMA-ES state: {what} is {got}, this learner's is {expected}")]
    Shape {
        /// Which part of the state.
        what: &'static str,
        /// Its size in the state.
        got: String,
        /// This learner's.
        expected: String,
    },
    /// A part of the state holds what no live learner does (a number that is not finite or
    /// out of its range, a covariance its sampling factor does not give): a forged or damaged
    /// checkpoint.
    #[error(
        "C-CMA-ES state: {what} holds values no learner could have saved (not finite, out of range, or not consistent)"
    )]
    Values {
        /// Which part.
        what: &'static str,
    },
}

/// The constants of the strategy for one problem's dimensions.
#[derive(Clone, Debug, PartialEq)]
struct Strategy {
    population: usize,
    /// The weights of the ranks 1..=mu, summing to 1.
    weights: Vec<f64>,
    mu_eff: f64,
    c_sigma: f64,
    d_sigma: f64,
    c_c: f64,
    c_1: f64,
    c_mu: f64,
    /// `E ||N(0, I_n_theta)||`.
    chi_n: f64,
    /// `1.4 + 2 / (n_theta + 1)`: the stall test of the path `p_c`.
    h_sigma_threshold: f64,
}

/// How far `1 - c_1 - c_mu` may be from 0 and count as 0: `(1 - c_1) + c_1` rounds to 1 or its
/// neighbours.
const ROUNDING: f64 = 1e-12;

impl Strategy {
    fn new(
        config: &CCmaesConfig,
        n_theta: usize,
        n_s: usize,
        n_phi: usize,
        n_psi: usize,
    ) -> Result<Self, CCmaesCreateError> {
        let population = config.population(n_theta, n_s);
        let needed = (2 * n_phi).max(n_psi + 1).max(2);
        if population < needed {
            return Err(CCmaesCreateError::Population {
                population,
                needed,
                n_phi,
                n_psi,
            });
        }
        let mu = population / 2;
        let raw: Vec<f64> = (1..=mu)
            .map(|i| ((population as f64 + 1.0) / 2.0).ln() - (i as f64).ln())
            .collect();
        let total: f64 = raw.iter().sum();
        let weights: Vec<f64> = raw.iter().map(|w| w / total).collect();
        let mu_eff = 1.0 / weights.iter().map(|w| w * w).sum::<f64>();
        let n = (n_theta + n_s) as f64;
        let rates = &config.rates;
        let c_sigma = rates.c_sigma.unwrap_or((mu_eff + 2.0) / (n + mu_eff + 5.0));
        check_positive("rates.c_sigma", c_sigma)?;
        check_range("rates.c_sigma", c_sigma, (0.0, 1.0))?;
        let d_sigma = rates
            .d_sigma
            .unwrap_or(1.0 + 2.0 * (((mu_eff - 1.0) / (n + 1.0)).sqrt() - 1.0).max(0.0) + c_sigma);
        check_positive("rates.d_sigma", d_sigma)?;
        let c_c = rates.c_c.unwrap_or((4.0 + mu_eff / n) / (n + 4.0 + 2.0 * mu_eff / n));
        check_positive("rates.c_c", c_c)?;
        check_range("rates.c_c", c_c, (0.0, 1.0))?;
        let c_1 = rates.c_1.unwrap_or(2.0 / ((n + 1.3).powi(2) + mu_eff));
        check_range("rates.c_1", c_1, (0.0, 1.0))?;
        let c_mu = rates
            .c_mu
            .unwrap_or((1.0 - c_1).min(2.0 * (mu_eff - 2.0 + 1.0 / mu_eff) / ((n + 2.0).powi(2) + mu_eff)));
        check_range("rates.c_mu", c_mu, (0.0, 1.0))?;
        // Hansen's default reaches c_1 + c_mu = 1 (to rounding) once mu_eff is about (n + 2)^2,
        // from a population of about 4 (n + 2)^2: the old shape then keeps no weight, and C is
        // made of the new steps alone, positive definite when the mu best span n_theta.
        let old_weight = 1.0 - c_1 - c_mu;
        if old_weight < -ROUNDING || (old_weight <= ROUNDING && mu <= n_theta) {
            return Err(CCmaesCreateError::RatesSum { c_1, c_mu, mu, n_theta });
        }
        let c_mu = c_mu.min(1.0 - c_1);
        Ok(Self {
            population,
            weights,
            mu_eff,
            c_sigma,
            d_sigma,
            c_c,
            c_1,
            c_mu,
            chi_n: generation::expected_norm(n_theta),
            h_sigma_threshold: 1.4 + 2.0 / (n_theta as f64 + 1.0),
        })
    }
}

/// What one C-CMA-ES update did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CCmaesReport {
    /// The rollouts of the generation (lambda).
    pub samples: usize,
    /// The step size sigma after the update.
    pub sigma: f64,
    /// `||p_sigma|| / E||N(0, I)||` after the update (about 1 when selection is random; above 1
    /// makes sigma grow).
    pub p_sigma: f64,
    /// `||p_c||` after the update.
    pub p_c: f64,
    /// Whether the path `p_c` was updated (the stall test h_sigma).
    pub h_sigma: bool,
    /// The shift of the mean at the generation's average context features, in units of the
    /// old sigma (in the metric of C).
    pub mean_shift: f64,
    /// The condition number of C (largest over smallest eigenvalue) after the update.
    pub condition: f64,
    /// The effective sample size of the rank weights, `mu_eff = 1 / sum w_i^2`.
    pub ess: f64,
    /// `ln det Sigma` of the policy in force after the update.
    pub logdet_sigma: f64,
    /// `trace Sigma` of that policy.
    pub trace_sigma: f64,
    /// Why the update was rejected; `None` when it was applied.
    pub rejected: Option<Rejection>,
}

/// One rollout of the current generation, its context as the policy's and the baseline's
/// features (computed once, when it is recorded).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Rollout {
    features: Vec<f64>,
    baseline: Vec<f64>,
    theta: Vec<f64>,
    reward: f64,
}

/// Everything of a [`CCmaes`] that changes while it learns (for checkpoints).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CCmaesState {
    weights: DMatrix<f64>,
    sigma: f64,
    shape: DMatrix<f64>,
    sampling_factor: DMatrix<f64>,
    p_sigma: DVector<f64>,
    p_c: DVector<f64>,
    generations: u64,
    feature_scale: DVector<f64>,
    rollouts: Vec<Rollout>,
    dropped: usize,
}

/// A contextual CMA-ES learner: its policy, paths, step size and the rollouts of the current
/// generation.
#[derive(Clone, Debug)]
pub struct CCmaes {
    config: CCmaesConfig,
    strategy: Strategy,
    context_dim: usize,
    policy: LinearGaussianPolicy,
    generation: Generation,
    rollouts: Vec<Rollout>,
    dropped: usize,
}

impl CCmaes {
    /// A learner for `context_dim`-dimensional contexts and initial mean `theta0`. Every field of
    /// `config` and every argument is validated.
    pub fn new(config: CCmaesConfig, context_dim: usize, theta0: &[f64]) -> Result<Self, CCmaesCreateError> {
        check_at_least_one("theta0 length (n_theta)", theta0.len())?;
        check_finite("theta0", theta0)?;
        check_positive("initial_sigma", config.initial_sigma)?;
        check_non_negative("ridge", config.ridge)?;
        check_range("ridge", config.ridge, (0.0, 1.0))?;
        config.features.validate(context_dim, theta0)?;
        config.baseline.validate(context_dim, &[])?;
        let n_phi = config.features.dim(context_dim);
        let n_psi = config.baseline.dim(context_dim);
        let strategy = Strategy::new(&config, theta0.len(), context_dim, n_phi, n_psi)?;
        let mut weights = DMatrix::zeros(n_phi, theta0.len());
        if let Some(constant) = config.features.constant_index(context_dim) {
            weights.row_mut(constant).copy_from_slice(theta0);
        }
        let generation = Generation::start(config.initial_sigma.sqrt(), theta0.len(), n_phi);
        let policy = generation
            .policy(weights)
            .expect("W is finite (theta0 was checked) and sigma_0^2 I with a checked initial_sigma");
        Ok(Self {
            config,
            strategy,
            context_dim,
            policy,
            generation,
            rollouts: Vec::new(),
            dropped: 0,
        })
    }

    /// `theta ~ N(W^T phi(s), sigma^2 C)`, as `W^T phi(s) + L z` with `z` drawn in order from
    /// `rng`.
    ///
    /// # Panics
    /// If `context.len() != context_dim`.
    pub fn sample(&self, context: &[f64], rng: &mut dyn RngCore) -> Vec<f64> {
        self.policy.sample(&self.features(context), rng).data.into()
    }

    /// The mean `W^T phi(s)` (exploration off).
    ///
    /// # Panics
    /// If `context.len() != context_dim`.
    pub fn greedy(&self, context: &[f64]) -> Vec<f64> {
        self.policy.mean(&self.features(context)).data.into()
    }

    /// Stores one rollout and, when it completes a generation, runs the update and returns its
    /// report. A rollout with a non-finite reward, theta, context or feature is not stored, does
    /// not count towards the generation and returns `None` ([`dropped`](Self::dropped) counts
    /// them).
    ///
    /// # Panics
    /// If `context.len() != context_dim` or `theta.len() != n_theta`.
    pub fn record(&mut self, context: &[f64], theta: &[f64], reward: f64) -> Option<CCmaesReport> {
        let Ok(report) = self.record_stopping(context, theta, reward, Never);
        report
    }

    /// [`record`](Self::record), asking `stop` between the steps of the update it triggers
    /// (Ctrl-C, [`Learner::tell_until`](crate::Learner::tell_until)): a stopped update leaves
    /// the learner as it was before this rollout, which is not stored.
    pub(crate) fn record_stopping<S: Stop>(
        &mut self,
        context: &[f64],
        theta: &[f64],
        reward: f64,
        stop: S,
    ) -> Result<Option<CCmaesReport>, S::Halt> {
        self.policy.assert_params(theta);
        let features = self.features(context);
        let baseline = self.config.baseline.apply(context);
        let finite = reward.is_finite()
            && theta.iter().all(|t| t.is_finite())
            && features.iter().chain(&baseline).all(|f| f.is_finite());
        if !finite {
            self.dropped += 1;
            return Ok(None);
        }
        self.rollouts.push(Rollout {
            features: features.data.into(),
            baseline: baseline.data.into(),
            theta: theta.to_vec(),
            reward,
        });
        if self.rollouts.len() < self.strategy.population {
            return Ok(None);
        }
        let rollouts = std::mem::take(&mut self.rollouts);
        match self.update(&rollouts, stop) {
            Ok(report) => Ok(Some(report)),
            Err(halt) => {
                self.rollouts = rollouts;
                self.rollouts.pop();
                Err(halt)
            }
        }
    }

    /// The current policy, `N(W^T phi(s), sigma^2 C)`.
    pub fn policy(&self) -> &LinearGaussianPolicy {
        &self.policy
    }

    /// The configuration.
    pub fn config(&self) -> &CCmaesConfig {
        &self.config
    }

    /// lambda, the rollouts per update.
    pub fn population(&self) -> usize {
        self.strategy.population
    }

    /// The step size sigma.
    pub fn sigma(&self) -> f64 {
        self.generation.sigma
    }

    /// The covariance's shape C (`Sigma = sigma^2 C`).
    pub fn shape(&self) -> &DMatrix<f64> {
        &self.generation.shape
    }

    /// The context dimension.
    pub fn context_dim(&self) -> usize {
        self.context_dim
    }

    /// The number of rollouts [`record`](Self::record) refused because of non-finite values.
    pub fn dropped(&self) -> usize {
        self.dropped
    }

    /// The policy as data; `None` for a user-supplied feature map, which is code.
    pub fn snapshot(&self) -> Option<PolicySnapshot> {
        PolicySnapshot::of(&self.config.features, self.context_dim, &self.policy)
    }

    /// The learning state, for a checkpoint (the sampling factor as it is, so that sampling
    /// continues bit for bit).
    pub fn state(&self) -> CCmaesState {
        let g = &self.generation;
        CCmaesState {
            weights: self.policy.weights().clone(),
            sigma: g.sigma,
            shape: g.shape.clone(),
            sampling_factor: self.policy.sampling_factor().clone(),
            p_sigma: g.p_sigma.clone(),
            p_c: g.p_c.clone(),
            generations: g.count,
            feature_scale: g.feature_scale.clone(),
            rollouts: self.rollouts.clone(),
            dropped: self.dropped,
        }
    }

    /// Continue from `state`, saved by [`state`](Self::state) of a learner built with the same
    /// configuration and dimensions; a state of other dimensions is refused and leaves the
    /// learner unchanged.
    pub fn restore(&mut self, state: CCmaesState) -> Result<(), CCmaesRestoreError> {
        let (n_phi, n_theta) = (self.policy.n_features(), self.policy.n_params());
        let refuse = |what, got: String, expected: String| Err(CCmaesRestoreError::Shape { what, got, expected });
        let size = |m: &DMatrix<f64>| format!("{} x {}", m.nrows(), m.ncols());
        let square = format!("{n_theta} x {n_theta}");
        for (what, matrix, expected) in [
            ("W", &state.weights, format!("{n_phi} x {n_theta}")),
            ("C", &state.shape, square.clone()),
            ("the sampling factor", &state.sampling_factor, square),
        ] {
            if size(matrix) != expected {
                return refuse(what, size(matrix), expected);
            }
        }
        for (what, vector, expected) in [
            ("p_sigma", &state.p_sigma, n_theta),
            ("p_c", &state.p_c, n_theta),
            ("the feature scales", &state.feature_scale, n_phi),
        ] {
            if vector.len() != expected {
                return refuse(what, vector.len().to_string(), expected.to_string());
            }
        }
        if state.rollouts.len() >= self.strategy.population {
            return refuse(
                "the generation's rollout count",
                state.rollouts.len().to_string(),
                format!("below the population {}", self.strategy.population),
            );
        }
        let n_psi = self.config.baseline.dim(self.context_dim);
        let lengths = |r: &Rollout| format!("{}, {} and {}", r.features.len(), r.baseline.len(), r.theta.len());
        let expected = format!("{n_phi}, {n_psi} and {n_theta}");
        if let Some(bad) = state.rollouts.iter().find(|r| lengths(r) != expected) {
            return refuse(
                "a rollout's feature, baseline feature and theta lengths",
                lengths(bad),
                expected,
            );
        }
        let finite = |values: &[f64]| values.iter().all(|x| x.is_finite());
        let values = |what| Err(CCmaesRestoreError::Values { what });
        if !(state.sigma.is_finite() && state.sigma > 0.0) {
            return values("sigma");
        }
        if !(finite(state.p_sigma.as_slice()) && finite(state.p_c.as_slice())) {
            return values("an evolution path");
        }
        if !state.feature_scale.iter().all(|s| s.is_finite() && *s >= 0.0) {
            return values("the feature scales");
        }
        if !state
            .rollouts
            .iter()
            .all(|r| finite(&r.features) && finite(&r.baseline) && finite(&r.theta) && r.reward.is_finite())
        {
            return values("a rollout of the generation");
        }
        if !finite(state.shape.as_slice()) {
            return values("C");
        }
        let covariance = &state.shape * (state.sigma * state.sigma);
        self.policy = LinearGaussianPolicy::from_saved(state.weights, covariance, state.sampling_factor)
            .map_err(|what| CCmaesRestoreError::Values { what })?;
        self.generation = Generation {
            sigma: state.sigma,
            shape: state.shape,
            p_sigma: state.p_sigma,
            p_c: state.p_c,
            count: state.generations,
            feature_scale: state.feature_scale,
        };
        self.rollouts = state.rollouts;
        self.dropped = state.dropped;
        Ok(())
    }

    fn features(&self, context: &[f64]) -> DVector<f64> {
        self.config.features.apply_sized(context, self.context_dim)
    }

    /// One generation's update on `rollouts`; a rejected one keeps the policy, paths and step
    /// size.
    fn update<S: Stop>(&mut self, rollouts: &[Rollout], stop: S) -> Result<CCmaesReport, S::Halt> {
        let rows = |row: fn(&Rollout) -> &[f64]| {
            let width = rollouts.first().map_or(0, |r| row(r).len());
            DMatrix::from_fn(rollouts.len(), width, |i, j| row(&rollouts[i])[j])
        };
        let phi = rows(|r| &r.features);
        let psi = rows(|r| &r.baseline);
        let thetas = rows(|r| &r.theta);
        let returns: Vec<f64> = rollouts.iter().map(|r| r.reward).collect();
        let outcome = self.generation.next(
            &self.strategy,
            self.config.ridge,
            &self.policy,
            &generation::Data {
                phi: &phi,
                psi: &psi,
                thetas: &thetas,
                returns: &returns,
            },
            stop,
        )?;
        let mut report = match outcome {
            Ok((next, policy, report)) => {
                self.generation = next;
                self.policy = policy;
                report
            }
            Err(rejection) => self.generation.report(&self.policy, rollouts.len(), Some(rejection)),
        };
        report.ess = self.strategy.mu_eff;
        Ok(report)
    }
}

#[cfg(test)]
mod tests;
