//! A small bound-constrained quasi-Newton minimiser (projected L-BFGS with an active set), in the
//! spirit of L-BFGS-B for problems with lower bounds only, which is all the C-REPS dual needs
//! (eta >= eta_min, v free).
//!
//! Per iteration:
//! 1. Stop if the projected gradient `P(x - g) - x` has inf-norm <= `pgtol` (scipy's `pgtol`).
//! 2. Active set: variables on their bound whose gradient pushes outwards. They are held fixed;
//!    the L-BFGS memory lives on the free variables and is cleared whenever the active set
//!    changes, so every stored pair belongs to the current subspace.
//! 3. Direction: two-loop recursion on the free variables (memory `m`, initial scaling
//!    `s'y / y'y`); steepest descent when the memory is empty or the direction is not a descent.
//! 4. Step: a weak-Wolfe bisection/expansion search (Armijo `c1 = 1e-4`, curvature `c2 = 0.9`)
//!    capped at the largest feasible step; a step that reaches the cap puts the blocking
//!    variable exactly on its bound, so an active bound is met bit-exactly.
//! 5. Stop if the relative reduction `(f_k - f_{k+1}) / max(|f_k|, |f_{k+1}|, 1)` is
//!    <= `factr * f64::EPSILON` (scipy's `factr`).
//!
//! Only gradients and dot products are used, never a Hessian solve, so a direction in which the
//! objective is flat (the C-REPS dual along the constant feature's `v`) is harmless: its gradient
//! component is zero and so is the step along it.

use std::collections::VecDeque;

use nalgebra::DVector;

use super::DualOptions;

/// Armijo (sufficient decrease) constant.
const C1: f64 = 1e-4;
/// Curvature constant of the weak Wolfe condition.
const C2: f64 = 0.9;
/// Trial steps per line search before giving up.
const MAX_LINE_SEARCH_STEPS: usize = 60;

/// The result of [`minimize`].
#[derive(Clone, Debug)]
pub(crate) struct Minimum {
    pub x: DVector<f64>,
    pub f: f64,
    pub iterations: usize,
    /// False if the iteration cap was hit or the line search found no decrease.
    pub converged: bool,
}

/// One accepted point with its objective and gradient.
struct Point {
    x: DVector<f64>,
    f: f64,
    g: DVector<f64>,
}

/// Minimises `objective` (which returns f and writes the gradient into its second argument)
/// subject to `x >= lower` componentwise (`-inf` for a free variable), starting from `x0`
/// projected onto the feasible set. `objective` must be finite at the projected `x0`; where it is
/// not finite elsewhere the line search treats the trial step as too long.
pub(crate) fn minimize<F>(mut objective: F, x0: DVector<f64>, lower: &DVector<f64>, options: &DualOptions) -> Minimum
where
    F: FnMut(&DVector<f64>, &mut DVector<f64>) -> f64,
{
    let n = x0.len();
    let x = x0.zip_map(lower, f64::max);
    let mut g = DVector::zeros(n);
    let f = objective(&x, &mut g);
    let mut current = Point { x, f, g };
    let mut memory: VecDeque<(DVector<f64>, DVector<f64>, f64)> = VecDeque::new();
    let mut free_previous: Vec<bool> = Vec::new();

    for iteration in 0..options.max_iterations {
        if projected_gradient_norm(&current, lower) <= options.pgtol {
            return finish(current, iteration, true);
        }
        let free: Vec<bool> = (0..n).map(|i| current.x[i] > lower[i] || current.g[i] <= 0.0).collect();
        if free != free_previous {
            memory.clear();
            free_previous = free.clone();
        }
        let masked_gradient = mask(&current.g, &free);
        let mut direction = two_loop(&masked_gradient, &memory);
        // A released variable sits on its bound: it may only move inwards.
        for i in 0..n {
            if current.x[i] <= lower[i] && direction[i] < 0.0 {
                direction[i] = 0.0;
            }
        }
        if direction.dot(&current.g) >= 0.0 {
            memory.clear();
            direction = -&masked_gradient;
        }
        // A first step of unit length, as L-BFGS-B does, when there is no curvature information.
        let initial_step = if memory.is_empty() { 1.0 / direction.norm() } else { 1.0 };
        let Some(next) = line_search(&mut objective, &current, &direction, lower, initial_step) else {
            if memory.is_empty() {
                return finish(current, iteration, false);
            }
            memory.clear();
            continue;
        };

        let s = &next.x - &current.x;
        let y = mask(&(&next.g - &current.g), &free);
        let sy = s.dot(&y);
        if sy > f64::EPSILON * y.norm_squared() {
            if memory.len() == options.memory {
                memory.pop_front();
            }
            memory.push_back((s, y, 1.0 / sy));
        }
        let reduction = (current.f - next.f) / current.f.abs().max(next.f.abs()).max(1.0);
        current = next;
        if reduction <= options.factr * f64::EPSILON {
            return finish(current, iteration + 1, true);
        }
    }
    finish(current, options.max_iterations, false)
}

fn finish(point: Point, iterations: usize, converged: bool) -> Minimum {
    Minimum {
        x: point.x,
        f: point.f,
        iterations,
        converged,
    }
}

/// The inf-norm of `P(x - g) - x`, with P the projection onto `x >= lower`.
fn projected_gradient_norm(point: &Point, lower: &DVector<f64>) -> f64 {
    (0..point.x.len())
        .map(|i| ((point.x[i] - point.g[i]).max(lower[i]) - point.x[i]).abs())
        .fold(0.0, f64::max)
}

fn mask(v: &DVector<f64>, free: &[bool]) -> DVector<f64> {
    DVector::from_iterator(v.len(), v.iter().zip(free).map(|(&vi, &f)| if f { vi } else { 0.0 }))
}

/// `-H g` with H the L-BFGS inverse-Hessian approximation of the stored pairs.
fn two_loop(gradient: &DVector<f64>, memory: &VecDeque<(DVector<f64>, DVector<f64>, f64)>) -> DVector<f64> {
    let mut q = gradient.clone();
    let mut alphas = Vec::with_capacity(memory.len());
    for (s, y, rho) in memory.iter().rev() {
        let alpha = rho * s.dot(&q);
        q.axpy(-alpha, y, 1.0);
        alphas.push(alpha);
    }
    if let Some((s, y, _)) = memory.back() {
        q *= s.dot(y) / y.norm_squared();
    }
    for ((s, y, rho), alpha) in memory.iter().zip(alphas.iter().rev()) {
        let beta = rho * y.dot(&q);
        q.axpy(alpha - beta, s, 1.0);
    }
    -q
}

/// Weak-Wolfe line search along `x + t d`, `0 < t <= t_max` where `t_max` is the largest feasible
/// step. Returns `None` if no trial step satisfied the Armijo condition.
fn line_search<F>(
    objective: &mut F,
    start: &Point,
    direction: &DVector<f64>,
    lower: &DVector<f64>,
    initial_step: f64,
) -> Option<Point>
where
    F: FnMut(&DVector<f64>, &mut DVector<f64>) -> f64,
{
    let slope = start.g.dot(direction);
    // The largest feasible step and the variable that blocks it.
    let (max_step, blocking) = (0..direction.len())
        .filter(|&i| direction[i] < 0.0 && lower[i].is_finite())
        .map(|i| ((start.x[i] - lower[i]) / -direction[i], Some(i)))
        .fold((f64::INFINITY, None), |best, candidate| {
            if candidate.0 < best.0 { candidate } else { best }
        });
    let mut step = initial_step.min(max_step);
    let (mut low, mut high) = (0.0, f64::INFINITY);
    let mut best: Option<Point> = None;
    for _ in 0..MAX_LINE_SEARCH_STEPS {
        let mut x = &start.x + direction * step;
        if let Some(i) = blocking.filter(|_| step == max_step) {
            x[i] = lower[i];
        }
        let mut g = DVector::zeros(x.len());
        let f = objective(&x, &mut g);
        let sufficient_decrease = f <= start.f + C1 * step * slope;
        if !sufficient_decrease || !g.iter().all(|gi| gi.is_finite()) {
            high = step;
        } else {
            let flat_enough = g.dot(direction) >= C2 * slope;
            best = Some(Point { x, f, g });
            if flat_enough || step == max_step {
                return best;
            }
            low = step;
        }
        step = if high.is_finite() {
            0.5 * (low + high)
        } else {
            (2.0 * step).min(max_step)
        };
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rosenbrock's function with gradient.
    fn rosenbrock(x: &DVector<f64>, g: &mut DVector<f64>) -> f64 {
        let (a, b) = (x[0], x[1]);
        g[0] = -2.0 * (1.0 - a) - 400.0 * a * (b - a * a);
        g[1] = 200.0 * (b - a * a);
        (1.0 - a).powi(2) + 100.0 * (b - a * a).powi(2)
    }

    fn tight() -> DualOptions {
        DualOptions {
            pgtol: 1e-10,
            factr: 0.0,
            ..DualOptions::default()
        }
    }

    #[test]
    fn finds_the_unconstrained_rosenbrock_minimum() {
        let lower = DVector::from_element(2, f64::NEG_INFINITY);
        let result = minimize(rosenbrock, DVector::from_vec(vec![-1.2, 1.0]), &lower, &tight());
        assert!(result.converged);
        assert!((result.x[0] - 1.0).abs() < 1e-8 && (result.x[1] - 1.0).abs() < 1e-8);
    }

    #[test]
    fn stops_exactly_on_an_active_bound() {
        // The unconstrained minimum (1, 1) is infeasible for x_0 >= 1.5; the constrained one
        // is at x_0 = 1.5, x_1 = 2.25 (where the partial derivative in x_1 vanishes).
        let lower = DVector::from_vec(vec![1.5, f64::NEG_INFINITY]);
        let result = minimize(rosenbrock, DVector::from_vec(vec![3.0, 3.0]), &lower, &tight());
        assert!(result.converged);
        assert_eq!(result.x[0], 1.5);
        assert!((result.x[1] - 2.25).abs() < 1e-9);
    }

    #[test]
    fn a_flat_direction_does_not_break_it() {
        // f(x, y) = (x - 2)^2 does not depend on y at all.
        let flat = |x: &DVector<f64>, g: &mut DVector<f64>| {
            g[0] = 2.0 * (x[0] - 2.0);
            g[1] = 0.0;
            (x[0] - 2.0).powi(2)
        };
        let lower = DVector::from_element(2, f64::NEG_INFINITY);
        let result = minimize(flat, DVector::from_vec(vec![1.0, 1.0]), &lower, &tight());
        assert!(result.converged);
        assert!((result.x[0] - 2.0).abs() < 1e-10);
        assert_eq!(result.x[1], 1.0);
    }
}
