//! Self-paced contextual reinforcement learning (SPRL; Klink, Abdulsamad, Belousov & Peters,
//! CoRL 2019): contexts drawn from a Gaussian that C-REPS moves together with the policy, from
//! where the policy does well towards the target distribution.
//!
//! SPRL adds a context distribution q to the C-REPS problem: maximise the expected return minus
//! `alpha KL(q' || mu)`, mu the target, with the KL bound on the rollouts' weights and another on
//! the contexts'. One dual ([`solve_joint_dual`](crate::creps::solve_joint_dual)) weights the
//! rollouts for the policy and their contexts for q, which is then refitted by weighted maximum
//! likelihood. With alpha = 0 q moves to where the value of the contexts is high (the easy
//! ones); alpha pulls it towards mu.
//!
//! Here, as the issue asks, the target mu is the uniform distribution over the context space
//! (the problems' test contexts cover it), and q starts with mu's mean and covariance. As in the
//! original:
//! - alpha is 0 for the first `offset` updates, then set so that `alpha KL(q || mu)` is `zeta`
//!   times a scale of the returns (at most `max_alpha`); KL(q || mu) is estimated from the
//!   contexts in memory, `mean(ln q(c_i) - ln mu(c_i))`. The original's scale is `|mean return|`,
//!   which changes when the returns are shifted; here it is their standard deviation, so the
//!   selector is the same whatever the returns' units and offset (alpha is given to C-REPS
//!   relative to it).
//! - The context KL bound is C-REPS' epsilon.
//! - Both M-steps are bounded by KL, as in the original (`KLJoint.refit`): the weighted fit of q
//!   is pulled back towards the current q until `KL(q || q') <= epsilon`, each on its own bound
//!   (the original bounds the sum of the policy's and q's KL by one epsilon).
//! - Every coordinate's standard deviation is kept at least `min_std` times the space's width
//!   (the original clips variances to a lower bound; without it q can collapse on a point).
//! - Draws outside the space are drawn again (the original samples within bounds); after
//!   [`MAX_DRAWS`] misses the last draw is projected into the space.

use crate::creps::{GaussianKl, PacedContexts, PacedTerms, bound_by_kl, log_det};
use crate::selection::geometry::project;
use crate::selection::validate::check_space;
use crate::selection::{Choice, ContextSelector, SelectorCreateError, SelectorRestoreError, SelectorState};
use acps_shared::ContextSpace;
use nalgebra::{Cholesky, DMatrix, DVector, Dyn};
use rand::RngCore;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

/// Draws from q before one outside the space is projected into it.
pub const MAX_DRAWS: usize = 100;

/// SPRL parameters; see the module docs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SelfPacedConfig {
    /// C-REPS updates with alpha = 0 before q is pulled towards the target (60).
    pub offset: usize,
    /// `alpha KL(q || mu)` as a share of the returns' standard deviation, in (0, 100] (8).
    pub zeta: f64,
    /// The largest alpha, relative to the returns' standard deviation, in (0, 1e6] (1e3): the
    /// alpha used when the estimated KL is not positive.
    pub max_alpha: f64,
    /// Floor of every coordinate's standard deviation, as a share of the space's width along
    /// it, in (0, 1] (0.02).
    pub min_std: f64,
}

impl Default for SelfPacedConfig {
    fn default() -> Self {
        Self {
            offset: 60,
            zeta: 8.0,
            max_alpha: 1e3,
            min_std: 0.02,
        }
    }
}

impl SelfPacedConfig {
    /// Check every parameter's range.
    pub fn validate(&self) -> Result<(), SelectorCreateError> {
        let check = |name: &'static str, value: f64, high: f64| {
            if value > 0.0 && value <= high {
                Ok(())
            } else {
                Err(SelectorCreateError::SelfPaced {
                    name,
                    value,
                    range: format!("(0, {high}]"),
                })
            }
        };
        check("zeta", self.zeta, 100.0)?;
        check("max_alpha", self.max_alpha, 1e6)?;
        check("min_std", self.min_std, 1.0)
    }
}

/// The evolving state of a [`SelfPaced`] selector, for checkpoints.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SelfPacedState {
    mean: Vec<f64>,
    /// Row by row.
    covariance: Vec<f64>,
    updates: usize,
}

/// SPRL's Gaussian context distribution as a context selector; C-REPS moves it through
/// [`ContextSelector::paced`] (a [`Learner`](crate::Learner) does so by itself).
///
/// ```
/// use acps_learner::selection::{ContextSelector, SelfPaced, SelfPacedConfig};
/// use acps_shared::ContextSpace;
///
/// let space = ContextSpace::new_box(vec![0.0, 0.0], vec![4.0, 1.0])?;
/// let mut selector = SelfPaced::new(space.clone(), SelfPacedConfig::default())?;
/// // It starts with the uniform target's moments and draws inside the space.
/// assert_eq!(selector.mean(), [2.0, 0.5]);
/// let choice = selector.choose(&mut rand::rng());
/// assert!(choice.arm.is_none() && space.contains(&choice.context));
/// assert!(selector.paced().is_some());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone)]
pub struct SelfPaced {
    space: ContextSpace,
    config: SelfPacedConfig,
    /// `ln mu`, the uniform target's log-density.
    log_target: f64,
    /// The variance floor per coordinate.
    floor: Vec<f64>,
    mean: DVector<f64>,
    covariance: DMatrix<f64>,
    factor: Cholesky<f64, Dyn>,
    updates: usize,
}

impl SelfPaced {
    /// SPRL over `space`, targeting the uniform distribution over it, starting from that
    /// distribution's mean and covariance.
    pub fn new(space: ContextSpace, config: SelfPacedConfig) -> Result<Self, SelectorCreateError> {
        check_space(&space)?;
        config.validate()?;
        let dim = space.dim();
        let (low, high) = space.bounding_box();
        let floor = low
            .iter()
            .zip(&high)
            .map(|(l, h)| (config.min_std * (h - l)).powi(2))
            .collect();
        let (mean, variance, log_volume) = match &space {
            ContextSpace::Box { low, high } => (
                low.iter().zip(high).map(|(l, h)| 0.5 * (l + h)).collect(),
                low.iter().zip(high).map(|(l, h)| (h - l).powi(2) / 12.0).collect(),
                low.iter().zip(high).map(|(l, h)| (h - l).ln()).sum(),
            ),
            ContextSpace::Ball { dim, radius } => (
                vec![0.0; *dim],
                vec![radius * radius / (*dim as f64 + 2.0); *dim],
                log_ball_volume(*dim, *radius),
            ),
        };
        let mean = DVector::from_vec(mean);
        let covariance = DMatrix::from_diagonal(&DVector::<f64>::from_vec(variance));
        let factor = Cholesky::new(covariance.clone()).expect("a diagonal of positive variances");
        debug_assert_eq!(mean.len(), dim);
        Ok(Self {
            space,
            config,
            log_target: -log_volume,
            floor,
            mean,
            covariance,
            factor,
            updates: 0,
        })
    }

    /// The parameters.
    pub fn config(&self) -> &SelfPacedConfig {
        &self.config
    }

    /// The mean of the context distribution q.
    pub fn mean(&self) -> &[f64] {
        self.mean.as_slice()
    }

    /// The covariance of q.
    pub fn covariance(&self) -> &DMatrix<f64> {
        &self.covariance
    }

    /// Updates so far.
    pub fn updates(&self) -> usize {
        self.updates
    }

    /// `ln q(c)` of each context.
    fn log_densities<'a>(&'a self, contexts: &'a [&[f64]]) -> impl Iterator<Item = f64> + 'a {
        let dim = self.mean.len() as f64;
        let normaliser = -0.5 * (dim * (2.0 * std::f64::consts::PI).ln() + log_det(&self.factor));
        contexts.iter().map(move |c| {
            let centred = DVector::from_column_slice(c) - &self.mean;
            let whitened = self
                .factor
                .l_dirty()
                .solve_lower_triangular(&centred)
                .expect("a Cholesky factor has a positive diagonal");
            normaliser - 0.5 * whitened.norm_squared()
        })
    }

    /// The covariance with every variance raised to its floor, and its Cholesky factor. When a
    /// coordinate's variance given the ones before it is still below its floor (contexts on a
    /// line, where it is 0 up to rounding), the floor is added to the whole diagonal.
    fn floored(&self, mut covariance: DMatrix<f64>) -> Option<(DMatrix<f64>, Cholesky<f64, Dyn>)> {
        for (j, floor) in self.floor.iter().enumerate() {
            covariance[(j, j)] = covariance[(j, j)].max(*floor);
        }
        let conditional_above_floor = |factor: &Cholesky<f64, Dyn>| {
            let diagonal = factor.l_dirty().diagonal();
            diagonal.iter().zip(&self.floor).all(|(l, floor)| l * l >= *floor)
        };
        if let Some(factor) = Cholesky::new(covariance.clone()).filter(conditional_above_floor) {
            return Some((covariance, factor));
        }
        for (j, floor) in self.floor.iter().enumerate() {
            covariance[(j, j)] += floor;
        }
        Cholesky::new(covariance.clone()).map(|factor| (covariance, factor))
    }
}

/// `ln` of the volume of a `dim`-ball of `radius`: `V_d = V_{d-2} 2 pi r^2 / d`.
fn log_ball_volume(dim: usize, radius: f64) -> f64 {
    let mut log_unit = if dim.is_multiple_of(2) { 0.0 } else { 2f64.ln() };
    let mut d = if dim.is_multiple_of(2) { 2 } else { 3 };
    while d <= dim {
        log_unit += (2.0 * std::f64::consts::PI / d as f64).ln();
        d += 2;
    }
    log_unit + dim as f64 * radius.ln()
}

impl ContextSelector for SelfPaced {
    /// One standard normal per dimension per draw, until a draw lies in the space (at most
    /// [`MAX_DRAWS`]).
    fn choose(&mut self, rng: &mut dyn RngCore) -> Choice {
        let dim = self.mean.len();
        let mut point = Vec::new();
        for _ in 0..MAX_DRAWS {
            let z = DVector::from_fn(dim, |_, _| StandardNormal.sample(&mut *rng));
            point = (&self.mean + self.factor.l_dirty() * z).data.into();
            if self.space.contains(&point) {
                return Choice {
                    arm: None,
                    context: point,
                };
            }
        }
        Choice {
            arm: None,
            context: project(&self.space, point),
        }
    }

    /// Nothing: q moves with the C-REPS updates only.
    fn observe(&mut self, _choice: &Choice, _reward: f64) {}

    fn paced(&mut self) -> Option<&mut dyn PacedContexts> {
        Some(self)
    }

    fn save_state(&self) -> SelectorState {
        SelectorState::SelfPaced(SelfPacedState {
            mean: self.mean.as_slice().to_vec(),
            covariance: self.covariance.transpose().as_slice().to_vec(),
            updates: self.updates,
        })
    }

    fn restore_state(&mut self, state: SelectorState) -> Result<(), SelectorRestoreError> {
        let SelectorState::SelfPaced(state) = state else {
            return Err(state.wrong_kind("self-paced"));
        };
        let dim = self.mean.len();
        if state.mean.len() != dim || state.covariance.len() != dim * dim {
            return Err(SelectorRestoreError::SelfPaced(format!(
                "a distribution over {} dimensions, expected {dim}",
                state.mean.len()
            )));
        }
        // As a live one: its mean a weighted mean of contexts in the space, every variance
        // between its floor and what contexts in the space can spread (the floor may be added
        // to a whole diagonal: the square of the width, four times the most, bounds both). A
        // forged 1e300 would otherwise reach C-REPS as an infinite log-density ratio.
        let (low, high) = self.space.bounding_box();
        for j in 0..dim {
            let (mean, variance, width) = (state.mean[j], state.covariance[j * dim + j], high[j] - low[j]);
            if !(low[j]..=high[j]).contains(&mean) {
                return Err(SelectorRestoreError::SelfPaced(format!(
                    "mean coordinate {j} is {mean:?}, outside the space's {}..={}",
                    low[j], high[j]
                )));
            }
            let floor = self.floor[j] * (1.0 - 1e-9);
            if !(floor..=width * width).contains(&variance) {
                return Err(SelectorRestoreError::SelfPaced(format!(
                    "variance {j} is {variance:?}, outside {floor}..={} (the floor of min_std, and the square of the space's width)",
                    width * width
                )));
            }
        }
        let covariance = DMatrix::from_row_slice(dim, dim, &state.covariance);
        let finite = state.mean.iter().chain(&state.covariance).all(|x| x.is_finite());
        let factor = Cholesky::new(covariance.clone())
            .filter(|_| finite)
            .ok_or_else(|| SelectorRestoreError::SelfPaced("a covariance that is not positive definite".into()))?;
        self.mean = DVector::from_vec(state.mean);
        self.covariance = covariance;
        self.factor = factor;
        self.updates = state.updates;
        Ok(())
    }
}

impl PacedContexts for SelfPaced {
    fn terms(&self, contexts: &[&[f64]]) -> PacedTerms {
        let log_ratio: Vec<f64> = self.log_densities(contexts).map(|q| self.log_target - q).collect();
        let alpha = if self.updates < self.config.offset {
            0.0
        } else {
            let kl = -log_ratio.iter().sum::<f64>() / log_ratio.len().max(1) as f64;
            if kl > 0.0 {
                (self.config.zeta / kl).min(self.config.max_alpha)
            } else {
                self.config.max_alpha
            }
        };
        PacedTerms { alpha, log_ratio }
    }

    /// Weighted maximum likelihood pulled back towards the current q (as the policy's fit, see
    /// [`update_paced`](crate::creps::update_paced)) until `KL(q || q')` is at most `epsilon`,
    /// with the variance floor applied: `m' = (sum w c + nu m) / (1 + nu)`,
    /// `Sigma' = (sum w (c - m')(c - m')^T + nu (Sigma + (m - m')(m - m')^T)) / (1 + nu)`.
    fn refit(&mut self, contexts: &[&[f64]], weights: Option<&[f64]>, epsilon: f64) {
        self.updates += 1;
        let Some(fit) = weights.and_then(|weights| WeightedMoments::new(contexts, weights)) else {
            return;
        };
        let kl_from = GaussianKl::new(&self.covariance).expect("q's covariance has a factor");
        let kl = |nu: f64| match self.towards(&fit, nu) {
            Some(refit) => {
                let shift = refit.mean - &self.mean;
                kl_from.to(&refit.covariance, &(&shift * shift.transpose()))
            }
            None => f64::INFINITY,
        };
        let nu = bound_by_kl(kl, epsilon);
        if let Some(refit) = self.towards(&fit, nu) {
            self.mean = refit.mean;
            self.covariance = refit.covariance;
            self.factor = refit.factor;
        }
    }
}

/// The weighted contexts' total weight, mean and second moment about that mean: all a refit
/// needs of them, whatever its pull.
struct WeightedMoments {
    total: f64,
    mean: DVector<f64>,
    spread: DMatrix<f64>,
}

impl WeightedMoments {
    /// `None` without weight or with non-finite moments.
    fn new(contexts: &[&[f64]], weights: &[f64]) -> Option<Self> {
        let dim = contexts.first()?.len();
        let total: f64 = weights.iter().sum();
        let mut mean = DVector::zeros(dim);
        for (c, w) in contexts.iter().zip(weights) {
            mean.axpy(*w / total, &DVector::from_column_slice(c), 1.0);
        }
        let mut spread = DMatrix::zeros(dim, dim);
        for (c, w) in contexts.iter().zip(weights) {
            let centred = DVector::from_column_slice(c) - &mean;
            spread.ger(*w / total, &centred, &centred, 1.0);
        }
        let finite = total > 0.0 && mean.iter().chain(spread.iter()).all(|x| x.is_finite());
        finite.then_some(Self { total, mean, spread })
    }
}

impl SelfPaced {
    /// The refit pulled towards q by `nu`, floored, with its factor; `None` if not finite.
    fn towards(&self, fit: &WeightedMoments, nu: f64) -> Option<Refit> {
        let total = fit.total + nu;
        let mean = (&fit.mean * fit.total + &self.mean * nu) / total;
        let (to_fit, to_old) = (&fit.mean - &mean, &self.mean - &mean);
        let covariance = ((&fit.spread + &to_fit * to_fit.transpose()) * fit.total
            + (&self.covariance + &to_old * to_old.transpose()) * nu)
            / total;
        if !mean.iter().chain(covariance.iter()).all(|x| x.is_finite()) {
            return None;
        }
        self.floored(covariance).map(|(covariance, factor)| Refit {
            mean,
            covariance,
            factor,
        })
    }
}

/// A candidate q: mean, covariance and its factor.
struct Refit {
    mean: DVector<f64>,
    covariance: DMatrix<f64>,
    factor: Cholesky<f64, Dyn>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn unit_square() -> SelfPaced {
        let space = ContextSpace::new_box(vec![0.0, -1.0], vec![1.0, 1.0]).unwrap();
        SelfPaced::new(space, SelfPacedConfig::default()).unwrap()
    }

    #[test]
    fn starts_with_the_targets_moments_and_draws_inside_the_space() {
        let mut selector = unit_square();
        assert_eq!(selector.mean(), [0.5, 0.0]);
        assert_eq!(selector.covariance()[(0, 0)], 1.0 / 12.0);
        assert_eq!(selector.covariance()[(1, 1)], 4.0 / 12.0);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let draws: Vec<Vec<f64>> = (0..4000).map(|_| selector.choose(&mut rng).context).collect();
        assert!(draws.iter().all(|c| selector.space.contains(c)));
        for (d, centre) in [(0, 0.5), (1, 0.0)] {
            let mean = draws.iter().map(|c| c[d]).sum::<f64>() / draws.len() as f64;
            assert!((mean - centre).abs() < 0.02, "coordinate {d}: mean {mean}");
        }
    }

    #[test]
    fn log_density_is_the_gaussians() {
        let mut selector = unit_square();
        selector.refit(
            &[&[0.2, 0.3], &[0.4, 0.1], &[0.3, -0.5]],
            Some(&[0.5, 0.3, 0.2]),
            f64::INFINITY,
        );
        let (m, s) = (selector.mean.clone(), selector.covariance.clone());
        let c = [0.7, 0.2];
        let (dx, dy) = (c[0] - m[0], c[1] - m[1]);
        let det = s[(0, 0)] * s[(1, 1)] - s[(0, 1)] * s[(1, 0)];
        let quad = (s[(1, 1)] * dx * dx - 2.0 * s[(0, 1)] * dx * dy + s[(0, 0)] * dy * dy) / det;
        let expected = -(2.0 * std::f64::consts::PI).ln() - 0.5 * det.ln() - 0.5 * quad;
        let got = selector.log_densities(&[&c]).next().unwrap();
        assert!((got - expected).abs() < 1e-12);
    }

    #[test]
    fn alpha_is_zero_before_the_offset_then_zeta_over_the_kl() {
        let space = ContextSpace::new_box(vec![0.0], vec![2.0]).unwrap();
        let config = SelfPacedConfig {
            offset: 2,
            ..SelfPacedConfig::default()
        };
        let mut selector = SelfPaced::new(space, config).unwrap();
        let contexts: Vec<&[f64]> = vec![&[0.95], &[1.0], &[1.1]];
        for _ in 0..2 {
            assert_eq!(selector.terms(&contexts).alpha, 0.0);
            selector.refit(&contexts, None, f64::INFINITY);
        }
        // Narrow q around 1: KL(q || U[0, 2]) is positive.
        selector.refit(&[&[0.9], &[1.1]], Some(&[0.5, 0.5]), f64::INFINITY);
        let terms = selector.terms(&contexts);
        let variance = selector.covariance()[(0, 0)];
        let log_q = |x: f64| -0.5 * ((2.0 * std::f64::consts::PI * variance).ln() + (x - 1.0).powi(2) / variance);
        let expected: Vec<f64> = [0.95, 1.0, 1.1].iter().map(|&x| -(2f64.ln()) - log_q(x)).collect();
        for (got, want) in terms.log_ratio.iter().zip(&expected) {
            assert!((got - want).abs() < 1e-12, "{got} vs {want}");
        }
        let kl = -expected.iter().sum::<f64>() / 3.0;
        assert!(kl > 0.0);
        assert!((terms.alpha - selector.config().zeta / kl).abs() < 1e-15);
        assert_eq!(selector.updates(), 3);
    }

    #[test]
    fn a_wide_q_gets_the_largest_alpha() {
        let space = ContextSpace::new_box(vec![0.0], vec![1.0]).unwrap();
        let config = SelfPacedConfig {
            offset: 0,
            ..SelfPacedConfig::default()
        };
        let selector = SelfPaced::new(space, config).unwrap();
        // q = N(0.5, 1/12) against U[0, 1] = mu: ln q < ln mu = 0 near the edges, so contexts
        // there give a negative KL estimate; at the centre a positive one.
        assert_eq!(selector.terms(&[&[0.05], &[0.95]]).alpha, 1e3);
        let centre = selector.terms(&[&[0.5]]).alpha;
        assert!(centre > 0.0 && centre < 1e3);
    }

    #[test]
    fn refit_is_weighted_maximum_likelihood_with_the_floor() {
        let mut selector = unit_square();
        let contexts: Vec<&[f64]> = vec![&[0.1, 0.5], &[0.3, 0.5], &[0.2, 0.9]];
        selector.refit(&contexts, Some(&[0.25, 0.25, 0.5]), f64::INFINITY);
        assert!((selector.mean()[0] - 0.2).abs() < 1e-15 && (selector.mean()[1] - 0.7).abs() < 1e-15);
        assert!((selector.covariance()[(0, 0)] - 0.005).abs() < 1e-15);
        assert!((selector.covariance()[(1, 1)] - 0.04).abs() < 1e-15);
        // All the weight on contexts with one y: its variance is raised to (0.02 x 2)^2.
        selector.refit(&[&[0.1, 0.5], &[0.3, 0.5]], Some(&[0.5, 0.5]), f64::INFINITY);
        assert_eq!(selector.covariance()[(1, 1)], 0.04f64.powi(2));
    }

    #[test]
    fn refit_moves_q_by_at_most_epsilon() {
        let far: Vec<&[f64]> = vec![&[0.95, 0.9], &[0.9, 0.95]];
        let mut free = unit_square();
        free.refit(&far, Some(&[0.5, 0.5]), f64::INFINITY);
        for epsilon in [0.05, 0.5, 2.0] {
            let mut bounded = unit_square();
            let start = unit_square();
            bounded.refit(&far, Some(&[0.5, 0.5]), epsilon);
            let shift = &bounded.mean - &start.mean;
            let kl = GaussianKl::new(&start.covariance)
                .unwrap()
                .to(&bounded.covariance, &(&shift * shift.transpose()));
            assert!(kl <= epsilon && kl > 0.9 * epsilon, "epsilon {epsilon}: KL {kl}");
            // Part of the way: between the start and the free fit.
            assert!(bounded.mean()[0] > start.mean()[0] && bounded.mean()[0] < free.mean()[0]);
        }
    }

    #[test]
    fn collinear_contexts_still_give_a_factor() {
        let mut selector = unit_square();
        selector.refit(
            &[&[0.0, -1.0], &[0.5, 0.0], &[1.0, 1.0]],
            Some(&[0.3, 0.4, 0.3]),
            f64::INFINITY,
        );
        let covariance = selector.covariance();
        // The weighted covariance is singular; the floor is added to its whole diagonal.
        assert!((covariance[(0, 0)] - (0.15 + 0.02f64.powi(2))).abs() < 1e-15);
        assert!((covariance[(1, 1)] - (0.6 + 0.04f64.powi(2))).abs() < 1e-15);
        assert!((covariance[(0, 1)] - 0.3).abs() < 1e-15);
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let choice = selector.choose(&mut rng);
        assert!(selector.space.contains(&choice.context));
    }

    #[test]
    fn restored_states_a_live_selector_cannot_have_are_refused() {
        let selector = unit_square();
        let SelectorState::SelfPaced(live) = selector.save_state() else {
            panic!("a self-paced state")
        };
        let forged = |change: fn(&mut SelfPacedState)| {
            let mut state = live.clone();
            change(&mut state);
            unit_square()
                .restore_state(SelectorState::SelfPaced(state))
                .unwrap_err()
                .to_string()
        };
        assert!(forged(|s| s.mean[0] = 1e300).contains("mean coordinate 0 is 1e300, outside the space's"));
        assert!(forged(|s| s.covariance[3] = 1e300).contains("variance 1 is 1e300, outside"));
        assert!(forged(|s| s.covariance[0] = 0.0).contains("variance 0 is 0.0, outside"));
        assert!(forged(|s| s.mean[1] = f64::NAN).contains("mean coordinate 1 is NaN"));
        let mut restored = unit_square();
        restored.restore_state(SelectorState::SelfPaced(live)).unwrap();
    }

    #[test]
    fn restored_selectors_draw_the_same_contexts() {
        let mut selector = unit_square();
        selector.refit(
            &[&[0.2, 0.3], &[0.4, 0.1], &[0.3, -0.5]],
            Some(&[0.5, 0.3, 0.2]),
            f64::INFINITY,
        );
        let mut restored = unit_square();
        restored.restore_state(selector.save_state()).unwrap();
        assert_eq!(restored.updates(), 1);
        let (mut a, mut b) = (ChaCha8Rng::seed_from_u64(5), ChaCha8Rng::seed_from_u64(5));
        for _ in 0..50 {
            assert_eq!(selector.choose(&mut a), restored.choose(&mut b));
        }
        let one_d = SelfPaced::new(
            ContextSpace::new_box(vec![0.0], vec![1.0]).unwrap(),
            SelfPacedConfig::default(),
        );
        let error = one_d.unwrap().restore_state(selector.save_state()).unwrap_err();
        assert_eq!(
            error.to_string(),
            "selector state: self-paced: a distribution over 2 dimensions, expected 1"
        );
        let mut broken = selector.save_state();
        if let SelectorState::SelfPaced(state) = &mut broken {
            state.covariance[0] = -1.0;
        }
        assert!(restored.restore_state(broken).is_err());
        assert!(matches!(
            restored.restore_state(SelectorState::UniformContinuous),
            Err(SelectorRestoreError::WrongKind { .. })
        ));
    }

    #[test]
    fn parameters_out_of_range_are_refused() {
        let space = ContextSpace::new_box(vec![0.0], vec![1.0]).unwrap();
        for (config, message) in [
            (
                SelfPacedConfig {
                    zeta: 0.0,
                    ..Default::default()
                },
                "self-paced zeta must be in (0, 100], got 0",
            ),
            (
                SelfPacedConfig {
                    max_alpha: f64::NAN,
                    ..Default::default()
                },
                "self-paced max_alpha must be in (0, 1000000], got NaN",
            ),
            (
                SelfPacedConfig {
                    min_std: 1.5,
                    ..Default::default()
                },
                "self-paced min_std must be in (0, 1], got 1.5",
            ),
        ] {
            let error = SelfPaced::new(space.clone(), config).unwrap_err();
            assert_eq!(error.to_string(), message);
        }
    }

    #[test]
    fn ball_volumes() {
        let pi = std::f64::consts::PI;
        for (dim, volume) in [
            (1, 2.0 * 3.0),
            (2, pi * 9.0),
            (3, 4.0 / 3.0 * pi * 27.0),
            (4, pi * pi / 2.0 * 81.0),
        ] {
            assert!((log_ball_volume(dim, 3.0) - f64::ln(volume)).abs() < 1e-12, "dim {dim}");
        }
    }
}
