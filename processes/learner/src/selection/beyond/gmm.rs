//! Gaussian mixtures with full covariances, fitted by expectation-maximisation, for ALP-GMM.
//!
//! As scikit-learn's `GaussianMixture` (which the original ALP-GMM uses) with its defaults: EM
//! until the mean log-likelihood per point changes by less than 1e-3, at most 100 iterations,
//! 1e-6 added to every covariance's diagonal so that none becomes singular, and a start from the
//! partition of Lloyd's k-means seeded by k-means++. Scikit-learn's k-means seeds greedily from
//! several candidates and restarts; here one k-means++ seeding draws from the caller's random
//! stream, so a fit is a function of the data and that stream. The number of components is
//! chosen by the Akaike information criterion, as in the original.

use super::progress::proportional;
use rand::{Rng, RngCore};
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use std::ops::RangeInclusive;

/// Stop when the mean log-likelihood per point changes by less than this (scikit-learn's `tol`).
const TOLERANCE: f64 = 1e-3;
/// Most EM iterations per fit (scikit-learn's `max_iter`).
const MAX_ITERATIONS: usize = 100;
/// Added to every covariance's diagonal (scikit-learn's `reg_covar`).
const REGULARISATION: f64 = 1e-6;

/// One Gaussian of a mixture over points of D coordinates.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Component {
    /// Its share of the mixture.
    pub weight: f64,
    /// Mean, D coordinates.
    pub mean: Vec<f64>,
    /// Covariance, D x D, row by row.
    pub covariance: Vec<f64>,
}

/// A mixture ready to evaluate and sample: its components and their Cholesky factors.
#[derive(Debug, Clone)]
pub(crate) struct Mixture {
    dim: usize,
    components: Vec<Component>,
    /// Lower Cholesky factor of every covariance, D x D row by row.
    factors: Vec<Vec<f64>>,
    /// ln weight - (D ln 2 pi + ln det covariance) / 2 of every component.
    log_norms: Vec<f64>,
}

impl Mixture {
    /// The mixture of `components` over points of `dim` coordinates; `None` unless every
    /// component has that dimension, a positive finite weight and a positive-definite
    /// covariance.
    pub(crate) fn new(dim: usize, components: Vec<Component>) -> Option<Self> {
        if components.is_empty() {
            return None;
        }
        let mut mixture = Self::unfactorised(dim, components);
        mixture.factorise()?;
        Some(mixture)
    }

    /// `k` components of zero weight, mean and covariance: buffers for [`Self::maximise`] to
    /// fill, and refill at every iteration of a fit.
    fn zeroed(dim: usize, k: usize) -> Self {
        let component = Component {
            weight: 0.0,
            mean: vec![0.0; dim],
            covariance: vec![0.0; dim * dim],
        };
        Self::unfactorised(dim, vec![component; k])
    }

    /// `components` with zeroed factors and log norms, for [`Self::factorise`] to fill.
    fn unfactorised(dim: usize, components: Vec<Component>) -> Self {
        let k = components.len();
        Self {
            dim,
            components,
            factors: vec![vec![0.0; dim * dim]; k],
            log_norms: vec![0.0; k],
        }
    }

    /// The Cholesky factors and log norms of the components, into their buffers; `None` unless
    /// every component has the mixture's dimension, a positive finite weight and a
    /// positive-definite covariance.
    fn factorise(&mut self) -> Option<()> {
        let dim = self.dim;
        let factors = self.factors.iter_mut().zip(&mut self.log_norms);
        for (component, (factor, log_norm)) in self.components.iter().zip(factors) {
            let valid = component.mean.len() == dim
                && component.covariance.len() == dim * dim
                && component.weight > 0.0
                && component.weight.is_finite()
                && component.mean.iter().all(|x| x.is_finite());
            if !valid {
                return None;
            }
            cholesky(&component.covariance, dim, factor)?;
            let log_det: f64 = (0..dim).map(|i| factor[i * dim + i].ln()).sum::<f64>() * 2.0;
            *log_norm = component.weight.ln() - 0.5 * (dim as f64 * (2.0 * std::f64::consts::PI).ln() + log_det);
        }
        Some(())
    }

    /// The components.
    pub(crate) fn components(&self) -> &[Component] {
        &self.components
    }

    /// The log-likelihood of the points of `e`, and every point's responsibilities (row by row,
    /// one per component) into `responsibilities`. Each loop runs over all the points, which
    /// the compiler vectorises, but makes every point's quantities with the operations, and in
    /// the order, of a point at a time.
    fn expect(&self, e: &mut EStep, responsibilities: &mut [f64]) -> f64 {
        let (dim, n, k) = (self.dim, e.n, self.components.len());
        let EStep {
            columns,
            joints,
            solved,
            largest,
            sums,
            ..
        } = e;
        for (c, joints) in joints.chunks_exact_mut(n).enumerate() {
            let (factor, mean) = (&self.factors[c], &self.components[c].mean);
            // Solve L y = point - mean by forward substitution; the Mahalanobis distance is
            // |y|^2, summed in `joints`.
            joints.fill(0.0);
            for i in 0..dim {
                let (before, y) = solved.split_at_mut(i * n);
                let y = &mut y[..n];
                // L's row times the y so far, from -0.0 as `Iterator::sum` starts.
                y.fill(-0.0);
                for (j, y_j) in before.chunks_exact(n).enumerate() {
                    let l = factor[i * dim + j];
                    y.iter_mut().zip(y_j).for_each(|(dot, y_j)| *dot += l * y_j);
                }
                let (m, l) = (mean[i], factor[i * dim + i]);
                let x = &columns[i * n..(i + 1) * n];
                for ((y, x), distance) in y.iter_mut().zip(x).zip(joints.iter_mut()) {
                    *y = (x - m - *y) / l;
                    *distance += *y * *y;
                }
            }
            let log_norm = self.log_norms[c];
            joints.iter_mut().for_each(|j| *j = log_norm - 0.5 * *j);
        }
        largest.fill(f64::NEG_INFINITY);
        for joints in joints.chunks_exact(n) {
            largest.iter_mut().zip(joints).for_each(|(max, j)| *max = max.max(*j));
        }
        sums.fill(-0.0);
        for joints in joints.chunks_exact_mut(n) {
            for ((j, max), sum) in joints.iter_mut().zip(&*largest).zip(sums.iter_mut()) {
                *j = exp(*j - max);
                *sum += *j;
            }
        }
        for (c, joints) in joints.chunks_exact_mut(n).enumerate() {
            joints.iter_mut().zip(&*sums).for_each(|(j, sum)| *j /= sum);
            let column = responsibilities[c..].iter_mut().step_by(k);
            column.zip(&*joints).for_each(|(r, j)| *r = *j);
        }
        let mut total = 0.0;
        for (max, sum) in largest.iter().zip(&*sums) {
            total += max + sum.ln();
        }
        total
    }

    /// The M step: weights, means and regularised covariances from the responsibilities (row
    /// by row, one per component), then the factors; `None` as [`Self::factorise`]. One pass
    /// over the points makes every component's sums, each still added in point order as a pass
    /// per component would; the covariances take a second pass, about the final means.
    fn maximise(&mut self, data: &[f64], responsibilities: &[f64]) -> Option<()> {
        // The dimension a constant for ALP-GMM's points (a context of 1 to 3 coordinates and its
        // ALP), so that the compiler unrolls the loops over coordinates; the arithmetic is the
        // same.
        match self.dim {
            2 => self.maximise_in::<2>(data, responsibilities),
            3 => self.maximise_in::<3>(data, responsibilities),
            4 => self.maximise_in::<4>(data, responsibilities),
            _ => self.maximise_in::<0>(data, responsibilities),
        }
    }

    /// [`Self::maximise`] for points of `D` coordinates, or of [`Self::dim`] when `D` is 0.
    fn maximise_in<const D: usize>(&mut self, data: &[f64], responsibilities: &[f64]) -> Option<()> {
        let (dim, k) = (if D == 0 { self.dim } else { D }, self.components.len());
        let n = data.len() / dim;
        // Masses from -0.0, where `Iterator::sum` (a pass per component) starts.
        let mut masses = vec![-0.0; k];
        let mut means = vec![0.0; k * dim];
        for (point, row) in data.chunks_exact(dim).zip(responsibilities.chunks_exact(k)) {
            for ((mass, mean), &r) in masses.iter_mut().zip(means.chunks_exact_mut(dim)).zip(row) {
                *mass += r;
                mean.iter_mut().zip(point).for_each(|(m, x)| *m += r * x);
            }
        }
        for (mass, mean) in masses.iter_mut().zip(means.chunks_exact_mut(dim)) {
            // scikit-learn's guard against a component that owns no point.
            *mass += 10.0 * f64::EPSILON;
            mean.iter_mut().for_each(|m| *m /= *mass);
        }
        let mut covariances = vec![0.0; k * dim * dim];
        let mut centred = vec![0.0; dim];
        // Each responsibility by value, which no store can alias, and `0..i + 1` rather than
        // `0..=i`: so the compiler unrolls these loops and keeps r * centred[i] for every j.
        for (point, row) in data.chunks_exact(dim).zip(responsibilities.chunks_exact(k)) {
            let sums = covariances.chunks_exact_mut(dim * dim).zip(means.chunks_exact(dim));
            for ((covariance, mean), &r) in sums.zip(row) {
                centred
                    .iter_mut()
                    .zip(point.iter().zip(mean))
                    .for_each(|(d, (x, m))| *d = x - m);
                for i in 0..dim {
                    for j in 0..i + 1 {
                        covariance[i * dim + j] += r * centred[i] * centred[j];
                    }
                }
            }
        }
        let sums = masses
            .iter()
            .zip(means.chunks_exact(dim))
            .zip(covariances.chunks_exact(dim * dim));
        for (((&mass, mean), sum), component) in sums.zip(&mut self.components) {
            component.weight = mass / n as f64;
            component.mean.copy_from_slice(mean);
            for i in 0..dim {
                for j in 0..=i {
                    let value = sum[i * dim + j] / mass + if i == j { REGULARISATION } else { 0.0 };
                    component.covariance[i * dim + j] = value;
                    component.covariance[j * dim + i] = value;
                }
            }
        }
        self.factorise()
    }

    /// The first `leading` coordinates of a draw from component `k`: the component's marginal
    /// over them, whose Cholesky factor is the leading block of the full one. Draws `leading`
    /// standard normals.
    pub(crate) fn sample_leading(&self, k: usize, leading: usize, rng: &mut dyn RngCore) -> Vec<f64> {
        let (dim, factor, mean) = (self.dim, &self.factors[k], &self.components[k].mean);
        let z: Vec<f64> = (0..leading).map(|_| rng.sample(StandardNormal)).collect();
        (0..leading)
            .map(|i| mean[i] + (0..=i).map(|j| factor[i * dim + j] * z[j]).sum::<f64>())
            .collect()
    }

    /// Fit `k` components to `data` (points of `dim` coordinates one after another) by EM from
    /// a k-means++ start; the mixture and its log-likelihood, or `None` when the data have fewer
    /// than `k` distinct points or a covariance cannot be factorised.
    pub(crate) fn fit(data: &[f64], dim: usize, k: usize, rng: &mut dyn RngCore) -> Option<(Self, f64)> {
        let n = data.len() / dim;
        let labels = kmeans(data, dim, kmeans_plus_plus(data, dim, k, rng)?);
        let mut responsibilities = vec![0.0; n * k];
        for (row, &label) in responsibilities.chunks_mut(k).zip(&labels) {
            row[label] = 1.0;
        }
        let mut mixture = Self::zeroed(dim, k);
        mixture.maximise(data, &responsibilities)?;
        let mut e = EStep::new(data, dim, k);
        let mut previous = f64::NEG_INFINITY;
        for _ in 0..MAX_ITERATIONS {
            let log_likelihood = mixture.expect(&mut e, &mut responsibilities);
            if (log_likelihood - previous).abs() < TOLERANCE * n as f64 {
                return Some((mixture, log_likelihood));
            }
            previous = log_likelihood;
            mixture.maximise(data, &responsibilities)?;
        }
        let log_likelihood = mixture.expect(&mut e, &mut responsibilities);
        Some((mixture, log_likelihood))
    }

    /// The mixture of lowest Akaike information criterion among fits of every `k` in `ks`
    /// (in increasing order, so the random stream is used in a fixed order; ties to the fewer
    /// components), or `None` when no `k` could be fitted.
    pub(crate) fn fit_best(data: &[f64], dim: usize, ks: RangeInclusive<usize>, rng: &mut dyn RngCore) -> Option<Self> {
        let mut best: Option<(f64, Self)> = None;
        for k in ks {
            let Some((mixture, log_likelihood)) = Self::fit(data, dim, k, rng) else {
                continue;
            };
            let criterion = aic(log_likelihood, k, dim);
            if best.as_ref().is_none_or(|(b, _)| criterion < *b) {
                best = Some((criterion, mixture));
            }
        }
        best.map(|(_, mixture)| mixture)
    }
}

/// The points of a fit coordinate by coordinate, and the buffers of [`Mixture::expect`], kept
/// for all its iterations. Each holds a value per point, point p of row r at r * n + p.
struct EStep {
    n: usize,
    /// A row per coordinate.
    columns: Vec<f64>,
    /// A row per component: ln(weight * density), then e^(that - the point's largest), then the
    /// responsibility.
    joints: Vec<f64>,
    /// A row per coordinate: the forward substitution's y.
    solved: Vec<f64>,
    /// Every point's largest log joint, and the sum of its exponentials.
    largest: Vec<f64>,
    sums: Vec<f64>,
}

impl EStep {
    fn new(data: &[f64], dim: usize, k: usize) -> Self {
        let n = data.len() / dim;
        let mut columns = vec![0.0; dim * n];
        for (p, point) in data.chunks_exact(dim).enumerate() {
            for (i, &x) in point.iter().enumerate() {
                columns[i * n + p] = x;
            }
        }
        Self {
            n,
            columns,
            joints: vec![0.0; k * n],
            solved: vec![0.0; dim * n],
            largest: vec![0.0; n],
            sums: vec![0.0; n],
        }
    }
}

/// e^x, without calling exp where its result is known: exactly 1.0 at +-0 (every point's
/// largest log joint), and exactly 0.0 below -746, as e^x < 2^-1075 (half the smallest
/// subnormal) below -745.14 rounds to 0.0, which glibc returns through a slow underflow path.
/// (With either test alone, LLVM calls exp for every argument and selects the result.)
fn exp(x: f64) -> f64 {
    if x < -746.0 {
        0.0
    } else if x == 0.0 {
        1.0
    } else {
        x.exp()
    }
}

/// The Akaike information criterion of a mixture of `k` full-covariance Gaussians in `dim`
/// dimensions: 2 (number of parameters) - 2 ln L.
pub(crate) fn aic(log_likelihood: f64, k: usize, dim: usize) -> f64 {
    let parameters = (k - 1) + k * dim + k * dim * (dim + 1) / 2;
    2.0 * parameters as f64 - 2.0 * log_likelihood
}

fn distance2(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// `k` centres among the points: the first uniformly, each next one with probability
/// proportional to its squared distance to the nearest centre so far; `None` when fewer than
/// `k` points are distinct (or there are none).
fn kmeans_plus_plus(data: &[f64], dim: usize, k: usize, rng: &mut dyn RngCore) -> Option<Vec<Vec<f64>>> {
    let n = data.len() / dim;
    if n == 0 {
        return None;
    }
    let point = |i: usize| &data[i * dim..(i + 1) * dim];
    let first = point(rng.random_range(0..n)).to_vec();
    let mut nearest: Vec<f64> = (0..n).map(|i| distance2(point(i), &first)).collect();
    let mut centres = vec![first];
    while centres.len() < k {
        let next = point(proportional(nearest.iter().copied(), rng.random())?).to_vec();
        for (i, d) in nearest.iter_mut().enumerate() {
            *d = d.min(distance2(point(i), &next));
        }
        centres.push(next);
    }
    Some(centres)
}

/// Lloyd's k-means from `centres` until no point changes its centre (at most
/// [`MAX_ITERATIONS`] rounds): the label of every point, its nearest centre (ties to the lowest
/// index). A centre that loses every point stays where it was.
fn kmeans(data: &[f64], dim: usize, mut centres: Vec<Vec<f64>>) -> Vec<usize> {
    // Each distance once, and the first of the least; as a NaN is never less, one never wins.
    let nearest = |point: &[f64], centres: &[Vec<f64>]| {
        let mut distances = centres.iter().map(|centre| distance2(point, centre)).enumerate();
        let first = distances.next().unwrap_or((0, 0.0));
        distances
            .fold(first, |best, (c, d)| if d < best.1 { (c, d) } else { best })
            .0
    };
    let mut labels: Vec<usize> = data.chunks(dim).map(|point| nearest(point, &centres)).collect();
    for _ in 0..MAX_ITERATIONS {
        let mut sums = vec![vec![0.0; dim]; centres.len()];
        let mut counts = vec![0usize; centres.len()];
        for (point, &label) in data.chunks(dim).zip(&labels) {
            sums[label].iter_mut().zip(point).for_each(|(s, x)| *s += x);
            counts[label] += 1;
        }
        for ((centre, sum), &count) in centres.iter_mut().zip(sums).zip(&counts) {
            if count > 0 {
                *centre = sum.into_iter().map(|s| s / count as f64).collect();
            }
        }
        let next: Vec<usize> = data.chunks(dim).map(|point| nearest(point, &centres)).collect();
        if next == labels {
            break;
        }
        labels = next;
    }
    labels
}

/// The lower Cholesky factor of the symmetric `dim` x `dim` matrix `a` (row by row) into the
/// lower triangle of `l` (its upper one stays as it is, zero), or `None` when `a` is not
/// positive definite.
fn cholesky(a: &[f64], dim: usize, l: &mut [f64]) -> Option<()> {
    for i in 0..dim {
        for j in 0..=i {
            let dot: f64 = (0..j).map(|m| l[i * dim + m] * l[j * dim + m]).sum();
            if i == j {
                let pivot = a[i * dim + i] - dot;
                if !(pivot > 0.0 && pivot.is_finite()) {
                    return None;
                }
                l[i * dim + i] = pivot.sqrt();
            } else {
                l[i * dim + j] = (a[i * dim + j] - dot) / l[j * dim + j];
            }
        }
    }
    Some(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// `counts[c]` points from N(means[c], sd[c]^2 I), shuffled, one after another.
    fn sample(means: &[Vec<f64>], sds: &[f64], counts: &[usize], rng: &mut ChaCha8Rng) -> Vec<f64> {
        let mut points: Vec<Vec<f64>> = Vec::new();
        for ((mean, &sd), &count) in means.iter().zip(sds).zip(counts) {
            for _ in 0..count {
                points.push(
                    mean.iter()
                        .map(|m| m + sd * rng.sample::<f64, _>(StandardNormal))
                        .collect(),
                );
            }
        }
        rand::seq::SliceRandom::shuffle(points.as_mut_slice(), rng);
        points.concat()
    }

    fn well_separated() -> (Vec<Vec<f64>>, Vec<f64>, Vec<usize>) {
        (
            vec![vec![0.1, 0.2, 0.0], vec![0.8, 0.7, 0.5], vec![0.2, 0.9, 1.0]],
            vec![0.03, 0.05, 0.04],
            vec![300, 180, 120],
        )
    }

    #[test]
    fn a_fit_recovers_the_means_and_weights_of_well_separated_gaussians() {
        let (means, sds, counts) = well_separated();
        for seed in 0..3 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let data = sample(&means, &sds, &counts, &mut rng);
            let (mixture, _) = Mixture::fit(&data, 3, 3, &mut rng).unwrap();
            for (mean, (&sd, &count)) in means.iter().zip(sds.iter().zip(&counts)) {
                let fitted = mixture
                    .components()
                    .iter()
                    .min_by(|a, b| distance2(&a.mean, mean).total_cmp(&distance2(&b.mean, mean)))
                    .unwrap();
                assert!(
                    distance2(&fitted.mean, mean).sqrt() < 0.02,
                    "seed {seed}: {fitted:?} vs {mean:?}"
                );
                assert!(
                    (fitted.weight - count as f64 / 600.0).abs() < 0.02,
                    "seed {seed}: {fitted:?}"
                );
                // Each variance is about sd^2 (within 40% for 120..300 points).
                for i in 0..3 {
                    let variance = fitted.covariance[i * 3 + i];
                    assert!(
                        (variance / (sd * sd) - 1.0).abs() < 0.4,
                        "seed {seed}: {variance} vs {}",
                        sd * sd
                    );
                }
            }
            let weights: f64 = mixture.components().iter().map(|c| c.weight).sum();
            assert!((weights - 1.0).abs() < 1e-9);
        }
    }

    #[test]
    fn aic_picks_the_number_of_components_that_made_the_data() {
        for (components, seed) in [(2, 10), (3, 11), (4, 12)] {
            let (mut means, mut sds, mut counts) = well_separated();
            means.push(vec![0.9, 0.1, 0.9]);
            sds.push(0.04);
            counts.push(150);
            means.truncate(components);
            sds.truncate(components);
            counts.truncate(components);
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let data = sample(&means, &sds, &counts, &mut rng);
            let best = Mixture::fit_best(&data, 3, 2..=8, &mut rng).unwrap();
            assert_eq!(best.components().len(), components, "seed {seed}");
        }
    }

    #[test]
    fn the_criterion_counts_weights_means_and_full_covariances() {
        // k = 2 in 3 dimensions: 1 weight, 6 mean coordinates, 12 covariance entries.
        assert_eq!(aic(-10.0, 2, 3), 2.0 * 19.0 + 20.0);
    }

    #[test]
    fn same_stream_same_fit_and_degenerate_data_fit_what_they_can() {
        let (means, sds, counts) = well_separated();
        let data = sample(&means, &sds, &counts, &mut ChaCha8Rng::seed_from_u64(5));
        let fit = |seed| {
            let mixture = Mixture::fit_best(&data, 3, 2..=5, &mut ChaCha8Rng::seed_from_u64(seed)).unwrap();
            mixture.components().to_vec()
        };
        assert_eq!(fit(1), fit(1));
        // Two distinct points, each repeated: two components fit, three do not.
        let two = [[0.0, 0.0], [1.0, 1.0]].repeat(20).concat();
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        assert!(Mixture::fit(&two, 2, 2, &mut rng).is_some());
        assert!(Mixture::fit(&two, 2, 3, &mut rng).is_none());
        assert_eq!(
            Mixture::fit_best(&two, 2, 2..=4, &mut rng).unwrap().components().len(),
            2
        );
        let one = [0.5, 0.5].repeat(10);
        assert!(Mixture::fit_best(&one, 2, 2..=4, &mut rng).is_none());
        // Every point with the same value in one coordinate: the regularisation keeps the
        // covariances positive definite.
        let flat: Vec<f64> = (0..50).flat_map(|i| [i as f64 / 50.0, 0.0]).collect();
        assert!(Mixture::fit_best(&flat, 2, 2..=3, &mut rng).is_some());
    }

    #[test]
    fn draws_follow_the_marginal_of_the_leading_coordinates() {
        // A correlated 3-D Gaussian: the first two coordinates have means (1, -2), variances
        // 4 and 1 and covariance 1.2.
        let component = Component {
            weight: 1.0,
            mean: vec![1.0, -2.0, 0.5],
            covariance: vec![4.0, 1.2, 0.3, 1.2, 1.0, 0.1, 0.3, 0.1, 0.5],
        };
        let mixture = Mixture::new(3, vec![component]).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let n = 50_000;
        let draws: Vec<Vec<f64>> = (0..n).map(|_| mixture.sample_leading(0, 2, &mut rng)).collect();
        let mean = |i: usize| draws.iter().map(|d| d[i]).sum::<f64>() / n as f64;
        let (m0, m1) = (mean(0), mean(1));
        let moment = |i: usize, j: usize, mi: f64, mj: f64| {
            draws.iter().map(|d| (d[i] - mi) * (d[j] - mj)).sum::<f64>() / n as f64
        };
        assert!((m0 - 1.0).abs() < 0.05 && (m1 + 2.0).abs() < 0.03, "{m0} {m1}");
        assert!((moment(0, 0, m0, m0) - 4.0).abs() < 0.15);
        assert!((moment(1, 1, m1, m1) - 1.0).abs() < 0.04);
        assert!((moment(0, 1, m0, m1) - 1.2).abs() < 0.06);
        // Not positive definite, or of the wrong size: refused.
        let bad = Component {
            weight: 1.0,
            mean: vec![0.0, 0.0],
            covariance: vec![1.0, 2.0, 2.0, 1.0],
        };
        assert!(Mixture::new(2, vec![bad.clone()]).is_none());
        assert!(Mixture::new(3, vec![bad]).is_none());
    }

    /// [`Mixture::fit`] as first written, a point and a component at a time, for the fast one to
    /// match bit for bit: its components and log-likelihood.
    fn reference_fit(data: &[f64], dim: usize, k: usize, rng: &mut dyn RngCore) -> Option<(Vec<Component>, f64)> {
        let n = data.len() / dim;
        let x = |p: usize, i: usize| data[p * dim + i];
        let point = |p: usize| &data[p * dim..(p + 1) * dim];
        let nearest = |p: usize, centres: &[Vec<f64>]| {
            let d = |c: usize| distance2(point(p), &centres[c]);
            (0..centres.len()).fold(0, |best, c| if d(c) < d(best) { c } else { best })
        };
        let mut centres = kmeans_plus_plus(data, dim, k, rng)?;
        let mut labels: Vec<usize> = (0..n).map(|p| nearest(p, &centres)).collect();
        for _ in 0..MAX_ITERATIONS {
            for (c, centre) in centres.iter_mut().enumerate() {
                let members: Vec<usize> = (0..n).filter(|&p| labels[p] == c).collect();
                if !members.is_empty() {
                    let sum = |i| members.iter().fold(0.0, |sum, &p| sum + x(p, i));
                    *centre = (0..dim).map(|i| sum(i) / members.len() as f64).collect();
                }
            }
            let next: Vec<usize> = (0..n).map(|p| nearest(p, &centres)).collect();
            if next == labels {
                break;
            }
            labels = next;
        }
        let mut r: Vec<Vec<f64>> = labels
            .iter()
            .map(|&label| (0..k).map(|c| if c == label { 1.0 } else { 0.0 }).collect())
            .collect();
        let maximise = |r: &[Vec<f64>]| {
            let component = |c: usize| {
                let mass = r.iter().map(|row| row[c]).sum::<f64>() + 10.0 * f64::EPSILON;
                let mean: Vec<f64> = (0..dim)
                    .map(|i| (0..n).fold(0.0, |m, p| m + r[p][c] * x(p, i)) / mass)
                    .collect();
                let mut covariance = vec![0.0; dim * dim];
                for i in 0..dim {
                    for j in 0..=i {
                        let d = |p: usize, i: usize| x(p, i) - mean[i];
                        let sum = (0..n).fold(0.0, |s, p| s + r[p][c] * d(p, i) * d(p, j));
                        covariance[i * dim + j] = sum / mass + if i == j { REGULARISATION } else { 0.0 };
                        covariance[j * dim + i] = covariance[i * dim + j];
                    }
                }
                let weight = mass / n as f64;
                Component {
                    weight,
                    mean,
                    covariance,
                }
            };
            Mixture::new(dim, (0..k).map(component).collect())
        };
        let expect = |mixture: &Mixture, r: &mut [Vec<f64>]| {
            let mut total = 0.0;
            for (p, row) in r.iter_mut().enumerate() {
                for (c, joint) in row.iter_mut().enumerate() {
                    let (l, mean) = (&mixture.factors[c], &mixture.components[c].mean);
                    let (mut y, mut distance) = (vec![0.0; dim], 0.0);
                    for i in 0..dim {
                        let dot: f64 = (0..i).map(|j| l[i * dim + j] * y[j]).sum();
                        y[i] = (x(p, i) - mean[i] - dot) / l[i * dim + i];
                        distance += y[i] * y[i];
                    }
                    *joint = mixture.log_norms[c] - 0.5 * distance;
                }
                let max = row.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                row.iter_mut().for_each(|r| *r = (*r - max).exp());
                let sum: f64 = row.iter().sum();
                row.iter_mut().for_each(|r| *r /= sum);
                total += max + sum.ln();
            }
            total
        };
        let mut mixture = maximise(&r)?;
        let mut previous = f64::NEG_INFINITY;
        for _ in 0..MAX_ITERATIONS {
            let log_likelihood = expect(&mixture, &mut r);
            if (log_likelihood - previous).abs() < TOLERANCE * n as f64 {
                return Some((mixture.components, log_likelihood));
            }
            previous = log_likelihood;
            mixture = maximise(&r)?;
        }
        let log_likelihood = expect(&mixture, &mut r);
        Some((mixture.components, log_likelihood))
    }

    #[test]
    fn fits_are_bit_identical_to_the_point_at_a_time_reference() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let (means, sds, counts) = well_separated();
        let mut sets = vec![(sample(&means, &sds, &counts, &mut rng), 3)];
        // Every dimension with a constant M step, and one without.
        for dim in 2..=5 {
            sets.push(((0..150 * dim).map(|_| rng.random()).collect(), dim));
        }
        // Tight clusters, where most exponentials underflow; repeated points, where large k fail.
        sets.push((sample(&means, &[1e-3; 3], &[50, 40, 30], &mut rng), 3));
        sets.push((
            [[0.1, 0.2, 0.3], [0.9, 0.8, 0.7], [0.5, 0.5, 0.0]].repeat(30).concat(),
            3,
        ));
        let bits = |(components, log_likelihood): (Vec<Component>, f64)| {
            let values = components
                .into_iter()
                .flat_map(|c| [vec![c.weight], c.mean, c.covariance].concat());
            values.chain([log_likelihood]).map(f64::to_bits).collect::<Vec<_>>()
        };
        for (set, (data, dim)) in sets.iter().enumerate() {
            for k in 1..=6 {
                let seed = 10 * set as u64 + k as u64;
                let fit = Mixture::fit(data, *dim, k, &mut ChaCha8Rng::seed_from_u64(seed));
                let reference = reference_fit(data, *dim, k, &mut ChaCha8Rng::seed_from_u64(seed));
                let fit = fit.map(|(mixture, log_likelihood)| (mixture.components, log_likelihood));
                assert_eq!(fit.map(bits), reference.map(bits), "set {set}, k = {k}");
            }
        }
    }

    #[test]
    fn the_shortcuts_of_exp_return_its_bits() {
        let edges = [0.0, -0.0, 1e-300, -1e-300, -745.133, -745.134, -746.0, -1e300];
        let around_the_underflow = (0..1500).map(|i| -750.0 + 0.01 * i as f64);
        for x in edges.into_iter().chain(around_the_underflow).chain([f64::NEG_INFINITY]) {
            assert_eq!(exp(x).to_bits(), x.exp().to_bits(), "{x}");
        }
        assert!(exp(f64::NAN).is_nan());
    }

    #[test]
    fn cholesky_factors_reproduce_the_matrix() {
        let a = [4.0, 2.0, 0.4, 2.0, 5.0, 1.0, 0.4, 1.0, 3.0];
        let mut l = [0.0; 9];
        cholesky(&a, 3, &mut l).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                let product: f64 = (0..3).map(|m| l[i * 3 + m] * l[j * 3 + m]).sum();
                assert!((product - a[i * 3 + j]).abs() < 1e-12);
            }
            assert!((i + 1..3).all(|j| l[i * 3 + j] == 0.0), "lower triangular");
        }
    }
}
