use super::*;
use crate::creps::{Batch, FeatureMap, LinearGaussianPolicy, UpdateSettings, update};
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

/// Rollouts and a policy of one of the two scales.
pub(crate) struct DataSet {
    pub(crate) features: FeatureMap,
    pub(crate) contexts: Vec<Vec<f64>>,
    thetas: Vec<Vec<f64>>,
    pub(crate) returns: Vec<f64>,
    pub(crate) epsilon: f64,
    policy: LinearGaussianPolicy,
}

impl DataSet {
    pub(crate) fn phi(&self) -> DMatrix<f64> {
        let rows: Vec<_> = self
            .contexts
            .iter()
            .map(|s| self.features.apply(s).transpose())
            .collect();
        DMatrix::from_rows(&rows)
    }

    fn solve(&self, returns: &[f64]) -> DualSolution {
        solve_dual(
            &self.phi(),
            returns,
            self.epsilon,
            DEFAULT_ETA_MIN,
            &DualOptions::default(),
        )
        .unwrap()
    }

    fn update(&self, returns: &[f64]) -> (LinearGaussianPolicy, crate::creps::UpdateReport) {
        let batch = Batch::from_contexts(&self.features, &self.contexts, &self.thetas, returns).unwrap();
        let settings = UpdateSettings {
            epsilon: self.epsilon,
            ..UpdateSettings::default()
        };
        update(&self.policy, &batch, &settings).unwrap()
    }
}

/// The PA-10 grid scale: N 300, 21 parameters, polar-quadratic features of targets in
/// [-5, -3]^2, epsilon 0.5; returns `-||landing - target||^2` in m^2 with a landing error linear
/// in theta plus a context-dependent bias, on an exploration scale that varies per data set
/// (from the start of learning to near convergence).
pub(crate) fn throwing(seed: u64) -> DataSet {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let spread = 10f64.powf(rng.random_range(-3.0..-0.8));
    let gains = DMatrix::from_fn(2, 21, |_, _| rng.sample::<f64, _>(StandardNormal));
    let bias = [rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3)];
    let (mut contexts, mut thetas, mut returns) = (vec![], vec![], vec![]);
    for _ in 0..300 {
        let s = vec![rng.random_range(-5.0..-3.0), rng.random_range(-5.0..-3.0)];
        let theta = DVector::from_fn(21, |_, _| spread * rng.sample::<f64, _>(StandardNormal));
        let error = &gains * &theta;
        let dx = error[0] + bias[0] * (s[0] + 4.0);
        let dy = error[1] + bias[1] * (s[1] + 4.0).powi(2);
        returns.push(-(dx * dx + dy * dy));
        contexts.push(s);
        thetas.push(theta.as_slice().to_vec());
    }
    let covariance = DMatrix::identity(21, 21) * spread * spread;
    DataSet {
        features: FeatureMap::PolarQuadratic,
        contexts,
        thetas,
        returns,
        epsilon: 0.5,
        policy: LinearGaussianPolicy::new(DMatrix::zeros(6, 21), covariance).unwrap(),
    }
}

/// The Section 5.1 scale: N 50, 20 parameters, quadratic features of grid contexts in
/// [-1, 1]^2, epsilon 2, exploration on a scale that varies per data set.
pub(crate) fn function(seed: u64) -> DataSet {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let a = DMatrix::from_fn(2, 20, |_, _| rng.random_range(0.0..1.0));
    let spread = 10f64.powf(rng.random_range(-2.0..0.0));
    let grid = linspace(-1.0, 1.0, 5);
    function_rollouts(&mut rng, &a, spread, 50, |rng, _| {
        vec![grid[rng.random_range(0..5)], grid[rng.random_range(0..5)]]
    })
}

/// The first update of every Section 5.1 run: one rollout of the initial policy (W = 0, Sigma
/// = I) at each of the 25 grid contexts, as the initial sweep of D-UCB or round robin gives. Each
/// context has a single sample, so the greedy limit of the weights is a degenerate linear program.
pub(crate) fn sweep(seed: u64) -> DataSet {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let a = DMatrix::from_fn(2, 20, |_, _| rng.random_range(0.0..1.0));
    let grid = linspace(-1.0, 1.0, 5);
    function_rollouts(&mut rng, &a, 1.0, 25, |_, i| vec![grid[i / 5], grid[i % 5]])
}

/// `n` rollouts of the contextual function `-||A theta - s|| ||s||^2 + sum s` with
/// `theta ~ N(0, spread^2 I)` at the contexts `context(rng, i)`.
fn function_rollouts(
    rng: &mut ChaCha8Rng,
    a: &DMatrix<f64>,
    spread: f64,
    n: usize,
    mut context: impl FnMut(&mut ChaCha8Rng, usize) -> Vec<f64>,
) -> DataSet {
    let (mut contexts, mut thetas, mut returns) = (vec![], vec![], vec![]);
    for i in 0..n {
        let s = DVector::from_vec(context(rng, i));
        let theta = DVector::from_fn(a.ncols(), |_, _| spread * rng.sample::<f64, _>(StandardNormal));
        returns.push(-(a * &theta - &s).norm() * s.norm_squared() + s.sum());
        contexts.push(s.as_slice().to_vec());
        thetas.push(theta.as_slice().to_vec());
    }
    let covariance = DMatrix::identity(a.ncols(), a.ncols()) * spread * spread;
    DataSet {
        features: FeatureMap::Quadratic,
        contexts,
        thetas,
        returns,
        epsilon: 2.0,
        policy: LinearGaussianPolicy::new(DMatrix::zeros(6, a.ncols()), covariance).unwrap(),
    }
}

/// Checks the optimality conditions of `solution` on `phi` and returns whether eta was off its
/// bound: the projected gradient below 1e-8, KL = epsilon to 1e-6 relative off the bound (and
/// at most epsilon on it), weighted feature means equal to the sample means to 1e-8 relative to
/// each feature's standard deviation over the samples.
fn assert_optimal(name: &str, phi: &DMatrix<f64>, solution: &DualSolution, epsilon: f64) -> bool {
    assert!(
        solution.converged && solution.optimality <= 1e-8,
        "{name}: optimality {} after {} iterations",
        solution.optimality,
        solution.iterations
    );
    if solution.eta_at_bound {
        assert!(
            solution.kl <= epsilon * (1.0 + 1e-6),
            "{name}: KL {} on the bound",
            solution.kl
        );
    } else {
        assert!(
            (solution.kl - epsilon).abs() <= 1e-6 * epsilon,
            "{name}: KL {} for epsilon {epsilon}",
            solution.kl
        );
    }
    let residual = feature_matching_residual(phi, solution.weights.as_slice());
    for j in 0..phi.ncols() {
        let column = phi.column(j);
        let spread = (column.add_scalar(-column.mean()).norm_squared() / phi.nrows() as f64).sqrt();
        // A constant feature is matched exactly up to the rounding of sum d = 1.
        let allowed = 1e-8 * spread + 1e-14 * column.amax();
        assert!(
            residual[j].abs() <= allowed,
            "{name}: feature {j} residual {} (spread {spread})",
            residual[j]
        );
    }
    !solution.eta_at_bound
}

/// Largest entry of `a - b` relative to the largest of `b`.
fn relative_difference(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).amax() / b.amax()
}

/// At both scales of the issue, over many random data sets, the solution is optimal, and rewards
/// scaled by 1e-6 .. 1e6 and shifted give the same eta (scaled), W and Sigma to 1e-9.
///
/// On the initial sweep of the smaller scale (eta on its bound) the same holds for eta and the
/// weights, but W and Sigma only to 1e-7: there about 4 samples carry the weight for 6 features,
/// so two directions of W are set by the ridge (1e-4) and by samples whose weights are at the
/// solver's resolution (1e-11 to 1e-10, or 0 in the other solve), which the fit amplifies by
/// 1 / ridge (CHOICES.md).
#[test]
fn random_problems_are_solved_to_the_optimum_in_any_units() {
    let mut off_bound = 0;
    let mut total = 0;
    let mut worst = [0.0f64; 3];
    for seed in 0..40 {
        for (family, data) in [throwing(seed), function(1000 + seed), sweep(2000 + seed)]
            .into_iter()
            .enumerate()
        {
            let phi = data.phi();
            let name = format!("{:?} {} seed {seed}", data.features, data.returns.len());
            let solution = data.solve(&data.returns);
            off_bound += usize::from(assert_optimal(&name, &phi, &solution, data.epsilon));
            total += 1;
            let (policy, report) = data.update(&data.returns);
            assert_eq!(report.rejected, None, "{name}");
            let n = data.returns.len() as f64;
            let mean = data.returns.iter().sum::<f64>() / n;
            let spread = (data.returns.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n).sqrt();
            let limit = if family == 2 { 1e-7 } else { 1e-9 };
            for scale in [1e-6, 1e-3, 1e3, 1e6] {
                for shift in [0.0, -3.0, 250.0] {
                    let returns: Vec<f64> = data
                        .returns
                        .iter()
                        .map(|r| scale * r + shift * scale * spread)
                        .collect();
                    let case = format!("{name} x{scale:e} + {shift} std");
                    let scaled = data.solve(&returns);
                    assert_optimal(&case, &phi, &scaled, data.epsilon);
                    assert_eq!(scaled.eta_at_bound, solution.eta_at_bound, "{case}");
                    assert!((scaled.eta / (scale * solution.eta) - 1.0).abs() < 1e-9, "{case}");
                    assert!((&scaled.weights - &solution.weights).amax() < 1e-9, "{case}");
                    let (scaled_policy, _) = data.update(&returns);
                    for (what, got, want) in [
                        ("W", scaled_policy.weights(), policy.weights()),
                        ("Sigma", scaled_policy.covariance(), policy.covariance()),
                    ] {
                        let difference = relative_difference(got, want);
                        worst[family] = worst[family].max(difference);
                        assert!(difference <= limit, "{case}: {what} differs by {difference:e}");
                    }
                }
            }
        }
    }
    eprintln!("largest relative difference of W or Sigma per family: {worst:?}");
    // Both regimes occur: the KL bound active, and slack with eta on its bound.
    assert!(
        off_bound >= total / 2 && off_bound < total,
        "{off_bound} of {total} off the bound"
    );
}

#[test]
fn gradient_matches_central_differences() {
    for seed in 0..5 {
        let data = function(seed);
        let phi = data.phi();
        let mut rng = ChaCha8Rng::seed_from_u64(100 + seed);
        let eta = rng.random_range(0.2..3.0);
        let v: Vec<f64> = (0..6).map(|_| rng.random_range(-2.0..2.0)).collect();
        let x = DVector::from_fn(7, |i, _| if i == 0 { eta } else { v[i - 1] });
        let at = |x: &DVector<f64>| evaluate_dual(&phi, &data.returns, 0.7, x[0], &x.as_slice()[1..]).unwrap();
        let value = |x: &DVector<f64>| DVector::from_element(1, at(x).value);
        let gradient = DMatrix::from_row_slice(1, x.len(), at(&x).gradient.as_slice());
        assert_derivatives_match(&x, value, &gradient, &format!("seed {seed}: "));
    }
}

/// The solver's Hessian is the derivative of its gradient (the standardised dual's).
#[test]
fn hessian_matches_central_differences_of_the_gradient() {
    let data = throwing(3);
    let problem = Standardised::new(&data.phi(), &data.returns, data.epsilon).unwrap();
    let k = problem.rank();
    let mut scratch = Scratch::new(300, k);
    let u = DVector::from_fn(k, |i, _| 0.1 * i as f64 - 0.2);
    let eta = 0.7;
    problem.evaluate(eta, u.clone(), &mut scratch);
    let hessian = scratch.hessian(&problem.basis, eta);
    let x = DVector::from_fn(1 + k, |i, _| if i == 0 { eta } else { u[i - 1] });
    let gradient = |x: &DVector<f64>| {
        let point = problem.evaluate(x[0], x.rows(1, k).into_owned(), &mut scratch);
        let mut g = DVector::zeros(1 + k);
        g[0] = point.gradient_eta;
        g.rows_mut(1, k).copy_from(&point.gradient_u);
        g
    };
    assert_derivatives_match(&x, gradient, &hessian, "");
}

/// Every column of `jacobian` equals the central difference (step 1e-6) of `f` at `x`, to 1e-6
/// relative: a gradient (one row) of a value, or a Hessian of a gradient. `label` starts the
/// failure message.
pub(crate) fn assert_derivatives_match(
    x: &DVector<f64>,
    mut f: impl FnMut(&DVector<f64>) -> DVector<f64>,
    jacobian: &DMatrix<f64>,
    label: &str,
) {
    let h = 1e-6;
    for i in 0..x.len() {
        let (mut up, mut down) = (x.clone(), x.clone());
        up[i] += h;
        down[i] -= h;
        let column = (f(&up) - f(&down)) / (2.0 * h);
        for j in 0..column.len() {
            assert!(
                (column[j] - jacobian[(j, i)]).abs() < 1e-6 * (1.0 + column[j].abs()),
                "{label}[{j}, {i}]: analytic {} vs numeric {}",
                jacobian[(j, i)],
                column[j]
            );
        }
    }
}

#[test]
fn evaluation_is_stable_for_tiny_eta_and_huge_returns() {
    let mut data = function(3);
    data.returns.iter_mut().for_each(|r| *r *= 1e6);
    let value = evaluate_dual(&data.phi(), &data.returns, 0.5, 1e-8, &[0.0; 6]).unwrap();
    // eta LSE -> max_i R_i as eta -> 0.
    let max_return = data.returns.iter().cloned().fold(f64::MIN, f64::max);
    assert!((value.value - max_return).abs() < 1e-6 * max_return.abs());
    assert!(value.gradient.iter().all(|g| g.is_finite()));
}

/// The notes' NumPy re-run of BOLeRo's dual: the same optimum (BOLeRo's solver stops within
/// about 1e-6 of it).
#[test]
fn reproduces_the_reference_solution() {
    let x = linspace(-1.0, 1.0, 11);
    let phi = polynomial_features(&x, 1);
    let returns: Vec<f64> = x.iter().map(|x| (3.0 * x).sin() - x * x).collect();
    let solution = solve_dual(&phi, &returns, 0.5, 1e-8, &DualOptions::default()).unwrap();
    assert!(solution.converged && !solution.eta_at_bound);
    assert!((solution.eta - 0.341885).abs() < 1e-5, "{}", solution.eta);
    assert!((solution.v[0] - 1.227724).abs() < 1e-5, "{}", solution.v);
    assert!((solution.objective - 0.08925233).abs() < 1e-7, "{}", solution.objective);
    assert!((solution.kl - 0.5).abs() < 1e-10, "{}", solution.kl);
    let expected = [
        0.1487, 0.04355, 0.02013, 0.01991, 0.04038, 0.1154, 0.2612, 0.2626, 0.08061, 0.007241, 0.000258,
    ];
    for (d, want) in solution.weights.iter().zip(expected) {
        assert!((d - want).abs() < 1e-3, "{} vs {want}", solution.weights);
    }
    // The returned point is the dual's minimum in the original parametrisation too.
    let at = evaluate_dual(&phi, &returns, 0.5, solution.eta, solution.v.as_slice()).unwrap();
    assert!((at.value - solution.objective).abs() < 1e-14);
    assert!(at.gradient.amax() < 1e-10, "{}", at.gradient);
}

/// BOLeRo's `test_baseline_overestimates`: R is exactly a quadratic of the features, so the
/// baseline absorbs it, the weights are uniform, the KL bound is slack and eta is on its bound.
#[test]
fn an_exactly_representable_return_gives_uniform_weights_on_the_bound() {
    let x = linspace(0.0, 1.0, 11);
    let phi = polynomial_features(&x, 2);
    let returns: Vec<f64> = x.iter().map(|x| 10.0 * (x - 0.3).powi(2)).collect();
    let solution = solve_dual(&phi, &returns, 1.0, 1e-6, &DualOptions::default()).unwrap();
    assert!(solution.eta_at_bound && solution.converged);
    let std = (returns.iter().map(|r| r * r).sum::<f64>() / 11.0 - (returns.iter().sum::<f64>() / 11.0).powi(2)).sqrt();
    assert!((solution.eta / (1e-6 * std) - 1.0).abs() < 1e-12);
    for d in solution.weights.iter() {
        assert!((d - 1.0 / 11.0).abs() < 1e-9, "{}", solution.weights);
    }
    assert!(solution.kl < 1e-12);
}

/// With epsilon above what the features allow (log N = 2.3 for 10 samples), the KL bound is
/// slack and the weights are the greedy limit: the feature-matched weighting concentrated on as
/// few samples as the features allow.
#[test]
fn a_slack_kl_bound_puts_eta_on_its_bound_with_features_still_matched() {
    for seed in 0..10 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let x: Vec<f64> = (0..10).map(|_| rng.random_range(-1.0..1.0)).collect();
        let phi = polynomial_features(&x, 1);
        let returns: Vec<f64> = (0..10).map(|_| rng.sample(StandardNormal)).collect();
        let solution = solve_dual(&phi, &returns, 3.0, DEFAULT_ETA_MIN, &DualOptions::default()).unwrap();
        assert!(solution.eta_at_bound, "seed {seed}: eta {}", solution.eta);
        assert_optimal(&format!("seed {seed}"), &phi, &solution, 3.0);
        // At most rank + 1 = 2 samples carry weight at the greedy limit.
        assert!(solution.weights.iter().filter(|&&d| d > 1e-6).count() <= 2);
    }
}

#[test]
fn degenerate_data_have_well_defined_solutions() {
    let phi = polynomial_features(&linspace(0.0, 1.0, 5), 1);
    // Equal returns: uniform weights, eta 0 on its bound.
    let equal = solve_dual(&phi, &[-2.5; 5], 0.5, DEFAULT_ETA_MIN, &DualOptions::default()).unwrap();
    assert_eq!(equal.weights.as_slice(), &[0.2; 5]);
    assert!(equal.eta_at_bound && equal.eta == 0.0 && equal.kl == 0.0 && equal.objective == -2.5);
    // One context only: the features carry nothing, eta alone meets the KL bound.
    let same = DMatrix::from_fn(20, 2, |_, j| if j == 0 { 0.3 } else { 1.0 });
    let returns: Vec<f64> = (0..20).map(|i| (i as f64).sin()).collect();
    let solution = solve_dual(&same, &returns, 0.5, DEFAULT_ETA_MIN, &DualOptions::default()).unwrap();
    assert_optimal("one context", &same, &solution, 0.5);
    assert!(!solution.eta_at_bound);
    // A single sample.
    let one = solve_dual(
        &phi.rows(0, 1).into_owned(),
        &[3.0],
        0.5,
        DEFAULT_ETA_MIN,
        &DualOptions::default(),
    )
    .unwrap();
    assert_eq!(one.weights.as_slice(), &[1.0]);
    // Fewer samples than features: feature matching fixes the weights, which are uniform.
    let few = DMatrix::from_fn(3, 6, |i, j| {
        ((i * 7 + j * 3) % 5) as f64 - 2.0 + if j == 5 { 10.0 } else { 0.0 }
    });
    let solution = solve_dual(&few, &[1.0, 4.0, -2.0], 0.5, DEFAULT_ETA_MIN, &DualOptions::default()).unwrap();
    assert_optimal("N < n_phi", &few, &solution, 0.5);
    // Returns at the edge of the finite range stay finite.
    let huge = solve_dual(
        &phi,
        &[f64::MAX, -f64::MAX, 0.0, 1.0, f64::MAX],
        0.5,
        DEFAULT_ETA_MIN,
        &DualOptions::default(),
    )
    .unwrap();
    assert_optimal("huge returns", &phi, &huge, 0.5);
    assert!(huge.eta.is_finite() && huge.objective.is_finite());
}

#[test]
fn helpers_match_hand_values() {
    assert_eq!(kl_to_uniform(&[0.25; 4]), 0.0);
    assert!((kl_to_uniform(&[1.0, 0.0]) - 2f64.ln()).abs() < 1e-15);
    assert!((kl_to_uniform(&[0.75, 0.25]) - (0.75 * 1.5f64.ln() + 0.25 * 0.5f64.ln())).abs() < 1e-15);
    assert_eq!(effective_sample_size(&[0.25; 4]), 4.0);
    assert_eq!(effective_sample_size(&[1.0, 0.0, 0.0]), 1.0);
}

#[test]
fn bad_inputs_are_errors_naming_the_argument() {
    let phi = polynomial_features(&linspace(-1.0, 1.0, 11), 1);
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
    assert_eq!(
        message(0.5, 0.0, &defaults),
        "eta_min must be within [1e-8, 1e0], got 0e0"
    );
    assert_eq!(
        message(0.5, 2.0, &defaults),
        "eta_min must be within [1e-8, 1e0], got 2e0"
    );
    let loose = DualOptions {
        tolerance: f64::NAN,
        ..DualOptions::default()
    };
    assert!(message(0.5, 1e-8, &loose).starts_with("tolerance must be within [1e-14, 1e-3]"));
    let no_iterations = DualOptions {
        max_iterations: 0,
        ..DualOptions::default()
    };
    assert!(message(0.5, 1e-8, &no_iterations).starts_with("max_iterations must be"));
    let mut nan_returns = returns.clone();
    nan_returns[3] = f64::NAN;
    let error = solve_dual(&phi, &nan_returns, 0.5, 1e-8, &defaults).unwrap_err();
    assert_eq!(error.to_string(), "returns must be finite, got NaN at index 3");
    assert_eq!(
        solve_dual(&DMatrix::zeros(0, 2), &[], 0.5, 1e-8, &defaults).unwrap_err(),
        DualSolveError::NoSamples
    );
    let error = evaluate_dual(&phi, &returns, 0.5, 1.0, &[0.0]).unwrap_err();
    assert_eq!(
        error.to_string(),
        "the length of v (1) must equal the number of phi columns (2)"
    );
    assert!(evaluate_dual(&phi, &returns, 0.5, 0.0, &[0.0, 0.0]).is_err());
}

/// Every solve of 250 random data sets per family converges, in few Newton steps: the PA-10
/// scale (KL bound active), the Section 5.1 scale (mostly active) and its initial sweep (slack,
/// eta follows the path down to its bound). Step counts are deterministic, so this guards the
/// solver's efficiency; `--nocapture` prints their distribution.
#[test]
fn solves_take_few_newton_steps() {
    /// A family: its name, its data sets, and limits on the 90th percentile and the maximum.
    type Family = (&'static str, fn(u64) -> DataSet, usize, usize);
    let families: [Family; 3] = [
        ("PA-10 scale", throwing, 8, 12),
        ("Section 5.1 scale", function, 13, 30),
        ("Section 5.1 initial sweep", sweep, 25, 45),
    ];
    for (name, data, p90_limit, max_limit) in families {
        let mut steps = Vec::new();
        let mut on_bound = 0;
        for seed in 0..250 {
            let data = data(3000 + seed);
            let solution = data.solve(&data.returns);
            assert!(solution.converged, "{name} seed {seed}: {}", solution.optimality);
            steps.push(solution.iterations);
            on_bound += usize::from(solution.eta_at_bound);
        }
        steps.sort_unstable();
        let (median, p90, max) = (steps[125], steps[225], steps[249]);
        eprintln!(
            "{name}: Newton steps median {median}, 90th percentile {p90}, max {max}; eta on its bound in {on_bound} of 250"
        );
        assert!(p90 <= p90_limit && max <= max_limit, "{name}: {steps:?}");
    }
}
