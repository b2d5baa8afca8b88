//! A C-REPS upper-level policy as plain data, for saving a learned policy and replaying it.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use super::{CReps, FeatureMap, LinearGaussianPolicy};

/// The policy `N(theta | W^T phi(s), Sigma)` with its feature map named: everything needed to
/// act greedily or to sample. Matrices are stored row by row.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PolicySnapshot {
    /// The feature map: "affine", "quadratic" or "polar-quadratic".
    pub features: String,
    /// The context dimension.
    pub context_dim: usize,
    /// W, n_phi rows of n_theta entries.
    pub weights: Vec<Vec<f64>>,
    /// Sigma, n_theta rows of n_theta entries.
    pub covariance: Vec<Vec<f64>>,
}

/// A snapshot that does not describe a usable policy; the message names the field and what it
/// must be.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("policy {field}: {reason}")]
pub struct PolicySnapshotRestoreError {
    /// The offending field.
    pub field: &'static str,
    /// What is wrong and what is accepted.
    pub reason: String,
}

/// A policy restored from a snapshot.
#[derive(Clone, Debug)]
pub struct RestoredPolicy {
    features: FeatureMap,
    context_dim: usize,
    policy: LinearGaussianPolicy,
}

impl CReps {
    /// The current policy as data; `None` for a user-supplied feature map, which is code.
    pub fn snapshot(&self) -> Option<PolicySnapshot> {
        PolicySnapshot::of(&self.config().features, self.context_dim(), self.policy())
    }
}

fn feature_map_name(features: &FeatureMap) -> Option<&'static str> {
    match features {
        FeatureMap::Affine => Some("affine"),
        FeatureMap::Quadratic => Some("quadratic"),
        FeatureMap::PolarQuadratic => Some("polar-quadratic"),
        FeatureMap::Custom(_) => None,
    }
}

impl PolicySnapshot {
    /// `policy` on `features` of `context_dim`-dimensional contexts as data; `None` for a
    /// user-supplied feature map, which is code.
    pub(crate) fn of(features: &FeatureMap, context_dim: usize, policy: &LinearGaussianPolicy) -> Option<Self> {
        let features = feature_map_name(features)?;
        let rows = |m: &DMatrix<f64>| (0..m.nrows()).map(|i| m.row(i).iter().copied().collect()).collect();
        Some(Self {
            features: features.to_string(),
            context_dim,
            weights: rows(policy.weights()),
            covariance: rows(policy.covariance()),
        })
    }

    /// The policy of `n_theta` parameters this snapshot describes, after checking every shape
    /// and value: a known feature map valid for `context_dim`, W of as many rows as features and
    /// `n_theta` columns, Sigma `n_theta` x `n_theta`, finite, symmetric and positive
    /// semi-definite. The caller states n_theta (a saved policy's problem knows it), so that a
    /// row of the wrong length is the one blamed, also when it is the first.
    pub fn restore(&self, n_theta: usize) -> Result<RestoredPolicy, PolicySnapshotRestoreError> {
        let error = |field, reason: String| PolicySnapshotRestoreError { field, reason };
        let features = [FeatureMap::Affine, FeatureMap::Quadratic, FeatureMap::PolarQuadratic]
            .into_iter()
            .find(|map| feature_map_name(map) == Some(self.features.as_str()))
            .ok_or_else(|| {
                error(
                    "features",
                    format!(
                        "must be \"affine\", \"quadratic\" or \"polar-quadratic\", got {:?}",
                        self.features
                    ),
                )
            })?;
        features
            .validate(self.context_dim, &[0.0])
            .map_err(|e| error("context_dim", e.to_string()))?;
        let n_phi = features.dim(self.context_dim);
        if n_theta == 0 {
            return Err(error("weights", "n_theta must be >= 1, got 0".into()));
        }
        let weights = matrix(&self.weights, "weights", n_phi, n_theta)?;
        let covariance = matrix(&self.covariance, "covariance", n_theta, n_theta)?;
        let policy = LinearGaussianPolicy::new(weights, covariance).map_err(|e| error("covariance", e.to_string()))?;
        Ok(RestoredPolicy {
            features,
            context_dim: self.context_dim,
            policy,
        })
    }
}

/// A `rows` x `columns` matrix (columns = n_theta) from row vectors.
fn matrix(
    data: &[Vec<f64>],
    field: &'static str,
    rows: usize,
    columns: usize,
) -> Result<DMatrix<f64>, PolicySnapshotRestoreError> {
    let error = |reason: String| PolicySnapshotRestoreError { field, reason };
    if data.len() != rows {
        return Err(error(format!("must have {rows} rows, got {}", data.len())));
    }
    if let Some((i, row)) = data.iter().enumerate().find(|(_, row)| row.len() != columns) {
        return Err(error(format!(
            "every row must have {columns} entries (n_theta), row {i} has {}",
            row.len()
        )));
    }
    if let Some((i, j)) = (0..rows)
        .flat_map(|i| (0..columns).map(move |j| (i, j)))
        .find(|&(i, j)| !data[i][j].is_finite())
    {
        return Err(error(format!(
            "entries must be finite, got {} at row {i}, column {j}",
            data[i][j]
        )));
    }
    Ok(DMatrix::from_fn(rows, columns, |i, j| data[i][j]))
}

impl RestoredPolicy {
    /// The context dimension.
    pub fn context_dim(&self) -> usize {
        self.context_dim
    }

    /// n_theta.
    pub fn n_params(&self) -> usize {
        self.policy.n_params()
    }

    /// The mean `W^T phi(s)` (exploration off), computed exactly as [`CReps::greedy`] does.
    ///
    /// # Panics
    /// If `context.len() != context_dim`.
    pub fn greedy(&self, context: &[f64]) -> Vec<f64> {
        assert_eq!(context.len(), self.context_dim, "context dimension");
        let features: DVector<f64> = self.features.apply(context);
        self.policy.mean(&features).data.into()
    }

    /// The Gaussian policy.
    pub fn policy(&self) -> &LinearGaussianPolicy {
        &self.policy
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::creps::{CRepsConfig, MemoryConfig};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A C-REPS learner after a few updates, so that W and Sigma are no longer their start values.
    fn trained() -> CReps {
        let config = CRepsConfig {
            features: FeatureMap::PolarQuadratic,
            update_every: 10,
            memory: MemoryConfig::SlidingWindow { capacity: 30 },
            ..CRepsConfig::default()
        };
        let mut creps = CReps::new(config, 2, &[0.5, -1.0, 2.0], 1).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..40 {
            let context = [rng.random_range(-2.0..-1.0), rng.random_range(-2.0..-1.0)];
            let theta = creps.sample(&context, &mut rng);
            let reward = -theta.iter().map(|t| (t - context[0]).powi(2)).sum::<f64>();
            creps.record(0, &context, &theta, reward);
        }
        creps
    }

    #[test]
    fn a_restored_snapshot_acts_like_the_learner_through_json() {
        let creps = trained();
        let snapshot = creps.snapshot().unwrap();
        assert_eq!(snapshot.weights.len(), 6);
        let json = serde_json::to_string(&snapshot).unwrap();
        let restored = serde_json::from_str::<PolicySnapshot>(&json)
            .unwrap()
            .restore(3)
            .unwrap();
        for context in [[-1.5, -1.2], [-3.0, -0.5], [-0.1, -4.0]] {
            assert_eq!(restored.greedy(&context), creps.greedy(&context));
        }
        assert_eq!(restored.policy().covariance(), creps.policy().covariance());
    }

    #[test]
    fn bad_snapshots_name_the_field() {
        let good = trained().snapshot().unwrap();
        let message = |change: &dyn Fn(&mut PolicySnapshot)| {
            let mut snapshot = good.clone();
            change(&mut snapshot);
            snapshot.restore(3).unwrap_err().to_string()
        };
        type Change = dyn Fn(&mut PolicySnapshot);
        let cases: [(&Change, &str); 8] = [
            (&|s| s.features = "cubic".into(), "policy features: must be \"affine\""),
            (
                &|s| s.context_dim = 3,
                "policy context_dim: context_dim must be exactly 2",
            ),
            (
                &|s| s.weights.pop().map(drop).unwrap(),
                "policy weights: must have 6 rows, got 5",
            ),
            (
                &|s| s.weights[2].push(0.0),
                "policy weights: every row must have 3 entries (n_theta), row 2 has 4",
            ),
            // The first row is the one blamed, not the next one.
            (
                &|s| s.weights[0].pop().map(drop).unwrap(),
                "policy weights: every row must have 3 entries (n_theta), row 0 has 2",
            ),
            (
                &|s| s.covariance[1].pop().map(drop).unwrap(),
                "policy covariance: every row must have 3 entries (n_theta), row 1 has 2",
            ),
            (
                &|s| s.covariance[0][0] = f64::NAN,
                "policy covariance: entries must be finite, got NaN at row 0, column 0",
            ),
            (&|s| s.covariance[0][1] += 1.0, "policy covariance: covariance must be"),
        ];
        for (change, expected) in cases {
            let got = message(change);
            assert!(got.starts_with(expected), "{got}");
        }
    }
}
