//! The arm: its description file (`models/pa10.toml`), forward kinematics and the Jacobian of the
//! ball centre.
//!
//! Kinematics as a product of exponentials: in the zero pose every joint frame is aligned with the
//! world frame; joint i sits at `origin_i` in joint i-1's frame and rotates about `axis_i`. The
//! ball centre sits at the tool offset in the last joint's frame.

use nalgebra::{DVector, Isometry3, Matrix3xX, Translation3, Unit, UnitQuaternion, Vector3};
use serde::Deserialize;
use std::path::Path;

/// The description file of the PA10-7C, shipped with the crate.
pub const PA10_FILE: &str = include_str!("../pa10.toml");

/// Why [`Robot::from_file`] or [`Robot::from_toml`] cannot load a description.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RobotLoadError {
    /// The file could not be read.
    #[error("{file}: cannot read: {reason}")]
    Read {
        /// The file.
        file: String,
        /// The operating system's reason.
        reason: String,
    },
    /// Not TOML, an unknown key, a missing key or a wrong type; the message names line and column.
    #[error("{file}: {message}")]
    Syntax {
        /// The file.
        file: String,
        /// The parser's message, with the position.
        message: String,
    },
    /// A value outside its accepted range, or an inconsistent description.
    #[error("{file}: {field} must be {accepted}, got {got}")]
    Invalid {
        /// The file.
        file: String,
        /// The offending field, as a path (`joints[2].max_speed`).
        field: String,
        /// The accepted range.
        accepted: &'static str,
        /// The given value.
        got: String,
    },
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RobotFile {
    name: String,
    gravity: f64,
    base: BaseFile,
    joints: Vec<JointFile>,
    tool: ToolFile,
    ball: BallFile,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct BaseFile {
    mass: f64,
    com: [f64; 3],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct JointFile {
    name: String,
    axis: [f64; 3],
    origin: [f64; 3],
    limit_deg: [f64; 2],
    max_speed: f64,
    link: LinkFile,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LinkFile {
    mass: f64,
    com: [f64; 3],
    /// Radius and length of the solid cylinder (along the joint's z) that estimates the inertia.
    cylinder: [f64; 2],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ToolFile {
    offset: [f64; 3],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct BallFile {
    mass: f64,
    radius: f64,
}

/// A rigid link: mass, centre of mass and principal inertia in its joint's frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Link {
    /// Mass in kg.
    pub mass: f64,
    /// Centre of mass relative to the joint's axis point, in the joint's frame (m).
    pub com: Vector3<f64>,
    /// Principal moments of inertia about the centre of mass, along the joint frame's axes (kg m^2).
    pub inertia: Vector3<f64>,
}

/// A revolute joint and the link it moves.
#[derive(Debug, Clone, PartialEq)]
pub struct Joint {
    /// Name (S1 .. W2 for the PA-10).
    pub name: String,
    /// Unit rotation axis in the joint's frame (which equals the world frame in the zero pose).
    pub axis: Unit<Vector3<f64>>,
    /// Axis point relative to the previous joint's axis point, in the previous joint's frame.
    pub origin: Vector3<f64>,
    /// Position limits in rad (lower, upper).
    pub limits: (f64, f64),
    /// Speed limit in rad/s.
    pub max_speed: f64,
    /// The link the joint moves.
    pub link: Link,
}

/// The ball the arm throws.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ball {
    /// Mass in kg.
    pub mass: f64,
    /// Radius in m.
    pub radius: f64,
}

/// A serial arm with a ball at its tool.
#[derive(Debug, Clone, PartialEq)]
pub struct Robot {
    /// Name from the file.
    pub name: String,
    /// Gravitational acceleration (m/s^2), pointing down -z.
    pub gravity: f64,
    /// Mass of the fixed base (kg), for the physics simulation.
    pub base_mass: f64,
    /// Centre of mass of the base (m).
    pub base_com: Vector3<f64>,
    /// The joints from base to tool.
    pub joints: Vec<Joint>,
    /// The ball centre relative to the last joint's axis point, in its frame.
    pub tool_offset: Vector3<f64>,
    /// The ball.
    pub ball: Ball,
}

struct Checker<'a> {
    file: &'a str,
}

impl Checker<'_> {
    fn check(
        &self,
        ok: bool,
        field: String,
        accepted: &'static str,
        got: impl std::fmt::Debug,
    ) -> Result<(), RobotLoadError> {
        if ok {
            Ok(())
        } else {
            Err(RobotLoadError::Invalid {
                file: self.file.to_string(),
                field,
                accepted,
                got: format!("{got:?}"),
            })
        }
    }

    fn finite(&self, values: &[f64], field: String) -> Result<(), RobotLoadError> {
        self.check(values.iter().all(|v| v.is_finite()), field, "finite", values)
    }

    fn positive(&self, value: f64, field: String) -> Result<(), RobotLoadError> {
        self.check(value.is_finite() && value > 0.0, field, "finite and > 0", value)
    }
}

impl Robot {
    /// The PA10-7C from the description file shipped with the crate.
    pub fn pa10() -> Self {
        Self::from_toml(PA10_FILE, "models/pa10.toml").expect("the shipped PA-10 description is valid (tested)")
    }

    /// Read and validate a description file.
    pub fn from_file(path: &Path) -> Result<Self, RobotLoadError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| RobotLoadError::Read {
            file: file.clone(),
            reason: e.to_string(),
        })?;
        Self::from_toml(&text, &file)
    }

    /// Parse and validate a description; `file` names it in errors.
    pub fn from_toml(text: &str, file: &str) -> Result<Self, RobotLoadError> {
        let raw: RobotFile = toml::from_str(text).map_err(|e| RobotLoadError::Syntax {
            file: file.to_string(),
            message: e.to_string(),
        })?;
        let c = Checker { file };
        c.check(!raw.name.trim().is_empty(), "name".into(), "non-empty", &raw.name)?;
        c.positive(raw.gravity, "gravity".into())?;
        c.positive(raw.base.mass, "base.mass".into())?;
        c.finite(&raw.base.com, "base.com".into())?;
        c.check(
            !raw.joints.is_empty(),
            "joints".into(),
            "at least one joint",
            raw.joints.len(),
        )?;
        let mut joints = Vec::with_capacity(raw.joints.len());
        for (i, j) in raw.joints.iter().enumerate() {
            let at = |field: &str| format!("joints[{i}].{field}");
            c.check(!j.name.trim().is_empty(), at("name"), "non-empty", &j.name)?;
            c.check(
                raw.joints[..i].iter().all(|other| other.name != j.name),
                at("name"),
                "unique",
                &j.name,
            )?;
            c.finite(&j.axis, at("axis"))?;
            let axis = Vector3::from(j.axis);
            c.check((axis.norm() - 1.0).abs() < 1e-9, at("axis"), "a unit vector", j.axis)?;
            c.finite(&j.origin, at("origin"))?;
            let [low, high] = j.limit_deg;
            c.check(
                low.is_finite() && high.is_finite() && low < high,
                at("limit_deg"),
                "finite [lower, upper] with lower < upper",
                j.limit_deg,
            )?;
            c.positive(j.max_speed, at("max_speed"))?;
            c.positive(j.link.mass, at("link.mass"))?;
            c.finite(&j.link.com, at("link.com"))?;
            let [radius, length] = j.link.cylinder;
            c.check(
                radius.is_finite() && length.is_finite() && radius > 0.0 && length > 0.0,
                at("link.cylinder"),
                "[radius, length], both finite and > 0",
                j.link.cylinder,
            )?;
            let m = j.link.mass;
            let across = m * (3.0 * radius * radius + length * length) / 12.0;
            joints.push(Joint {
                name: j.name.clone(),
                axis: Unit::new_normalize(axis),
                origin: Vector3::from(j.origin),
                limits: (low.to_radians(), high.to_radians()),
                max_speed: j.max_speed,
                link: Link {
                    mass: m,
                    com: Vector3::from(j.link.com),
                    inertia: Vector3::new(across, across, m * radius * radius / 2.0),
                },
            });
        }
        c.finite(&raw.tool.offset, "tool.offset".into())?;
        c.positive(raw.ball.mass, "ball.mass".into())?;
        c.positive(raw.ball.radius, "ball.radius".into())?;
        Ok(Self {
            name: raw.name,
            gravity: raw.gravity,
            base_mass: raw.base.mass,
            base_com: Vector3::from(raw.base.com),
            joints,
            tool_offset: Vector3::from(raw.tool.offset),
            ball: Ball {
                mass: raw.ball.mass,
                radius: raw.ball.radius,
            },
        })
    }

    /// Number of joints.
    pub fn dof(&self) -> usize {
        self.joints.len()
    }

    /// World pose of every joint frame at configuration `q` (after the joint's own rotation),
    /// followed by the pose of the ball centre (the tool frame).
    ///
    /// # Panics
    /// If `q` does not have one entry per joint.
    pub fn frames(&self, q: &[f64]) -> Vec<Isometry3<f64>> {
        assert_eq!(
            q.len(),
            self.dof(),
            "q has {} entries for {} joints",
            q.len(),
            self.dof()
        );
        let mut pose = Isometry3::identity();
        let mut frames = Vec::with_capacity(self.dof() + 1);
        for (joint, &angle) in self.joints.iter().zip(q) {
            pose = pose * Translation3::from(joint.origin) * UnitQuaternion::from_axis_angle(&joint.axis, angle);
            frames.push(pose);
        }
        frames.push(pose * Translation3::from(self.tool_offset));
        frames
    }

    /// World position of the ball centre at `q`.
    pub fn ball_position(&self, q: &[f64]) -> Vector3<f64> {
        self.frames(q)
            .last()
            .expect("frames end with the tool")
            .translation
            .vector
    }

    /// The 3 x dof Jacobian of the ball centre's linear velocity: column i is
    /// `axis_i x (p_ball - p_i)` in world coordinates.
    pub fn ball_jacobian(&self, q: &[f64]) -> Matrix3xX<f64> {
        let frames = self.frames(q);
        let ball = frames[self.dof()].translation.vector;
        Matrix3xX::from_columns(
            &self
                .joints
                .iter()
                .zip(&frames)
                .map(|(joint, frame)| {
                    (frame.rotation * joint.axis.into_inner()).cross(&(ball - frame.translation.vector))
                })
                .collect::<Vec<_>>(),
        )
    }

    /// Position and velocity of the ball centre at joint positions `q` and velocities `qd`.
    pub fn ball_state(&self, q: &[f64], qd: &[f64]) -> (Vector3<f64>, Vector3<f64>) {
        assert_eq!(
            qd.len(),
            self.dof(),
            "qd has {} entries for {} joints",
            qd.len(),
            self.dof()
        );
        (
            self.ball_position(q),
            self.ball_jacobian(q) * DVector::from_column_slice(qd),
        )
    }

    /// Where a ball released at `position` with `velocity` first touches the ground (its centre at
    /// height `radius`), flying without drag; `None` if it never comes down to that height (the
    /// release point is below it while moving down, or values are not finite).
    pub fn landing(&self, position: &Vector3<f64>, velocity: &Vector3<f64>) -> Option<[f64; 2]> {
        let height = position.z - self.ball.radius;
        let g = self.gravity;
        let discriminant = velocity.z * velocity.z + 2.0 * g * height;
        let finite = position.iter().chain(velocity.iter()).all(|v| v.is_finite());
        if !finite || discriminant < 0.0 {
            return None;
        }
        let time = (velocity.z + discriminant.sqrt()) / g;
        if time < 0.0 {
            return None;
        }
        Some([position.x + velocity.x * time, position.y + velocity.y * time])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn the_shipped_pa10_matches_the_catalogue_geometry() {
        let robot = Robot::pa10();
        assert_eq!(robot.dof(), 7);
        let names: Vec<_> = robot.joints.iter().map(|j| j.name.as_str()).collect();
        assert_eq!(names, ["S1", "S2", "S3", "E1", "E2", "W1", "W2"]);
        // Zero pose: straight up, 0.315 + 0.45 + 0.50 + 0.18 (flange and gripper).
        let up = robot.ball_position(&[0.0; 7]);
        assert!((up - Vector3::new(0.0, 0.0, 1.445)).norm() < 1e-12, "{up}");
        // S2 at +90 deg tips the whole arm over onto +x, pivoting at the shoulder (0.315 m).
        let tipped = robot.ball_position(&[0.0, std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0, 0.0, 0.0]);
        assert!((tipped - Vector3::new(1.13, 0.0, 0.315)).norm() < 1e-12, "{tipped}");
        // Elbow E1 at +90 deg bends the forearm (0.50 + 0.18 m) onto +x at the elbow height 0.765.
        let bent = robot.ball_position(&[0.0, 0.0, 0.0, std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0]);
        assert!((bent - Vector3::new(0.68, 0.0, 0.765)).norm() < 1e-12, "{bent}");
        // S1 turns that about z.
        let turned = robot.ball_position(&[
            std::f64::consts::FRAC_PI_2,
            0.0,
            0.0,
            std::f64::consts::FRAC_PI_2,
            0.0,
            0.0,
            0.0,
        ]);
        assert!((turned - Vector3::new(0.0, 0.68, 0.765)).norm() < 1e-12, "{turned}");
        assert_eq!(robot.joints[3].limits, ((-137f64).to_radians(), 137f64.to_radians()));
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let robot = Robot::pa10();
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        for _ in 0..20 {
            let q: Vec<f64> = (0..7).map(|_| rng.random_range(-2.0..2.0)).collect();
            let jacobian = robot.ball_jacobian(&q);
            for i in 0..7 {
                let h = 1e-6;
                let (mut plus, mut minus) = (q.clone(), q.clone());
                plus[i] += h;
                minus[i] -= h;
                let numeric = (robot.ball_position(&plus) - robot.ball_position(&minus)) / (2.0 * h);
                assert!(
                    (numeric - jacobian.column(i)).norm() < 1e-8,
                    "joint {i}: {numeric} vs {}",
                    jacobian.column(i)
                );
            }
        }
    }

    #[test]
    fn ballistic_landing_is_closed_form() {
        let robot = Robot::pa10();
        let r = robot.ball.radius;
        // Dropped from rest at height h + r: lands straight below.
        assert_eq!(
            robot.landing(&Vector3::new(1.0, -2.0, 2.0 + r), &Vector3::zeros()),
            Some([1.0, -2.0])
        );
        // Thrown horizontally at 3 m/s from h = g/2 (+ r): flight time 1 s.
        let g = robot.gravity;
        let [x, y] = robot
            .landing(&Vector3::new(0.0, 0.0, g / 2.0 + r), &Vector3::new(3.0, -1.0, 0.0))
            .unwrap();
        assert!((x - 3.0).abs() < 1e-12 && (y + 1.0).abs() < 1e-12);
        assert_eq!(
            robot.landing(&Vector3::new(0.0, 0.0, f64::NAN), &Vector3::zeros()),
            None
        );
    }

    #[test]
    fn bad_files_name_the_field_and_line() {
        let edit = |from: &str, to: &str| {
            Robot::from_toml(&PA10_FILE.replacen(from, to, 1), "edited.toml")
                .unwrap_err()
                .to_string()
        };
        let error = edit("max_speed = 1.0 ", "max_speed = -1.0 ");
        assert!(
            error.contains("edited.toml: joints[0].max_speed must be finite and > 0, got -1.0"),
            "{error}"
        );
        let error = edit("limit_deg = [-91.0, 91.0]", "limit_deg = [91.0, -91.0]");
        assert!(
            error.contains("joints[1].limit_deg must be finite [lower, upper]"),
            "{error}"
        );
        let error = edit("axis = [0.0, 1.0, 0.0]", "axis = [0.0, 2.0, 0.0]");
        assert!(error.contains("joints[1].axis must be a unit vector"), "{error}");
        let error = edit("name = \"S3\"", "name = \"S1\"");
        assert!(error.contains("joints[2].name must be unique"), "{error}");
        let error = edit("radius = 0.035", "radius = 0.035\ncolour = \"red\"");
        assert!(
            error.contains("edited.toml") && error.contains("unknown field") && error.contains("colour"),
            "{error}"
        );
        let error = edit("gravity = 9.81", "gravity = \"down\"");
        assert!(error.contains("line"), "TOML errors carry the position: {error}");
        let missing = Robot::from_file(Path::new("no/such/robot.toml"))
            .unwrap_err()
            .to_string();
        assert!(missing.starts_with("no/such/robot.toml: cannot read"), "{missing}");
    }
}
