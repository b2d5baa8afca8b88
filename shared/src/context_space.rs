//! The continuous space that contexts are drawn from and that the policy must generalise over.

use rand::{Rng, RngCore};
use serde::{Deserialize, Serialize};

/// A continuous context space.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum ContextSpace {
    /// The axis-aligned box `low[i] <= s[i] <= high[i]`.
    Box {
        /// Lower corner.
        low: Vec<f64>,
        /// Upper corner.
        high: Vec<f64>,
    },
    /// The ball `||s||_2 <= radius` in `dim` dimensions.
    Ball {
        /// Number of dimensions.
        dim: usize,
        /// Radius of the ball.
        radius: f64,
    },
}

/// Why [`ContextSpace::new_box`] or [`ContextSpace::new_ball`] refuses its arguments.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ContextSpaceCreateError {
    /// Corners of different lengths, an empty box, or a non-finite or inverted bound.
    #[error(
        "context box: low and high must have the same non-zero length and finite low[i] < high[i]; got low {low:?}, high {high:?}"
    )]
    InvalidBox {
        /// The offending lower corner.
        low: Vec<f64>,
        /// The offending upper corner.
        high: Vec<f64>,
    },
    /// A zero dimension or a radius that is not finite and positive.
    #[error("context ball: dim must be >= 1 and radius finite and > 0; got dim {dim}, radius {radius}")]
    InvalidBall {
        /// The offending dimension.
        dim: usize,
        /// The offending radius.
        radius: f64,
    },
}

impl ContextSpace {
    /// A validated box.
    pub fn new_box(low: Vec<f64>, high: Vec<f64>) -> Result<Self, ContextSpaceCreateError> {
        let space = Self::Box { low, high };
        space.validate()?;
        Ok(space)
    }

    /// A validated ball around the origin.
    pub fn new_ball(dim: usize, radius: f64) -> Result<Self, ContextSpaceCreateError> {
        let space = Self::Ball { dim, radius };
        space.validate()?;
        Ok(space)
    }

    /// Refuse a space [`new_box`](Self::new_box) or [`new_ball`](Self::new_ball) would refuse:
    /// a deserialised one (a file's, say) is not checked on the way in.
    pub fn validate(&self) -> Result<(), ContextSpaceCreateError> {
        match self {
            Self::Box { low, high } => {
                let valid = !low.is_empty()
                    && low.len() == high.len()
                    && low
                        .iter()
                        .zip(high)
                        .all(|(l, h)| l.is_finite() && h.is_finite() && l < h);
                if valid {
                    Ok(())
                } else {
                    Err(ContextSpaceCreateError::InvalidBox {
                        low: low.clone(),
                        high: high.clone(),
                    })
                }
            }
            &Self::Ball { dim, radius } => {
                if dim >= 1 && radius.is_finite() && radius > 0.0 {
                    Ok(())
                } else {
                    Err(ContextSpaceCreateError::InvalidBall { dim, radius })
                }
            }
        }
    }

    /// Number of dimensions.
    pub fn dim(&self) -> usize {
        match self {
            Self::Box { low, .. } => low.len(),
            Self::Ball { dim, .. } => *dim,
        }
    }

    /// The smallest box that contains the space, as (low, high).
    pub fn bounding_box(&self) -> (Vec<f64>, Vec<f64>) {
        match self {
            Self::Box { low, high } => (low.clone(), high.clone()),
            Self::Ball { dim, radius } => (vec![-radius; *dim], vec![*radius; *dim]),
        }
    }

    /// True when `s` lies in the space.
    pub fn contains(&self, s: &[f64]) -> bool {
        match self {
            Self::Box { low, high } => {
                s.len() == low.len() && s.iter().zip(low.iter().zip(high)).all(|(x, (l, h))| l <= x && x <= h)
            }
            Self::Ball { dim, radius } => s.len() == *dim && s.iter().map(|x| x * x).sum::<f64>() <= radius * radius,
        }
    }

    /// A uniform sample. The ball uses a Gaussian direction and a radius of `radius * u^(1/dim)`.
    pub fn sample(&self, rng: &mut dyn RngCore) -> Vec<f64> {
        match self {
            Self::Box { low, high } => low.iter().zip(high).map(|(l, h)| rng.random_range(*l..*h)).collect(),
            Self::Ball { dim, radius } => {
                let direction = random_unit_vector(*dim, rng);
                let r = radius * rng.random::<f64>().powf(1.0 / *dim as f64);
                direction.into_iter().map(|d| d * r).collect()
            }
        }
    }
}

/// A direction drawn uniformly from the unit sphere in `dim` dimensions.
pub fn random_unit_vector(dim: usize, rng: &mut dyn RngCore) -> Vec<f64> {
    loop {
        let v: Vec<f64> = (0..dim)
            .map(|_| rng.sample::<f64, _>(rand::distr::StandardUniform) * 2.0 - 1.0)
            .collect();
        let norm2: f64 = v.iter().map(|x| x * x).sum();
        // Rejection from the cube keeps the direction uniform without a normal sampler.
        if norm2 > 1e-12 && norm2 <= 1.0 {
            let norm = norm2.sqrt();
            return v.into_iter().map(|x| x / norm).collect();
        }
    }
}

/// Index of the point of `points` nearest to `point` (squared Euclidean distance over the
/// coordinates both have); among equally near points the first, so a result never depends on
/// rounding order. A point at a NaN distance (a NaN coordinate on either side) is never nearest:
/// 0 when no point is at a comparable distance (none, or all NaN), which indexes any non-empty
/// list.
pub fn nearest(points: &[Vec<f64>], point: &[f64]) -> usize {
    let distance2 = |p: &Vec<f64>| p.iter().zip(point).map(|(a, b)| (a - b) * (a - b)).sum::<f64>();
    points
        .iter()
        .map(distance2)
        .enumerate()
        .filter(|(_, d)| !d.is_nan())
        // `min_by` keeps the first of equal minima.
        .min_by(|(_, a), (_, b)| a.total_cmp(b))
        .map_or(0, |(i, _)| i)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn invalid_spaces_are_refused() {
        assert!(ContextSpace::new_box(vec![0.0], vec![0.0]).is_err());
        assert!(ContextSpace::new_box(vec![0.0, 1.0], vec![1.0]).is_err());
        assert!(ContextSpace::new_box(vec![f64::NAN], vec![1.0]).is_err());
        assert!(ContextSpace::new_ball(0, 1.0).is_err());
        assert!(ContextSpace::new_ball(2, -1.0).is_err());
    }

    #[test]
    fn samples_lie_inside_and_fill_the_ball() {
        let ball = ContextSpace::new_ball(2, 1.0).unwrap();
        let mut rng = rand::rngs::StdRng::seed_from_u64(1);
        let samples: Vec<_> = (0..4000).map(|_| ball.sample(&mut rng)).collect();
        assert!(samples.iter().all(|s| ball.contains(s)));
        // Uniform in the disc: the fraction inside radius 0.5 is 0.25.
        let inner = samples.iter().filter(|s| s[0] * s[0] + s[1] * s[1] < 0.25).count() as f64 / 4000.0;
        assert!((inner - 0.25).abs() < 0.03, "inner fraction {inner}");
    }

    #[test]
    fn the_nearest_point_is_the_first_of_the_closest_and_never_one_at_a_nan_distance() {
        let points = [vec![0.0, 0.0], vec![1.0, 1.0], vec![1.0, 0.9]];
        assert_eq!(nearest(&points, &[0.9, 0.9]), 2);
        assert_eq!(nearest(&points, &[-1.0, -1.0]), 0);
        // Ties go to the lowest index, whichever side of the point the tied points lie.
        assert_eq!(nearest(&[vec![0.0], vec![2.0]], &[1.0]), 0);
        assert_eq!(nearest(&[vec![2.0], vec![0.0]], &[1.0]), 0);
        assert_eq!(nearest(&[vec![5.0], vec![2.0], vec![0.0]], &[1.0]), 1);
        // A NaN distance never wins, wherever it is and whatever its sign.
        for nan in [f64::NAN, -f64::NAN] {
            assert_eq!(nearest(&[vec![nan], vec![3.0], vec![2.0]], &[1.0]), 2);
            assert_eq!(nearest(&[vec![3.0], vec![nan], vec![2.0]], &[1.0]), 2);
            assert_eq!(nearest(&[vec![f64::INFINITY], vec![nan]], &[1.0]), 0);
            assert_eq!(nearest(&[vec![nan], vec![f64::INFINITY]], &[1.0]), 1);
            assert_eq!(nearest(&[vec![nan], vec![nan]], &[1.0]), 0);
            assert_eq!(nearest(&[vec![3.0], vec![2.0]], &[nan]), 0, "no distance is comparable");
        }
        assert_eq!(nearest(&[], &[1.0]), 0);
    }
}
