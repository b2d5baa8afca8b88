//! The upper-level policy `pi(theta | s) = N(theta | W^T phi(s), Sigma)` and its weighted
//! maximum-likelihood update (P Alg. 2 lines 11-17, with BOLeRo's choices).

use nalgebra::{Cholesky, DMatrix, DVector, SymmetricEigen};
use rand::RngCore;
use rand_distr::{Distribution, StandardNormal};

use crate::stop::{Never, Stop};

use super::error::{
    InvalidValue, PolicyCreateError, PolicyFitError, Rejection, check_finite, check_len, check_non_negative,
};

/// A Gaussian over parameter vectors whose mean is linear in the context features.
///
/// `W` is stored as n_phi x n_theta (the paper's orientation: the mean is `W^T phi`); BOLeRo
/// stores its transpose.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearGaussianPolicy {
    weights: DMatrix<f64>,
    covariance: DMatrix<f64>,
    /// A factor L with `Sigma = L L^T`, for sampling.
    sampling_factor: DMatrix<f64>,
}

impl LinearGaussianPolicy {
    /// A policy with mean coefficients `weights` (n_phi x n_theta) and covariance `covariance`
    /// (n_theta x n_theta), which must be finite, symmetric (to 1e-12 relative) and positive
    /// semi-definite. The covariance is stored symmetrised.
    ///
    /// The sampling factor is `V sqrt(Lambda)` from the symmetric eigendecomposition, with
    /// eigenvalues that rounding made slightly negative clipped to 0. Weighted ML on fewer
    /// effective samples than parameters (epsilon = 2 keeps about N e^-2 of them) makes Sigma
    /// numerically singular; BOLeRo samples such covariances through numpy's SVD-based
    /// `multivariate_normal`, so refusing them (as a Cholesky factorisation would) would throw
    /// away most updates of the paper's Section 5.1 setting. A clearly negative eigenvalue
    /// (below -1e-9 times the largest) is still refused.
    pub fn new(weights: DMatrix<f64>, covariance: DMatrix<f64>) -> Result<Self, PolicyCreateError> {
        check_len(
            "the covariance's row count",
            covariance.nrows(),
            "its column count",
            covariance.ncols(),
        )?;
        check_len(
            "the number of columns of W (n_theta)",
            weights.ncols(),
            "the covariance's size",
            covariance.nrows(),
        )?;
        check_finite("W", weights.as_slice())?;
        check_finite("covariance", covariance.as_slice())?;
        let not_psd = PolicyCreateError::NotPositiveSemiDefinite;
        let asymmetry = (&covariance - covariance.transpose()).amax();
        if asymmetry > 1e-12 * covariance.amax() {
            return Err(not_psd);
        }
        let covariance = (&covariance + covariance.transpose()) * 0.5;
        let eigen = SymmetricEigen::new(covariance.clone());
        let largest = eigen.eigenvalues.max();
        if eigen.eigenvalues.min() < -1e-9 * largest.max(0.0) || !eigen.eigenvalues.iter().all(|l| l.is_finite()) {
            return Err(not_psd);
        }
        let roots = eigen.eigenvalues.map(|l| l.max(0.0).sqrt());
        let sampling_factor = eigen.eigenvectors * DMatrix::from_diagonal(&roots);
        Ok(Self {
            weights,
            covariance,
            sampling_factor,
        })
    }

    /// A policy from saved parts (restoring a checkpoint), kept bit for bit, when they are what a
    /// live learner holds: every number finite and the sampling factor's `F F^T` the covariance
    /// (to 1e-6 of its largest entry; rounding leaves 1e-12). Else names the part that is not: a
    /// NaN had made a resumed run loop for ever, a 1e300 run on to another result.
    pub(crate) fn from_saved(
        weights: DMatrix<f64>,
        covariance: DMatrix<f64>,
        sampling_factor: DMatrix<f64>,
    ) -> Result<Self, &'static str> {
        for (what, matrix) in [
            ("W", &weights),
            ("the covariance", &covariance),
            ("the sampling factor", &sampling_factor),
        ] {
            if !matrix.iter().all(|x| x.is_finite()) {
                return Err(what);
            }
        }
        let product = &sampling_factor * sampling_factor.transpose();
        let gap = (&product - &covariance).amax();
        if !product.iter().all(|x| x.is_finite()) || gap > 1e-6 * covariance.amax() {
            return Err("the covariance and its sampling factor");
        }
        Ok(Self {
            weights,
            covariance,
            sampling_factor,
        })
    }

    /// W, n_phi x n_theta.
    pub fn weights(&self) -> &DMatrix<f64> {
        &self.weights
    }

    /// Sigma, n_theta x n_theta.
    pub fn covariance(&self) -> &DMatrix<f64> {
        &self.covariance
    }

    /// The factor L with `Sigma = L L^T` used for sampling.
    pub fn sampling_factor(&self) -> &DMatrix<f64> {
        &self.sampling_factor
    }

    /// n_phi.
    pub fn n_features(&self) -> usize {
        self.weights.nrows()
    }

    /// n_theta.
    pub fn n_params(&self) -> usize {
        self.weights.ncols()
    }

    /// Checks that `theta` has n_theta entries, as a learner's record does.
    ///
    /// # Panics
    /// If it does not.
    pub(crate) fn assert_params(&self, theta: &[f64]) {
        assert_eq!(
            theta.len(),
            self.n_params(),
            "theta has {} entries, n_theta is {}",
            theta.len(),
            self.n_params()
        );
    }

    /// The mean `W^T phi`.
    pub fn mean(&self, features: &DVector<f64>) -> DVector<f64> {
        self.weights.tr_mul(features)
    }

    /// `W^T phi + L z` with `z ~ N(0, I)` drawn component by component, in order, from `rng`.
    pub fn sample(&self, features: &DVector<f64>, rng: &mut dyn RngCore) -> DVector<f64> {
        let z = DVector::from_iterator(
            self.n_params(),
            (0..self.n_params()).map(|_| StandardNormal.sample(rng)),
        );
        self.mean(features) + &self.sampling_factor * z
    }

    /// `ln det Sigma`, from the sampling factor `V sqrt(Lambda)`, whose column norms are the
    /// square roots of the eigenvalues; -inf when Sigma is singular.
    pub fn log_det_covariance(&self) -> f64 {
        self.sampling_factor.column_iter().map(|c| c.norm_squared().ln()).sum()
    }

    /// Weighted maximum likelihood on samples (rows of `features` and `thetas`) with weights
    /// `weights` (>= 0; C-REPS passes the softmax weights, which sum to 1), following BOLeRo:
    ///
    /// - weights that are exactly 0 become `f64::EPSILON`, so that a single dominant sample
    ///   does not make the covariance estimate singular outright;
    /// - `W_new = (Phi^T D Phi + ridge I)^-1 Phi^T D Theta`, solved by Cholesky (never inverted);
    ///   the ridge acts on every feature including the constant one, and its strength relative
    ///   to the data depends on the weights' scale;
    /// - `Sigma_new = [sum d / ((sum d)^2 - sum d^2)] sum_i d_i e_i e_i^T` with the residuals
    ///   `e_i = theta_i - W_old^T phi_i` of the **old** mean (P Alg. 2 line 17 does not say which
    ///   W it means; BOLeRo uses the old one, before the mean update).
    ///
    /// Returns the new policy. Inputs of the wrong shape or with non-finite or negative entries
    /// are errors; a fit the data makes impossible is [`PolicyFitError::Rejected`] with the reason.
    pub fn fit(
        &self,
        features: &DMatrix<f64>,
        thetas: &DMatrix<f64>,
        weights: &[f64],
        ridge: f64,
    ) -> Result<Self, PolicyFitError> {
        check_len(
            "the number of feature rows",
            features.nrows(),
            "the number of weights",
            weights.len(),
        )?;
        check_len(
            "the number of theta rows",
            thetas.nrows(),
            "the number of weights",
            weights.len(),
        )?;
        check_len(
            "the number of feature columns",
            features.ncols(),
            "the policy's n_phi",
            self.n_features(),
        )?;
        check_len(
            "the number of theta columns",
            thetas.ncols(),
            "the policy's n_theta",
            self.n_params(),
        )?;
        check_non_negative("ridge", ridge)?;
        check_finite("weights", weights)?;
        if let Some(&value) = weights.iter().find(|&&w| w < 0.0) {
            return Err(InvalidValue::Negative { name: "weights", value }.into());
        }
        check_finite("features", features.as_slice())?;
        check_finite("thetas", thetas.as_slice())?;
        let Ok(fitted) = self.fit_weighted(features, thetas, weights, ridge, Never);
        Ok(fitted?)
    }

    /// [`fit`](Self::fit) on inputs already checked.
    /// Asks `stop` between its steps, the longest of which (the covariance's sum over the
    /// rollouts) it takes a few columns at a time.
    pub(crate) fn fit_weighted<S: Stop>(
        &self,
        features: &DMatrix<f64>,
        thetas: &DMatrix<f64>,
        weights: &[f64],
        ridge: f64,
        stop: S,
    ) -> Result<Result<Self, Rejection>, S::Halt> {
        let d = DVector::from_iterator(
            weights.len(),
            weights.iter().map(|&w| if w == 0.0 { f64::EPSILON } else { w }),
        );
        let sum = d.sum();
        let scale = sum / (sum * sum - d.norm_squared());
        let residuals = thetas - features * &self.weights;
        let weighted_residuals = scale_rows(&residuals, &d);
        let covariance = tr_mul_stopping(&residuals, &weighted_residuals, stop)? * scale;
        stop.check()?;
        Ok(Self::fit_mean(features, thetas, &d, ridge, covariance))
    }

    /// The rest of [`fit_weighted`](Self::fit_weighted) once it has the covariance: the mean's
    /// regression, whose sums over the rollouts are n_phi wide.
    fn fit_mean(
        features: &DMatrix<f64>,
        thetas: &DMatrix<f64>,
        d: &DVector<f64>,
        ridge: f64,
        covariance: DMatrix<f64>,
    ) -> Result<Self, Rejection> {
        if !covariance.iter().all(|c| c.is_finite()) {
            return Err(Rejection::CovarianceNotFinite);
        }

        let mut normal_matrix = features.tr_mul(&scale_rows(features, d));
        for i in 0..normal_matrix.nrows() {
            normal_matrix[(i, i)] += ridge;
        }
        let right_hand_side = features.tr_mul(&scale_rows(thetas, d));
        let weights = Cholesky::new(normal_matrix)
            .ok_or(Rejection::SingularRegression)?
            .solve(&right_hand_side);
        if !weights.iter().all(|w| w.is_finite()) {
            return Err(Rejection::MeanNotFinite);
        }
        Self::new(weights, covariance).map_err(|_| Rejection::CovarianceNotPositiveSemiDefinite)
    }
}

/// The largest pull `nu` of a bounded fit towards the old distribution: the new one then moves
/// a millionth of the way from it.
pub(crate) const MAX_NU: f64 = 1e6;

/// Most trials of [`bound_by_kl`] within its bracket.
const MAX_TRIALS: usize = 60;

/// The smallest `nu >= 0` at which `kl(nu) <= epsilon`, for a KL that falls as nu pulls the new
/// distribution towards the old: 0 when the unregularised fit is within the bound, [`MAX_NU`]
/// when even that is not. After bracketing nu between powers of ten, the Illinois variant of
/// false position narrows the bracket until the KL is within 1e-6 epsilon below the bound or
/// the bracket within 1e-9 of its upper end (bisecting where the KL is infinite); the upper end,
/// where the bound holds, is returned. Deterministic: a fixed sequence of trials.
pub(crate) fn bound_by_kl(mut kl: impl FnMut(f64) -> f64, epsilon: f64) -> f64 {
    let excess = |value: f64| value - epsilon;
    let at_zero = excess(kl(0.0));
    if at_zero <= 0.0 {
        return 0.0;
    }
    let (mut low, mut low_excess) = (0.0, at_zero);
    let mut high = 1.0;
    let mut high_excess = excess(kl(high));
    while high_excess > 0.0 {
        if high >= MAX_NU {
            return MAX_NU;
        }
        (low, low_excess) = (high, high_excess);
        high *= 10.0;
        high_excess = excess(kl(high));
    }
    // False position uses weights that start as the ends' excesses; the other end's weight is
    // halved when the same end moves twice (Illinois), while the stopping test uses the true
    // excess of the upper end.
    let (mut low_weight, mut high_weight) = (low_excess, high_excess);
    let mut last_high = None;
    for _ in 0..MAX_TRIALS {
        if high_excess > -1e-6 * epsilon || high - low <= 1e-9 * high {
            break;
        }
        let trial = if low_weight.is_finite() {
            (low * high_weight - high * low_weight) / (high_weight - low_weight)
        } else {
            0.5 * (low + high)
        };
        let trial_excess = excess(kl(trial));
        if trial_excess <= 0.0 {
            (high, high_excess, high_weight) = (trial, trial_excess, trial_excess);
            if last_high == Some(true) {
                low_weight /= 2.0;
            }
            last_high = Some(true);
        } else {
            (low, low_weight) = (trial, trial_excess);
            if last_high == Some(false) {
                high_weight /= 2.0;
            }
            last_high = Some(false);
        }
    }
    high
}

/// `KL(N(mu_old, old) || N(mu_new, new))` for a fixed `old`, averaged over mean shifts
/// `mu_new - mu_old` given by their second moment `M` (the mean of their outer products):
/// `(tr(new^-1 (old + M)) - k + ln|new| - ln|old|) / 2`.
pub(crate) struct GaussianKl {
    old: DMatrix<f64>,
    old_log_det: f64,
}

impl GaussianKl {
    /// `None` when `old` is not positive definite.
    pub(crate) fn new(old: &DMatrix<f64>) -> Option<Self> {
        let factor = Cholesky::new(old.clone())?;
        Some(Self {
            old: old.clone(),
            old_log_det: log_det(&factor),
        })
    }

    /// The KL to `new` with shifts of second moment `shift_moment`; infinite when `new` is not
    /// positive definite.
    pub(crate) fn to(&self, new: &DMatrix<f64>, shift_moment: &DMatrix<f64>) -> f64 {
        let Some(factor) = Cholesky::new(new.clone()) else {
            return f64::INFINITY;
        };
        let trace = factor.solve(&(&self.old + shift_moment)).trace();
        let value = 0.5 * (trace - self.old.nrows() as f64 + log_det(&factor) - self.old_log_det);
        if value.is_finite() {
            value.max(0.0)
        } else {
            f64::INFINITY
        }
    }
}

/// `ln det` of the matrix a Cholesky factor factors.
pub(crate) fn log_det(factor: &Cholesky<f64, nalgebra::Dyn>) -> f64 {
    factor.l_dirty().diagonal().iter().map(|d| 2.0 * d.ln()).sum()
}

impl LinearGaussianPolicy {
    /// Weighted maximum likelihood bounded by KL (the M-step of SPRL, Klink et al. 2019): the
    /// fit to the rollouts weighted by `weights` (which sum to 1) pulled towards this policy by
    /// the smallest `nu` at which the mean over the rollouts' contexts of
    /// `KL(this policy || the new one)` is at most `epsilon`. With nu, the mean is the ridge
    /// regression on the rollouts (weights d_i) and on this policy's means at their contexts
    /// (weights nu / N), and the covariance `(S + nu (Sigma + D)) / (1 + nu)`, S the weighted
    /// residuals' and D the mean shifts' second moments. Returns the new policy and nu.
    ///
    /// The search for nu works on second moments of the rollouts (n_phi and n_theta wide, not N
    /// long), so each trial costs a few small factorisations; the covariance of the fit is then
    /// made from the rollouts' residuals.
    ///
    /// Asks `stop` between its steps, the longest of which (the sums of n_theta x n_theta
    /// terms over the rollouts) it takes a few columns at a time.
    pub(crate) fn fit_bounded<S: Stop>(
        &self,
        features: &DMatrix<f64>,
        thetas: &DMatrix<f64>,
        weights: &[f64],
        ridge: f64,
        epsilon: f64,
        stop: S,
    ) -> Result<Result<(Self, f64), Rejection>, S::Halt> {
        let d = DVector::from_column_slice(weights);
        let n = weights.len() as f64;
        let weighted_features = scale_rows(features, &d);
        let weighted_gram = features.tr_mul(&weighted_features);
        let gram = features.tr_mul(features) / n;
        let cross = weighted_features.tr_mul(thetas);
        let second = tr_mul_stopping(thetas, &scale_rows(thetas, &d), stop)?;
        stop.check()?;
        let old_cross = &gram * &self.weights;
        // The ridge regression on the rollouts (weights d_i) and on this policy's means at their
        // contexts (weights nu / N), from the second moments: one small solve per trial.
        let mean_at = |nu: f64| {
            let mut normal_matrix = &weighted_gram + &gram * nu;
            for i in 0..normal_matrix.nrows() {
                normal_matrix[(i, i)] += ridge;
            }
            Cholesky::new(normal_matrix).map(|factor| factor.solve(&(&cross + &old_cross * nu)))
        };
        let kl_from = GaussianKl::new(&self.covariance);
        let kl = |nu: f64| {
            let (Some(kl_from), Some(w)) = (&kl_from, mean_at(nu)) else {
                return f64::INFINITY;
            };
            // W^T C's transpose is C^T W: one product.
            let w_cross = w.tr_mul(&cross);
            let spread = &second - &w_cross - w_cross.transpose() + w.tr_mul(&(&weighted_gram * &w));
            let shift = &w - &self.weights;
            let moment = shift.tr_mul(&(&gram * &shift));
            let covariance = (spread + (&self.covariance + &moment) * nu) / (d.sum() + nu);
            kl_from.to(&covariance, &moment)
        };
        let nu = bound_by_kl(kl, epsilon);
        // The covariance from the rollouts' residuals themselves: the moments' difference of
        // large terms would round away a small spread.
        let Some(weights) = mean_at(nu) else {
            return Ok(Err(Rejection::SingularRegression));
        };
        if !weights.iter().all(|w| w.is_finite()) {
            return Ok(Err(Rejection::MeanNotFinite));
        }
        let old_means = features * &self.weights;
        let new_means = features * &weights;
        let residuals = thetas - &new_means;
        let shifts = new_means - old_means;
        let spread = tr_mul_stopping(&residuals, &scale_rows(&residuals, &d), stop)?;
        let shifted = tr_mul_stopping(&shifts, &shifts, stop)?;
        stop.check()?;
        let covariance = (spread + (&self.covariance + shifted / n) * nu) / (d.sum() + nu);
        if !covariance.iter().all(|c| c.is_finite()) {
            return Ok(Err(Rejection::CovarianceNotFinite));
        }
        let policy = Self::new(weights, covariance).map_err(|_| Rejection::CovarianceNotPositiveSemiDefinite);
        Ok(policy.map(|policy| (policy, nu)))
    }
}

/// `a^T b`, a few columns of `b` at a time with `stop` asked in between: nalgebra's `tr_mul`
/// makes each entry one `dot` of two columns, so the blocks give the same bits as one call.
pub(crate) fn tr_mul_stopping<S: Stop>(a: &DMatrix<f64>, b: &DMatrix<f64>, stop: S) -> Result<DMatrix<f64>, S::Halt> {
    // 8 columns of 100,000 rollouts against 64 take about 50 ms.
    const COLUMNS: usize = 8;
    let mut product = DMatrix::zeros(a.ncols(), b.ncols());
    for start in (0..b.ncols()).step_by(COLUMNS) {
        stop.check()?;
        let width = COLUMNS.min(b.ncols() - start);
        a.tr_mul_to(&b.columns(start, width), &mut product.columns_mut(start, width));
    }
    Ok(product)
}

/// `diag(d) m`.
pub(crate) fn scale_rows(m: &DMatrix<f64>, d: &DVector<f64>) -> DMatrix<f64> {
    let mut scaled = m.clone();
    for (mut row, &di) in scaled.row_iter_mut().zip(d.iter()) {
        row *= di;
    }
    scaled
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Interrupted;
    use crate::creps::FeatureMap;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn policy(n_phi: usize, n_theta: usize) -> LinearGaussianPolicy {
        LinearGaussianPolicy::new(DMatrix::zeros(n_phi, n_theta), DMatrix::identity(n_theta, n_theta)).unwrap()
    }

    /// Rows `phi(x_i)` for x = linspace(0, 1, n).
    fn design(map: &FeatureMap, n: usize) -> (Vec<f64>, DMatrix<f64>) {
        let x: Vec<f64> = (0..n).map(|i| i as f64 / (n - 1) as f64).collect();
        let rows: Vec<_> = x.iter().map(|&xi| map.apply(&[xi]).transpose()).collect();
        (x, DMatrix::from_rows(&rows))
    }

    /// BOLeRo's test_linear_gaussian: 3x + 10 with noise 0.05, unit weights, no ridge; "2
    /// decimals" in numpy's sense (|error| < 1.5e-2). The slope's standard error is
    /// 0.05 / sqrt(1001 / 12) = 0.0055, so unittest's stricter 0.005 would be a 1-sigma test.
    #[test]
    fn noisy_line_fit_recovers_w() {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let (x, phi) = design(&FeatureMap::Affine, 1001);
        let thetas = DMatrix::from_fn(1001, 1, |i, _| {
            3.0 * x[i] + 10.0 + 0.05 * rng.sample::<f64, _>(StandardNormal)
        });
        let fitted = policy(2, 1).fit(&phi, &thetas, &[1.0; 1001], 0.0).unwrap();
        assert!((fitted.weights()[(0, 0)] - 3.0).abs() < 1.5e-2, "{}", fitted.weights());
        assert!((fitted.weights()[(1, 0)] - 10.0).abs() < 1.5e-2, "{}", fitted.weights());
    }

    /// BOLeRo's test_context_transformation: an exact quadratic is recovered to 7 places.
    #[test]
    fn quadratic_fit_is_exact() {
        let (x, phi) = design(&FeatureMap::Quadratic, 101);
        let thetas = DMatrix::from_fn(101, 1, |i, _| 3.0 * x[i] * x[i] + 2.0 * x[i] + 10.0);
        let fitted = policy(3, 1).fit(&phi, &thetas, &[1.0; 101], 0.0).unwrap();
        for (got, want) in fitted.weights().iter().zip([3.0, 2.0, 10.0]) {
            assert!((got - want).abs() < 1e-7, "{}", fitted.weights());
        }
    }

    /// With uniform normalised weights 1/N the update is ridge regression with penalty
    /// `N ridge` on the unnormalised data, computed here independently as the least-squares
    /// solution of the augmented system `[Phi; sqrt(N ridge) I] W = [Theta; 0]` by SVD.
    #[test]
    fn uniform_weights_reproduce_ridge_regression() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let n = 40;
        let ridge = 0.05;
        let phi = DMatrix::from_fn(n, 3, |_, j| if j == 2 { 1.0 } else { rng.random_range(-1.0..1.0) });
        let thetas = DMatrix::from_fn(n, 2, |_, _| rng.random_range(-2.0..2.0));
        let fitted = policy(3, 2)
            .fit(&phi, &thetas, &vec![1.0 / n as f64; n], ridge)
            .unwrap();

        let penalty = (n as f64 * ridge).sqrt();
        let augmented = DMatrix::from_fn(n + 3, 3, |i, j| {
            if i < n {
                phi[(i, j)]
            } else if i - n == j {
                penalty
            } else {
                0.0
            }
        });
        let target = DMatrix::from_fn(n + 3, 2, |i, j| if i < n { thetas[(i, j)] } else { 0.0 });
        let expected = augmented.svd(true, true).solve(&target, 1e-14).unwrap();
        assert!(
            (fitted.weights() - &expected).amax() < 1e-12,
            "{} vs {expected}",
            fitted.weights()
        );
    }

    /// Noise-free data on a line: the new mean fits it exactly (new-W residuals are 0), so a
    /// non-zero Sigma can only come from the old W = 0, whose residuals are the thetas.
    #[test]
    fn covariance_uses_the_old_mean() {
        let n = 11;
        let (x, phi) = design(&FeatureMap::Affine, n);
        let thetas = DMatrix::from_fn(n, 1, |i, _| 3.0 * x[i] + 10.0);
        let d = vec![1.0 / n as f64; n];
        let fitted = policy(2, 1).fit(&phi, &thetas, &d, 0.0).unwrap();
        let new_residuals = &thetas - &phi * fitted.weights();
        assert!(new_residuals.amax() < 1e-10);
        let sum_d2: f64 = d.iter().map(|d| d * d).sum();
        let expected = thetas.iter().map(|t| t * t / n as f64).sum::<f64>() / (1.0 - sum_d2);
        assert!((fitted.covariance()[(0, 0)] - expected).abs() < 1e-10 * expected);
    }

    /// BOLeRo: samples around mean 10 with Sigma = I have mean 10 +- 0.1 and std 1 +- 0.1.
    #[test]
    fn samples_follow_the_gaussian() {
        let mut weights = DMatrix::zeros(2, 1);
        weights[(1, 0)] = 10.0;
        let policy = LinearGaussianPolicy::new(weights, DMatrix::identity(1, 1)).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let phi = DVector::from_vec(vec![0.3, 1.0]);
        let samples: Vec<f64> = (0..1001).map(|_| policy.sample(&phi, &mut rng)[0]).collect();
        let mean = samples.iter().sum::<f64>() / 1001.0;
        let std = (samples.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / 1001.0).sqrt();
        assert!((mean - 10.0).abs() < 0.1 && (std - 1.0).abs() < 0.1, "{mean} {std}");
    }

    #[test]
    fn degenerate_fits_are_errors() {
        let (_, phi) = design(&FeatureMap::Affine, 5);
        let thetas = DMatrix::from_element(5, 1, 1e200);
        // Squared residuals of 1e200 overflow.
        let error = policy(2, 1).fit(&phi, &thetas, &[0.2; 5], 1e-4).unwrap_err();
        assert_eq!(error, PolicyFitError::Rejected(Rejection::CovarianceNotFinite));
        // One sample: sum d = sum d^2, the normaliser divides by zero.
        let one = policy(2, 1).fit(
            &phi.rows(0, 1).into_owned(),
            &thetas.rows(0, 1).into_owned(),
            &[1.0],
            1e-4,
        );
        assert!(one.is_err());
        // Identical contexts without ridge: Phi^T D Phi is singular.
        let same = DMatrix::from_fn(5, 2, |_, j| if j == 0 { 0.5 } else { 1.0 });
        let error = policy(2, 1)
            .fit(&same, &DMatrix::zeros(5, 1), &[0.2; 5], 0.0)
            .unwrap_err();
        assert_eq!(error, PolicyFitError::Rejected(Rejection::SingularRegression));
        let error = policy(2, 1)
            .fit(&phi, &DMatrix::zeros(4, 1), &[0.2; 5], 0.0)
            .unwrap_err();
        assert!(error.to_string().contains("(4) must equal the number of weights (5)"));
    }

    #[test]
    fn new_rejects_bad_covariances() {
        let bad = |covariance: DMatrix<f64>| LinearGaussianPolicy::new(DMatrix::zeros(2, 2), covariance);
        assert!(bad(DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0])).is_err());
        assert!(bad(DMatrix::from_row_slice(2, 2, &[1.0, 0.5, 0.0, 1.0])).is_err());
        assert!(bad(DMatrix::identity(3, 3)).is_err());
        assert!(bad(DMatrix::from_row_slice(2, 2, &[f64::NAN, 0.0, 0.0, 1.0])).is_err());
        assert!(bad(DMatrix::identity(2, 2)).is_ok());
        // Singular but positive semi-definite: accepted, and the factor reproduces it.
        let singular = DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 1.0, 1.0]);
        let policy = bad(singular.clone()).unwrap();
        let factor = policy.sampling_factor();
        assert!((factor * factor.transpose() - singular).amax() < 1e-12);
    }

    #[test]
    fn products_taken_a_few_columns_at_a_time_are_nalgebras_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        for (rows, left, right) in [(1000, 64, 64), (37, 6, 21), (5, 3, 8), (9, 2, 1)] {
            let a = DMatrix::from_fn(rows, left, |_, _| rng.random::<f64>() - 0.3);
            let b = DMatrix::from_fn(rows, right, |_, _| rng.random::<f64>() * 1e3);
            let Ok(product) = tr_mul_stopping(&a, &b, Never);
            assert_eq!(product, a.tr_mul(&b), "{rows} x {left} by {right}");
            // Asked before every block of 8 columns; stopped at the last question.
            let asked = std::cell::Cell::new(0);
            let blocks = right.div_ceil(8);
            let stop = || {
                asked.set(asked.get() + 1);
                asked.get() == blocks
            };
            assert_eq!(tr_mul_stopping(&a, &b, &stop as &dyn Fn() -> bool), Err(Interrupted));
            assert_eq!(asked.get(), blocks);
        }
    }

    #[test]
    fn bound_by_kl_finds_the_smallest_pull_within_the_bound() {
        // KL(nu) = 4 / (1 + nu)^2 is 1 at nu = 1.
        let nu = bound_by_kl(|nu| 4.0 / (1.0 + nu).powi(2), 1.0);
        assert!((1.0..1.0 + 1e-5).contains(&nu), "{nu}");
        // Within the bound unregularised, out of it for every nu, infinite near 0.
        assert_eq!(bound_by_kl(|nu| 0.5 / (1.0 + nu), 1.0), 0.0);
        assert_eq!(bound_by_kl(|_| 2.0, 1.0), MAX_NU);
        let kinked = |nu: f64| if nu < 3.0 { f64::INFINITY } else { 100.0 / nu.powi(2) };
        let nu = bound_by_kl(kinked, 1.0);
        assert!((10.0..10.0 + 1e-4).contains(&nu), "{nu}");
    }

    /// The mean over the rows of `KL(old(.|phi_i) || new(.|phi_i))`, row by row.
    fn mean_kl(old: &LinearGaussianPolicy, new: &LinearGaussianPolicy, features: &DMatrix<f64>) -> f64 {
        let k = old.n_params() as f64;
        let new_factor = Cholesky::new(new.covariance().clone()).unwrap();
        let trace = new_factor.solve(old.covariance()).trace();
        let log_det = |m: &DMatrix<f64>| m.clone().cholesky().unwrap().determinant().ln();
        let mut total = 0.0;
        for row in features.row_iter() {
            let phi = row.transpose();
            let shift = new.mean(&phi) - old.mean(&phi);
            let mahalanobis = shift.dot(&new_factor.solve(&shift));
            total += 0.5 * (trace + mahalanobis - k + log_det(new.covariance()) - log_det(old.covariance()));
        }
        total / features.nrows() as f64
    }

    #[test]
    fn bounded_fits_move_the_policy_by_at_most_epsilon() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (_, features) = design(&FeatureMap::Quadratic, 40);
        let old = policy(3, 2);
        let thetas = DMatrix::from_fn(40, 2, |i, j| {
            2.0 + features[(i, 1)] * (j as f64 + 1.0) + rng.random::<f64>() * 0.1
        });
        let mut weights: Vec<f64> = (0..40).map(|i| ((i as f64) / 8.0).exp()).collect();
        let total: f64 = weights.iter().sum();
        weights.iter_mut().for_each(|w| *w /= total);
        for epsilon in [0.05, 0.5, 2.0] {
            let Ok(fitted) = old.fit_bounded(&features, &thetas, &weights, 1e-6, epsilon, Never);
            let (new, nu) = fitted.unwrap();
            let kl = mean_kl(&old, &new, &features);
            assert!(
                nu > 0.0 && kl <= epsilon * (1.0 + 1e-9) && kl > 0.99 * epsilon,
                "epsilon {epsilon}: nu {nu}, KL {kl}"
            );
        }
        // A bound that does not bind leaves the weighted maximum-likelihood mean.
        let Ok(free) = old.fit_bounded(&features, &thetas, &weights, 1e-6, 1e6, Never);
        let (free, nu) = free.unwrap();
        let unbounded = old.fit(&features, &thetas, &weights, 1e-6).unwrap();
        assert_eq!(nu, 0.0);
        assert!((free.weights() - unbounded.weights()).amax() < 1e-9);
    }
}
