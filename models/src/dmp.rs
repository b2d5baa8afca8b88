//! Dynamic movement primitives (DMPs) in the variant of Mülling et al. (2013), which reaches a final position *and* a
//! final velocity in a given time: the paper's throw (Section 5.2.1) chains two of them.
//!
//! The formulation follows BOLeRo's `Dmp.cpp`:
//!
//! - phase z(t) = b^(t / [`PHASE_DT`]), b = max(1 - alpha_z [`PHASE_DT`] / tau, 1e-10), with alpha_z chosen so that
//!   z(tau) = [`FINAL_PHASE`];
//! - forcing term f_d(z) = z sum_i w_di psi_i(z) / sum_i psi_i(z), psi_i(z) = exp(-h_i (z - c_i)^2), centres
//!   c_i = z(i tau / (n_w - 1)), widths such that each RBF has the value [`RBF_OVERLAP`] at the next centre;
//! - goal trajectory g(t): per dimension the quintic from the start state (y0, yd0, ydd0) at t = 0 to (g, gd, 0) at
//!   t = tau;
//! - transformation system tau^2 ydd = alpha_y (beta_y (g(t) - y) + tau (gd(t) - yd)) + tau^2 gdd(t) + f(z),
//!   beta_y = alpha_y / 4, integrated with explicit Euler.
//!
//! Without forcing term the exact solution *is* g(t) (the tracking error obeys a homogeneous, critically damped
//! system with zero initial conditions), so the movement ends in (g, gd) up to the Euler error; the forcing term
//! shapes the path and fades with z.

use crate::trajectory::JointTrajectory;
use crate::{InvalidArgument, check, check_len};
use nalgebra::DMatrix;

/// Time step (s) of BOLeRo's discretised phase z(t) = b^(t / PHASE_DT); independent of the integration substep.
pub const PHASE_DT: f64 = 0.001;
/// Phase at the end of the movement, z(tau).
pub const FINAL_PHASE: f64 = 0.01;
/// Value of each basis function at the next centre; sets the widths.
pub const RBF_OVERLAP: f64 = 0.8;
/// Most samples a rollout may return: bounds the allocation for extreme tau / control_dt ratios.
pub const MAX_SAMPLES: usize = 10_000_000;
/// Most Euler substeps per movement (tau / substep): bounds the run time of a rollout.
pub const MAX_SUBSTEPS: usize = 1_000_000_000;
/// Longest substep grid whose forcing term [`Dmp::new`] tabulates (5.6 MB at 7 dimensions).
const MAX_TABULATED_SUBSTEPS: usize = 100_000;

/// Relative tolerance for "tau is an integer multiple of control_dt" and similar ratio roundings.
const RATIO_TOLERANCE: f64 = 1e-9;

/// Why [`Dmp::new`] (or [`DmpConfig::validate`]) refuses its arguments.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(transparent)]
pub struct DmpCreateError(#[from] pub InvalidArgument);

/// Why [`Dmp::imitate`] cannot learn from a demonstration.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DmpImitateError {
    /// The demonstration, the accelerations or the regularisation is outside its range.
    #[error(transparent)]
    Invalid(#[from] InvalidArgument),
    /// The demonstration's duration or the configuration makes no DMP.
    #[error(transparent)]
    Dmp(#[from] DmpCreateError),
    /// The regression of the forcing weights did not give finite weights.
    #[error("demonstration must be data whose regression converges to finite weights, got a failed fit")]
    NoFit,
}

/// Why [`Dmp::rollout`] produces no trajectory.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DmpRolloutError {
    /// The start state, the goal or the control period is outside its range.
    #[error(transparent)]
    Invalid(#[from] InvalidArgument),
    /// The integration overflowed, e.g. because weights or meta-parameters are huge.
    #[error("rollout diverged: the state became non-finite (weights, goal or start values too large?)")]
    Diverged,
}

/// Why [`chain`] cannot join two trajectories.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(transparent)]
pub struct TrajectoryChainError(#[from] pub InvalidArgument);

fn check_finite<'a>(argument: &'static str, values: impl IntoIterator<Item = &'a f64>) -> Result<(), InvalidArgument> {
    match values.into_iter().find(|v| !v.is_finite()) {
        None => Ok(()),
        Some(v) => check(false, argument, "finite", v),
    }
}

fn check_vector(argument: &'static str, values: &[f64], n_dims: usize) -> Result<(), InvalidArgument> {
    check_len(argument, n_dims, values.len())?;
    check_finite(argument, values)
}

/// Meta-parameters shared by all dimensions of a [`Dmp`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DmpConfig {
    /// Basis functions (weights) per dimension, >= 2. BOLeRo's default: 50.
    pub n_weights: usize,
    /// Damping constant alpha_y of the transformation system, > 0; beta_y = alpha_y / 4 makes it critically damped.
    /// BOLeRo's default: 25.
    pub alpha_y: f64,
    /// Longest Euler substep in s, > 0. BOLeRo's default: 0.001. Explicit Euler is stable for
    /// substep < 4 tau / alpha_y; its error grows linearly with the substep.
    pub substep: f64,
}

impl Default for DmpConfig {
    fn default() -> Self {
        Self {
            n_weights: 50,
            alpha_y: 25.0,
            substep: 0.001,
        }
    }
}

impl DmpConfig {
    /// Checks every field against its accepted range.
    pub fn validate(&self) -> Result<(), DmpCreateError> {
        check(self.n_weights >= 2, "n_weights", "at least 2", self.n_weights)?;
        check(
            self.alpha_y.is_finite() && self.alpha_y > 0.0,
            "alpha_y",
            "finite and > 0",
            self.alpha_y,
        )?;
        check(
            self.substep.is_finite() && self.substep > 0.0,
            "substep",
            "finite and > 0 (s)",
            self.substep,
        )?;
        Ok(())
    }

    /// Spring constant beta_y = alpha_y / 4 (critical damping).
    pub fn beta_y(&self) -> f64 {
        self.alpha_y / 4.0
    }
}

/// Position, velocity and acceleration of every dimension at one instant.
#[derive(Debug, Clone, PartialEq)]
pub struct DmpState {
    /// Positions.
    pub position: Vec<f64>,
    /// Velocities.
    pub velocity: Vec<f64>,
    /// Accelerations.
    pub acceleration: Vec<f64>,
}

impl DmpState {
    /// The state at `position` with zero velocity and acceleration.
    pub fn at_rest(position: &[f64]) -> Self {
        Self {
            position: position.to_vec(),
            velocity: vec![0.0; position.len()],
            acceleration: vec![0.0; position.len()],
        }
    }
}

/// alpha_z such that the discretised phase reaches `final_phase` at `tau` (BOLeRo's `calculateAlpha`).
///
/// BOLeRo counts phase steps as floor(tau / PHASE_DT) + 1; the floor is taken after snapping ratios within
/// [`RATIO_TOLERANCE`] of an integer, because e.g. 0.7 / 0.001 = 699.9999999999999 would lose a step and miss
/// z(tau) = final_phase.
fn phase_decay(final_phase: f64, tau: f64) -> f64 {
    let steps = snap(tau / PHASE_DT).floor();
    (1.0 - final_phase.powf(1.0 / steps)) * steps
}

/// `ratio` rounded to the nearest integer when it is within the relative tolerance of it.
fn snap(ratio: f64) -> f64 {
    let nearest = ratio.round();
    if (ratio - nearest).abs() <= RATIO_TOLERANCE * nearest.max(1.0) {
        nearest
    } else {
        ratio
    }
}

/// Coefficients c_0..c_5 of the quintic with value, slope and curvature (y0, v0, a0) at t = 0 and (y1, v1, 0) at
/// t = tau (closed form of BOLeRo's 6x6 solve with t0 = 0).
fn quintic(y0: f64, v0: f64, a0: f64, y1: f64, v1: f64, tau: f64) -> [f64; 6] {
    // What the cubic, quartic and quintic terms must add at tau to the Taylor part y0 + v0 t + a0 t^2 / 2.
    let dy = y1 - (y0 + v0 * tau + 0.5 * a0 * tau * tau);
    let dv = v1 - (v0 + a0 * tau);
    let da = -a0;
    let t2 = tau * tau;
    let t3 = t2 * tau;
    [
        y0,
        v0,
        0.5 * a0,
        (20.0 * dy - 8.0 * dv * tau + da * t2) / (2.0 * t3),
        (-30.0 * dy + 14.0 * dv * tau - 2.0 * da * t2) / (2.0 * t3 * tau),
        (12.0 * dy - 6.0 * dv * tau + da * t2) / (2.0 * t3 * t2),
    ]
}

/// Value, first and second derivative of the quintic `c` at `t` (Horner).
fn eval_quintic(c: &[f64; 6], t: f64) -> (f64, f64, f64) {
    let pos = c[0] + t * (c[1] + t * (c[2] + t * (c[3] + t * (c[4] + t * c[5]))));
    let vel = c[1] + t * (2.0 * c[2] + t * (3.0 * c[3] + t * (4.0 * c[4] + t * 5.0 * c[5])));
    let acc = 2.0 * c[2] + t * (6.0 * c[3] + t * (12.0 * c[4] + t * 20.0 * c[5]));
    (pos, vel, acc)
}

/// A multi-dimensional Mülling DMP: forcing weights plus the phase and basis functions they live on. The
/// meta-parameters start state, goal, goal velocity are arguments of [`Dmp::rollout`].
#[derive(Debug, Clone, PartialEq)]
pub struct Dmp {
    execution_time: f64,
    /// n_dims x n_weights.
    weights: DMatrix<f64>,
    config: DmpConfig,
    alpha_z: f64,
    /// b of z(t) = b^(t / PHASE_DT).
    phase_base: f64,
    centers: Vec<f64>,
    widths: Vec<f64>,
    /// Forcing term at the substep ends of the default grid (see [`Dmp::new`]), n_dims values per substep; empty
    /// when that grid is longer than `MAX_TABULATED_SUBSTEPS`.
    forcing_table: Vec<f64>,
}

impl Dmp {
    /// A DMP with `n_dims` dimensions lasting `execution_time` (tau, s) with forcing `weights`
    /// (n_dims x `config.n_weights`).
    ///
    /// tau must be finite and >= [`PHASE_DT`] (shorter movements have no phase step, so alpha_z is undefined) and
    /// at most [`MAX_SUBSTEPS`] substeps long.
    ///
    /// The forcing term depends on time only, so it is tabulated here for the default substep grid,
    /// n = ceil(tau / substep) equal substeps; rollouts whose control period is a multiple of the substep use that
    /// grid and skip the basis functions entirely (7 dimensions over 0.5 s: about 50 instead of 300 us). Other grids
    /// compute it on the fly, with the same function, so both paths give the same bits on the same grid.
    pub fn new(
        n_dims: usize,
        execution_time: f64,
        weights: DMatrix<f64>,
        config: DmpConfig,
    ) -> Result<Self, DmpCreateError> {
        config.validate()?;
        check(n_dims >= 1, "n_dims", "at least 1", n_dims)?;
        check(
            execution_time.is_finite() && execution_time >= PHASE_DT,
            "execution_time",
            "finite and >= 0.001 (s)",
            execution_time,
        )?;
        check_len("weights (rows = n_dims)", n_dims, weights.nrows())?;
        check_len("weights (columns = n_weights)", config.n_weights, weights.ncols())?;
        check_finite("weights", weights.iter())?;
        check(
            execution_time / config.substep <= MAX_SUBSTEPS as f64,
            "execution_time",
            "at most 1e9 substeps long",
            execution_time,
        )?;

        let alpha_z = phase_decay(FINAL_PHASE, execution_time);
        let phase_base = (1.0 - alpha_z * PHASE_DT / execution_time).max(1e-10);
        let step = execution_time / (config.n_weights - 1) as f64;
        let centers: Vec<f64> = (0..config.n_weights)
            .map(|i| phase_base.powf(i as f64 * step / PHASE_DT))
            .collect();
        let mut widths: Vec<f64> = centers
            .windows(2)
            .map(|c| -RBF_OVERLAP.ln() / ((c[1] - c[0]) * (c[1] - c[0])))
            .collect();
        widths.push(widths[widths.len() - 1]);
        // Only reachable for absurdly long tau, where b rounds to 1 and neighbouring centres coincide.
        check(
            widths.iter().all(|w| w.is_finite()),
            "execution_time",
            "short enough that the basis-function centres are distinct",
            execution_time,
        )?;
        let mut dmp = Self {
            execution_time,
            weights,
            config,
            alpha_z,
            phase_base,
            centers,
            widths,
            forcing_table: Vec::new(),
        };
        let n_substeps = snap(execution_time / config.substep).ceil() as usize;
        if n_substeps <= MAX_TABULATED_SUBSTEPS {
            let mut features = vec![0.0; config.n_weights];
            let mut table = vec![0.0; n_substeps * n_dims];
            for (i, forces) in table.chunks_exact_mut(n_dims).enumerate() {
                dmp.forcing_term(substep_time(execution_time, n_substeps, i + 1), &mut features, forces);
            }
            dmp.forcing_table = table;
        }
        Ok(dmp)
    }

    /// Learns forcing weights that make the transformation system reproduce `demonstration` (positions and
    /// velocities at t = 0, dt, ..., tau, at least 3 samples); its duration tau = (len - 1) dt becomes the DMP's
    /// execution time.
    ///
    /// `accelerations` (one row per sample) are used if given. Otherwise they are finite differences of the
    /// demonstrated velocities: central inside, second-order one-sided at both ends (BOLeRo uses backward
    /// differences and zeroes the first and last value instead; ours are O(dt^2) everywhere).
    ///
    /// The target forces are F = tau^2 Ydd - alpha_y (beta_y (g - Y) + tau gd - tau Yd) - tau^2 gdd, where g(t) is
    /// the quintic goal trajectory a rollout would use: from (Y_0, Yd_0, Ydd_0) to (Y_T, Yd_T, 0). To reproduce the
    /// demonstration, roll out from that start state with goal Y_T and goal velocity Yd_T. The weights solve the
    /// ridge regression min |X w - F|^2 + `regularization` |w|^2 (BOLeRo's default 1e-10; 0 gives the minimum-norm
    /// least-squares fit) over the features X = z psi(z) / sum psi(z) at the sample times, via an SVD of X.
    pub fn imitate(
        demonstration: &JointTrajectory,
        accelerations: Option<&[Vec<f64>]>,
        config: DmpConfig,
        regularization: f64,
    ) -> Result<Self, DmpImitateError> {
        let n_samples = demonstration.len();
        check(n_samples >= 3, "demonstration", "at least 3 samples long", n_samples)?;
        check_len("demonstration.velocities", n_samples, demonstration.velocities.len())?;
        let dt = demonstration.dt;
        check(dt.is_finite() && dt > 0.0, "demonstration.dt", "finite and > 0 (s)", dt)?;
        let n_dims = demonstration.positions[0].len();
        for row in &demonstration.positions {
            check_vector("demonstration.positions (every sample)", row, n_dims)?;
        }
        for row in &demonstration.velocities {
            check_vector("demonstration.velocities (every sample)", row, n_dims)?;
        }
        check(
            regularization.is_finite() && regularization >= 0.0,
            "regularization",
            "finite and >= 0",
            regularization,
        )?;
        let tau = (n_samples - 1) as f64 * dt;
        // Validates tau and provides the phase and basis functions.
        let basis = Self::new(n_dims, tau, DMatrix::zeros(n_dims, config.n_weights), config)?;

        let accelerations = match accelerations {
            Some(rows) => {
                check_len("accelerations", n_samples, rows.len())?;
                for row in rows {
                    check_vector("accelerations (every sample)", row, n_dims)?;
                }
                rows.to_vec()
            }
            None => differentiate(&demonstration.velocities, dt),
        };

        let (y, yd, ydd) = (&demonstration.positions, &demonstration.velocities, &accelerations);
        let last = n_samples - 1;
        let goals: Vec<[f64; 6]> = (0..n_dims)
            .map(|d| quintic(y[0][d], yd[0][d], ydd[0][d], y[last][d], yd[last][d], tau))
            .collect();
        let (alpha_y, beta_y) = (config.alpha_y, config.beta_y());
        let mut features = vec![0.0; n_samples * config.n_weights];
        let mut targets = DMatrix::zeros(n_samples, n_dims);
        for (k, row) in features.chunks_exact_mut(config.n_weights).enumerate() {
            let t = k as f64 * dt;
            basis.features(basis.phase(t), row);
            for (d, goal) in goals.iter().enumerate() {
                let (g, gd, gdd) = eval_quintic(goal, t);
                targets[(k, d)] = tau * tau * ydd[k][d]
                    - alpha_y * (beta_y * (g - y[k][d]) + tau * gd - tau * yd[k][d])
                    - tau * tau * gdd;
            }
        }
        check_finite("demonstration (target forces)", targets.iter())?;
        let design = DMatrix::from_row_slice(n_samples, config.n_weights, &features);
        let fit = ridge_regression(design, &targets, regularization).filter(|w| w.iter().all(|v| v.is_finite()));
        let Some(weights) = fit else {
            return Err(DmpImitateError::NoFit);
        };
        Ok(Self::new(n_dims, tau, weights.transpose(), config)?)
    }

    /// Number of dimensions.
    pub fn n_dims(&self) -> usize {
        self.weights.nrows()
    }

    /// Duration tau in s.
    pub fn execution_time(&self) -> f64 {
        self.execution_time
    }

    /// Forcing weights, n_dims x n_weights.
    pub fn weights(&self) -> &DMatrix<f64> {
        &self.weights
    }

    /// The configuration the DMP was built with.
    pub fn config(&self) -> &DmpConfig {
        &self.config
    }

    /// Decay constant alpha_z of the phase.
    pub fn alpha_z(&self) -> f64 {
        self.alpha_z
    }

    /// Basis-function centres in phase space, decreasing from 1 to [`FINAL_PHASE`].
    pub fn centers(&self) -> &[f64] {
        &self.centers
    }

    /// Basis-function widths h_i.
    pub fn widths(&self) -> &[f64] {
        &self.widths
    }

    /// Phase z(t) = b^(t / [`PHASE_DT`]), t in s since the start of the movement.
    pub fn phase(&self, t: f64) -> f64 {
        self.phase_base.powf(t / PHASE_DT)
    }

    /// Writes z psi_i(z) / sum_j psi_j(z) into `out`: the forcing term is the weights times these features.
    fn features(&self, z: f64, out: &mut [f64]) {
        let mut sum = 0.0;
        for ((o, c), h) in out.iter_mut().zip(&self.centers).zip(&self.widths) {
            let d = z - c;
            *o = (-h * d * d).exp();
            sum += *o;
        }
        let scale = z / sum;
        out.iter_mut().for_each(|o| *o *= scale);
    }

    /// Writes the forcing term f(z(t)) of every dimension into `out`; `features` is scratch space.
    fn forcing_term(&self, t: f64, features: &mut [f64], out: &mut [f64]) {
        self.features(self.phase(t), features);
        out.fill(0.0);
        // Column-major weights: one column per basis function.
        for (column, x) in self.weights.as_slice().chunks_exact(out.len()).zip(features.iter()) {
            for (o, w) in out.iter_mut().zip(column) {
                *o += w * x;
            }
        }
    }

    /// Integrates the DMP from `start` towards `goal` (position) and `goal_velocity`, reached at tau.
    ///
    /// Returns the samples at t = 0, control_dt, ..., tau (so tau must be an integer multiple of `control_dt` to a
    /// relative 1e-9) and the final state, from which a following DMP can continue. Each control period is split into
    /// the fewest equal Euler substeps no longer than `config.substep`; substep i ends at t = i h (exactly tau for the
    /// last). Each substep evaluates phase, forcing term, goal trajectory and acceleration at its end time, then
    /// updates y += h yd (old velocity), yd += h ydd. The same inputs give the same bits.
    pub fn rollout(
        &self,
        start: &DmpState,
        goal: &[f64],
        goal_velocity: &[f64],
        control_dt: f64,
    ) -> Result<(JointTrajectory, DmpState), DmpRolloutError> {
        let n_dims = self.n_dims();
        check_vector("start.position", &start.position, n_dims)?;
        check_vector("start.velocity", &start.velocity, n_dims)?;
        check_vector("start.acceleration", &start.acceleration, n_dims)?;
        check_vector("goal", goal, n_dims)?;
        check_vector("goal_velocity", goal_velocity, n_dims)?;
        let tau = self.execution_time;
        check(
            control_dt.is_finite() && control_dt > 0.0,
            "control_dt",
            "finite and > 0 (s)",
            control_dt,
        )?;
        let steps = (tau / control_dt).round();
        check(
            steps >= 1.0 && (steps * control_dt - tau).abs() <= RATIO_TOLERANCE * tau,
            "control_dt",
            "tau / k for an integer k >= 1 (to a relative 1e-9)",
            control_dt,
        )?;
        check(
            steps < MAX_SAMPLES as f64,
            "control_dt",
            "large enough for at most 10^7 samples",
            control_dt,
        )?;
        let steps = steps as usize;
        // control_dt <= tau (up to 1e-9) and tau / substep <= MAX_SUBSTEPS, so this product stays far from overflow.
        let substeps = (snap(control_dt / self.config.substep).ceil() as usize).max(1);
        let n_substeps = steps * substeps;
        let h = tau / n_substeps as f64;

        let goals: Vec<[f64; 6]> = (0..n_dims)
            .map(|d| {
                quintic(
                    start.position[d],
                    start.velocity[d],
                    start.acceleration[d],
                    goal[d],
                    goal_velocity[d],
                    tau,
                )
            })
            .collect();
        let (alpha_y, beta_y) = (self.config.alpha_y, self.config.beta_y());
        let tau2 = tau * tau;

        let tabulated = self.forcing_table.len() == n_substeps * n_dims;
        let mut features = vec![0.0; self.config.n_weights];
        let mut forces = vec![0.0; n_dims];
        let mut y = start.position.clone();
        let mut yd = start.velocity.clone();
        let mut ydd = start.acceleration.clone();
        let mut positions = Vec::with_capacity(steps + 1);
        let mut velocities = Vec::with_capacity(steps + 1);
        positions.push(y.clone());
        velocities.push(yd.clone());
        for i in 1..=n_substeps {
            let t = substep_time(tau, n_substeps, i);
            let f: &[f64] = if tabulated {
                &self.forcing_table[(i - 1) * n_dims..i * n_dims]
            } else {
                self.forcing_term(t, &mut features, &mut forces);
                &forces
            };
            for d in 0..n_dims {
                let (g, gd, gdd) = eval_quintic(&goals[d], t);
                ydd[d] = (alpha_y * (beta_y * (g - y[d]) + tau * (gd - yd[d])) + tau2 * gdd + f[d]) / tau2;
                y[d] += h * yd[d];
                yd[d] += h * ydd[d];
            }
            if i % substeps == 0 {
                positions.push(y.clone());
                velocities.push(yd.clone());
            }
        }
        let end = DmpState {
            position: y,
            velocity: yd,
            acceleration: ydd,
        };
        // Overflow persists (inf and NaN absorb later updates), so the final state tells whether any occurred.
        if [&end.position, &end.velocity, &end.acceleration]
            .iter()
            .any(|v| v.iter().any(|x| !x.is_finite()))
        {
            return Err(DmpRolloutError::Diverged);
        }
        let trajectory = JointTrajectory {
            dt: control_dt,
            positions,
            velocities,
        };
        Ok((trajectory, end))
    }
}

/// Joins two rollouts of chained DMPs: `second` must start where `first` ends (as a rollout from `first`'s final
/// state does) and share its control period; the duplicate junction sample is kept once.
pub fn chain(first: &JointTrajectory, second: &JointTrajectory) -> Result<JointTrajectory, TrajectoryChainError> {
    check(second.dt == first.dt, "second.dt", "equal to first.dt", second.dt)?;
    let starts_at_end = match (first.last(), second.positions.first(), second.velocities.first()) {
        (Some((position, velocity)), Some(p), Some(v)) => position == p.as_slice() && velocity == v.as_slice(),
        _ => false,
    };
    check(
        starts_at_end,
        "second",
        "non-empty and starting at first's last sample",
        "a different first sample",
    )?;
    let mut joined = first.clone();
    joined.positions.extend_from_slice(&second.positions[1..]);
    joined.velocities.extend_from_slice(&second.velocities[1..]);
    Ok(joined)
}

/// End time of substep `i` of `n` equal substeps over [0, tau]; the last ends at tau exactly, so the goal trajectory
/// is never evaluated past tau (where its velocity would drop to zero).
fn substep_time(tau: f64, n: usize, i: usize) -> f64 {
    if i == n { tau } else { i as f64 * (tau / n as f64) }
}

/// Time derivative of rows sampled every `dt` (at least 3 rows): central differences inside, second-order one-sided
/// differences at the ends.
fn differentiate(rows: &[Vec<f64>], dt: f64) -> Vec<Vec<f64>> {
    let n = rows.len();
    (0..n)
        .map(|k| {
            // (coefficient, sample) pairs, to be divided by 2 dt.
            let stencil = match k {
                0 => [(-3.0, 0), (4.0, 1), (-1.0, 2)],
                _ if k == n - 1 => [(3.0, k), (-4.0, k - 1), (1.0, k - 2)],
                _ => [(-1.0, k - 1), (1.0, k + 1), (0.0, k)],
            };
            (0..rows[k].len())
                .map(|d| stencil.iter().map(|&(c, i)| c * rows[i][d]).sum::<f64>() / (2.0 * dt))
                .collect()
        })
        .collect()
}

/// Ridge regression min |X w - F|^2 + lambda |w|^2 for every column of F (n_samples x n_outputs); returns
/// n_features x n_outputs. Uses the SVD X = U S V^T, w = V diag(s / (s^2 + lambda)) U^T F, which avoids squaring the
/// condition number of the strongly overlapping basis functions as the normal equations would. Singular values
/// below the usual pseudo-inverse cutoff are dropped so that lambda = 0 gives the minimum-norm solution.
fn ridge_regression(design: DMatrix<f64>, targets: &DMatrix<f64>, lambda: f64) -> Option<DMatrix<f64>> {
    let (rows, cols) = design.shape();
    // Capped so that a pathological matrix reports an error instead of iterating forever.
    let svd = design.try_svd(true, true, f64::EPSILON, 1000 * cols)?;
    let (u, v_t) = (svd.u?, svd.v_t?);
    let s = svd.singular_values;
    let cutoff = s.max() * rows.max(cols) as f64 * f64::EPSILON;
    let mut projected = u.transpose() * targets;
    for (j, mut row) in projected.row_iter_mut().enumerate() {
        let s = s[j];
        row *= if s > cutoff { s / (s * s + lambda) } else { 0.0 };
    }
    Some(v_t.transpose() * projected)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};
    use std::f64::consts::PI;

    const TAU: f64 = 0.5;
    const Y0: [f64; 7] = [0.1, -0.5, 1.0, 0.0, 0.3, -1.2, 2.0];
    const Y1: [f64; 7] = [1.0, 0.5, -1.0, 0.7, -0.3, 0.2, 0.0];
    const V1: [f64; 7] = [2.0, -1.0, 0.0, 3.0, -2.0, 1.0, 0.5];

    fn zero_weights(n_dims: usize, tau: f64, config: DmpConfig) -> Dmp {
        Dmp::new(n_dims, tau, DMatrix::zeros(n_dims, config.n_weights), config).unwrap()
    }

    fn max_diff(a: &[f64], b: &[f64]) -> f64 {
        assert_eq!(a.len(), b.len());
        a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
    }

    fn max_diff_rows(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
        assert_eq!(a.len(), b.len());
        a.iter().zip(b).map(|(x, y)| max_diff(x, y)).fold(0.0, f64::max)
    }

    fn bits(rows: &[Vec<f64>]) -> Vec<u64> {
        rows.iter().flatten().map(|v| v.to_bits()).collect()
    }

    /// Position, velocity and acceleration of dimension d at time t.
    type Motion = dyn Fn(usize, f64) -> [f64; 3];

    /// An analytic movement sampled every `dt` over [0, tau]: the trajectory and its exact accelerations.
    fn sample(
        tau: f64,
        dt: f64,
        n_dims: usize,
        motion: impl Fn(usize, f64) -> [f64; 3],
    ) -> (JointTrajectory, Vec<Vec<f64>>) {
        let n = (tau / dt).round() as usize;
        let states: Vec<Vec<[f64; 3]>> = (0..=n)
            .map(|k| (0..n_dims).map(|d| motion(d, k as f64 * dt)).collect())
            .collect();
        let column = |j: usize| states.iter().map(|row| row.iter().map(|s| s[j]).collect()).collect();
        let trajectory = JointTrajectory {
            dt,
            positions: column(0),
            velocities: column(1),
        };
        (trajectory, column(2))
    }

    /// The Mülling goal trajectory from rest at Y0 to (Y1, V1): what a zero-weight DMP should follow.
    fn goal_motion(d: usize, t: f64) -> [f64; 3] {
        let (p, v, a) = eval_quintic(&quintic(Y0[d], 0.0, 0.0, Y1[d], V1[d], TAU), t);
        [p, v, a]
    }

    /// The goal trajectory plus a cosine with amplitudes up to 1 rad: non-zero acceleration at both ends, peak
    /// speeds near 8 rad/s.
    fn sinusoid_motion(d: usize, t: f64) -> [f64; 3] {
        let amplitude = [0.5, -0.3, 0.2, 1.0, -0.8, 0.4, 0.1][d];
        let w = 2.0 * PI / TAU;
        let [p, v, a] = goal_motion(d, t);
        let bump = amplitude / 2.0;
        [
            p + bump * (1.0 - (w * t).cos()),
            v + bump * w * (w * t).sin(),
            a + bump * w * w * (w * t).cos(),
        ]
    }

    /// A quintic between two states plus the bump 64 b (s (1 - s))^3, s = t / tau, whose value, slope and curvature
    /// vanish at both ends: a movement that starts and ends exactly in the given states.
    fn bump_motion(start: [f64; 3], end: [f64; 2], b: f64, t: f64) -> [f64; 3] {
        let (p, v, a) = eval_quintic(&quintic(start[0], start[1], start[2], end[0], end[1], TAU), t);
        let s = t / TAU;
        let q = s * (1.0 - s);
        let (dq, ddq) = (1.0 - 2.0 * s, -2.0);
        let k = 64.0 * b;
        [
            p + k * q.powi(3),
            v + k * 3.0 * q * q * dq / TAU,
            a + k * (6.0 * q * dq * dq + 3.0 * q * q * ddq) / (TAU * TAU),
        ]
    }

    fn start_of(demonstration: &JointTrajectory, accelerations: &[Vec<f64>]) -> DmpState {
        DmpState {
            position: demonstration.positions[0].clone(),
            velocity: demonstration.velocities[0].clone(),
            acceleration: accelerations[0].clone(),
        }
    }

    fn message(result: Result<impl std::fmt::Debug, impl std::error::Error>) -> String {
        result.unwrap_err().to_string()
    }

    #[test]
    fn phase_ends_at_final_value_and_decreases() {
        // 0.35 / 0.001 and 0.7 / 0.001 fall just below integers: without snapping, BOLeRo's floor loses a phase step.
        for tau in [0.001, 0.35, 0.446, 0.5, 0.7, 0.853, 1.0, 2.0] {
            let dmp = zero_weights(1, tau, DmpConfig::default());
            assert_eq!(dmp.phase(0.0), 1.0);
            assert!(
                (dmp.phase(tau) - FINAL_PHASE).abs() < 1e-12,
                "tau {tau}: z(tau) = {}",
                dmp.phase(tau)
            );
            let z: Vec<f64> = (0..=1000).map(|i| dmp.phase(tau * i as f64 / 1000.0)).collect();
            assert!(z.windows(2).all(|p| p[1] < p[0]), "tau {tau}: phase not decreasing");

            let c = dmp.centers();
            assert_eq!(c[0], 1.0);
            assert!((c[c.len() - 1] - FINAL_PHASE).abs() < 1e-12);
            assert!(c.windows(2).all(|p| p[1] < p[0]), "tau {tau}: centres not decreasing");
            let h = dmp.widths();
            for i in 0..c.len() - 1 {
                let overlap = (-h[i] * (c[i + 1] - c[i]).powi(2)).exp();
                assert!((overlap - RBF_OVERLAP).abs() < 1e-12);
            }
            assert_eq!(h[h.len() - 1], h[h.len() - 2]);
        }
    }

    #[test]
    fn phase_and_basis_match_bolero() {
        // Reference values from BOLeRo's dmp/test/test_dmp.py (calculate_alpha, initialize_rbf with 10 weights).
        let config = DmpConfig {
            n_weights: 10,
            ..DmpConfig::default()
        };
        let dmp = zero_weights(1, 0.446, config);
        assert!((dmp.alpha_z() - 4.5814764780043).abs() < 1e-12);
        let widths = [
            1.39105769528669,
            3.87070066903258,
            10.7704545397461,
            29.969429545615,
            83.3917179609352,
            232.042408878407,
            645.671786535403,
            1796.62010036397,
            4999.20215246208,
            4999.20215246208,
        ];
        let centers = [
            1.0,
            0.59948425031894,
            0.359381366380461,
            0.215443469003187,
            0.129154966501487,
            0.0774263682681117,
            0.0464158883361271,
            0.0278255940220708,
            0.0166810053720003,
            0.00999999999999978,
        ];
        for (ours, theirs) in dmp.widths().iter().zip(widths).chain(dmp.centers().iter().zip(centers)) {
            assert!((ours - theirs).abs() <= 1e-11 * theirs, "{ours} vs {theirs}");
        }
    }

    #[test]
    fn quintic_meets_its_boundary_conditions() {
        let mut rng = StdRng::seed_from_u64(3);
        for _ in 0..100 {
            let [y0, v0, a0, y1, v1]: [f64; 5] = std::array::from_fn(|_| rng.random_range(-5.0..5.0));
            let tau = rng.random_range(0.01..3.0);
            let c = quintic(y0, v0, a0, y1, v1, tau);
            let (p, v, a) = eval_quintic(&c, 0.0);
            assert_eq!([p, v, a], [y0, v0, a0]);
            let (p, v, a) = eval_quintic(&c, tau);
            let scale = 1.0 + y0.abs().max(y1.abs()) + (v0.abs() + v1.abs()) / tau + a0.abs() / (tau * tau);
            assert!((p - y1).abs() < 1e-11 * scale, "position {p} vs {y1}");
            assert!((v - v1).abs() * tau < 1e-10 * scale, "velocity {v} vs {v1}");
            assert!(a.abs() * tau * tau < 1e-9 * scale, "acceleration {a}");
        }
    }

    #[test]
    fn samples_every_control_period_from_start_to_tau() {
        // Sample counts of BOLeRo's test_dmp_behavior.py (execution time, dt -> steps).
        for (tau, dt, len) in [
            (1.0, 0.01, 101),
            (2.0, 0.01, 201),
            (1.5, 0.01, 151),
            (0.853, 0.001, 854),
        ] {
            let dmp = zero_weights(2, tau, DmpConfig::default());
            let start = DmpState::at_rest(&[0.43, -1.0]);
            let (trajectory, _) = dmp.rollout(&start, &[-0.21, 1.0], &[0.12, 0.0], dt).unwrap();
            assert_eq!(trajectory.len(), len);
            assert_eq!(trajectory.dt, dt);
            assert_eq!(trajectory.positions[0], start.position);
            assert_eq!(trajectory.velocities[0], start.velocity);
        }
    }

    #[test]
    fn goal_at_start_keeps_the_system_at_rest_exactly() {
        let dmp = zero_weights(7, TAU, DmpConfig::default());
        let start = DmpState::at_rest(&Y0);
        let (trajectory, end) = dmp.rollout(&start, &Y0, &[0.0; 7], 0.001).unwrap();
        assert!(trajectory.positions.iter().all(|p| p == &Y0));
        assert!(trajectory.velocities.iter().flatten().all(|&v| v == 0.0));
        assert_eq!(end, start);
    }

    #[test]
    fn euler_substep_advances_time_first_and_moves_with_the_old_velocity() {
        let config = DmpConfig::default();
        let weights = DMatrix::from_fn(1, 50, |_, i| 30.0 - i as f64);
        let dmp = Dmp::new(1, TAU, weights, config).unwrap();
        let start = DmpState {
            position: vec![0.2],
            velocity: vec![1.5],
            acceleration: vec![-3.0],
        };
        let (trajectory, _) = dmp.rollout(&start, &[1.0], &[2.0], 0.001).unwrap();
        let h = TAU / 500.0;
        assert_eq!(trajectory.positions[1][0], 0.2 + h * 1.5);
        // The acceleration of the first substep uses goal, forcing term and phase at its end time h.
        let (g, gd, gdd) = eval_quintic(&quintic(0.2, 1.5, -3.0, 1.0, 2.0, TAU), h);
        let mut features = vec![0.0; 50];
        let mut f = [0.0];
        dmp.forcing_term(h, &mut features, &mut f);
        let (alpha, beta) = (config.alpha_y, config.beta_y());
        let ydd = (alpha * (beta * (g - 0.2) + TAU * (gd - 1.5)) + TAU * TAU * gdd + f[0]) / (TAU * TAU);
        assert!((trajectory.velocities[1][0] - (1.5 + h * ydd)).abs() < 1e-12);
    }

    #[test]
    fn zero_weights_reach_goal_up_to_first_order_euler_error() {
        // Without forcing the exact solution is the goal quintic, which ends in (g, gd); what remains is the error of
        // BOLeRo's explicit Euler, which lags the continuous solution by about one substep: at 1 ms, 2.9e-3 rad and
        // 2.4e-2 rad/s here (moves up to 2 rad, goal speeds up to 3 rad/s), i.e. about substep x goal speed.
        let start = DmpState::at_rest(&Y0);
        let errors = |substep: f64| {
            let dmp = zero_weights(
                7,
                TAU,
                DmpConfig {
                    substep,
                    ..DmpConfig::default()
                },
            );
            let (_, end) = dmp.rollout(&start, &Y1, &V1, 0.001).unwrap();
            (max_diff(&end.position, &Y1), max_diff(&end.velocity, &V1))
        };
        let (position, velocity) = errors(0.001);
        assert!(
            position < 4e-3 && velocity < 4e-2,
            "1 ms: {position:e} rad, {velocity:e} rad/s"
        );
        // First order: a 10x finer substep cuts both errors about 10x, so the residual is integration error.
        let (fine_position, fine_velocity) = errors(0.0001);
        assert!(fine_position < position / 8.0 && fine_velocity < velocity / 8.0);
    }

    #[test]
    fn meets_bolero_end_state_assertions() {
        // test_dmp_behavior.py: decimal = 3, 2, 1 for position, velocity, acceleration (|error| < 1.5 10^-decimal).
        let cases: [(f64, f64, f64, f64, f64); 4] = [
            // (tau, x0, g, gd, weight)
            (1.0, 0.0, 1.0, 0.0, 0.0),
            (1.0, 0.0, 0.0, 1.0, 0.0),
            (1.5, 0.43, -0.21, 0.12, 0.0),
            (1.0, 0.0, 0.0, 0.0, 1.0),
        ];
        for (tau, x0, g, gd, weight) in cases {
            let dmp = Dmp::new(1, tau, DMatrix::repeat(1, 50, weight), DmpConfig::default()).unwrap();
            let (_, end) = dmp.rollout(&DmpState::at_rest(&[x0]), &[g], &[gd], 0.01).unwrap();
            assert!((end.position[0] - g).abs() < 1.5e-3, "{end:?}");
            assert!((end.velocity[0] - gd).abs() < 1.5e-2, "{end:?}");
            assert!(end.acceleration[0].abs() < 1.5e-1, "{end:?}");
        }
    }

    #[test]
    fn rollouts_are_deterministic_across_control_periods_and_forcing_paths() {
        let weights = DMatrix::from_fn(7, 50, |d, i| 80.0 * ((d * 50 + i) as f64 * 0.37).sin());
        let dmp = Dmp::new(7, TAU, weights.clone(), DmpConfig::default()).unwrap();
        let start = DmpState {
            position: Y0.to_vec(),
            velocity: vec![0.5; 7],
            acceleration: vec![-2.0; 7],
        };
        let (fine, fine_end) = dmp.rollout(&start, &Y1, &V1, 0.001).unwrap();
        let (again, again_end) = dmp.rollout(&start, &Y1, &V1, 0.001).unwrap();
        assert_eq!(bits(&fine.positions), bits(&again.positions));
        assert_eq!(bits(&fine.velocities), bits(&again.velocities));
        assert_eq!(fine_end, again_end);

        // Control periods that are multiples of the substep share its grid, so they sample the same states.
        let (coarse, coarse_end) = dmp.rollout(&start, &Y1, &V1, 0.002).unwrap();
        let every_other = |rows: &[Vec<f64>]| rows.iter().step_by(2).cloned().collect::<Vec<_>>();
        assert_eq!(bits(&coarse.positions), bits(&every_other(&fine.positions)));
        assert_eq!(bits(&coarse.velocities), bits(&every_other(&fine.velocities)));
        assert_eq!(coarse_end, fine_end);

        // A substep of 1.1 ms tabulates a 455-step grid; 1 ms control periods then integrate on the 500-step grid
        // with the forcing term computed on the fly, which must reproduce the tabulated path bit for bit.
        let untabulated = Dmp::new(
            7,
            TAU,
            weights,
            DmpConfig {
                substep: 0.0011,
                ..DmpConfig::default()
            },
        )
        .unwrap();
        let (other, other_end) = untabulated.rollout(&start, &Y1, &V1, 0.001).unwrap();
        assert_eq!(bits(&other.positions), bits(&fine.positions));
        assert_eq!(bits(&other.velocities), bits(&fine.velocities));
        assert_eq!(other_end, fine_end);
    }

    #[test]
    fn imitating_the_goal_trajectory_needs_no_forcing() {
        // The quintic from rest to (Y1, V1) is the goal trajectory itself, so the target forces vanish.
        let (demonstration, accelerations) = sample(TAU, 0.001, 7, goal_motion);
        let dmp = Dmp::imitate(&demonstration, Some(&accelerations), DmpConfig::default(), 1e-10).unwrap();
        assert!(dmp.weights().amax() < 1e-6, "{}", dmp.weights().amax());
    }

    #[test]
    fn imitation_reproduces_demonstrations() {
        let bump = |d: usize, t: f64| bump_motion([Y0[d], 0.0, 0.0], [Y1[d], V1[d]], 0.4 - 0.1 * d as f64, t);
        let motions: [(&str, &Motion); 3] = [("goal", &goal_motion), ("sinusoid", &sinusoid_motion), ("bump", &bump)];
        for (name, motion) in motions {
            for dt in [0.001, 0.01] {
                let (demonstration, exact) = sample(TAU, dt, 7, motion);
                let start = start_of(&demonstration, &exact);
                let (goal, goal_velocity) = demonstration.last().unwrap();
                // Finite-difference accelerations; the rollout starts from the exact state, as a user would.
                let errors = |substep: f64| {
                    let config = DmpConfig {
                        substep,
                        ..DmpConfig::default()
                    };
                    let dmp = Dmp::imitate(&demonstration, None, config, 1e-10).unwrap();
                    let (replay, end) = dmp.rollout(&start, goal, goal_velocity, dt).unwrap();
                    [
                        max_diff_rows(&replay.positions, &demonstration.positions),
                        max_diff_rows(&replay.velocities, &demonstration.velocities),
                        max_diff(&end.position, goal),
                        max_diff(&end.velocity, goal_velocity),
                    ]
                };
                // The residual is the Euler error of the rollout (about substep x speed, as for zero weights):
                // measured 7.4e-3 rad, 0.11 rad/s, 2.9e-3 rad, 0.11 rad/s at 1 ms for peak speeds near 8 rad/s.
                let coarse = errors(0.001);
                let tolerance = [1e-2, 0.15, 4e-3, 0.15];
                assert!(
                    coarse.iter().zip(tolerance).all(|(e, t)| *e < t),
                    "{name}, dt {dt}: {coarse:?}"
                );
                // ... and with 1 ms samples it shrinks with the substep, so the fitted forcing term itself is accurate.
                // (With 10 ms samples the finite-difference accelerations limit the fit to about 4e-3 rad.)
                if dt == 0.001 {
                    let fine = errors(0.0001);
                    assert!(
                        fine.iter().zip(tolerance).all(|(e, t)| *e < t / 6.0),
                        "{name}: {fine:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn imitation_uses_given_accelerations_and_regularization() {
        let (demonstration, exact) = sample(TAU, 0.001, 7, sinusoid_motion);
        let config = DmpConfig::default();
        let from_differences = Dmp::imitate(&demonstration, None, config, 1e-10).unwrap();
        let from_exact = Dmp::imitate(&demonstration, Some(&exact), config, 1e-10).unwrap();
        // O(dt^2) differences barely change the fit, but they do change it.
        let change = (from_exact.weights() - from_differences.weights()).amax();
        assert!(change > 0.0 && change < 1e-3 * from_exact.weights().amax(), "{change}");
        // Ridge shrinks the weights; lambda = 0 is the minimum-norm least-squares fit.
        let shrunk = Dmp::imitate(&demonstration, Some(&exact), config, 1.0).unwrap();
        assert!(shrunk.weights().norm() < 0.5 * from_exact.weights().norm());
        let unregularized = Dmp::imitate(&demonstration, Some(&exact), config, 0.0).unwrap();
        assert!(unregularized.weights().iter().all(|w| w.is_finite()));
        // Same inputs, same bits.
        let again = Dmp::imitate(&demonstration, None, config, 1e-10).unwrap();
        assert_eq!(again, from_differences);
    }

    #[test]
    fn new_goals_move_the_end_state_by_the_change() {
        let (demonstration, exact) = sample(TAU, 0.001, 7, sinusoid_motion);
        let dmp = Dmp::imitate(&demonstration, None, DmpConfig::default(), 1e-10).unwrap();
        let start = start_of(&demonstration, &exact);
        let (goal, goal_velocity) = demonstration.last().unwrap();
        let (_, base) = dmp.rollout(&start, goal, goal_velocity, 0.001).unwrap();

        let shift = [0.3, -0.3, 0.2, -0.1, 0.25, -0.2, 0.15];
        let speedup = [1.0, -1.0, 0.5, -0.5, 2.0, -2.0, 0.7];
        let new_goal: Vec<f64> = goal.iter().zip(shift).map(|(g, s)| g + s).collect();
        let new_velocity: Vec<f64> = goal_velocity.iter().zip(speedup).map(|(v, s)| v + s).collect();
        let (_, end) = dmp.rollout(&start, &new_goal, &new_velocity, 0.001).unwrap();
        for d in 0..7 {
            // The end state follows the meta-parameters to within 1% of the change (measured <= 0.9%, from the
            // forcing term z f at z = 0.01 and the Euler error) ...
            let moved = end.position[d] - base.position[d];
            let sped = end.velocity[d] - base.velocity[d];
            assert!(
                (moved - shift[d]).abs() < 0.01 * shift[d].abs(),
                "dim {d}: moved {moved}"
            );
            assert!(
                (sped - speedup[d]).abs() < 0.01 * speedup[d].abs(),
                "dim {d}: sped up {sped}"
            );
            // ... and lands as close to the new goal as the reproduction did to the old one.
            assert!((end.position[d] - new_goal[d]).abs() < 4e-3, "dim {d}");
            assert!((end.velocity[d] - new_velocity[d]).abs() < 0.15, "dim {d}");
        }
    }

    #[test]
    fn chained_rollouts_are_continuous_at_the_junction() {
        // A strike-out ending in (Y1, V1) and a throw from there to (Y0, -V1), each imitated from a bump movement.
        let out = |d: usize, t: f64| bump_motion([Y0[d], 0.0, 0.0], [Y1[d], V1[d]], 0.3, t);
        let back = |d: usize, t: f64| bump_motion([Y1[d], V1[d], 0.0], [Y0[d], -V1[d]], -0.2, t);
        let config = DmpConfig::default();
        let (demo_out, exact_out) = sample(TAU, 0.001, 7, out);
        let (demo_back, _) = sample(TAU, 0.001, 7, back);
        let first = Dmp::imitate(&demo_out, None, config, 1e-10).unwrap();
        let second = Dmp::imitate(&demo_back, None, config, 1e-10).unwrap();

        let (trajectory_out, junction) = first
            .rollout(&start_of(&demo_out, &exact_out), &Y1, &V1, 0.001)
            .unwrap();
        let minus_v1 = V1.map(|v| -v);
        let (trajectory_back, _) = second.rollout(&junction, &Y0, &minus_v1, 0.001).unwrap();
        let joined = chain(&trajectory_out, &trajectory_back).unwrap();
        assert_eq!(joined.len(), trajectory_out.len() + trajectory_back.len() - 1);

        // Per-sample changes at the junction are no larger than elsewhere: no jump in position or velocity.
        let steps = |rows: &[Vec<f64>]| -> Vec<f64> { rows.windows(2).map(|w| max_diff(&w[0], &w[1])).collect() };
        let at = trajectory_out.len() - 1;
        for rows in [&joined.positions, &joined.velocities] {
            let changes = steps(rows);
            let elsewhere = changes
                .iter()
                .enumerate()
                .filter(|(k, _)| k.abs_diff(at) > 1)
                .map(|(_, c)| *c);
            assert!(changes[at] <= elsewhere.fold(0.0, f64::max));
        }

        // Starting the second DMP at rest instead breaks the chain: its first sample is not the junction.
        let (from_rest, _) = second.rollout(&DmpState::at_rest(&Y1), &Y0, &minus_v1, 0.001).unwrap();
        assert!(message(chain(&trajectory_out, &from_rest)).contains("second must be"));
        let (coarse, _) = second.rollout(&junction, &Y0, &minus_v1, 0.002).unwrap();
        assert!(message(chain(&trajectory_out, &coarse)).contains("second.dt"));
    }

    #[test]
    fn errors_name_the_argument() {
        let config = DmpConfig::default();
        let zeros = || DMatrix::zeros(2, 50);
        for tau in [0.0, -1.0, 0.0005, f64::NAN, f64::INFINITY] {
            assert!(message(Dmp::new(2, tau, zeros(), config)).starts_with("execution_time must be finite"));
        }
        assert!(message(Dmp::new(2, 1e7, zeros(), config)).starts_with("execution_time must be at most 1e9 substeps"));
        assert!(message(Dmp::new(0, TAU, DMatrix::zeros(0, 50), config)).starts_with("n_dims"));
        assert!(message(Dmp::new(3, TAU, zeros(), config)).starts_with("weights (rows = n_dims) must have 3 entries"));
        assert!(message(Dmp::new(2, TAU, DMatrix::zeros(2, 49), config)).starts_with("weights (columns"));
        let mut bad = zeros();
        bad[(1, 7)] = f64::NAN;
        assert!(message(Dmp::new(2, TAU, bad, config)).starts_with("weights must be finite"));
        for (config, argument) in [
            (DmpConfig { n_weights: 1, ..config }, "n_weights"),
            (DmpConfig { alpha_y: 0.0, ..config }, "alpha_y"),
            (
                DmpConfig {
                    alpha_y: f64::NAN,
                    ..config
                },
                "alpha_y",
            ),
            (
                DmpConfig {
                    substep: -0.001,
                    ..config
                },
                "substep",
            ),
            (
                DmpConfig {
                    substep: f64::INFINITY,
                    ..config
                },
                "substep",
            ),
        ] {
            assert!(message(Dmp::new(2, TAU, zeros(), config)).starts_with(argument));
        }

        let dmp = Dmp::new(2, TAU, zeros(), config).unwrap();
        let start = DmpState::at_rest(&[0.0, 0.0]);
        let ok = [0.0, 0.0];
        for dt in [0.0, -0.001, f64::NAN, f64::INFINITY, 0.003, 0.6, 1e-9] {
            assert!(
                message(dmp.rollout(&start, &ok, &ok, dt)).starts_with("control_dt must be"),
                "{dt}"
            );
        }
        // Within the relative 1e-9 tolerance tau / control_dt counts as an integer.
        assert!(dmp.rollout(&start, &ok, &ok, 0.001 * (1.0 + 1e-12)).is_ok());
        assert!(message(dmp.rollout(&start, &[0.0], &ok, 0.001)).starts_with("goal must have 2 entries, got 1"));
        assert!(message(dmp.rollout(&start, &ok, &[0.0, f64::NAN], 0.001)).starts_with("goal_velocity must be finite"));
        let mut bad_start = start.clone();
        bad_start.position.push(0.0);
        assert!(message(dmp.rollout(&bad_start, &ok, &ok, 0.001)).starts_with("start.position"));
        let mut bad_start = start.clone();
        bad_start.velocity[0] = f64::INFINITY;
        assert!(message(dmp.rollout(&bad_start, &ok, &ok, 0.001)).starts_with("start.velocity"));
        let mut bad_start = start.clone();
        bad_start.acceleration[1] = f64::NAN;
        assert!(message(dmp.rollout(&bad_start, &ok, &ok, 0.001)).starts_with("start.acceleration"));
        // A finite but huge goal overflows the goal quintic.
        assert_eq!(
            dmp.rollout(&start, &[f64::MAX, 0.0], &ok, 0.001).unwrap_err(),
            DmpRolloutError::Diverged
        );

        let (demonstration, _) = sample(TAU, 0.01, 2, |d, t| [d as f64 * t, d as f64, 0.0]);
        let imitate = |demo: &JointTrajectory, accelerations: Option<&[Vec<f64>]>, regularization: f64| {
            message(Dmp::imitate(demo, accelerations, config, regularization))
        };
        let mut short = demonstration.clone();
        short.positions.truncate(2);
        short.velocities.truncate(2);
        assert!(imitate(&short, None, 0.0).starts_with("demonstration must be at least 3 samples long"));
        let mut bad = demonstration.clone();
        bad.velocities.pop();
        assert!(imitate(&bad, None, 0.0).starts_with("demonstration.velocities must have 51 entries"));
        let mut bad = demonstration.clone();
        bad.positions[5].pop();
        assert!(imitate(&bad, None, 0.0).starts_with("demonstration.positions (every sample) must have 2"));
        let mut bad = demonstration.clone();
        bad.velocities[9][1] = f64::NAN;
        assert!(imitate(&bad, None, 0.0).starts_with("demonstration.velocities (every sample) must be finite"));
        let mut bad = demonstration.clone();
        bad.dt = 0.0;
        assert!(imitate(&bad, None, 0.0).starts_with("demonstration.dt"));
        for regularization in [-1.0, f64::NAN] {
            assert!(imitate(&demonstration, None, regularization).starts_with("regularization"));
        }
        let too_few = vec![vec![0.0; 2]; 50];
        assert!(imitate(&demonstration, Some(&too_few), 0.0).starts_with("accelerations must have 51 entries"));
    }
}
