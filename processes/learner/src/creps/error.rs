//! The errors of the C-REPS operations, one type per operation, and the argument checks that
//! produce their shared cause, [`InvalidValue`]; and [`Rejection`], why an update that ran kept the
//! old policy.

use serde::{Deserialize, Serialize};

/// A setting or argument outside its accepted range: the cause shared by the errors of the
/// C-REPS operations. Every message names the setting or argument and the accepted range.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum InvalidValue {
    /// A value that must be finite and strictly positive.
    #[error("{name} must be finite and > 0, got {value}")]
    NotPositive {
        /// The field or argument.
        name: &'static str,
        /// The rejected value.
        value: f64,
    },
    /// A value that must be finite and non-negative.
    #[error("{name} must be finite and >= 0, got {value}")]
    Negative {
        /// The field or argument.
        name: &'static str,
        /// The rejected value.
        value: f64,
    },
    /// A value outside its accepted range.
    #[error("{name} must be within [{low:e}, {high:e}], got {value:e}")]
    OutOfRange {
        /// The field or argument.
        name: &'static str,
        /// The rejected value.
        value: f64,
        /// The smallest accepted value.
        low: f64,
        /// The largest accepted value.
        high: f64,
    },
    /// A count that must be at least 1.
    #[error("{name} must be >= 1, got 0")]
    Zero {
        /// The field or argument.
        name: &'static str,
    },
    /// A vector or matrix entry that must be finite.
    #[error("{name} must be finite, got {value} at index {index}")]
    NonFinite {
        /// The argument.
        name: &'static str,
        /// The index of the first non-finite entry (column-major for matrices).
        index: usize,
        /// The entry.
        value: f64,
    },
    /// Two lengths that must agree.
    #[error("{first} ({first_len}) must equal {second} ({second_len})")]
    LengthMismatch {
        /// What the first length counts.
        first: &'static str,
        /// The first length.
        first_len: usize,
        /// What the second length counts.
        second: &'static str,
        /// The second length.
        second_len: usize,
    },
}

/// Why [`CReps::new`](super::CReps::new) refuses its configuration or arguments.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CRepsCreateError {
    /// A field of the [`CRepsConfig`](super::CRepsConfig), the context dimension, theta0 or the
    /// number of tasks is outside its range.
    #[error(transparent)]
    Invalid(#[from] InvalidValue),
    /// The feature map does not fit the context dimension or theta0.
    #[error(transparent)]
    Features(#[from] FeatureMapValidateError),
}

/// Why [`CReps::restore`](super::CReps::restore) refuses a saved state: it was saved by a
/// learner of other dimensions or another memory. The learner is left unchanged.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CRepsRestoreError {
    /// The saved policy's matrices have other shapes than this policy's.
    #[error(
        "C-REPS state: W {weights:?}, Sigma {covariance:?} and its factor {factor:?}; this policy has W {expected_weights:?} and Sigma {expected_covariance:?}"
    )]
    Shape {
        /// The saved W's (rows, columns).
        weights: (usize, usize),
        /// The saved Sigma's (rows, columns).
        covariance: (usize, usize),
        /// The saved sampling factor's (rows, columns).
        factor: (usize, usize),
        /// This policy's W shape, (n_phi, n_theta).
        expected_weights: (usize, usize),
        /// This policy's Sigma shape, (n_theta, n_theta).
        expected_covariance: (usize, usize),
    },
    /// A part of the state holds what no live learner does (a number that is not finite, a
    /// covariance its sampling factor does not give): a forged or damaged checkpoint.
    #[error("C-REPS state: {what} holds values no learner could have saved (not finite, or not consistent)")]
    Values {
        /// Which part.
        what: &'static str,
    },
    /// The saved sample memory is of another kind or size, or holds samples of other widths;
    /// says which.
    #[error("C-REPS state: the saved memory is {0}")]
    Memory(super::MemoryFitError),
    /// The saved update schedule is past this configuration's `update_every`.
    #[error("C-REPS state: {since_update} rollouts since the last update, but an update runs every {update_every}")]
    Schedule {
        /// Rollouts recorded since the last update, saved.
        since_update: usize,
        /// This learner's `update_every`.
        update_every: usize,
    },
}

/// Why [`update`](super::update) refuses to run: its settings are outside their ranges, or the
/// batch's widths do not fit the policy. (What the data makes impossible is a
/// [`Rejection`](super::Rejection) in the report instead.)
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CRepsUpdateError {
    /// A setting outside its range, or a batch width other than the policy's.
    #[error(transparent)]
    Invalid(#[from] InvalidValue),
}

/// Why a [`Batch`](super::Batch) cannot be made of the given rollouts.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum BatchCreateError {
    /// Lengths that disagree, or a non-finite entry.
    #[error(transparent)]
    Invalid(#[from] InvalidValue),
    /// No rollouts.
    #[error("a batch needs at least one rollout, got none")]
    NoSamples,
    /// The feature map does not fit the contexts' dimension.
    #[error(transparent)]
    Features(#[from] FeatureMapValidateError),
}

/// Why [`LinearGaussianPolicy::new`](super::LinearGaussianPolicy::new) refuses its matrices.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PolicyCreateError {
    /// Shapes that do not fit together, or a non-finite entry.
    #[error(transparent)]
    Invalid(#[from] InvalidValue),
    /// The covariance is not symmetric or has a clearly negative eigenvalue.
    #[error("covariance must be symmetric positive semi-definite")]
    NotPositiveSemiDefinite,
}

/// Why an update was rejected (the old policy is kept).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, thiserror::Error)]
pub enum Rejection {
    /// Fewer than two samples: the covariance estimate divides by `1 - sum d^2 = 0`.
    #[error("fewer than 2 samples, too few to estimate a covariance")]
    TooFewSamples,
    /// The dual solver reached its iteration cap before its tolerance (the report's
    /// `optimality` says how far it got).
    #[error("the dual solver reached its iteration cap before the optimum")]
    DualNotSolved,
    /// `Phi^T D Phi + ridge I` is not positive definite (ridge 0 and too few distinct contexts).
    #[error("the weighted least-squares matrix Phi^T D Phi + ridge I is not positive definite; use ridge > 0")]
    SingularRegression,
    /// The new mean coefficients W overflowed.
    #[error("the new mean coefficients W are not finite")]
    MeanNotFinite,
    /// The new covariance overflowed.
    #[error("the new covariance is not finite")]
    CovarianceNotFinite,
    /// The new covariance has a clearly negative eigenvalue.
    #[error("the new covariance is not positive semi-definite")]
    CovarianceNotPositiveSemiDefinite,
}

impl Rejection {
    /// A short kebab-case name, as in `updates.csv`.
    pub fn name(self) -> &'static str {
        match self {
            Rejection::TooFewSamples => "too-few-samples",
            Rejection::DualNotSolved => "dual-not-solved",
            Rejection::SingularRegression => "singular-regression",
            Rejection::MeanNotFinite => "mean-not-finite",
            Rejection::CovarianceNotFinite => "covariance-not-finite",
            Rejection::CovarianceNotPositiveSemiDefinite => "covariance-not-positive-semi-definite",
        }
    }
}

/// Why [`LinearGaussianPolicy::fit`](super::LinearGaussianPolicy::fit) produces no policy.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PolicyFitError {
    /// Inputs of the wrong shape, non-finite entries, negative weights or a negative ridge.
    #[error(transparent)]
    Invalid(#[from] InvalidValue),
    /// The data make the weighted fit impossible.
    #[error("update rejected: {0}")]
    Rejected(#[from] Rejection),
}

/// Why [`solve_dual`](super::solve_dual) refuses its inputs.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DualSolveError {
    /// Inconsistent or non-finite data, or a setting outside its range.
    #[error(transparent)]
    Invalid(#[from] InvalidValue),
    /// No samples.
    #[error("solve_dual needs at least one sample, got phi with 0 rows")]
    NoSamples,
}

/// Why [`evaluate_dual`](super::evaluate_dual) refuses its inputs.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DualEvaluateError {
    /// Inconsistent or non-finite data, or an argument outside its range.
    #[error(transparent)]
    Invalid(#[from] InvalidValue),
    /// No samples.
    #[error("evaluate_dual needs at least one sample, got phi with 0 rows")]
    NoSamples,
}

/// Why a feature map does not fit a context dimension or an initial mean theta0.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FeatureMapValidateError {
    /// A context dimension the feature map cannot handle.
    #[error("context_dim must be {expected} for the {feature_map} feature map, got {got}")]
    ContextDim {
        /// The feature map.
        feature_map: &'static str,
        /// The accepted dimensions.
        expected: &'static str,
        /// The rejected dimension.
        got: usize,
    },
    /// A custom map that declares zero features.
    #[error("the custom feature map's dim must be >= 1, got 0")]
    NoFeatures,
    /// A custom map whose output at the zero context has another length than it declares.
    #[error("the custom feature map returns {got} features at the zero context, but declares dim {dim}")]
    Length {
        /// The length of the output at the zero context.
        got: usize,
        /// The declared dimension.
        dim: usize,
    },
    /// A custom constant-feature index outside the feature vector.
    #[error("the custom feature map's constant index must be < its dim ({dim}), got {index}")]
    ConstantIndex {
        /// The rejected index.
        index: usize,
        /// The declared feature dimension.
        dim: usize,
    },
    /// A custom "constant" feature that is not 1.
    #[error("the custom feature map's constant feature (index {index}) must be 1, got {value} at the zero context")]
    ConstantValue {
        /// The declared constant index.
        index: usize,
        /// Its value at the zero context.
        value: f64,
    },
    /// A non-zero theta0 with a feature map that has no constant feature.
    #[error(
        "theta0 must be all zeros when the custom feature map has no constant feature (the initial mean W^T phi(s) could not equal theta0 for every s)"
    )]
    NoConstantFeature,
}

/// `value` must be finite and > 0.
pub(crate) fn check_positive(name: &'static str, value: f64) -> Result<(), InvalidValue> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(InvalidValue::NotPositive { name, value })
    }
}

/// `value` must be finite and >= 0.
pub(crate) fn check_non_negative(name: &'static str, value: f64) -> Result<(), InvalidValue> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(InvalidValue::Negative { name, value })
    }
}

/// `value` must be >= 1.
pub(crate) fn check_at_least_one(name: &'static str, value: usize) -> Result<(), InvalidValue> {
    if value >= 1 {
        Ok(())
    } else {
        Err(InvalidValue::Zero { name })
    }
}

/// Every entry of `values` must be finite.
pub(crate) fn check_finite(name: &'static str, values: &[f64]) -> Result<(), InvalidValue> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(InvalidValue::NonFinite {
            name,
            index,
            value: values[index],
        }),
        None => Ok(()),
    }
}

/// Two lengths that must agree.
pub(crate) fn check_len(
    first: &'static str,
    first_len: usize,
    second: &'static str,
    second_len: usize,
) -> Result<(), InvalidValue> {
    if first_len == second_len {
        Ok(())
    } else {
        Err(InvalidValue::LengthMismatch {
            first,
            first_len,
            second,
            second_len,
        })
    }
}

/// `value` must lie in `[low, high]` (NaN does not).
pub(crate) fn check_range(name: &'static str, value: f64, (low, high): (f64, f64)) -> Result<(), InvalidValue> {
    if (low..=high).contains(&value) {
        Ok(())
    } else {
        Err(InvalidValue::OutOfRange { name, value, low, high })
    }
}
