//! The nearest earlier context, for ALP-GMM's learning progress: a k-d tree that only grows
//! (the original keeps a k-d tree too, rebuilt in batches). A run's contexts arrive in an order
//! its teacher randomises, so the tree stays shallow without rebalancing; a context equal to a
//! stored one replaces its return instead of adding a node, so repeated (snapped) contexts do not
//! stack up in a chain.

/// Marks a missing child.
const NONE: u32 = u32::MAX;

/// Points with a value each, searchable for the nearest one.
#[derive(Debug, Clone, Default)]
pub(crate) struct NeighbourIndex {
    dim: usize,
    /// Node i's point is `points[i * dim..(i + 1) * dim]`.
    points: Vec<f64>,
    values: Vec<f64>,
    children: Vec<[u32; 2]>,
}

impl NeighbourIndex {
    /// An empty index of points of `dim >= 1` coordinates.
    pub(crate) fn new(dim: usize) -> Self {
        Self { dim, ..Self::default() }
    }

    /// Number of distinct points.
    pub(crate) fn len(&self) -> usize {
        self.values.len()
    }

    /// The distinct points, in the order they were first inserted, one after another.
    pub(crate) fn points(&self) -> &[f64] {
        &self.points
    }

    /// The value of every point, in the same order.
    pub(crate) fn values(&self) -> &[f64] {
        &self.values
    }

    fn point(&self, node: usize) -> &[f64] {
        &self.points[node * self.dim..(node + 1) * self.dim]
    }

    /// The value of the point nearest to `query` (Euclidean; among equally near points the one
    /// inserted first, so the answer does not depend on the tree's shape), or `None` when empty.
    pub(crate) fn nearest(&self, query: &[f64]) -> Option<f64> {
        if self.values.is_empty() {
            return None;
        }
        let mut best = (f64::INFINITY, usize::MAX);
        // (node, depth, squared distance of the query to the node's side of the parent's cut)
        let mut stack = vec![(0u32, 0usize, 0.0f64)];
        while let Some((node, depth, bound)) = stack.pop() {
            if bound > best.0 {
                continue;
            }
            let node = node as usize;
            let point = self.point(node);
            let distance: f64 = point.iter().zip(query).map(|(a, b)| (a - b) * (a - b)).sum();
            if distance < best.0 || (distance == best.0 && node < best.1) {
                best = (distance, node);
            }
            let axis = depth % self.dim;
            let offset = query[axis] - point[axis];
            let (near, far) = if offset < 0.0 { (0, 1) } else { (1, 0) };
            let children = self.children[node];
            // Far side first, so the near side is searched first and prunes more.
            if children[far] != NONE {
                stack.push((children[far], depth + 1, offset * offset));
            }
            if children[near] != NONE {
                stack.push((children[near], depth + 1, 0.0));
            }
        }
        Some(self.values[best.1])
    }

    /// Store `point` with `value`; a point equal to a stored one takes over its place with the
    /// new value.
    pub(crate) fn insert(&mut self, point: &[f64], value: f64) {
        let new = self.values.len() as u32;
        if self.values.is_empty() {
            self.push(point, value);
            return;
        }
        let (mut node, mut depth) = (0usize, 0usize);
        loop {
            if self.point(node) == point {
                self.values[node] = value;
                return;
            }
            let axis = depth % self.dim;
            let side = usize::from(point[axis] >= self.point(node)[axis]);
            match self.children[node][side] {
                NONE => {
                    self.children[node][side] = new;
                    self.push(point, value);
                    return;
                }
                child => (node, depth) = (child as usize, depth + 1),
            }
        }
    }

    fn push(&mut self, point: &[f64], value: f64) {
        self.points.extend_from_slice(point);
        self.values.push(value);
        self.children.push([NONE; 2]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The value of the nearest point by brute force, ties to the earliest.
    fn brute_force(points: &[Vec<f64>], values: &[f64], query: &[f64]) -> f64 {
        let distance = |p: &Vec<f64>| p.iter().zip(query).map(|(a, b)| (a - b) * (a - b)).sum::<f64>();
        let best = (0..points.len()).fold(0, |best, i| {
            if distance(&points[i]) < distance(&points[best]) {
                i
            } else {
                best
            }
        });
        values[best]
    }

    #[test]
    fn nearest_is_the_brute_force_nearest_in_every_dimension() {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        for dim in [1, 2, 3, 5] {
            let mut index = NeighbourIndex::new(dim);
            let (mut points, mut values) = (Vec::new(), Vec::new());
            assert_eq!(index.nearest(&vec![0.5; dim]), None);
            for i in 0..2000 {
                // A coarse grid makes exact ties and repeated points common.
                let point: Vec<f64> = (0..dim).map(|_| f64::from(rng.random_range(0..8u8)) / 8.0).collect();
                let query: Vec<f64> = (0..dim).map(|_| rng.random::<f64>()).collect();
                if !points.is_empty() {
                    assert_eq!(
                        index.nearest(&query),
                        Some(brute_force(&points, &values, &query)),
                        "dim {dim} step {i}"
                    );
                    // A query on a stored point finds that point's latest value.
                    if let Some(j) = points.iter().position(|p| *p == point) {
                        assert_eq!(index.nearest(&point), Some(values[j]));
                    }
                }
                let value = i as f64;
                match points.iter().position(|p| *p == point) {
                    Some(j) => values[j] = value,
                    None => {
                        points.push(point.clone());
                        values.push(value);
                    }
                }
                index.insert(&point, value);
                assert_eq!(index.len(), points.len());
            }
            assert_eq!(index.points(), points.concat());
            assert_eq!(index.values(), values);
        }
    }

    #[test]
    fn inserting_the_stored_points_again_rebuilds_the_same_tree() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut index = NeighbourIndex::new(2);
        for _ in 0..500 {
            let point = [rng.random::<f64>(), rng.random::<f64>()];
            index.insert(&point, rng.random());
        }
        let mut rebuilt = NeighbourIndex::new(2);
        for (point, &value) in index.points().chunks(2).zip(index.values()) {
            rebuilt.insert(point, value);
        }
        assert_eq!(rebuilt.children, index.children);
        assert_eq!(rebuilt.points, index.points);
    }
}
