//! Physical simulation of a throw: the arm of a [`Robot`] as a reduced-coordinate multibody in
//! rapier3d (f64), tracking a commanded [`JointTrajectory`] with joint motors and releasing the
//! ball at the trajectory's last sample.
//!
//! Model: a fixed base, one dynamic link per joint with the mass, centre of mass and principal
//! inertia from the robot file (no colliders on the links), revolute multibody joints at the
//! file's axis points, and the ball as the last multibody link on a fixed joint at the tool offset.
//! A ground plane has its top at z = 0. Gravity is -z.
//!
//! Servo: every joint motor is a velocity servo with position feedback (rapier's
//! acceleration-based motor, [`RapierConfig::motor_stiffness`] and [`RapierConfig::motor_damping`]).
//! The commanded trajectory is interpolated (cubic Hermite on its positions and velocities) at the
//! simulation steps, and the motors follow a plan of setpoints that the simulation's integrator
//! can represent exactly: during a step the feed-forward velocity is the setpoints' difference
//! quotient, and the last two setpoints are chosen so that the plan reaches the commanded release
//! position with the commanded release velocity. A perfect servo therefore releases the ball at
//! exactly the commanded state; what remains is the physical tracking error of the motors under
//! gravity, inertia and coupling, and the solver's convergence.
//!
//! Release: after the step that reaches the last sample's time, the ball's fixed joint is removed.
//! Its release position is the ball body's pose in rapier; its release velocity is the ball
//! Jacobian of the robot at the simulated joint angles times the simulated joint velocities
//! (the same physical state; rapier's link velocities lag by one step, see
//! [`ThrowOutcome::release_velocity`]). The flight is the closed-form drag-free parabola
//! ([`Robot::landing`]): stepping the arm after release would double the cost without changing
//! the landing.

use crate::robot::Robot;
use crate::trajectory::JointTrajectory;
use crate::{InvalidArgument, check};
use nalgebra::{DVector, Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use rapier3d_f64::prelude::{
    ColliderBuilder, FixedJointBuilder, JointAxis, MassProperties, MultibodyJointHandle, PhysicsWorld, RevoluteJoint,
    RevoluteJointBuilder, RigidBodyBuilder, RigidBodyHandle,
};
use serde::{Deserialize, Serialize};

/// The most simulation steps a throw may take (a 1 s throw takes 125 at the default `dt`).
pub const MAX_STEPS: usize = 100_000;

/// The rapier vector type (glam `DVec3`).
type RVector = rapier3d_f64::math::Vector;

fn to_rapier(v: &Vector3<f64>) -> RVector {
    RVector::new(v.x, v.y, v.z)
}

fn from_rapier(v: RVector) -> Vector3<f64> {
    Vector3::new(v.x, v.y, v.z)
}

/// Settings of the physical simulation.
///
/// The defaults (dt 8 ms, 32 solver iterations, stiffness 1e10, damping 1e7) take about 2 ms per
/// 1 s throw on one core and land within 0.2 mm of the analytic oracle (see the module tests).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RapierConfig {
    /// Simulation and servo step (s). The release time is divided into equal steps of at most
    /// this length. The cost of a throw is about proportional to the number of steps.
    pub dt: f64,
    /// Gauss-Seidel sweeps of the constraint solver over the joint motors per step (rapier's
    /// `num_internal_pgs_iterations`). The motors are coupled through the arm's mass matrix, so
    /// few sweeps leave each step's joint velocities short of their targets; the shortfall
    /// shrinks about tenfold per 8 sweeps, at about 1 % of a step's cost per sweep. Rapier's
    /// substeps (`num_solver_iterations`) stay at 1: each substep would re-evaluate the motors'
    /// position error against a target meant for the start of the step, and costs a full
    /// recomputation of the arm's mass matrix; a finer time resolution is a smaller `dt`.
    pub solver_iterations: usize,
    /// Motor stiffness k (1/s^2, rapier's acceleration-based motor model). In a step of length h,
    /// a motor drives its joint to the velocity `v + k / (k h + c) (p - q)`, where q is the joint
    /// angle at the start of the step, p and v the setpoint and feed-forward velocity of the plan;
    /// the constraint's compliance is `1 / (k h^2 + c h)`. Stiff values make a near-ideal servo.
    pub motor_stiffness: f64,
    /// Motor damping c (1/s, rapier's acceleration-based motor model); see `motor_stiffness`.
    pub motor_damping: f64,
    /// A joint further than this from the commanded trajectory (rad) marks the throw as exploded.
    pub max_tracking_error: f64,
    /// A release speed of the ball above this (m/s) marks the throw as exploded.
    pub max_release_speed: f64,
}

impl Default for RapierConfig {
    fn default() -> Self {
        Self {
            dt: 0.008,
            solver_iterations: 32,
            motor_stiffness: 1e10,
            motor_damping: 1e7,
            max_tracking_error: 0.5,
            max_release_speed: 100.0,
        }
    }
}

impl RapierConfig {
    /// Check every field against its accepted range.
    pub fn validate(&self) -> Result<(), RapierArmCreateError> {
        check(
            self.dt.is_finite() && self.dt >= 1e-5 && self.dt <= 0.02,
            "dt",
            "in [1e-5, 0.02] s",
            self.dt,
        )?;
        check(
            (1..=1000).contains(&self.solver_iterations),
            "solver_iterations",
            "in 1..=1000",
            self.solver_iterations,
        )?;
        check(
            self.motor_stiffness.is_finite() && self.motor_stiffness >= 0.0,
            "motor_stiffness",
            "finite and >= 0",
            self.motor_stiffness,
        )?;
        check(
            self.motor_damping.is_finite() && self.motor_damping >= 0.0,
            "motor_damping",
            "finite and >= 0",
            self.motor_damping,
        )?;
        check(
            self.motor_stiffness + self.motor_damping > 0.0,
            "motor_damping",
            "> 0 when motor_stiffness is 0",
            self.motor_damping,
        )?;
        check(
            self.max_tracking_error.is_finite() && self.max_tracking_error > 0.0,
            "max_tracking_error",
            "finite and > 0",
            self.max_tracking_error,
        )?;
        check(
            self.max_release_speed.is_finite() && self.max_release_speed > 0.0,
            "max_release_speed",
            "finite and > 0",
            self.max_release_speed,
        )?;
        Ok(())
    }
}

/// Why [`RapierArm::new`] (or [`RapierConfig::validate`]) refuses its configuration or robot.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("rapier: {0}")]
pub struct RapierArmCreateError(#[from] pub InvalidArgument);

/// Why a throw failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ThrowFailure {
    /// The trajectory cannot be tracked: empty, wrong number of joints, bad `dt` or non-finite
    /// values.
    #[error("invalid trajectory: {0}")]
    InvalidTrajectory(String),
    /// The simulated state became NaN or infinite.
    #[error("non-finite simulation state at t = {time} s")]
    NonFinite {
        /// Simulated time (s).
        time: f64,
    },
    /// The arm left the commanded trajectory by more than
    /// [`RapierConfig::max_tracking_error`], or the ball was released faster than
    /// [`RapierConfig::max_release_speed`].
    #[error("the simulation exploded at t = {time} s: {what}")]
    Exploded {
        /// Simulated time (s).
        time: f64,
        /// What exceeded its bound.
        what: String,
    },
    /// The ball was released below the ground, or never comes down to it.
    #[error("the ball never lands: {0}")]
    NoLanding(String),
}

/// Whether a throw's outcome can be used.
#[derive(Debug, Clone, PartialEq)]
pub enum ThrowStatus {
    /// The simulation ran and the ball lands at [`ThrowOutcome::landing`].
    Ok,
    /// The throw has no valid landing.
    Failed(ThrowFailure),
}

/// The result of one simulated throw.
#[derive(Debug, Clone, PartialEq)]
pub struct ThrowOutcome {
    /// Ok, or why the throw failed.
    pub status: ThrowStatus,
    /// Where the ball centre comes down to the height of its radius (m); `Some` exactly when the
    /// status is Ok.
    pub landing: Option<[f64; 2]>,
    /// Release time (s), the time of the trajectory's last sample.
    pub release_time: f64,
    /// Ball centre at release (m), from rapier's ball body. NaN if the simulation did not get
    /// that far.
    pub release_position: Vector3<f64>,
    /// Ball centre velocity at release (m/s): the robot's ball Jacobian at the simulated joint
    /// angles times the simulated joint velocities. (Rapier's own body velocity after a step is
    /// the Jacobian at the step's *start* angles times the new joint velocities; it differs by
    /// O(dt).) NaN if the simulation did not get that far.
    pub release_velocity: Vector3<f64>,
    /// Simulated joint angles at release (rad); NaN if the simulation did not get that far.
    pub release_joint_positions: Vec<f64>,
    /// Simulated joint velocities at release (rad/s); NaN if the simulation did not get that far.
    pub release_joint_velocities: Vec<f64>,
    /// Largest |simulated - commanded| joint angle at the ends of the steps, over all joints
    /// (rad), up to release or failure. It includes the plan's own deviation of h^2 qdd / 2 one
    /// step before release.
    pub max_tracking_error: f64,
}

impl ThrowOutcome {
    /// True when the status is Ok.
    pub fn is_ok(&self) -> bool {
        self.status == ThrowStatus::Ok
    }

    fn failed(failure: ThrowFailure, release_time: f64, dof: usize, max_tracking_error: f64) -> Self {
        Self {
            status: ThrowStatus::Failed(failure),
            landing: None,
            release_time,
            release_position: Vector3::repeat(f64::NAN),
            release_velocity: Vector3::repeat(f64::NAN),
            release_joint_positions: vec![f64::NAN; dof],
            release_joint_velocities: vec![f64::NAN; dof],
            max_tracking_error,
        }
    }
}

/// The rapier world of one arm and its handles.
struct ArmWorld {
    world: PhysicsWorld,
    /// The multibody joint of every arm link, base to tool; its handle also names the multibody.
    joints: Vec<MultibodyJointHandle>,
    /// The ball body.
    ball: RigidBodyHandle,
    /// The ball's fixed joint while the ball is held.
    ball_joint: Option<MultibodyJointHandle>,
}

/// The rapier joint of one arm joint: a revolute joint about the robot's axis at its origin.
fn revolute(origin: &Vector3<f64>, axis: &Vector3<f64>) -> RevoluteJoint {
    RevoluteJointBuilder::new(to_rapier(axis))
        .local_anchor1(to_rapier(origin))
        .local_anchor2(RVector::ZERO)
        .build()
}

impl ArmWorld {
    fn build(robot: &Robot, config: &RapierConfig) -> Result<Self, RapierArmCreateError> {
        let mut world = PhysicsWorld::new();
        world.gravity = RVector::new(0.0, 0.0, -robot.gravity);
        let params = &mut world.integration_parameters;
        params.dt = config.dt;
        params.num_solver_iterations = 1;
        params.num_internal_pgs_iterations = config.solver_iterations;
        // Nothing collides: no CCD.
        params.max_ccd_substeps = 0;
        world.physics_pipeline.counters.disable();

        // The ground: a fixed slab whose top face is z = 0.
        world.insert(
            RigidBodyBuilder::fixed().translation(RVector::new(0.0, 0.0, -0.5)),
            ColliderBuilder::cuboid(100.0, 100.0, 0.5),
        );
        let base = world.insert_body(
            RigidBodyBuilder::fixed().additional_mass_properties(MassProperties::new(
                to_rapier(&robot.base_com),
                robot.base_mass,
                RVector::ZERO,
            )),
        );
        // Zero pose: every joint frame is aligned with the world frame, at its axis point.
        let mut parent = base;
        let mut position = Vector3::zeros();
        let mut joints = Vec::with_capacity(robot.dof());
        for joint in &robot.joints {
            position += joint.origin;
            let link = &joint.link;
            let body = world.insert_body(
                RigidBodyBuilder::dynamic()
                    .translation(to_rapier(&position))
                    .can_sleep(false)
                    .additional_mass_properties(MassProperties::new(
                        to_rapier(&link.com),
                        link.mass,
                        to_rapier(&link.inertia),
                    )),
            );
            let handle = world
                .insert_multibody_joint(parent, body, revolute(&joint.origin, &joint.axis))
                .ok_or_else(|| invalid_robot("joints", "a serial chain", &joint.name))?;
            joints.push(handle);
            parent = body;
        }
        let ball_inertia = 0.4 * robot.ball.mass * robot.ball.radius * robot.ball.radius;
        let ball = world.insert_body(
            RigidBodyBuilder::dynamic()
                .translation(to_rapier(&(position + robot.tool_offset)))
                .can_sleep(false)
                .additional_mass_properties(MassProperties::new(
                    RVector::ZERO,
                    robot.ball.mass,
                    RVector::splat(ball_inertia),
                )),
        );
        let mut arm = Self {
            world,
            joints,
            ball,
            ball_joint: None,
        };
        arm.attach_ball(robot)?;
        let world = &mut arm.world;
        let (multibody, _) = world
            .multibody_joints
            .get_mut(*arm.joints.last().expect("at least one joint"))
            .expect("inserted");
        // Turns the root's free joint into a fixed one (the base is fixed): 7 generalized coordinates.
        multibody.forward_kinematics(&world.bodies, true);
        if multibody.ndofs() != robot.dof() {
            return Err(invalid_robot(
                "joints",
                "one degree of freedom each",
                &multibody.ndofs().to_string(),
            ));
        }
        // No artificial joint damping: the motors are the only joint forces.
        multibody.damping_mut().fill(0.0);
        Ok(arm)
    }

    fn attach_ball(&mut self, robot: &Robot) -> Result<(), RapierArmCreateError> {
        let last = self.last_link_body();
        let joint = FixedJointBuilder::new()
            .local_anchor1(to_rapier(&robot.tool_offset))
            .local_anchor2(RVector::ZERO);
        let handle = self
            .world
            .insert_multibody_joint(last, self.ball, joint)
            .ok_or_else(|| invalid_robot("tool", "attachable to the last link", "ball"))?;
        self.ball_joint = Some(handle);
        Ok(())
    }

    /// The multibody link id of every arm joint, base to tool.
    fn link_ids(&self) -> Vec<usize> {
        self.joints
            .iter()
            .map(|h| {
                self.world
                    .multibody_joints
                    .get(*h)
                    .expect("the arm's joints stay inserted")
                    .1
            })
            .collect()
    }

    fn last_link_body(&self) -> RigidBodyHandle {
        let (multibody, link) = self.multibody();
        multibody
            .link(link)
            .expect("link of a stored handle")
            .rigid_body_handle()
    }

    /// The multibody and the link id of the last arm joint.
    fn multibody(&self) -> (&rapier3d_f64::prelude::Multibody, usize) {
        let last = *self.joints.last().expect("at least one joint");
        self.world
            .multibody_joints
            .get(last)
            .expect("the arm's joints stay inserted")
    }
}

fn invalid_robot(field: &'static str, accepted: &'static str, got: &str) -> RapierArmCreateError {
    RapierArmCreateError(InvalidArgument::OutOfRange {
        name: field,
        accepted,
        got: got.to_string(),
    })
}

/// Positions and velocities of a trajectory at any time in its span, by cubic Hermite
/// interpolation between its samples (exact at the samples).
struct Reference<'a> {
    trajectory: &'a JointTrajectory,
}

impl Reference<'_> {
    fn at(&self, time: f64, q: &mut [f64], qd: &mut [f64]) {
        let tr = self.trajectory;
        let last = tr.len() - 1;
        let x = time / tr.dt;
        if last == 0 || x <= 0.0 {
            q.copy_from_slice(&tr.positions[0]);
            qd.copy_from_slice(&tr.velocities[0]);
            return;
        }
        if x >= last as f64 {
            q.copy_from_slice(&tr.positions[last]);
            qd.copy_from_slice(&tr.velocities[last]);
            return;
        }
        let i = (x.floor() as usize).min(last - 1);
        let s = x - i as f64;
        if s == 0.0 {
            q.copy_from_slice(&tr.positions[i]);
            qd.copy_from_slice(&tr.velocities[i]);
            return;
        }
        let (s2, s3) = (s * s, s * s * s);
        let (h00, h10, h01, h11) = (
            2.0 * s3 - 3.0 * s2 + 1.0,
            s3 - 2.0 * s2 + s,
            -2.0 * s3 + 3.0 * s2,
            s3 - s2,
        );
        let (d00, d10, d01, d11) = (
            6.0 * s2 - 6.0 * s,
            3.0 * s2 - 4.0 * s + 1.0,
            -6.0 * s2 + 6.0 * s,
            3.0 * s2 - 2.0 * s,
        );
        let dt = tr.dt;
        let (p0, p1, v0, v1) = (
            &tr.positions[i],
            &tr.positions[i + 1],
            &tr.velocities[i],
            &tr.velocities[i + 1],
        );
        for k in 0..q.len() {
            q[k] = h00 * p0[k] + h10 * dt * v0[k] + h01 * p1[k] + h11 * dt * v1[k];
            qd[k] = (d00 * p0[k] + d01 * p1[k]) / dt + d10 * v0[k] + d11 * v1[k];
        }
    }
}

/// A simulated PA-10 (or any serial arm from a robot file) that throws a ball.
pub struct RapierArm {
    robot: Robot,
    config: RapierConfig,
    /// The world: freshly built, or in the state the last throw left it (ball released).
    arm: ArmWorld,
    /// True while `arm` has not simulated a throw yet.
    fresh: bool,
}

impl std::fmt::Debug for RapierArm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RapierArm")
            .field("robot", &self.robot.name)
            .field("config", &self.config)
            .finish_non_exhaustive()
    }
}

impl RapierArm {
    /// Build the simulated arm of `robot`.
    pub fn new(robot: &Robot, config: RapierConfig) -> Result<Self, RapierArmCreateError> {
        config.validate()?;
        let arm = ArmWorld::build(robot, &config)?;
        Ok(Self {
            robot: robot.clone(),
            config,
            arm,
            fresh: true,
        })
    }

    /// The robot being simulated.
    pub fn robot(&self) -> &Robot {
        &self.robot
    }

    /// The simulation settings.
    pub fn config(&self) -> &RapierConfig {
        &self.config
    }

    fn check_trajectory(&self, trajectory: &JointTrajectory) -> Result<(), String> {
        let dof = self.robot.dof();
        if trajectory.is_empty() {
            return Err("no samples".into());
        }
        if trajectory.velocities.len() != trajectory.len() {
            return Err(format!(
                "{} position samples but {} velocity samples",
                trajectory.len(),
                trajectory.velocities.len()
            ));
        }
        if let Some(row) = trajectory
            .positions
            .iter()
            .chain(&trajectory.velocities)
            .find(|row| row.len() != dof)
        {
            return Err(format!("a sample has {} joints, the robot {dof}", row.len()));
        }
        if !(trajectory.dt.is_finite() && trajectory.dt > 0.0) {
            return Err(format!("dt must be finite and > 0, got {}", trajectory.dt));
        }
        if !trajectory.is_finite() {
            return Err("non-finite positions or velocities".into());
        }
        let steps = trajectory.duration() / self.config.dt;
        if steps > MAX_STEPS as f64 {
            return Err(format!(
                "a release at t = {} s takes more than {MAX_STEPS} steps of {} s",
                trajectory.duration(),
                self.config.dt
            ));
        }
        Ok(())
    }

    /// Simulate one throw: start at the trajectory's first sample, track it, release the ball at
    /// its last sample's time and return where the ball lands. Never panics on bad input; a
    /// failed simulation yields [`ThrowStatus::Failed`] and no landing.
    pub fn throw(&mut self, trajectory: &JointTrajectory) -> ThrowOutcome {
        let dof = self.robot.dof();
        if let Err(reason) = self.check_trajectory(trajectory) {
            let time = trajectory.duration();
            return ThrowOutcome::failed(ThrowFailure::InvalidTrajectory(reason), time, dof, 0.0);
        }
        // A fresh world for every throw: the same trajectory gives the same bits, whatever was
        // thrown before. Building costs about 15 us, under 1 % of a throw; resetting a used world
        // instead measured no faster.
        if !self.fresh {
            match ArmWorld::build(&self.robot, &self.config) {
                Ok(arm) => self.arm = arm,
                Err(e) => unreachable!("the same robot built in RapierArm::new: {e}"),
            }
        }
        self.fresh = false;
        simulate(&self.robot, &self.config, &mut self.arm, trajectory)
    }

    /// The simulated joint angles (rad): the initial pose of a fresh arm, or the release pose
    /// after a throw.
    pub fn joint_positions(&self) -> Vec<f64> {
        let link_ids = self.arm.link_ids();
        let mut q = vec![0.0; link_ids.len()];
        let mut qd = vec![0.0; link_ids.len()];
        read_joints(&self.arm, &link_ids, &mut q, &mut qd);
        q
    }

    /// World poses of the rapier bodies: one per link, base to tool, in its joint's frame (the
    /// frames of [`Robot::frames`]), then the ball.
    pub fn link_poses(&self) -> Vec<Isometry3<f64>> {
        let (multibody, _) = self.arm.multibody();
        let mut bodies: Vec<RigidBodyHandle> = self
            .arm
            .link_ids()
            .iter()
            .map(|&id| multibody.link(id).expect("link of the arm").rigid_body_handle())
            .collect();
        bodies.push(self.arm.ball);
        bodies
            .iter()
            .map(|&handle| {
                let pose = self.arm.world.bodies[handle].position();
                let r = pose.rotation;
                Isometry3::from_parts(
                    Translation3::from(from_rapier(pose.translation)),
                    UnitQuaternion::new_normalize(Quaternion::new(r.w, r.x, r.y, r.z)),
                )
            })
            .collect()
    }
}

/// Equal steps of at most `dt` that end exactly at `release_time`: their number and length.
fn step_plan(release_time: f64, dt: f64) -> (usize, f64) {
    if release_time > 0.0 {
        // The factor keeps a release time that is a multiple of dt from gaining a tiny step.
        let steps = ((release_time / dt) * (1.0 - 1e-12)).ceil().max(1.0) as usize;
        (steps, release_time / steps as f64)
    } else {
        (0, 0.0)
    }
}

fn simulate(robot: &Robot, config: &RapierConfig, arm: &mut ArmWorld, trajectory: &JointTrajectory) -> ThrowOutcome {
    let dof = robot.dof();
    let release_time = trajectory.duration();
    let reference = Reference { trajectory };
    let (steps, h) = step_plan(release_time, config.dt);
    arm.world.integration_parameters.dt = h;
    let link_ids = arm.link_ids();
    let last_joint = *arm.joints.last().expect("at least one joint");

    // Initial state: the first sample (the world is fresh: every joint coordinate is 0).
    let (q0, qd0) = (&trajectory.positions[0], &trajectory.velocities[0]);
    {
        let world = &mut arm.world;
        let (multibody, _) = world.multibody_joints.get_mut(last_joint).expect("inserted");
        let mut displacement = vec![0.0; multibody.ndofs()];
        let mut velocity = vec![0.0; multibody.ndofs()];
        for (i, &link_id) in link_ids.iter().enumerate() {
            let at = multibody.link(link_id).expect("link of the arm").assembly_id();
            displacement[at] = q0[i];
            velocity[at] = qd0[i];
        }
        multibody.apply_displacements(&displacement);
        multibody.generalized_velocity_mut().copy_from_slice(&velocity);
        multibody.forward_kinematics(&world.bodies, true);
        multibody.update_rigid_bodies(&mut world.bodies, true);
    }

    // The plan: setpoints P_j at t_j = j h, and the velocity (P_j - P_{j-1}) / h that moves the
    // arm from one to the next in a step of rapier's (symplectic Euler) integrator. P_j is the
    // commanded position, except that P_{N-1} = q(T) - h qd(T), so that the last step ends at
    // the commanded release position with the commanded release velocity.
    let (q_end, qd_end) = trajectory.last().expect("not empty");
    let setpoint = |j: usize, out: &mut [f64], scratch: &mut [f64]| {
        if j == steps {
            out.copy_from_slice(q_end);
        } else if j + 1 == steps {
            for ((p, q), qd) in out.iter_mut().zip(q_end).zip(qd_end) {
                *p = q - h * qd;
            }
        } else if j == 0 {
            out.copy_from_slice(q0);
        } else {
            reference.at(j as f64 * h, out, scratch);
        }
    };
    let (mut previous, mut next, mut scratch) = (vec![0.0; dof], vec![0.0; dof], vec![0.0; dof]);
    let (mut q_ref, mut qd_ref) = (vec![0.0; dof], vec![0.0; dof]);
    let (mut q, mut qd) = (q0.clone(), qd0.clone());
    setpoint(0, &mut previous, &mut scratch);
    let (k, c) = (config.motor_stiffness, config.motor_damping);
    let mut max_error: f64 = 0.0;

    for j in 1..=steps {
        setpoint(j, &mut next, &mut scratch);
        {
            let (multibody, _) = arm.world.multibody_joints.get_mut(last_joint).expect("inserted");
            for (i, &link_id) in link_ids.iter().enumerate() {
                // Rapier's motor asks for the velocity target_vel + erp (target_pos - q) at the end
                // of the step, q being the angle at its start (erp = k / (h k + c)). The last step's
                // feed-forward is the commanded release velocity itself (the difference quotient
                // equals it up to rounding).
                let target_vel = if j == steps {
                    qd_end[i]
                } else {
                    (next[i] - previous[i]) / h
                };
                let link = multibody.link_mut(link_id).expect("link of the arm");
                link.joint
                    .data
                    .set_motor(JointAxis::AngX, previous[i], target_vel, k, c);
            }
        }
        arm.world.step();
        std::mem::swap(&mut previous, &mut next);

        let time = j as f64 * h;
        read_joints(arm, &link_ids, &mut q, &mut qd);
        if !(q.iter().chain(&qd).all(|v| v.is_finite()) && arm.world.quarantine().is_empty()) {
            return ThrowOutcome::failed(ThrowFailure::NonFinite { time }, release_time, dof, max_error);
        }
        reference.at(time, &mut q_ref, &mut qd_ref);
        let error = q
            .iter()
            .zip(&q_ref)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, |max: f64, e| if e.is_nan() { f64::INFINITY } else { max.max(e) });
        max_error = max_error.max(error);
        if error > config.max_tracking_error {
            let what = format!("tracking error {error:.3e} rad > {} rad", config.max_tracking_error);
            return ThrowOutcome::failed(ThrowFailure::Exploded { time, what }, release_time, dof, max_error);
        }
    }

    // Release: read the state the last step reached, then let go of the ball.
    read_joints(arm, &link_ids, &mut q, &mut qd);
    let position = from_rapier(arm.world.bodies[arm.ball].translation());
    if let Some(joint) = arm.ball_joint.take() {
        arm.world.remove_multibody_joint(joint);
    }
    let velocity = robot.ball_jacobian(&q) * DVector::from_column_slice(&qd);
    let mut outcome = ThrowOutcome {
        status: ThrowStatus::Ok,
        landing: None,
        release_time,
        release_position: position,
        release_velocity: velocity,
        release_joint_positions: q,
        release_joint_velocities: qd,
        max_tracking_error: max_error,
    };
    let speed = velocity.norm();
    let failure = if !position.iter().chain(velocity.iter()).all(|v| v.is_finite()) {
        Some(ThrowFailure::NonFinite { time: release_time })
    } else if speed > config.max_release_speed {
        let what = format!("release speed {speed:.3e} m/s > {} m/s", config.max_release_speed);
        Some(ThrowFailure::Exploded {
            time: release_time,
            what,
        })
    } else if position.z < robot.ball.radius {
        let why = format!("released with its centre at z = {:.3} m, inside the ground", position.z);
        Some(ThrowFailure::NoLanding(why))
    } else {
        match robot.landing(&position, &velocity) {
            Some(landing) if landing.iter().all(|v| v.is_finite()) => {
                outcome.landing = Some(landing);
                None
            }
            _ => Some(ThrowFailure::NoLanding("no finite landing point".into())),
        }
    };
    if let Some(failure) = failure {
        outcome.status = ThrowStatus::Failed(failure);
    }
    outcome
}

fn read_joints(arm: &ArmWorld, link_ids: &[usize], q: &mut [f64], qd: &mut [f64]) {
    let last = *arm.joints.last().expect("at least one joint");
    let (multibody, _) = arm.world.multibody_joints.get(last).expect("inserted");
    let velocities = multibody.generalized_velocity();
    for (i, &link_id) in link_ids.iter().enumerate() {
        let link = multibody.link(link_id).expect("link of the arm");
        // The revolute angle is the joint's first angular coordinate (AngX), not wrapped.
        q[i] = link.joint().coords()[3];
        qd[i] = velocities[link.assembly_id()];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Coefficients of the quintic from (p0, v0, a0) to (p1, v1, a1) over `d`.
    fn quintic(start: [f64; 3], end: [f64; 3], d: f64) -> [f64; 6] {
        let [p0, v0, a0] = start;
        let [p1, v1, a1] = end;
        let (c0, c1, c2) = (p0, v0, a0 / 2.0);
        let r0 = p1 - (c0 + c1 * d + c2 * d * d);
        let r1 = v1 - (c1 + 2.0 * c2 * d);
        let r2 = a1 - 2.0 * c2;
        let c3 = (10.0 * r0 - 4.0 * r1 * d + 0.5 * r2 * d * d) / d.powi(3);
        let c4 = (-15.0 * r0 + 7.0 * r1 * d - r2 * d * d) / d.powi(4);
        let c5 = (6.0 * r0 - 3.0 * r1 * d + 0.5 * r2 * d * d) / d.powi(5);
        [c0, c1, c2, c3, c4, c5]
    }

    fn evaluate(c: &[f64; 6], t: f64) -> (f64, f64) {
        let p = c[0] + t * (c[1] + t * (c[2] + t * (c[3] + t * (c[4] + t * c[5]))));
        let v = c[1] + t * (2.0 * c[2] + t * (3.0 * c[3] + t * (4.0 * c[4] + t * 5.0 * c[5])));
        (p, v)
    }

    /// A throw: from rest at `start` to rest at `wind_up` over 0-0.5 s, then to `release` with
    /// `release_velocity` and `release_acceleration` over 0.5-1.0 s; sampled every `dt`.
    struct Throw {
        start: [f64; 7],
        wind_up: [f64; 7],
        release: [f64; 7],
        release_velocity: [f64; 7],
        release_acceleration: [f64; 7],
    }

    impl Throw {
        /// Notes section 2: planar (S1 = -135 deg), lands near (-3.55, -3.55).
        fn nominal() -> Self {
            let (s1, s) = (-135f64.to_radians(), 2.081);
            Self {
                start: [s1, -0.4, 0.0, -0.6, 0.0, -0.8, 0.0],
                wind_up: [s1, -0.9, 0.0, -1.5, 0.0, -2.0, 0.0],
                release: [s1, -0.3, 0.0, -0.3, 0.0, -0.1, 0.0],
                release_velocity: [0.0, s, 0.0, 2.0 * s, 0.0, 4.0 * s, 0.0],
                release_acceleration: [0.0; 7],
            }
        }

        /// Exploration noise on every joint's waypoints, release velocity and acceleration.
        fn perturbed(rng: &mut impl Rng) -> Self {
            let mut throw = Self::nominal();
            for j in 0..7 {
                throw.start[j] += rng.random_range(-0.1..0.1);
                throw.wind_up[j] += rng.random_range(-0.2..0.2);
                throw.release[j] += rng.random_range(-0.1..0.1);
                throw.release_velocity[j] += rng.random_range(-0.5..0.5);
                throw.release_acceleration[j] = rng.random_range(-30.0..30.0);
            }
            throw
        }

        fn sample(&self, dt: f64) -> JointTrajectory {
            let first: Vec<_> = (0..7)
                .map(|j| quintic([self.start[j], 0.0, 0.0], [self.wind_up[j], 0.0, 0.0], 0.5))
                .collect();
            let second: Vec<_> = (0..7)
                .map(|j| {
                    let end = [self.release[j], self.release_velocity[j], self.release_acceleration[j]];
                    quintic([self.wind_up[j], 0.0, 0.0], end, 0.5)
                })
                .collect();
            let samples = (1.0 / dt).round() as usize;
            let (mut positions, mut velocities) = (vec![], vec![]);
            for k in 0..=samples {
                let t = k as f64 * dt;
                let (segment, local) = if k * 2 < samples {
                    (&first, t)
                } else {
                    (&second, t - 0.5)
                };
                let (q, qd) = segment.iter().map(|c| evaluate(c, local)).unzip();
                positions.push(q);
                velocities.push(qd);
            }
            JointTrajectory {
                dt,
                positions,
                velocities,
            }
        }
    }

    /// The analytic landing of the commanded release state.
    fn oracle(robot: &Robot, trajectory: &JointTrajectory) -> [f64; 2] {
        let (q, qd) = trajectory.last().unwrap();
        let (position, velocity) = robot.ball_state(q, qd);
        robot.landing(&position, &velocity).unwrap()
    }

    fn distance(a: [f64; 2], b: [f64; 2]) -> f64 {
        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
    }

    fn arm() -> RapierArm {
        RapierArm::new(&Robot::pa10(), RapierConfig::default()).unwrap()
    }

    fn assert_poses_match(arm: &RapierArm, tolerance: f64) {
        let robot = arm.robot();
        let q = arm.joint_positions();
        let poses = arm.link_poses();
        let frames = robot.frames(&q);
        assert_eq!(poses.len(), robot.dof() + 1);
        for (i, (pose, frame)) in poses.iter().zip(&frames).enumerate() {
            let offset = (pose.translation.vector - frame.translation.vector).norm();
            let angle = pose.rotation.angle_to(&frame.rotation);
            assert!(
                offset < tolerance && angle < tolerance,
                "body {i}: {offset} m, {angle} rad"
            );
        }
        let ball = poses[robot.dof()].translation.vector;
        let offset = (ball - robot.ball_position(&q)).norm();
        assert!(offset < tolerance, "ball: {offset} m");
    }

    #[test]
    fn rapier_poses_match_the_robot_kinematics() {
        let robot = Robot::pa10();
        let mut arm = arm();
        // Zero pose.
        assert_eq!(arm.joint_positions(), vec![0.0; 7]);
        assert_poses_match(&arm, 1e-14);
        // Random configurations: a one-sample trajectory releases at once.
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        for _ in 0..20 {
            let q: Vec<f64> = (0..7).map(|_| rng.random_range(-3.0..3.0)).collect();
            let trajectory = JointTrajectory {
                dt: 0.01,
                positions: vec![q.clone()],
                velocities: vec![vec![0.0; 7]],
            };
            let outcome = arm.throw(&trajectory);
            assert_eq!(arm.joint_positions(), q);
            assert_poses_match(&arm, 1e-13);
            assert!((outcome.release_position - robot.ball_position(&q)).norm() < 1e-13);
        }
        // After a simulated throw, at the angles the simulation reached.
        let outcome = arm.throw(&Throw::nominal().sample(0.001));
        assert!(outcome.is_ok(), "{:?}", outcome.status);
        assert_eq!(arm.joint_positions(), outcome.release_joint_positions);
        assert_poses_match(&arm, 1e-12);
        let q = &outcome.release_joint_positions;
        assert!((outcome.release_position - robot.ball_position(q)).norm() < 1e-12);
        let (_, velocity) = robot.ball_state(q, &outcome.release_joint_velocities);
        assert_eq!(outcome.release_velocity, velocity);
    }

    #[test]
    fn landing_matches_the_analytic_oracle() {
        let robot = Robot::pa10();
        let mut arm = arm();
        let nominal = Throw::nominal().sample(0.001);
        let outcome = arm.throw(&nominal);
        let target = oracle(&robot, &nominal);
        assert!(distance(target, [-3.55, -3.55]) < 0.01, "{target:?}");
        let landing = outcome.landing.expect("the nominal throw lands");
        assert!(distance(landing, target) < 1e-3, "{landing:?} vs {target:?}");
        assert!(outcome.max_tracking_error < 1e-3, "{}", outcome.max_tracking_error);
        let (q, qd) = nominal.last().unwrap();
        let (position, velocity) = robot.ball_state(q, qd);
        assert!((outcome.release_position - position).norm() < 1e-4);
        assert!((outcome.release_velocity - velocity).norm() < 1e-3);

        // Perturbed throws, with a non-zero release acceleration, sampled at 1 and 2 ms.
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let mut errors: Vec<f64> = (0..60)
            .map(|i| {
                let trajectory = Throw::perturbed(&mut rng).sample(if i % 2 == 0 { 0.001 } else { 0.002 });
                let outcome = arm.throw(&trajectory);
                assert!(outcome.is_ok(), "{:?}", outcome.status);
                distance(outcome.landing.unwrap(), oracle(&robot, &trajectory))
            })
            .collect();
        errors.sort_by(f64::total_cmp);
        let (median, max) = (errors[errors.len() / 2], errors[errors.len() - 1]);
        // The acceptance bound is 2 cm; the default configuration does far better.
        assert!(max < 0.02, "max {max} m");
        assert!(median < 1e-4 && max < 1e-3, "median {median} m, max {max} m");
    }

    #[test]
    fn few_solver_iterations_miss_the_oracle() {
        // The landing accuracy comes from the solver converging: a single sweep is centimetres off.
        let robot = Robot::pa10();
        let config = RapierConfig {
            solver_iterations: 1,
            ..RapierConfig::default()
        };
        let mut arm = RapierArm::new(&robot, config).unwrap();
        let nominal = Throw::nominal().sample(0.001);
        let error = distance(arm.throw(&nominal).landing.unwrap(), oracle(&robot, &nominal));
        assert!(error > 0.01, "{error}");
    }

    #[test]
    fn throws_are_deterministic() {
        let robot = Robot::pa10();
        let nominal = Throw::nominal().sample(0.001);
        let other = Throw::perturbed(&mut rand::rngs::StdRng::seed_from_u64(1)).sample(0.002);
        let mut reused = arm();
        let first = reused.throw(&nominal);
        let second = reused.throw(&nominal);
        reused.throw(&other);
        let third = reused.throw(&nominal);
        let fresh = RapierArm::new(&robot, RapierConfig::default()).unwrap().throw(&nominal);
        let bits = |o: &ThrowOutcome| {
            let mut bits: Vec<u64> = o.landing.unwrap().iter().map(|v| v.to_bits()).collect();
            bits.extend(
                o.release_position
                    .iter()
                    .chain(o.release_velocity.iter())
                    .map(|v| v.to_bits()),
            );
            bits.extend(o.release_joint_positions.iter().map(|v| v.to_bits()));
            bits.push(o.max_tracking_error.to_bits());
            bits
        };
        assert_eq!(bits(&first), bits(&second));
        assert_eq!(bits(&first), bits(&third));
        assert_eq!(bits(&first), bits(&fresh));
        assert_ne!(bits(&first), bits(&reused.throw(&other)));
    }

    fn assert_failed(outcome: &ThrowOutcome, expected: fn(&ThrowFailure) -> bool) {
        match &outcome.status {
            ThrowStatus::Failed(failure) => assert!(expected(failure), "{failure}"),
            ThrowStatus::Ok => panic!("not flagged: {outcome:?}"),
        }
        assert!(!outcome.is_ok());
        assert_eq!(outcome.landing, None);
    }

    #[test]
    fn failures_are_flagged_without_panicking() {
        let mut arm = arm();
        let nominal = Throw::nominal().sample(0.002);
        let invalid = |o: &ThrowFailure| matches!(o, ThrowFailure::InvalidTrajectory(_));

        let mut nan = nominal.clone();
        nan.positions[100][3] = f64::NAN;
        assert_failed(&arm.throw(&nan), invalid);
        let mut infinite = nominal.clone();
        infinite.velocities[0][0] = f64::INFINITY;
        assert_failed(&arm.throw(&infinite), invalid);
        let mut short = nominal.clone();
        short.positions[7].pop();
        assert_failed(&arm.throw(&short), invalid);
        let empty = JointTrajectory {
            dt: 0.001,
            positions: vec![],
            velocities: vec![],
        };
        assert_failed(&arm.throw(&empty), invalid);
        let endless = JointTrajectory {
            dt: 1e3,
            ..nominal.clone()
        };
        assert_failed(&arm.throw(&endless), invalid);

        // Violent: a shoulder whose speed ramps to 1e5 rad/s; the simulation cannot follow it.
        let ramp = |rate: f64| {
            let time = |k: usize| k as f64 * 0.001;
            JointTrajectory {
                dt: 0.001,
                positions: (0..=1000)
                    .map(|k| vec![0.0, 0.5 * rate * time(k).powi(2), 0.0, 0.0, 0.0, 0.0, 0.0])
                    .collect(),
                velocities: (0..=1000)
                    .map(|k| vec![0.0, rate * time(k), 0.0, 0.0, 0.0, 0.0, 0.0])
                    .collect(),
            }
        };
        let exploded = |o: &ThrowFailure| matches!(o, ThrowFailure::Exploded { .. });
        assert_failed(&arm.throw(&ramp(1e5)), exploded);
        // Followed, but the ball would leave at over 1 km/s.
        assert_failed(&arm.throw(&ramp(1e3)), exploded);
        // Random jumps of up to 100 rad between samples.
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let mut noise = || {
            (0..1001)
                .map(|_| (0..7).map(|_| rng.random_range(-100.0..100.0)).collect())
                .collect()
        };
        let jumps = JointTrajectory {
            dt: 0.001,
            positions: noise(),
            velocities: noise(),
        };
        let outcome = arm.throw(&jumps);
        assert_failed(&outcome, exploded);
        assert!(outcome.max_tracking_error > arm.config().max_tracking_error);
        assert!(outcome.release_position.iter().all(|v| v.is_nan()));
        // Finite commands whose dynamics overflow.
        let overflow = JointTrajectory {
            dt: 0.001,
            positions: vec![vec![0.0; 7]; 2],
            velocities: vec![vec![f64::MAX; 7], vec![0.0; 7]],
        };
        assert_failed(&arm.throw(&overflow), |o| matches!(o, ThrowFailure::NonFinite { .. }));
        // A gentle ramp still lands.
        assert!(arm.throw(&ramp(1.0)).is_ok());

        // The arm folded down (S2 and E1 at +90 deg): the ball is released inside the ground.
        let down = JointTrajectory {
            dt: 0.001,
            positions: vec![vec![0.0, 1.5, 0.0, 1.5, 0.0, 0.0, 0.0]; 2],
            velocities: vec![vec![0.0, 0.5, 0.0, 0.5, 0.0, 0.0, 0.0]; 2],
        };
        assert_failed(&arm.throw(&down), |o| matches!(o, ThrowFailure::NoLanding(_)));
    }

    #[test]
    fn bad_configs_name_the_field() {
        let robot = Robot::pa10();
        let error = |config: RapierConfig| RapierArm::new(&robot, config).unwrap_err().to_string();
        let default = RapierConfig::default();
        let message = error(RapierConfig { dt: 0.0, ..default });
        assert_eq!(message, "rapier: dt must be in [1e-5, 0.02] s, got 0");
        let message = error(RapierConfig {
            dt: f64::NAN,
            ..default
        });
        assert!(message.contains("dt must be"), "{message}");
        let message = error(RapierConfig {
            solver_iterations: 0,
            ..default
        });
        assert_eq!(message, "rapier: solver_iterations must be in 1..=1000, got 0");
        let message = error(RapierConfig {
            motor_stiffness: -1.0,
            ..default
        });
        assert!(message.contains("motor_stiffness must be finite and >= 0"), "{message}");
        let message = error(RapierConfig {
            motor_stiffness: 0.0,
            motor_damping: 0.0,
            ..default
        });
        assert!(
            message.contains("motor_damping must be > 0 when motor_stiffness is 0"),
            "{message}"
        );
        let message = error(RapierConfig {
            max_tracking_error: 0.0,
            ..default
        });
        assert!(
            message.contains("max_tracking_error must be finite and > 0"),
            "{message}"
        );
        let message = error(RapierConfig {
            max_release_speed: f64::INFINITY,
            ..default
        });
        assert!(
            message.contains("max_release_speed must be finite and > 0"),
            "{message}"
        );

        // From TOML: unspecified fields keep their defaults, unknown ones are refused.
        let config: RapierConfig = toml::from_str("dt = 0.004\nsolver_iterations = 16").unwrap();
        assert_eq!((config.dt, config.solver_iterations), (0.004, 16));
        assert_eq!(config.motor_stiffness, default.motor_stiffness);
        let unknown = toml::from_str::<RapierConfig>("substeps = 2").unwrap_err().to_string();
        assert!(unknown.contains("substeps"), "{unknown}");
    }

    #[test]
    fn the_reference_interpolates_between_samples() {
        // A cubic is reproduced exactly between samples.
        let cubic = |t: f64| {
            (
                1.0 - 2.0 * t + 3.0 * t * t - 4.0 * t * t * t,
                -2.0 + 6.0 * t - 12.0 * t * t,
            )
        };
        let dt = 0.1;
        let (positions, velocities) = (0..=10)
            .map(|k| {
                let (p, v) = cubic(k as f64 * dt);
                (vec![p], vec![v])
            })
            .unzip();
        let trajectory = JointTrajectory {
            dt,
            positions,
            velocities,
        };
        let reference = Reference {
            trajectory: &trajectory,
        };
        let (mut q, mut qd) = ([0.0], [0.0]);
        for t in [0.0, 0.037, 0.1, 0.55, 0.999, 1.0] {
            reference.at(t, &mut q, &mut qd);
            let (p, v) = cubic(t);
            assert!((q[0] - p).abs() < 1e-12 && (qd[0] - v).abs() < 1e-11, "t = {t}");
        }
        assert_eq!(step_plan(1.0, 0.008), (125, 0.008));
        assert_eq!(step_plan(0.0, 0.008), (0, 0.0));
        let (steps, h) = step_plan(0.999, 0.008);
        assert_eq!(steps, 125);
        assert!(h <= 0.008 && (h * 125.0 - 0.999).abs() < 1e-12);
    }
}
