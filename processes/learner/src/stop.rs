//! Stopping a long policy update half-way (Ctrl-C), with nothing of it left behind.
//!
//! The largest C-REPS update acps allows (100,000 remembered rollouts of 64 parameters) takes
//! seconds; the run's Ctrl-C flag is only looked at between outcomes. So an update asks its
//! caller between its steps whether to go on ([`Learner::tell_until`](crate::Learner::tell_until));
//! a stopped update leaves the learner as it was before the outcome that started it.

use std::convert::Infallible;

/// A policy update was stopped half-way because its caller asked; it left nothing behind.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("the policy update was interrupted")]
pub struct Interrupted;

/// What a computation asks between its steps: whether to go on. Generic so that the public
/// functions that are never stopped ([`creps::update`](crate::creps::update)) keep an error
/// type without an interruption in it.
pub(crate) trait Stop: Copy {
    /// Why it stopped.
    type Halt;

    /// `Err` once the caller asks to stop.
    fn check(self) -> Result<(), Self::Halt>;
}

/// Never stops.
#[derive(Clone, Copy)]
pub(crate) struct Never;

impl Stop for Never {
    type Halt = Infallible;

    fn check(self) -> Result<(), Infallible> {
        Ok(())
    }
}

/// Stops once the function returns true (a Ctrl-C flag's load).
impl Stop for &dyn Fn() -> bool {
    type Halt = Interrupted;

    fn check(self) -> Result<(), Interrupted> {
        if self() { Err(Interrupted) } else { Ok(()) }
    }
}
