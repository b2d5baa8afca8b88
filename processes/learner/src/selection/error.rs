//! Why a selector could not be created, or could not continue from a saved state.

use super::{DUcbCreateError, DUcbRestoreError, IntrinsicTrackerRestoreError};
use acps_shared::ContextSpaceCreateError;

/// Why a selector's constructor (or [`SelectorConfig::build`](crate::SelectorConfig::build))
/// refuses its arguments. Each message names the parameter and the accepted range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SelectorCreateError {
    /// The list of training contexts is empty.
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
    /// A round-robin order that names an arm beyond the training contexts.
    #[error("round robin order must name arms < {arms} (the number of contexts), got {arm}")]
    OrderOutOfRange {
        /// The offending arm.
        arm: usize,
        /// The number of training contexts.
        arms: usize,
    },
    /// The context space is not a valid box or ball (its fields are public, so it may not have
    /// come from a validating constructor).
    #[error(transparent)]
    Space(#[from] ContextSpaceCreateError),
    /// D-UCB refuses its parameters.
    #[error(transparent)]
    DUcb(#[from] DUcbCreateError),
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
    /// Moving-average rates that are not ordered in the unit interval.
    #[error(
        "{teacher} ema_fast and ema_slow must satisfy 0 < ema_slow < ema_fast <= 1, got ema_fast {fast}, ema_slow {slow}"
    )]
    EmaRates {
        /// Whose rates: `absolute-progress` or `retire`.
        teacher: &'static str,
        /// The fast rate.
        fast: f64,
        /// The slow rate.
        slow: f64,
    },
    /// A share of uniform choices outside [0, 1].
    #[error("{teacher} random_share must be in [0, 1], got {share}")]
    RandomShare {
        /// Whose share: `absolute-progress` or `alp-gmm`.
        teacher: &'static str,
        /// The offending share.
        share: f64,
    },
    /// A retirement band outside (0, 1].
    #[error("retire tolerance must be in (0, 1], got {0}")]
    RetireTolerance(f64),
    /// Retired contexts probed more often than every second choice.
    #[error("retire probe_every must be >= 2, got {0}")]
    ProbeEvery(usize),
    /// ALP-GMM's largest mixture outside its accepted range.
    #[error("alp-gmm max_components must be in 2..=20, got {0}")]
    MaxComponents(usize),
    /// ALP-GMM's fit rate too small for its largest mixture, or too large.
    #[error(
        "alp-gmm fit_rate must be in {fewest}..=100000 (10 points per component of the largest mixture), got {fit_rate}"
    )]
    FitRate {
        /// The offending fit rate.
        fit_rate: usize,
        /// The smallest one accepted with this `max_components`.
        fewest: usize,
    },
    /// A self-paced parameter outside its range.
    #[error("self-paced {name} must be in {range}, got {value}")]
    SelfPaced {
        /// The parameter: `zeta`, `max_alpha` or `min_std`.
        name: &'static str,
        /// The offending value.
        value: f64,
        /// The accepted range.
        range: String,
    },
}

/// Why [`ContextSelector::restore_state`](super::ContextSelector::restore_state) refuses a saved
/// state. The selector is left unchanged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SelectorRestoreError {
    /// The state was saved by a selector of another kind.
    #[error("selector state: a {state} state cannot restore a {selector} selector")]
    WrongKind {
        /// The kind of selector that saved the state.
        state: &'static str,
        /// The kind of selector it was restored into.
        selector: &'static str,
    },
    /// A round-robin position beyond the selector's order.
    #[error("selector state: round-robin position {next} is outside its order of {len} arms")]
    Position {
        /// The saved position.
        next: usize,
        /// The length of this selector's order.
        len: usize,
    },
    /// D-UCB statistics for another number of arms.
    #[error("selector state: {0}")]
    DUcb(#[from] DUcbRestoreError),
    /// Intrinsic-reward baselines for another number of arms.
    #[error("selector state: {0}")]
    Baselines(#[from] IntrinsicTrackerRestoreError),
    /// A pending choice of an arm this selector does not have.
    #[error("selector state: pending arm {arm} of a D-UCB selector over {arms} arms")]
    PendingArm {
        /// The saved arm.
        arm: usize,
        /// This selector's number of arms.
        arms: usize,
    },
    /// A SAGG-RIAC region tree that is not one of this selector's space; says why.
    #[error("selector state: SAGG-RIAC: {0}")]
    Regions(String),
    /// Retirement statistics that do not fit this selector; says why.
    #[error("selector state: retirement: {0}")]
    Retirement(String),
    /// Absolute-progress statistics of another number of contexts; says why.
    #[error("selector state: absolute progress: {0}")]
    AbsoluteProgress(String),
    /// ALP-GMM history or mixture that does not fit this selector; says why.
    #[error("selector state: ALP-GMM: {0}")]
    AlpGmm(String),
    /// A self-paced context distribution that does not fit this selector; says why.
    #[error("selector state: self-paced: {0}")]
    SelfPaced(String),
    /// A state a selector defined outside this crate refuses; its message says why.
    #[error("selector state: {0}")]
    Custom(String),
}
