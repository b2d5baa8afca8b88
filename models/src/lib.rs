//! The environments of the paper's experiments, for acps.
//!
//! - [`learning_model`]: the artificial model of a contextual learning process (paper Sec. 4).
//! - [`contextual_function`]: the contextual function optimisation problem (paper Sec. 5.1).
//! - [`benchmark`]: BOLeRo's contextual sphere and Rosenbrock (the C-CMA-ES paper's benchmark).
//! - [`throw`]: the PA-10 throwing task (paper Sec. 5.2): the throw's DMPs and its environment.
//! - [`robot`]: the arm's description file and kinematics.
//! - [`rapier_sim`]: the arm simulated as a rapier3d multibody.
//! - [`dmp`]: dynamic movement primitives, as the throw chains them.
//! - [`trajectory`]: sampled joint trajectories.
//! - [`targets`]: the grid of targets and the dartboard's fields.
//! - [`environment`]: building any of these from an [`EnvironmentSpec`](acps_shared::EnvironmentSpec).
//!
//! The models' errors share [`InvalidArgument`] as their cause.
#![warn(missing_docs)]

pub mod benchmark;
pub mod contextual_function;
pub mod dmp;
pub mod environment;
pub mod learning_model;
pub mod rapier_sim;
pub mod robot;
pub mod targets;
pub mod throw;
pub mod trajectory;

/// A parameter or argument outside its accepted range: the cause the models' errors share.
/// The message names it and what it accepts.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InvalidArgument {
    /// A value outside its accepted range.
    #[error("{name} must be {accepted}, got {got}")]
    OutOfRange {
        /// The parameter's or argument's name.
        name: &'static str,
        /// The accepted range, in words.
        accepted: &'static str,
        /// The value that was given.
        got: String,
    },
    /// A vector or matrix of the wrong size.
    #[error("{name} must have {expected} entries, got {got}")]
    WrongLength {
        /// The argument's name.
        name: &'static str,
        /// The required size.
        expected: usize,
        /// The given size.
        got: usize,
    },
}

/// `Ok` when `ok`, else [`InvalidArgument::OutOfRange`].
pub(crate) fn check(
    ok: bool,
    name: &'static str,
    accepted: &'static str,
    got: impl std::fmt::Display,
) -> Result<(), InvalidArgument> {
    if ok {
        Ok(())
    } else {
        Err(InvalidArgument::OutOfRange {
            name,
            accepted,
            got: got.to_string(),
        })
    }
}

/// `Ok` when the lengths agree, else [`InvalidArgument::WrongLength`].
pub(crate) fn check_len(name: &'static str, expected: usize, got: usize) -> Result<(), InvalidArgument> {
    if expected == got {
        Ok(())
    } else {
        Err(InvalidArgument::WrongLength { name, expected, got })
    }
}
