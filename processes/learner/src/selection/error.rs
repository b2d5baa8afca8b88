//! Why a selector could not be built or could not accept an input.

use acps_shared::ContextSpaceError;

/// A configuration or input that a selector refuses. Each message names the parameter and the
/// accepted range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SelectionError {
    /// D-UCB's discount factor is outside (0, 1].
    #[error("D-UCB gamma must be in (0, 1], got {0}")]
    Gamma(f64),
    /// D-UCB's padding strength is not finite and positive.
    #[error("D-UCB xi must be finite and > 0, got {0}")]
    Xi(f64),
    /// D-UCB's reward bound is not finite and positive.
    #[error("D-UCB b must be finite and > 0, got {0}")]
    RewardBound(f64),
    /// D-UCB was asked for zero arms.
    #[error("D-UCB number of arms must be >= 1, got 0")]
    NoArms,
    /// An arm index that does not name one of the arms.
    #[error("arm must be < {arms} (the number of arms), got {arm}")]
    ArmOutOfRange {
        /// The offending index.
        arm: usize,
        /// The number of arms.
        arms: usize,
    },
    /// A reward that is NaN or infinite.
    #[error("reward must be finite, got {0}")]
    NonFiniteReward(f64),
    /// An empty list of training contexts.
    #[error("training contexts must number >= 1, got none")]
    NoContexts,
    /// A training context of the wrong dimension or with a non-finite coordinate.
    #[error("training context {index} must have {expected_dim} finite coordinates, got {context:?}")]
    InvalidContext {
        /// Position of the context in the list.
        index: usize,
        /// The dimension all contexts must share (that of context 0, or of the context space).
        expected_dim: usize,
        /// The offending context.
        context: Vec<f64>,
    },
    /// A round-robin order that names no arm.
    #[error("round robin order must name >= 1 arm, got none")]
    EmptyOrder,
    /// An unknown intrinsic-reward name.
    #[error("intrinsic reward must be one of best-reward, diversity, one-step-progress, monotonic-progress, got {0:?}")]
    UnknownIntrinsicReward(String),
    /// An invalid context space.
    #[error(transparent)]
    Space(#[from] ContextSpaceError),
    /// SAGG-RIAC's split threshold is zero.
    #[error("SAGG-RIAC split_threshold must be >= 1, got 0")]
    SplitThreshold,
    /// SAGG-RIAC's interest window is shorter than two returns.
    #[error("SAGG-RIAC window must be >= 2, got {0}")]
    Window(usize),
    /// SAGG-RIAC's mode probabilities are not a distribution.
    #[error(
        "SAGG-RIAC p_interest_uniform, p_global and p_near_lowest must each be in [0, 1] and sum to 1, \
         got {p_interest_uniform} + {p_global} + {p_near_lowest}"
    )]
    ModeProbabilities {
        /// Probability of a uniform goal in a region drawn by interest.
        p_interest_uniform: f64,
        /// Probability of a uniform goal in the whole space.
        p_global: f64,
        /// Probability of a goal near the lowest-return context of a region drawn by interest.
        p_near_lowest: f64,
    },
    /// SAGG-RIAC's neighbourhood radius is negative or not finite.
    #[error("SAGG-RIAC near_radius must be finite and >= 0, got {0}")]
    NearRadius(f64),
    /// A saved selector state that does not fit the selector it is restored into.
    #[error("selector state: {0}")]
    State(String),
}
