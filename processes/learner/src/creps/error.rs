//! The error type of the C-REPS module and the argument checks that produce it.

/// A rejected configuration or argument, or a failed numerical step. Every message names the
/// offending field or argument and the accepted range.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CRepsError {
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
    /// `solve_dual` without samples.
    #[error("solve_dual needs at least one sample, got phi with 0 rows")]
    NoSamples,
    /// A covariance that is not symmetric positive semi-definite.
    #[error("{name} must be symmetric positive semi-definite")]
    NotPositiveSemiDefinite {
        /// The matrix.
        name: &'static str,
    },
    /// A weighted fit the data makes impossible.
    #[error("update rejected: {0}")]
    Rejected(#[from] super::update::Rejection),
    /// A saved state that does not fit this learner (see [`CReps::restore`](super::CReps::restore)).
    #[error("C-REPS state: {0}")]
    State(String),
}

/// `value` must be finite and > 0.
pub(crate) fn check_positive(name: &'static str, value: f64) -> Result<(), CRepsError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(CRepsError::NotPositive { name, value })
    }
}

/// `value` must be finite and >= 0.
pub(crate) fn check_non_negative(name: &'static str, value: f64) -> Result<(), CRepsError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(CRepsError::Negative { name, value })
    }
}

/// `value` must be >= 1.
pub(crate) fn check_at_least_one(name: &'static str, value: usize) -> Result<(), CRepsError> {
    if value >= 1 {
        Ok(())
    } else {
        Err(CRepsError::Zero { name })
    }
}

/// Every entry of `values` must be finite.
pub(crate) fn check_finite(name: &'static str, values: &[f64]) -> Result<(), CRepsError> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(CRepsError::NonFinite {
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
) -> Result<(), CRepsError> {
    if first_len == second_len {
        Ok(())
    } else {
        Err(CRepsError::LengthMismatch {
            first,
            first_len,
            second,
            second_len,
        })
    }
}

/// `value` must lie in `[low, high]` (NaN does not).
pub(crate) fn check_range(name: &'static str, value: f64, (low, high): (f64, f64)) -> Result<(), CRepsError> {
    if (low..=high).contains(&value) {
        Ok(())
    } else {
        Err(CRepsError::OutOfRange { name, value, low, high })
    }
}
