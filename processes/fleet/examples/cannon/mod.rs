//! The examples' environment: a 2-D cannon whose ball flies with quadratic air drag in a
//! horizontal wind. A context is (target distance in m, wind in m/s); the parameters are
//! (elevation in rad, muzzle speed in m/s, spin), and a rollout returns minus the squared miss
//! in m^2 (the score is the miss in m).

use acps_shared::{ContextSpace, Environment, EnvironmentSpec, Outcome, Problem, ScoreAggregate, Task};

/// Everything that changes where a ball lands: part of the environment's identity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CannonSettings {
    /// Integration step, s.
    pub dt: f64,
    /// Drag coefficient per unit mass, 1/m.
    pub drag: f64,
    /// Gravity, m/s^2.
    pub gravity: f64,
    /// Lift per unit spin (a Magnus force), 1/s.
    pub magnus: f64,
}

impl Default for CannonSettings {
    fn default() -> Self {
        Self {
            dt: 1e-3,
            drag: 0.05,
            gravity: 9.81,
            magnus: 0.3,
        }
    }
}

/// The cannon.
#[derive(Debug, Clone)]
pub struct Cannon {
    settings: CannonSettings,
    spec: EnvironmentSpec,
}

impl Cannon {
    /// A cannon with `settings`.
    pub fn new(settings: CannonSettings) -> Self {
        let spec = EnvironmentSpec::new("cannon-2d", [0; 3], &settings).expect("a valid name");
        Self { settings, spec }
    }

    /// Where a ball shot with `theta` lands in `wind`, m from the cannon; `None` if it does not
    /// come down within 20 s.
    pub fn landing(&self, theta: &[f64], wind: f64) -> Option<f64> {
        let CannonSettings {
            dt,
            drag,
            gravity,
            magnus,
        } = self.settings;
        let (elevation, speed, spin) = (theta[0], theta[1], theta[2]);
        let (mut x, mut y) = (0.0, 0.0);
        let (mut vx, mut vy) = (speed * elevation.cos(), speed * elevation.sin());
        for _ in 0..(20.0 / dt) as usize {
            let (ax, ay) = (vx - wind, vy);
            let air = (ax * ax + ay * ay).sqrt();
            vx += dt * (-drag * air * ax - magnus * spin * ay);
            vy += dt * (-gravity - drag * air * ay + magnus * spin * ax);
            x += dt * vx;
            y += dt * vy;
            if y < 0.0 {
                return Some(x);
            }
        }
        None
    }

    /// The problem the learner sees: 9 training contexts on a 3 x 3 grid of targets 4-10 m
    /// away in winds of -2..2 m/s, tested on a 2 x 2 grid between them.
    pub fn problem(&self) -> Problem {
        let grid = |distances: &[f64], winds: &[f64]| -> Vec<Vec<f64>> {
            distances
                .iter()
                .flat_map(|&d| winds.iter().map(move |&w| vec![d, w]))
                .collect()
        };
        Problem {
            name: "cannon".into(),
            training_contexts: grid(&[4.0, 7.0, 10.0], &[-2.0, 0.0, 2.0]),
            test_contexts: grid(&[5.5, 8.5], &[-1.0, 1.0]),
            space: ContextSpace::new_box(vec![4.0, -2.0], vec![10.0, 2.0]).expect("a valid box"),
            theta0: vec![0.6, 8.0, 0.0],
            score: ScoreAggregate::Mean,
            metric: "mean miss (m)".into(),
            environment: self.spec,
        }
    }
}

impl Environment for Cannon {
    fn spec(&self) -> EnvironmentSpec {
        self.spec
    }

    fn context_dim(&self) -> usize {
        2
    }

    fn param_dim(&self) -> usize {
        3
    }

    fn rollout(&mut self, task: &Task) -> Outcome {
        let (target, wind) = (task.context[0], task.context[1]);
        match self.landing(&task.theta, wind) {
            Some(x) => Outcome::new(task.id, -(x - target).powi(2), (x - target).abs()).with_diagnostics(vec![x]),
            None => Outcome::failed(task.id),
        }
    }
}
