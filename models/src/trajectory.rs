//! A joint-space trajectory sampled at a fixed control period: what a movement primitive
//! produces and what a simulator tracks.

/// Joint positions and velocities at t = 0, dt, 2 dt, ..., (len - 1) dt.
#[derive(Debug, Clone, PartialEq)]
pub struct JointTrajectory {
    /// Control period in s.
    pub dt: f64,
    /// Joint positions (rad), one row per sample.
    pub positions: Vec<Vec<f64>>,
    /// Joint velocities (rad/s), one row per sample.
    pub velocities: Vec<Vec<f64>>,
}

impl JointTrajectory {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Time of the last sample.
    pub fn duration(&self) -> f64 {
        self.len().saturating_sub(1) as f64 * self.dt
    }

    /// Position and velocity of the last sample (the release state of a throw).
    pub fn last(&self) -> Option<(&[f64], &[f64])> {
        Some((self.positions.last()?, self.velocities.last()?))
    }

    /// True when every value is finite.
    pub fn is_finite(&self) -> bool {
        self.positions
            .iter()
            .chain(&self.velocities)
            .flatten()
            .all(|v| v.is_finite())
    }
}
