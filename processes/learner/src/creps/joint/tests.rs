use super::*;
use crate::creps::dual::tests::{DataSet, assert_derivatives_match, function, sweep, throwing};
use crate::creps::{DEFAULT_ETA_MIN, DualSolveError};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

fn defaults() -> DualOptions {
    DualOptions::default()
}

/// Rows `(x_i, x_i^2, 1)`.
fn quadratic_features(x: &[f64]) -> DMatrix<f64> {
    DMatrix::from_fn(x.len(), 3, |i, j| [x[i], x[i] * x[i], 1.0][j])
}

/// A small random problem: N samples of a 1-D context, returns and log-ratios with some
/// structure and noise.
fn small(seed: u64, n: usize) -> (DMatrix<f64>, Vec<f64>, Vec<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let x: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    let returns = x
        .iter()
        .map(|x| (3.0 * x).sin() + rng.sample::<f64, _>(StandardNormal))
        .collect();
    let log_ratio = x
        .iter()
        .map(|x| 2.0 * x + 0.3 * rng.sample::<f64, _>(StandardNormal))
        .collect();
    (quadratic_features(&x), returns, log_ratio)
}

/// The log-ratio of a uniform target over a Gaussian current context density `N(centre,
/// sigma^2 I)`, up to a constant.
fn gaussian_to_uniform(contexts: &[Vec<f64>], centre: &[f64], sigma: f64) -> Vec<f64> {
    contexts
        .iter()
        .map(|c| c.iter().zip(centre).map(|(c, m)| (c - m).powi(2)).sum::<f64>() / (2.0 * sigma * sigma))
        .collect()
}

fn population_std(values: &[f64]) -> f64 {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    (values.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n).sqrt()
}

/// Checks the optimality conditions of `solution`: converged, each KL at its bound to 1e-8 off
/// the temperature's bound (and at most the bound on it), the policy's weighted features equal
/// the contexts' to 1e-8 relative to each feature's spread, and the dual's gradient in the
/// returns' units (temperature components projected) at most 1e-8 times the features' spread.
fn assert_optimal(
    name: &str,
    phi: &DMatrix<f64>,
    returns: &[f64],
    context: &ContextTerm,
    epsilon: f64,
    solution: &JointDualSolution,
) {
    assert!(
        solution.converged && solution.optimality <= 1e-8,
        "{name}: optimality {} after {} iterations",
        solution.optimality,
        solution.iterations
    );
    for (kl, bound, at_bound, what) in [
        (solution.kl, epsilon, solution.eta_at_bound, "policy"),
        (
            solution.context_kl,
            context.epsilon,
            solution.eta_context_at_bound,
            "context",
        ),
    ] {
        if at_bound {
            assert!(kl <= bound + 1e-8, "{name}: {what} KL {kl} on the bound {bound}");
        } else {
            assert!((kl - bound).abs() <= 1e-8, "{name}: {what} KL {kl} for epsilon {bound}");
        }
    }
    assert!((solution.weights.sum() - 1.0).abs() < 1e-12 && (solution.context_weights.sum() - 1.0).abs() < 1e-12);
    let matched = phi.tr_mul(&solution.weights) - phi.tr_mul(&solution.context_weights);
    for j in 0..phi.ncols() {
        let spread = population_std(phi.column(j).as_slice());
        let allowed = 1e-8 * spread + 1e-14 * phi.column(j).amax();
        assert!(
            matched[j].abs() <= allowed,
            "{name}: feature {j} mismatch {} (spread {spread})",
            matched[j]
        );
    }
    if solution.eta > 0.0 {
        let at = evaluate_joint_dual(
            phi,
            returns,
            context,
            epsilon,
            solution.eta,
            solution.eta_context,
            solution.v.as_slice(),
        )
        .unwrap();
        let scale = 1.0 + solution.objective.abs();
        assert!(
            (at.value - solution.objective).abs() <= 1e-12 * scale,
            "{name}: objective {} vs evaluated {}",
            solution.objective,
            at.value
        );
        let held = [
            solution.eta_at_bound && at.gradient[0] > 0.0,
            solution.eta_context_at_bound && at.gradient[1] > 0.0,
        ];
        let spread = (0..phi.ncols())
            .map(|j| population_std(phi.column(j).as_slice()))
            .fold(1.0, f64::max);
        for (i, g) in at.gradient.iter().enumerate() {
            if i < 2 && held[i] {
                continue;
            }
            assert!(g.abs() <= 1e-8 * spread, "{name}: gradient {i} is {g}");
        }
    }
}

/// The gradient is the derivative of the value, on the Section 5.1 data sets, at random
/// points and alphas (0 included).
#[test]
fn gradient_matches_central_differences() {
    for seed in 0..6 {
        let data = function(seed);
        let phi = data.phi();
        let mut rng = ChaCha8Rng::seed_from_u64(200 + seed);
        let log_ratio: Vec<f64> = (0..phi.nrows()).map(|_| rng.sample(StandardNormal)).collect();
        let alpha = if seed == 0 { 0.0 } else { rng.random_range(0.0..2.0) };
        let context = ContextTerm {
            log_ratio: &log_ratio,
            alpha,
            epsilon: 0.4,
        };
        let mut x: Vec<f64> = vec![rng.random_range(0.2..3.0), rng.random_range(0.2..3.0)];
        x.extend((0..6).map(|_| rng.random_range(-2.0..2.0)));
        let x = DVector::from_vec(x);
        let at = |x: &DVector<f64>| {
            evaluate_joint_dual(&phi, &data.returns, &context, 0.7, x[0], x[1], &x.as_slice()[2..]).unwrap()
        };
        let value = |x: &DVector<f64>| DVector::from_element(1, at(x).value);
        let gradient = DMatrix::from_row_slice(1, x.len(), at(&x).gradient.as_slice());
        assert_derivatives_match(&x, value, &gradient, &format!("seed {seed}: "));
    }
}

/// The solver's Hessian is the derivative of its gradient (signs of the context cross terms
/// included), for alpha 0 and > 0.
#[test]
fn hessian_matches_central_differences_of_the_gradient() {
    for (seed, alpha) in [(3, 0.0), (4, 0.7)] {
        let data = throwing(seed);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let log_ratio: Vec<f64> = (0..300).map(|_| rng.sample(StandardNormal)).collect();
        let context = ContextTerm {
            log_ratio: &log_ratio,
            alpha,
            epsilon: 0.3,
        };
        let problem = Joint::new(Standardised::new(&data.phi(), &data.returns, 0.5).unwrap(), &context);
        let k = problem.policy.rank();
        let mut scratch = (Scratch::new(300, k), Scratch::new(300, k));
        let u = DVector::from_fn(k, |i, _| 0.1 * i as f64 - 0.2);
        let temperatures = [0.7, 0.4];
        let point = problem.evaluate(temperatures, u.clone(), &mut scratch);
        let hessian = problem.hessian(&point, &mut scratch);
        let x = DVector::from_fn(2 + k, |i, _| if i < 2 { temperatures[i] } else { u[i - 2] });
        let gradient = |x: &DVector<f64>| {
            let point = problem.evaluate([x[0], x[1]], x.rows(2, k).into_owned(), &mut scratch);
            let mut g = DVector::zeros(2 + k);
            g[0] = point.gradient_temperatures[0];
            g[1] = point.gradient_temperatures[1];
            g.rows_mut(2, k).copy_from(&point.gradient_u);
            g
        };
        assert_derivatives_match(&x, gradient, &hessian, &format!("alpha {alpha}: "));
    }
}

/// On small random problems the solution meets the optimality conditions, and its objective
/// is below the dual's value at 200 random feasible points nearby.
#[test]
fn solutions_are_optimal_and_below_nearby_points() {
    let mut off_bounds = 0;
    for seed in 0..20 {
        let (phi, returns, log_ratio) = small(seed, 40);
        let alpha = [0.0, 0.1, 1.0, 5.0][seed as usize % 4];
        let context = ContextTerm {
            log_ratio: &log_ratio,
            alpha,
            epsilon: 0.1,
        };
        let name = format!("seed {seed}, alpha {alpha}");
        let solution = solve_joint_dual(&phi, &returns, &context, 0.8, DEFAULT_ETA_MIN, &defaults()).unwrap();
        assert_optimal(&name, &phi, &returns, &context, 0.8, &solution);
        off_bounds += usize::from(!solution.eta_at_bound && !solution.eta_context_at_bound);
        let floor = DEFAULT_ETA_MIN * population_std(&returns);
        let mut rng = ChaCha8Rng::seed_from_u64(500 + seed);
        for trial in 0..200 {
            let size = 10f64.powf(rng.random_range(-6.0..-1.0));
            let mut nearby = |value: f64| value * (1.0 + size * rng.sample::<f64, _>(StandardNormal));
            let eta = nearby(solution.eta).max(floor);
            let eta_context = nearby(solution.eta_context).max(floor);
            let v: Vec<f64> = solution
                .v
                .iter()
                .map(|v| v + size * rng.sample::<f64, _>(StandardNormal))
                .collect();
            let value = evaluate_joint_dual(&phi, &returns, &context, 0.8, eta, eta_context, &v)
                .unwrap()
                .value;
            assert!(
                solution.objective <= value + 1e-12 * (1.0 + value.abs()),
                "{name}, trial {trial}: objective {} above {value} at a nearby point",
                solution.objective
            );
        }
    }
    assert!(off_bounds >= 15, "only {off_bounds} of 20 with both bounds active");
}

/// Returns `a R + b` give the same weights (the temperatures scaled by a).
///
/// `a R + b` is rounded to about 1e-16 |b|, which for a = 1e-6 and b = -1e4 is 1e-6 of the
/// returns' spread: a perturbation of the data themselves, which moves the weights by about as
/// much. So the reference is the solve on the data the transformed returns represent,
/// `((a R + b) - b) / a` (the subtraction is exact, the division rounds by an ulp), and
/// the comparison isolates what the solver does with the units.
#[test]
fn solutions_are_invariant_to_the_returns_units() {
    for seed in 0..6 {
        let (phi, returns, log_ratio) = small(100 + seed, 30);
        let context = ContextTerm {
            log_ratio: &log_ratio,
            alpha: [0.0, 0.5, 3.0][seed as usize % 3],
            epsilon: 0.3,
        };
        for scale in [1e-6, 1e3] {
            for shift in [-1e4, 7.0] {
                let scaled: Vec<f64> = returns.iter().map(|r| scale * r + shift).collect();
                let represented: Vec<f64> = scaled.iter().map(|x| (x - shift) / scale).collect();
                let reference =
                    solve_joint_dual(&phi, &represented, &context, 0.6, DEFAULT_ETA_MIN, &defaults()).unwrap();
                assert!(reference.converged);
                let case = format!("seed {seed}, x{scale:e} + {shift}");
                let solution = solve_joint_dual(&phi, &scaled, &context, 0.6, DEFAULT_ETA_MIN, &defaults()).unwrap();
                assert!(solution.converged, "{case}");
                assert!(
                    (&solution.weights - &reference.weights).amax() < 1e-9,
                    "{case}: d {:e} {:?} {:?}",
                    (&solution.weights - &reference.weights).amax(),
                    (
                        solution.eta_at_bound,
                        solution.eta_context_at_bound,
                        solution.iterations,
                        solution.optimality
                    ),
                    (
                        reference.eta_at_bound,
                        reference.eta_context_at_bound,
                        reference.iterations,
                        reference.optimality
                    )
                );
                assert!(
                    (&solution.context_weights - &reference.context_weights).amax() < 1e-9,
                    "{case}: w"
                );
                assert!(
                    (solution.eta / (scale * reference.eta) - 1.0).abs() < 1e-8,
                    "{case}: eta"
                );
                assert!(
                    (solution.eta_context / (scale * reference.eta_context) - 1.0).abs() < 1e-8,
                    "{case}: eta_c"
                );
            }
        }
    }
}

/// A large alpha pulls the context weights towards the normalised `exp(a)` (the importance
/// weights to the target) as far as their KL bound allows.
#[test]
fn a_large_alpha_pulls_the_context_weights_towards_the_target() {
    for seed in 0..5 {
        let (phi, returns, log_ratio) = small(300 + seed, 50);
        let target = {
            let p: Vec<f64> = log_ratio.iter().map(|a| a.exp()).collect();
            let total: f64 = p.iter().sum();
            DVector::from_iterator(p.len(), p.iter().map(|p| p / total))
        };
        let distance = |w: &DVector<f64>| -> f64 { w.iter().zip(target.iter()).map(|(w, t)| w * (w / t).ln()).sum() };
        let mut last = f64::INFINITY;
        for alpha in [0.0, 1.0, 100.0] {
            let context = ContextTerm {
                log_ratio: &log_ratio,
                alpha,
                epsilon: 0.2,
            };
            let solution = solve_joint_dual(&phi, &returns, &context, 0.5, DEFAULT_ETA_MIN, &defaults()).unwrap();
            let name = format!("seed {seed}, alpha {alpha}");
            assert_optimal(&name, &phi, &returns, &context, 0.5, &solution);
            if alpha < 100.0 {
                continue;
            }
            assert!(!solution.eta_context_at_bound, "{name}");
            assert!((solution.context_kl - 0.2).abs() < 1e-8, "{name}");
            // ln w rises with a.
            let ln_w: Vec<f64> = solution.context_weights.iter().map(|w| w.ln()).collect();
            let correlation = {
                let (ma, mw) = (log_ratio.iter().sum::<f64>() / 50.0, ln_w.iter().sum::<f64>() / 50.0);
                let cov: f64 = log_ratio.iter().zip(&ln_w).map(|(a, w)| (a - ma) * (w - mw)).sum();
                cov / (population_std(&log_ratio) * population_std(&ln_w) * 50.0)
            };
            assert!(correlation > 0.9, "{name}: correlation {correlation}");
            // Closer to the target than with alpha 1 or 0.
            let now = distance(&solution.context_weights);
            assert!(now < last, "{name}: KL to the target {now} >= {last}");
            last = now;
        }
        let _ = last;
    }
}

/// With a context bound above what the baseline and alpha can use, eta_c ends on its bound
/// (the context KL is slack) and the solve converges.
#[test]
fn a_slack_context_bound_puts_eta_context_on_its_bound() {
    for seed in 0..10 {
        let (phi, returns, log_ratio) = small(400 + seed, 40);
        let context = ContextTerm {
            log_ratio: &log_ratio,
            alpha: 0.5,
            epsilon: 50.0,
        };
        let solution = solve_joint_dual(&phi, &returns, &context, 0.5, DEFAULT_ETA_MIN, &defaults()).unwrap();
        let name = format!("seed {seed}");
        assert!(
            solution.eta_context_at_bound && solution.converged,
            "{name}: {solution:?}"
        );
        assert!(solution.context_kl < 50.0);
        assert_optimal(&name, &phi, &returns, &context, 0.5, &solution);
    }
}

/// Equal returns and a single sample have well-defined solutions.
#[test]
fn degenerate_data_have_well_defined_solutions() {
    let phi = quadratic_features(&[0.0, 0.25, 0.5, 0.75, 1.0]);
    let log_ratio = [0.3, -0.2, 1.0, 0.0, 0.5];
    let context = ContextTerm {
        log_ratio: &log_ratio,
        alpha: 1.0,
        epsilon: 0.5,
    };
    let equal = solve_joint_dual(&phi, &[-2.5; 5], &context, 0.5, DEFAULT_ETA_MIN, &defaults()).unwrap();
    assert_eq!(equal.weights.as_slice(), &[0.2; 5]);
    assert_eq!(equal.context_weights.as_slice(), &[0.2; 5]);
    assert!(equal.eta == 0.0 && equal.eta_at_bound && equal.eta_context == 0.0 && equal.eta_context_at_bound);
    assert!(equal.v.iter().all(|&v| v == 0.0) && equal.objective == -2.5 && equal.converged);
    let one_context = ContextTerm {
        log_ratio: &log_ratio[..1],
        ..context
    };
    let one = solve_joint_dual(
        &phi.rows(0, 1).into_owned(),
        &[3.0],
        &one_context,
        0.5,
        DEFAULT_ETA_MIN,
        &defaults(),
    )
    .unwrap();
    assert_eq!(one.weights.as_slice(), &[1.0]);
    assert_eq!(one.context_weights.as_slice(), &[1.0]);
    assert!(one.converged && one.objective == 3.0);
    // All samples at one context: the features carry nothing, so the weights are set by eta and
    // eta_c alone, and with alpha 0 the context weights are uniform (eta_c on its bound).
    let same = DMatrix::from_fn(20, 3, |_, j| [0.3, 0.09, 1.0][j]);
    let returns: Vec<f64> = (0..20).map(|i| (i as f64).sin()).collect();
    let ratio: Vec<f64> = (0..20).map(|i| (i as f64 * 0.7).cos()).collect();
    for alpha in [0.0, 2.0] {
        let context = ContextTerm {
            log_ratio: &ratio,
            alpha,
            epsilon: 0.1,
        };
        let solution = solve_joint_dual(&same, &returns, &context, 0.5, DEFAULT_ETA_MIN, &defaults()).unwrap();
        assert_optimal(
            &format!("one context, alpha {alpha}"),
            &same,
            &returns,
            &context,
            0.5,
            &solution,
        );
        assert!(!solution.eta_at_bound);
        assert_eq!(solution.eta_context_at_bound, alpha == 0.0);
    }
}

/// Bad inputs are errors naming the argument and the accepted range.
#[test]
fn bad_inputs_are_errors_naming_the_argument() {
    let (phi, returns, log_ratio) = small(7, 11);
    let context = ContextTerm {
        log_ratio: &log_ratio,
        alpha: 1.0,
        epsilon: 0.5,
    };
    let message = |context: &ContextTerm, epsilon: f64| {
        solve_joint_dual(&phi, &returns, context, epsilon, DEFAULT_ETA_MIN, &defaults())
            .unwrap_err()
            .to_string()
    };
    assert_eq!(
        message(
            &ContextTerm {
                log_ratio: &log_ratio[..10],
                ..context
            },
            0.5
        ),
        "the length of context.log_ratio (10) must equal the number of returns (11)"
    );
    let mut nan = log_ratio.clone();
    nan[4] = f64::NAN;
    assert_eq!(
        message(
            &ContextTerm {
                log_ratio: &nan,
                ..context
            },
            0.5
        ),
        "context.log_ratio must be finite, got NaN at index 4"
    );
    assert_eq!(
        message(&ContextTerm { alpha: -1.0, ..context }, 0.5),
        "context.alpha must be finite and >= 0, got -1"
    );
    assert_eq!(
        message(
            &ContextTerm {
                alpha: f64::INFINITY,
                ..context
            },
            0.5
        ),
        "context.alpha must be finite and >= 0, got inf"
    );
    assert_eq!(
        message(
            &ContextTerm {
                epsilon: 0.0,
                ..context
            },
            0.5
        ),
        "context.epsilon must be finite and > 0, got 0"
    );
    assert_eq!(message(&context, 0.0), "epsilon must be finite and > 0, got 0");
    assert_eq!(
        solve_joint_dual(&phi, &returns[..10], &context, 0.5, DEFAULT_ETA_MIN, &defaults())
            .unwrap_err()
            .to_string(),
        "the number of phi rows (11) must equal the number of returns (10)"
    );
    assert!(
        solve_joint_dual(&phi, &returns, &context, 0.5, 0.0, &defaults())
            .unwrap_err()
            .to_string()
            .starts_with("eta_min must be within")
    );
    assert_eq!(
        solve_joint_dual(
            &DMatrix::zeros(0, 3),
            &[],
            &ContextTerm {
                log_ratio: &[],
                ..context
            },
            0.5,
            DEFAULT_ETA_MIN,
            &defaults()
        )
        .unwrap_err(),
        DualSolveError::NoSamples
    );
    let evaluate = |eta: f64, eta_context: f64, v: &[f64], context: &ContextTerm| {
        evaluate_joint_dual(&phi, &returns, context, 0.5, eta, eta_context, v)
            .unwrap_err()
            .to_string()
    };
    assert_eq!(
        evaluate(1.0, 1.0, &[0.0], &context),
        "the length of v (1) must equal the number of phi columns (3)"
    );
    assert_eq!(
        evaluate(1.0, 0.0, &[0.0; 3], &context),
        "eta_context must be finite and > 0, got 0"
    );
    assert_eq!(
        evaluate(1.0, 1.0, &[0.0; 3], &ContextTerm { alpha: -0.5, ..context }),
        "context.alpha must be finite and >= 0, got -0.5"
    );
}

/// The C-REPS dual's realistic data sets (the PA-10 grid scale, the Section 5.1 scale and
/// its initial sweep, with their epsilons), a Gaussian current context density against a
/// uniform target, and alpha 0, 0.1 and 10: every solve converges within the iteration cap, to
/// the optimality conditions, in at most 40 Newton steps. Step counts are deterministic, so this
/// guards the solver's efficiency; `--nocapture` prints their distribution. (A wider sweep, 100
/// data sets per family, alpha 0 to 1000 and context bounds 0.05 to 2, 5400 solves, all
/// converged; the 90th percentile was at most 37 steps and the slowest took 86, an initial
/// sweep with eta on its bound, alpha 1, context bound 0.05.)
#[test]
fn realistic_data_sets_converge() {
    type Family = (&'static str, fn(u64) -> DataSet, [f64; 2], f64);
    let families: [Family; 3] = [
        ("PA-10 scale", throwing, [-4.5, -4.5], 0.5),
        ("Section 5.1 scale", function, [0.5, 0.5], 0.4),
        ("Section 5.1 initial sweep", sweep, [0.5, -0.5], 0.6),
    ];
    for (name, data, centre, sigma) in families {
        for alpha in [0.0, 0.1, 10.0] {
            let mut steps = Vec::new();
            let mut bounds = [0; 2];
            for seed in 0..30 {
                let data = data(5000 + seed);
                let phi = data.phi();
                let log_ratio = gaussian_to_uniform(&data.contexts, &centre, sigma);
                let context = ContextTerm {
                    log_ratio: &log_ratio,
                    alpha,
                    epsilon: 0.5,
                };
                let case = format!("{name}, alpha {alpha}, seed {seed}");
                let solution = solve_joint_dual(
                    &phi,
                    &data.returns,
                    &context,
                    data.epsilon,
                    DEFAULT_ETA_MIN,
                    &defaults(),
                )
                .unwrap();
                assert!(solution.iterations <= defaults().max_iterations);
                assert_optimal(&case, &phi, &data.returns, &context, data.epsilon, &solution);
                steps.push(solution.iterations);
                bounds[0] += usize::from(solution.eta_at_bound);
                bounds[1] += usize::from(solution.eta_context_at_bound);
            }
            steps.sort_unstable();
            assert!(steps[29] <= 40, "{name}, alpha {alpha}: {steps:?}");
            eprintln!(
                "{name}, alpha {alpha}: Newton steps median {}, max {}; eta on its bound {}, eta_c {} of 30",
                steps[15], steps[29], bounds[0], bounds[1]
            );
        }
    }
}

/// A context distribution that can hardly move (a tiny context KL bound, alpha 0) leaves the
/// features matched to the samples' mean: the joint dual's policy weights become C-REPS'.
#[test]
fn a_frozen_context_distribution_gives_the_c_reps_weights() {
    for seed in 0..4 {
        let (phi, returns, log_ratio) = small(seed, 60);
        let plain = crate::creps::solve_dual(&phi, &returns, 0.5, DEFAULT_ETA_MIN, &defaults()).unwrap();
        let frozen = ContextTerm {
            log_ratio: &log_ratio,
            alpha: 0.0,
            epsilon: 1e-5,
        };
        let joint = solve_joint_dual(&phi, &returns, &frozen, 0.5, DEFAULT_ETA_MIN, &defaults()).unwrap();
        assert!(
            joint.converged,
            "seed {seed}: {} iterations, optimality {}",
            joint.iterations, joint.optimality
        );
        let gap = (&joint.weights - &plain.weights).amax();
        // The context weights may still move by KL 1e-5, so by about sqrt(2e-5) relative.
        assert!(
            gap < 3e-2 * plain.weights.amax(),
            "seed {seed}: weights differ by {gap}"
        );
        assert!((joint.eta - plain.eta).abs() < 3e-2 * plain.eta, "seed {seed}");
        // A free context distribution with alpha 0 moves the weights elsewhere.
        let free = ContextTerm { epsilon: 0.5, ..frozen };
        let moved = solve_joint_dual(&phi, &returns, &free, 0.5, DEFAULT_ETA_MIN, &defaults()).unwrap();
        assert!((&moved.weights - &plain.weights).amax() > 10.0 * gap, "seed {seed}");
    }
}
