//! Which environment a task needs.

use serde::{Deserialize, Serialize};

/// Which environment a task needs: workers build environments from this and cache them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct EnvironmentSpec {
    /// The model (see `acps_models::environment`).
    pub model: u32,
    /// Model-specific small integers (for example the simulator, context dimension, n_theta).
    pub options: [u32; 3],
    /// Seed of the problem instance (for example the contextual function's matrix A).
    pub problem_seed: u64,
}
