//! One C-CMA-ES generation: from the rollouts of the current policy to the next step size,
//! shape, paths and policy.

use nalgebra::{Cholesky, DMatrix, DVector, SymmetricEigen};

use super::{CCmaesReport, Strategy};
use crate::creps::{LinearGaussianPolicy, PolicyCreateError, Rejection, scale_rows, tr_mul_stopping};
use crate::stop::Stop;

/// What [`Generation::next`] makes: the next generation, its policy and the update's report.
pub(super) type Next = (Generation, LinearGaussianPolicy, CCmaesReport);

/// The step size, the covariance's shape and the two evolution paths, after `count`
/// generations.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Generation {
    pub(super) sigma: f64,
    pub(super) shape: DMatrix<f64>,
    pub(super) p_sigma: DVector<f64>,
    pub(super) p_c: DVector<f64>,
    pub(super) count: u64,
    /// Per policy feature, the largest weighted mean of its square over the generations so
    /// far: the scale its ridge is relative to.
    pub(super) feature_scale: DVector<f64>,
}

/// A generation's rollouts, one row each: policy features, baseline features, parameters and
/// returns, all finite.
pub(super) struct Data<'a> {
    pub(super) phi: &'a DMatrix<f64>,
    pub(super) psi: &'a DMatrix<f64>,
    pub(super) thetas: &'a DMatrix<f64>,
    pub(super) returns: &'a [f64],
}

/// The largest change of `ln sigma` in one generation. The first generations' regression can
/// move the mean by many sigma (it fits the context coefficients from scratch), and an uncapped
/// path would then multiply sigma by e^that.
const MAX_LOG_STEP: f64 = 1.0;

impl Generation {
    /// Generation 0: `sigma_0`, `C = I`, both paths 0, no feature scales yet.
    pub(super) fn start(sigma: f64, n_theta: usize, n_phi: usize) -> Self {
        Self {
            sigma,
            shape: DMatrix::identity(n_theta, n_theta),
            p_sigma: DVector::zeros(n_theta),
            p_c: DVector::zeros(n_theta),
            count: 0,
            feature_scale: DVector::zeros(n_phi),
        }
    }

    /// The policy `N(W^T phi, sigma^2 C)` with mean coefficients `weights`.
    pub(super) fn policy(&self, weights: DMatrix<f64>) -> Result<LinearGaussianPolicy, PolicyCreateError> {
        LinearGaussianPolicy::new(weights, &self.shape * (self.sigma * self.sigma))
    }

    /// The next generation and its policy from the rollouts `data` of `policy` (this
    /// generation's), or why the update is rejected; asks `stop` before its sum over the
    /// rollouts and every 8 columns of it.
    pub(super) fn next<S: Stop>(
        &self,
        strategy: &Strategy,
        ridge: f64,
        policy: &LinearGaussianPolicy,
        data: &Data,
        stop: S,
    ) -> Result<Result<Next, Rejection>, S::Halt> {
        let n = data.returns.len();
        let weights = rank_weights(&advantages(data.psi, data.returns, ridge), &strategy.weights);
        let old_w = policy.weights();
        // The residuals of the old mean, which the rank-mu update uses too, regressed on the
        // features: the ridge pulls the change of W towards 0, so that directions of W the
        // generation's contexts do not determine (a selector that practised a few contexts
        // only) keep their old values instead of being set by rounding.
        let residuals = data.thetas - data.phi * old_w;
        // A feature that is about 0 in this generation's contexts but not in others' keeps the
        // ridge of its scale elsewhere: relative to its own square here, its coefficient's change
        // would be nearly free and set by rounding (the dartboard's targets on the angle's zero).
        let squares = DVector::from_fn(data.phi.ncols(), |j, _| {
            data.phi
                .column(j)
                .iter()
                .zip(&weights)
                .map(|(x, w)| w * x * x)
                .sum::<f64>()
        });
        let feature_scale = self.feature_scale.zip_map(&squares, f64::max);
        let Some(regression) = Ridge::new(data.phi, &weights, ridge, feature_scale.as_slice()) else {
            return Ok(Err(Rejection::SingularRegression));
        };
        let step = regression.solve(&residuals);
        let new_w = old_w + &step;
        if !new_w.iter().all(|w| w.is_finite()) {
            return Ok(Err(Rejection::MeanNotFinite));
        }
        // The change of the mean at the generation's average features drives the paths. It is
        // sum_i a_i y_i of the residuals y_i ~ N(0, C), so under random selection its variance
        // is ||a||^2 C: 1 / mu_eff, as CSA assumes, only where the average is the weights' own
        // and there is no ridge. The regression extrapolates the selected rollouts' residuals
        // to the contexts they were not drawn in, ||a||^2 is then larger, and with 1 / mu_eff
        // in its place sigma ran away on the dartboard with monotonic progress (CHOICES.md).
        let mean_phi = data.phi.row_mean().transpose();
        let shift = step.tr_mul(&mean_phi) / self.sigma;
        let variance = regression.variance_at(&mean_phi);
        let samples = if variance > 0.0 { 1.0 / variance } else { 0.0 };

        let eigen = SymmetricEigen::new(self.shape.clone());
        if eigen.eigenvalues.min() <= 0.0 {
            return Ok(Err(Rejection::CovarianceNotPositiveSemiDefinite));
        }
        let inverse_roots = eigen.eigenvalues.map(|d| 1.0 / d.sqrt());
        let inverse_sqrt =
            &eigen.eigenvectors * DMatrix::from_diagonal(&inverse_roots) * eigen.eigenvectors.transpose();
        let whitened_shift = inverse_sqrt * &shift;

        let (c_sigma, c_c) = (strategy.c_sigma, strategy.c_c);
        let count = self.count + 1;
        let p_sigma = &self.p_sigma * (1.0 - c_sigma) + &whitened_shift * (c_sigma * (2.0 - c_sigma) * samples).sqrt();
        let unbiased = p_sigma.norm() / (1.0 - (1.0 - c_sigma).powf(2.0 * count as f64)).sqrt();
        let h_sigma = unbiased < strategy.h_sigma_threshold * strategy.chi_n;
        let mut p_c = &self.p_c * (1.0 - c_c);
        if h_sigma {
            p_c += &shift * (c_c * (2.0 - c_c) * samples).sqrt();
        }

        let residuals = residuals / self.sigma;
        let weight_vector = DVector::from_column_slice(&weights);
        let rank_mu = tr_mul_stopping(&residuals, &scale_rows(&residuals, &weight_vector), stop)?;
        stop.check()?;
        let lost = if h_sigma { 0.0 } else { c_c * (2.0 - c_c) };
        let (c_1, c_mu) = (strategy.c_1, strategy.c_mu);
        let shape = &self.shape * (1.0 - c_1 - c_mu + c_1 * lost) + &p_c * p_c.transpose() * c_1 + rank_mu * c_mu;
        let shape = (&shape + shape.transpose()) * 0.5;
        if !shape.iter().all(|c| c.is_finite()) {
            return Ok(Err(Rejection::CovarianceNotFinite));
        }
        let log_step = (c_sigma / strategy.d_sigma) * (p_sigma.norm() / strategy.chi_n - 1.0);
        let sigma = self.sigma * log_step.min(MAX_LOG_STEP).exp();
        let next = Self {
            sigma,
            shape,
            p_sigma,
            p_c,
            count,
            feature_scale,
        };
        let Ok(policy) = next.policy(new_w) else {
            return Ok(Err(Rejection::CovarianceNotPositiveSemiDefinite));
        };
        let mut report = next.report(&policy, n, None);
        report.h_sigma = h_sigma;
        report.mean_shift = whitened_shift.norm();
        Ok(Ok((next, policy, report)))
    }

    /// The report of an update that leaves this generation with `policy` (mean shift 0, h_sigma
    /// false and ess 0 until the caller says otherwise).
    pub(super) fn report(
        &self,
        policy: &LinearGaussianPolicy,
        samples: usize,
        rejected: Option<Rejection>,
    ) -> CCmaesReport {
        // The sampling factor's columns are the eigenvectors of Sigma scaled by the roots of
        // their eigenvalues, and C's eigenvalues are Sigma's over sigma^2.
        let eigenvalues: Vec<f64> = policy
            .sampling_factor()
            .column_iter()
            .map(|c| c.norm_squared())
            .collect();
        let largest = eigenvalues.iter().copied().fold(0.0, f64::max);
        let smallest = eigenvalues.iter().copied().fold(f64::INFINITY, f64::min);
        CCmaesReport {
            samples,
            sigma: self.sigma,
            p_sigma: self.p_sigma.norm() / expected_norm(self.p_sigma.len()),
            p_c: self.p_c.norm(),
            h_sigma: false,
            mean_shift: 0.0,
            condition: largest / smallest,
            ess: 0.0,
            logdet_sigma: policy.log_det_covariance(),
            trace_sigma: policy.covariance().trace(),
            rejected,
        }
    }
}

/// `E ||N(0, I_n)||`, Hansen's approximation.
pub(super) fn expected_norm(n: usize) -> f64 {
    let k = n as f64;
    k.sqrt() * (1.0 - 1.0 / (4.0 * k) + 1.0 / (21.0 * k * k))
}

/// The returns, standardised, minus their ridge fit on the baseline features `psi`: what is
/// left of each return after what its context makes of it. All 0 when the returns are equal.
fn advantages(psi: &DMatrix<f64>, returns: &[f64], ridge: f64) -> Vec<f64> {
    let n = returns.len() as f64;
    let mean = returns.iter().sum::<f64>() / n;
    let spread = (returns.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n).sqrt();
    if spread == 0.0 {
        return vec![0.0; returns.len()];
    }
    let standardised = DMatrix::from_iterator(returns.len(), 1, returns.iter().map(|r| (r - mean) / spread));
    let ones = vec![1.0; returns.len()];
    match Ridge::new(psi, &ones, ridge, &[]) {
        Some(baseline) => (&standardised - psi * baseline.solve(&standardised))
            .iter()
            .copied()
            .collect(),
        // Features that are all 0: no baseline to take.
        None => standardised.iter().copied().collect(),
    }
}

/// The weight of each rollout: `ranked[k]` for the rollout of the (k+1)-th largest advantage,
/// 0 beyond them. Rollouts of equal advantage (the dartboard's misses of one field) share the
/// weights of the ranks they span equally: their order says nothing of their parameters, and
/// choosing the first of them would choose the context a selector practised first.
fn rank_weights(advantages: &[f64], ranked: &[f64]) -> Vec<f64> {
    let mut order: Vec<usize> = (0..advantages.len()).collect();
    order.sort_by(|&a, &b| advantages[b].total_cmp(&advantages[a]).then(a.cmp(&b)));
    let mut weights = vec![0.0; advantages.len()];
    let mut start = 0;
    while start < order.len() {
        let value = advantages[order[start]];
        let end = start + order[start..].iter().take_while(|&&i| advantages[i] == value).count();
        let shared = ranked.iter().take(end).skip(start).sum::<f64>() / (end - start) as f64;
        for &i in &order[start..end] {
            weights[i] = shared;
        }
        start = end;
    }
    weights
}

/// A weighted ridge regression on the rows of `X`: `(X^T D X + R)^-1 X^T D Y` with
/// `D = diag(weights)` and `R` the diagonal of `X^T D X`, or the larger `scale` where given,
/// times `ridge` (Marquardt's scaling).
struct Ridge {
    /// `D X`.
    weighted: DMatrix<f64>,
    /// Of `X^T D X + R`.
    normal: Cholesky<f64, nalgebra::Dyn>,
}

impl Ridge {
    /// The regression, or `None` when `X^T D X + R` is not positive definite.
    fn new(x: &DMatrix<f64>, weights: &[f64], ridge: f64, scale: &[f64]) -> Option<Self> {
        let weighted = scale_rows(x, &DVector::from_column_slice(weights));
        let mut normal = weighted.tr_mul(x);
        let mean_diagonal = normal.trace() / normal.nrows() as f64;
        for i in 0..normal.nrows() {
            // Each feature's own scale, floored so that a feature that is 0 in every rollout
            // still gets a ridge.
            let own = scale.get(i).copied().unwrap_or(0.0).max(normal[(i, i)]);
            normal[(i, i)] += ridge * own.max(1e-12 * mean_diagonal);
        }
        Some(Self {
            normal: Cholesky::new(normal)?,
            weighted,
        })
    }

    /// The coefficients for the targets `y` (a row per row of `X`).
    fn solve(&self, y: &DMatrix<f64>) -> DMatrix<f64> {
        self.normal.solve(&self.weighted.tr_mul(y))
    }

    /// The variance of the fit at `point` for targets of unit variance, independent of each
    /// other and of the weights: `||D X (X^T D X + R)^-1 point||^2`.
    fn variance_at(&self, point: &DVector<f64>) -> f64 {
        (&self.weighted * self.normal.solve(point)).norm_squared()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::StandardNormal;

    #[test]
    fn equal_advantages_share_their_ranks_weights_and_the_rest_get_nothing() {
        let weights = rank_weights(&[1.0, 3.0, 1.0, 3.0, -2.0], &[0.5, 0.3, 0.2]);
        assert_eq!(weights, vec![0.1, 0.4, 0.1, 0.4, 0.0]);
        let distinct = rank_weights(&[1.0, 3.0, 2.0, 0.0], &[0.5, 0.3, 0.2]);
        assert_eq!(distinct, vec![0.2, 0.5, 0.3, 0.0]);
    }

    #[test]
    fn the_baseline_takes_out_what_the_context_explains() {
        // Returns = 10 s + an own part orthogonal to the features [s, 1]: the advantages are the
        // own parts, in the standardised returns' units.
        let contexts = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0];
        let own = [0.1, -0.2, 0.1, 0.1, -0.2, 0.1];
        let psi = DMatrix::from_fn(6, 2, |i, j| if j == 0 { contexts[i] } else { 1.0 });
        let returns: Vec<f64> = contexts.iter().zip(&own).map(|(s, o)| 10.0 * s + o).collect();
        let advantages = advantages(&psi, &returns, 0.0);
        let scale = advantages[0] / own[0];
        assert!(scale > 0.0);
        for (a, o) in advantages.iter().zip(&own) {
            assert!((a - scale * o).abs() < 1e-9 * scale, "{advantages:?}");
        }
    }

    #[test]
    fn the_paths_are_normalised_by_the_shifts_own_variance() {
        // 40 rollouts at a few contexts, selected unevenly (weights independent of the
        // targets): the fit at the unweighted mean features has the variance `variance_at`
        // gives, measured over 20,000 draws of unit normal targets; at the weights' own mean
        // without a ridge it is CMA-ES's 1 / mu_eff; and extrapolated it is larger.
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let contexts: Vec<f64> = (0..40).map(|i| [0.0, 0.1, 0.2, 3.0][i % 4]).collect();
        let x = DMatrix::from_fn(40, 2, |i, j| if j == 0 { 1.0 } else { contexts[i] });
        let weights: Vec<f64> = (0..40).map(|i| if i % 4 == 3 { 0.0 } else { (i + 1) as f64 }).collect();
        let total: f64 = weights.iter().sum();
        let weights: Vec<f64> = weights.iter().map(|w| w / total).collect();
        let mean = x.row_mean().transpose();
        let regression = Ridge::new(&x, &weights, 1e-5, &[]).unwrap();
        let draws = 20_000;
        let fits: Vec<f64> = (0..draws)
            .map(|_| {
                let y = DMatrix::from_fn(40, 1, |_, _| rng.sample(StandardNormal));
                (regression.solve(&y).transpose() * &mean)[(0, 0)]
            })
            .collect();
        let measured = fits.iter().map(|f| f * f).sum::<f64>() / draws as f64;
        let predicted = regression.variance_at(&mean);
        assert!(
            (measured / predicted - 1.0).abs() < 0.05,
            "{measured} against {predicted}"
        );
        let mu_eff = 1.0 / weights.iter().map(|w| w * w).sum::<f64>();
        let own = x.tr_mul(&DVector::from_column_slice(&weights));
        let exact = Ridge::new(&x, &weights, 0.0, &[]).unwrap();
        assert!((exact.variance_at(&own) * mu_eff - 1.0).abs() < 1e-9);
        assert!(predicted * mu_eff > 10.0, "{}", predicted * mu_eff);
    }

    #[test]
    fn the_expected_norm_is_hansens_approximation() {
        // E||N(0, I_n)|| = sqrt(2) Gamma((n+1)/2) / Gamma(n/2): 1.25331 for n = 2, 4.41661 for 20.
        assert!((expected_norm(2) - 1.25331).abs() < 1e-3);
        assert!((expected_norm(20) - 4.41661).abs() < 1e-3);
    }
}
