//! The paper's throwing task (Section 5.2): a throw is a strike-out DMP followed by a throw DMP,
//! 0.5 s each, in the joint space of all 7 joints; the ball is released at t = 1.0 s. The learner
//! adapts theta = (g1, g1dot, g2dot) (21 values) as an offset on the designed theta_0.
//!
//! # The designed throw (theta_0)
//! The paper does not give its initial policy, only that it lands at (-3.55, -3.55). Ours is a
//! planar overarm throw along the diagonal (S1 = -135 deg, S3 = E2 = W2 = 0):
//! - rest pose (S2, E1, W1) = (-0.4, -0.6, -0.8) rad, leaning away from the target;
//! - strike-out to g1 = (-0.9, -1.5, -2.0) rad, arriving at rest (g1dot = 0);
//! - throw to g2 = (-0.3, -0.3, -0.1) rad with g2dot = s (1, 2, 4) rad/s, s = [`THROW_SPEED`],
//!   chosen (by bisection with the analytic model) so that the ball lands at (-3.55, -3.55).
//!
//! The forcing weights are zero. With Mülling's moving goal (a quintic from the start state to
//! (g, gdot)), a DMP with zero forcing follows that quintic, so the shape of the movement is
//! fully set by the meta-parameters the learner adapts; there is no demonstration to imitate.
//! g2 and the durations stay fixed, as in the paper.

use crate::dmp::{Dmp, DmpConfig, DmpCreateError, DmpRolloutError, DmpState, TrajectoryChainError, chain};
use crate::rapier_sim::RapierArm;
use crate::robot::Robot;
use crate::targets::{self, Field, Point};
use crate::trajectory::JointTrajectory;
use acps_shared::{ContextSpace, Environment, EnvironmentSpec, Outcome, Problem, ScoreAggregate, Task};
use nalgebra::DMatrix;

/// Number of joints the throw drives.
pub const JOINTS: usize = 7;
/// Number of adapted parameters: g1, g1dot and g2dot for every joint.
pub const PARAMS: usize = 3 * JOINTS;
/// Duration of the strike-out DMP (s).
pub const STRIKE_DURATION: f64 = 0.5;
/// Duration of the throw DMP (s); the ball is released at its end.
pub const THROW_DURATION: f64 = 0.5;
/// Where the designed throw lands (the paper's initial policy), m.
pub const INITIAL_LANDING: Point = [-3.55, -3.55];
/// The designed throw's release-speed scale s (see the module documentation).
pub const THROW_SPEED: f64 = 2.0795;

/// A throw's meta-parameters for every joint.
#[derive(Debug, Clone, PartialEq)]
pub struct ThrowDesign {
    /// The rest pose the throw starts from.
    pub rest: [f64; JOINTS],
    /// Final position of the strike-out, g1.
    pub strike_goal: [f64; JOINTS],
    /// Final velocity of the strike-out, g1dot.
    pub strike_goal_velocity: [f64; JOINTS],
    /// Final position of the throw, g2 (fixed).
    pub throw_goal: [f64; JOINTS],
    /// Final velocity of the throw, g2dot.
    pub throw_goal_velocity: [f64; JOINTS],
}

impl ThrowDesign {
    /// The designed PA-10 throw that lands at [`INITIAL_LANDING`].
    pub fn pa10() -> Self {
        let s1 = (-135f64).to_radians();
        let planar = |s2: f64, e1: f64, w1: f64| [s1, s2, 0.0, e1, 0.0, w1, 0.0];
        Self {
            rest: planar(-0.4, -0.6, -0.8),
            strike_goal: planar(-0.9, -1.5, -2.0),
            strike_goal_velocity: [0.0; JOINTS],
            throw_goal: planar(-0.3, -0.3, -0.1),
            throw_goal_velocity: [0.0, THROW_SPEED, 0.0, 2.0 * THROW_SPEED, 0.0, 4.0 * THROW_SPEED, 0.0],
        }
    }

    /// theta_0 = (g1, g1dot, g2dot).
    pub fn theta0(&self) -> Vec<f64> {
        [self.strike_goal, self.strike_goal_velocity, self.throw_goal_velocity].concat()
    }
}

/// Why [`ThrowPolicy::new`] refuses a design or control period.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ThrowPolicyCreateError {
    /// The strike-out's or the throw's DMP cannot be built.
    #[error(transparent)]
    Dmp(#[from] DmpCreateError),
    /// The design's own throw (offset 0) does not roll out with this control period.
    #[error(transparent)]
    Trajectory(#[from] ThrowPolicyTrajectoryError),
}

/// Why [`ThrowPolicy::trajectory`] produces no trajectory.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ThrowPolicyTrajectoryError {
    /// An offset of another length than [`PARAMS`].
    #[error("theta must have {expected} entries, got {got}")]
    Length {
        /// [`PARAMS`].
        expected: usize,
        /// The offset's length.
        got: usize,
    },
    /// A DMP refused the goals or diverged.
    #[error(transparent)]
    Rollout(#[from] DmpRolloutError),
    /// The throw does not continue where the strike-out ends.
    #[error(transparent)]
    Chain(#[from] TrajectoryChainError),
}

/// Turns the learner's offsets into joint trajectories.
#[derive(Debug, Clone)]
pub struct ThrowPolicy {
    design: ThrowDesign,
    theta0: Vec<f64>,
    strike: Dmp,
    throw: Dmp,
    control_dt: f64,
}

impl ThrowPolicy {
    /// The policy of `design`, sampled every `control_dt` seconds (0.5 s must be a multiple).
    pub fn new(design: ThrowDesign, control_dt: f64) -> Result<Self, ThrowPolicyCreateError> {
        let config = DmpConfig::default();
        let zero = || DMatrix::zeros(JOINTS, config.n_weights);
        let strike = Dmp::new(JOINTS, STRIKE_DURATION, zero(), config)?;
        let throw = Dmp::new(JOINTS, THROW_DURATION, zero(), config)?;
        // Roll out once so a bad control period is reported here rather than on every throw.
        let policy = Self {
            theta0: design.theta0(),
            design,
            strike,
            throw,
            control_dt,
        };
        policy.trajectory(&[0.0; PARAMS])?;
        Ok(policy)
    }

    /// The designed meta-parameters.
    pub fn design(&self) -> &ThrowDesign {
        &self.design
    }

    /// The control period of the trajectories.
    pub fn control_dt(&self) -> f64 {
        self.control_dt
    }

    /// The joint trajectory of theta_0 + `offset` from t = 0 to the release at t = 1.0 s.
    pub fn trajectory(&self, offset: &[f64]) -> Result<JointTrajectory, ThrowPolicyTrajectoryError> {
        if offset.len() != PARAMS {
            return Err(ThrowPolicyTrajectoryError::Length {
                expected: PARAMS,
                got: offset.len(),
            });
        }
        let theta: Vec<f64> = self.theta0.iter().zip(offset).map(|(a, b)| a + b).collect();
        let (g1, rest) = theta.split_at(JOINTS);
        let (g1dot, g2dot) = rest.split_at(JOINTS);
        let start = DmpState::at_rest(&self.design.rest);
        let (first, junction) = self.strike.rollout(&start, g1, g1dot, self.control_dt)?;
        let (second, _) = self
            .throw
            .rollout(&junction, &self.design.throw_goal, g2dot, self.control_dt)?;
        Ok(chain(&first, &second)?)
    }
}

/// What to do about the PA-10's catalogue joint-speed limits. The paper's targets (3.5-7 m away)
/// need about twice those speeds, so the paper's simulator evidently ignored them. Speeds are
/// checked at the trajectory's samples, so enforcing or penalising needs a fine control period
/// (10 ms or less).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SpeedLimits {
    /// No limit (the default, compatible with the paper).
    Ignore,
    /// A throw exceeding `scale` times a joint's limit at any sample fails.
    Enforce {
        /// Factor on the catalogue limits, > 0.
        scale: f64,
    },
    /// The reward is reduced by `weight` per rad/s by which a joint's peak speed exceeds `scale`
    /// times its limit, summed over the joints.
    Penalise {
        /// Factor on the catalogue limits, > 0.
        scale: f64,
        /// Penalty per rad/s of excess, >= 0.
        weight: f64,
    },
}

impl SpeedLimits {
    /// The summed excess (rad/s) of the peak joint speeds over `scale` times the limits.
    fn excess(robot: &Robot, trajectory: &JointTrajectory, scale: f64) -> f64 {
        robot
            .joints
            .iter()
            .enumerate()
            .map(|(j, joint)| {
                let peak = trajectory.velocities.iter().map(|v| v[j].abs()).fold(0.0, f64::max);
                (peak - scale * joint.max_speed).max(0.0)
            })
            .sum()
    }
}

/// Which simulator a throwing environment uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sim {
    /// Forward kinematics at release and closed-form flight.
    Analytic,
    /// The rapier3d multibody arm.
    Rapier,
}

impl Sim {
    /// The first parameter of a throwing environment's spec: 0 analytic, 1 rapier.
    pub fn parameter(self) -> u64 {
        match self {
            Sim::Analytic => 0,
            Sim::Rapier => 1,
        }
    }

    /// The simulator a spec's first parameter names.
    pub fn from_parameter(parameter: u64) -> Option<Self> {
        [Sim::Analytic, Sim::Rapier]
            .into_iter()
            .find(|sim| sim.parameter() == parameter)
    }
}

/// How the ball's flight is obtained.
#[derive(Debug)]
pub enum Simulator {
    /// The commanded joint state at release, forward kinematics and the Jacobian, then the
    /// closed-form ballistic flight: exact for perfect tracking.
    Analytic,
    /// The rapier3d multibody arm tracks the trajectory with joint motors and releases the ball;
    /// the flight from its release state is closed-form.
    Rapier(Box<RapierArm>),
}

impl Simulator {
    /// Which simulator this is.
    pub fn sim(&self) -> Sim {
        match self {
            Simulator::Analytic => Sim::Analytic,
            Simulator::Rapier(_) => Sim::Rapier,
        }
    }

    fn landing(&mut self, robot: &Robot, trajectory: &JointTrajectory) -> Option<Point> {
        match self {
            Simulator::Analytic => {
                let (q, qd) = trajectory.last()?;
                let (position, velocity) = robot.ball_state(q, qd);
                robot.landing(&position, &velocity)
            }
            Simulator::Rapier(arm) => arm.throw(trajectory).landing,
        }
    }
}

/// The name of a throwing environment at [`Targets::Grid`]; its parameters are
/// [[`Sim::parameter`], 0, 0].
pub const GRID_ENVIRONMENT: &str = "throw-grid";
/// The name of a throwing environment at [`Targets::Dartboard`]; parameters as on the grid.
pub const DARTBOARD_ENVIRONMENT: &str = "throw-dartboard";

/// Which targets the contexts are.
#[derive(Debug, Clone)]
pub enum Targets {
    /// The grid problem: reward -||s - b||^2, score the distance in cm.
    Grid,
    /// The dartboard problem: the contexts are the fields' centres; reward per the paper, score
    /// the distance to the field centre in cm.
    Dartboard(Vec<Field>),
}

/// The throwing environment: context = target, theta = offset on theta_0; the outcome's
/// diagnostics are the landing point (x, y).
pub struct ThrowingEnvironment {
    robot: Robot,
    policy: ThrowPolicy,
    simulator: Simulator,
    targets: Targets,
    speed_limits: SpeedLimits,
    spec: EnvironmentSpec,
}

impl ThrowingEnvironment {
    /// An environment throwing with `policy` on `robot`.
    pub fn new(
        robot: Robot,
        policy: ThrowPolicy,
        simulator: Simulator,
        targets: Targets,
        speed_limits: SpeedLimits,
    ) -> Self {
        let name = match targets {
            Targets::Grid => GRID_ENVIRONMENT,
            Targets::Dartboard(_) => DARTBOARD_ENVIRONMENT,
        };
        // Every part of the environment shapes a throw: the arm, the policy's design and control
        // period, the simulator and its settings (a time step), the targets and the limits.
        let settings = (&robot, &policy, &simulator, &targets, &speed_limits);
        let spec = EnvironmentSpec::new(name, [simulator.sim().parameter(), 0, 0], &settings).expect("a valid name");
        Self {
            robot,
            policy,
            simulator,
            targets,
            speed_limits,
            spec,
        }
    }

    /// Where theta_0 + `offset` lands, or `None` for a failed throw.
    pub fn landing(&mut self, offset: &[f64]) -> Option<Point> {
        let trajectory = self.policy.trajectory(offset).ok()?;
        self.simulator.landing(&self.robot, &trajectory)
    }

    fn field(&self, context: &[f64]) -> Option<&Field> {
        match &self.targets {
            Targets::Grid => None,
            Targets::Dartboard(fields) => fields.iter().find(|f| f.centre[..] == *context),
        }
    }
}

impl Environment for ThrowingEnvironment {
    fn spec(&self) -> EnvironmentSpec {
        self.spec
    }

    fn context_dim(&self) -> usize {
        2
    }

    fn param_dim(&self) -> usize {
        PARAMS
    }

    fn rollout(&mut self, task: &Task) -> Outcome {
        let Ok(trajectory) = self.policy.trajectory(&task.theta) else {
            return Outcome::failed(task.id);
        };
        if task.context.len() != 2 || !trajectory.is_finite() {
            return Outcome::failed(task.id);
        }
        let penalty = match self.speed_limits {
            SpeedLimits::Ignore => 0.0,
            SpeedLimits::Enforce { scale } => {
                if SpeedLimits::excess(&self.robot, &trajectory, scale) > 0.0 {
                    return Outcome::failed(task.id);
                }
                0.0
            }
            SpeedLimits::Penalise { scale, weight } => weight * SpeedLimits::excess(&self.robot, &trajectory, scale),
        };
        let Some(landing) = self.simulator.landing(&self.robot, &trajectory) else {
            return Outcome::failed(task.id);
        };
        let target = [task.context[0], task.context[1]];
        let reward = match &self.targets {
            Targets::Grid => targets::grid_reward(&task.context, landing),
            Targets::Dartboard(_) => match self.field(&task.context) {
                Some(field) => field.reward(landing),
                None => return Outcome::failed(task.id),
            },
        };
        let distance_cm = 100.0 * targets::distance(target, landing);
        Outcome::new(task.id, reward - penalty, distance_cm).with_diagnostics(landing.to_vec())
    }
}

/// The grid problem in `environment` as the learner sees it: 25 training targets, 16 test
/// targets, offsets starting at 0 (W = 0 around theta_0).
pub fn grid_problem(environment: EnvironmentSpec) -> Problem {
    Problem {
        name: "grid".into(),
        training_contexts: targets::grid_training_targets(),
        test_contexts: targets::grid_test_targets(),
        space: ContextSpace::new_box(vec![-5.0; 2], vec![-3.0; 2]).expect("a valid box"),
        theta0: vec![0.0; PARAMS],
        score: ScoreAggregate::Mean,
        metric: "mean distance to the test targets in cm, exploration off".into(),
        environment,
    }
}

/// The dartboard problem for `fields` in `environment`: every field centre is a training and a
/// test context.
pub fn dartboard_problem(fields: &[Field], bull: Point, environment: EnvironmentSpec) -> Problem {
    let centres: Vec<Vec<f64>> = fields.iter().map(|f| f.centre.to_vec()).collect();
    let reach = targets::RING_RADII[4];
    Problem {
        name: "dartboard".into(),
        training_contexts: centres.clone(),
        test_contexts: centres,
        space: ContextSpace::new_box(
            vec![bull[0] - reach, bull[1] - reach],
            vec![bull[0] + reach, bull[1] + reach],
        )
        .expect("a valid box"),
        theta0: vec![0.0; PARAMS],
        score: ScoreAggregate::Mean,
        metric: "mean distance from the field centres in cm over the 81 fields, exploration off".into(),
        environment,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn analytic(targets: Targets) -> ThrowingEnvironment {
        let policy = ThrowPolicy::new(ThrowDesign::pa10(), 0.001).unwrap();
        ThrowingEnvironment::new(Robot::pa10(), policy, Simulator::Analytic, targets, SpeedLimits::Ignore)
    }

    #[test]
    fn the_spec_changes_with_every_setting_that_shapes_a_throw() {
        let robot = Robot::pa10();
        let build = |control_dt: f64, simulator: Simulator, speed_limits: SpeedLimits| {
            let policy = ThrowPolicy::new(ThrowDesign::pa10(), control_dt).unwrap();
            ThrowingEnvironment::new(robot.clone(), policy, simulator, Targets::Grid, speed_limits).spec()
        };
        let rapier = |dt: f64| {
            let config = crate::rapier_sim::RapierConfig {
                dt,
                ..Default::default()
            };
            Simulator::Rapier(Box::new(RapierArm::new(&robot, config).unwrap()))
        };
        let reference = build(0.004, Simulator::Analytic, SpeedLimits::Ignore);
        assert_eq!(reference, build(0.004, Simulator::Analytic, SpeedLimits::Ignore));
        assert_eq!(
            (reference.name(), reference.parameters()),
            (GRID_ENVIRONMENT, [0, 0, 0])
        );
        let enforced = build(0.004, Simulator::Analytic, SpeedLimits::Enforce { scale: 2.0 });
        let on_rapier = build(0.004, rapier(0.008), SpeedLimits::Ignore);
        assert_eq!(on_rapier.parameters(), [Sim::Rapier.parameter(), 0, 0]);
        for other in [
            build(0.002, Simulator::Analytic, SpeedLimits::Ignore),
            enforced,
            on_rapier,
        ] {
            assert_ne!(other, reference);
        }
        // Another time step of the physics: the same name and parameters, other settings.
        let finer = build(0.004, rapier(0.004), SpeedLimits::Ignore);
        assert_eq!(
            (finer.name(), finer.parameters()),
            (on_rapier.name(), on_rapier.parameters())
        );
        assert_ne!(finer.settings(), on_rapier.settings());
        assert_eq!(
            analytic(Targets::Dartboard(vec![])).spec().name(),
            DARTBOARD_ENVIRONMENT
        );
    }

    #[test]
    fn theta0_lands_at_the_papers_initial_point() {
        let mut env = analytic(Targets::Grid);
        let landing = env.landing(&[0.0; PARAMS]).unwrap();
        let error = targets::distance(landing, INITIAL_LANDING);
        assert!(
            error < 0.002,
            "theta_0 lands at {landing:?}, {error} m from (-3.55, -3.55)"
        );
    }

    #[test]
    fn offsets_move_the_landing_and_the_throw_is_deterministic() {
        let mut env = analytic(Targets::Grid);
        let base = env.landing(&[0.0; PARAMS]).unwrap();
        let mut faster = [0.0; PARAMS];
        faster[2 * JOINTS + 3] = 0.3; // more elbow speed at release
        let far = env.landing(&faster).unwrap();
        assert!(targets::distance(far, [0.0, 0.0]) > targets::distance(base, [0.0, 0.0]) + 0.1);
        // g2 is fixed, so aiming sideways takes S1's release velocity (its g2dot).
        let mut turned = [0.0; PARAMS];
        turned[2 * JOINTS] = 0.5;
        let side = env.landing(&turned).unwrap();
        assert!(targets::distance(side, base) > 0.15);
        let radial = |p: Point| targets::distance(p, [0.0, 0.0]);
        assert!(
            (radial(side) - radial(base)).abs() < 0.5 * targets::distance(side, base),
            "mostly sideways"
        );
        assert_eq!(env.landing(&faster).unwrap(), far);
    }

    #[test]
    fn failed_throws_are_flagged_not_nan() {
        let mut env = analytic(Targets::Grid);
        let task = |theta: Vec<f64>| Task {
            id: 1,
            kind: acps_shared::TaskKind::Train,
            seed: 0,
            context: vec![-4.0, -4.0],
            theta,
        };
        assert!(!env.rollout(&task(vec![f64::NAN; PARAMS])).is_ok());
        assert!(!env.rollout(&task(vec![0.0; 3])).is_ok());
        // A throw straight into the ground from below: lands nowhere sensible but must be finite or failed.
        let outcome = env.rollout(&task(vec![1e6; PARAMS]));
        assert!(!outcome.is_ok() || outcome.reward.is_finite());
        let ok = env.rollout(&task(vec![0.0; PARAMS]));
        assert!(ok.is_ok() && ok.reward < 0.0 && ok.diagnostics.len() == 2);
    }

    #[test]
    fn speed_limits_enforce_and_penalise() {
        let robot = Robot::pa10();
        let policy = ThrowPolicy::new(ThrowDesign::pa10(), 0.001).unwrap();
        let trajectory = policy.trajectory(&[0.0; PARAMS]).unwrap();
        // The designed throw needs about twice the catalogue speeds.
        assert!(SpeedLimits::excess(&robot, &trajectory, 1.0) > 0.5);
        assert_eq!(SpeedLimits::excess(&robot, &trajectory, 3.0), 0.0);
        let task = Task {
            id: 0,
            kind: acps_shared::TaskKind::Train,
            seed: 0,
            context: vec![-3.5, -3.5],
            theta: vec![0.0; PARAMS],
        };
        let mut enforce = ThrowingEnvironment::new(
            robot.clone(),
            policy.clone(),
            Simulator::Analytic,
            Targets::Grid,
            SpeedLimits::Enforce { scale: 1.0 },
        );
        assert!(!enforce.rollout(&task).is_ok());
        let mut penalise = ThrowingEnvironment::new(
            robot,
            policy,
            Simulator::Analytic,
            Targets::Grid,
            SpeedLimits::Penalise {
                scale: 1.0,
                weight: 10.0,
            },
        );
        let ignore = analytic(Targets::Grid).rollout(&task);
        assert!(penalise.rollout(&task).reward < ignore.reward - 5.0);
    }

    #[test]
    fn rapier_agrees_with_the_analytic_oracle_near_theta0() {
        use crate::rapier_sim::RapierConfig;
        use rand::{Rng, SeedableRng};
        let robot = Robot::pa10();
        let arm = RapierArm::new(&robot, RapierConfig::default()).unwrap();
        let policy = ThrowPolicy::new(ThrowDesign::pa10(), 0.004).unwrap();
        let mut rapier = ThrowingEnvironment::new(
            robot,
            policy,
            Simulator::Rapier(Box::new(arm)),
            Targets::Grid,
            SpeedLimits::Ignore,
        );
        let mut oracle = analytic(Targets::Grid);
        // 1000 offsets with the learner's initial exploration (Sigma_0 = 0.02 I, std 0.14).
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let mut differences: Vec<f64> = (0..1000)
            .map(|_| {
                let offset: Vec<f64> = (0..PARAMS)
                    .map(|_| 0.14 * rng.sample::<f64, _>(rand_distr::StandardNormal))
                    .collect();
                targets::distance(rapier.landing(&offset).unwrap(), oracle.landing(&offset).unwrap())
            })
            .collect();
        differences.sort_by(f64::total_cmp);
        let (median, p99, max) = (differences[500], differences[990], differences[999]);
        println!("rapier vs oracle over 1000 throws: median {median:.2e} m, 99% {p99:.2e} m, max {max:.2e} m");
        assert!(max < 0.02, "max {max}");
        assert!(median < 1e-3, "median {median}");
    }

    #[test]
    fn dartboard_rewards_use_the_field_of_the_context() {
        let fields = targets::dartboard(INITIAL_LANDING);
        let mut env = analytic(Targets::Dartboard(fields.clone()));
        let task = |context: Point| Task {
            id: 0,
            kind: acps_shared::TaskKind::Train,
            seed: 0,
            context: context.to_vec(),
            theta: vec![0.0; PARAMS],
        };
        // theta_0 lands (within 2 cm) on the bull.
        let bull = env.rollout(&task(fields[0].centre));
        assert!(bull.is_ok() && bull.reward > -10_000.0 * 0.02 / fields[0].region_radius - 1.0);
        // A double is out of reach of theta_0: the constant miss reward.
        let double = fields.iter().find(|f| f.category == targets::Category::Double).unwrap();
        assert_eq!(env.rollout(&task(double.centre)).reward, targets::MISS_REWARD);
        assert!(!env.rollout(&task([0.0, 0.0])).is_ok(), "a context that is no field");
        let problem = dartboard_problem(&fields, INITIAL_LANDING, env.spec());
        assert_eq!((problem.training_contexts.len(), problem.theta0.len()), (81, PARAMS));
    }
}
