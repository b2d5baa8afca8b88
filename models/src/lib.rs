//! Environments for acps.
//!
//! - [`learning_model`]: the artificial model of a contextual learning process (paper Section 4).
//! - [`contextual_function`]: the contextual function optimisation problem (paper Section 5.1).
#![warn(missing_docs)]

pub mod contextual_function;
pub mod dmp;
pub mod environment;
pub mod learning_model;
pub mod rapier_sim;
pub mod robot;
pub mod targets;
pub mod throw;
pub mod trajectory;

/// A model parameter outside its accepted range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{model}: {field} must be {accepted}, got {got}")]
pub struct ModelError {
    /// The model the parameter belongs to.
    pub model: &'static str,
    /// The parameter's name.
    pub field: &'static str,
    /// The accepted range, in words.
    pub accepted: &'static str,
    /// The value that was given.
    pub got: String,
}

pub(crate) fn check(
    ok: bool,
    model: &'static str,
    field: &'static str,
    accepted: &'static str,
    got: impl std::fmt::Display,
) -> Result<(), ModelError> {
    if ok {
        Ok(())
    } else {
        Err(ModelError {
            model,
            field,
            accepted,
            got: got.to_string(),
        })
    }
}
