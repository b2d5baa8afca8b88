//! Points of a context space: keeping a drawn point inside it. Shared by the selectors that draw
//! from the continuous space.

use acps_shared::ContextSpace;

/// Map a point into the space: clamped into a box (coordinate by coordinate, as numpy's `clip`),
/// radially projected onto the surface of a ball it lies outside of.
pub(crate) fn project(space: &ContextSpace, mut point: Vec<f64>) -> Vec<f64> {
    match space {
        ContextSpace::Box { low, high } => {
            point
                .iter_mut()
                .zip(low.iter().zip(high))
                .for_each(|(x, (l, h))| *x = x.clamp(*l, *h));
        }
        ContextSpace::Ball { radius, .. } => {
            let norm = point.iter().map(|x| x * x).sum::<f64>().sqrt();
            if norm > *radius {
                // A hair inside, so rounding cannot leave the point outside.
                let scale = radius / norm * (1.0 - f64::EPSILON);
                point.iter_mut().for_each(|x| *x *= scale);
            }
        }
    }
    point
}
