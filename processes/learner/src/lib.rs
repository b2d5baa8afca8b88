//! The acps learner: C-REPS (paper Appendix A), context selection (D-UCB with intrinsic rewards,
//! baselines, SAGG-RIAC; paper Sections 2.2 and 3) and the deterministic ask/tell core that every
//! way of running an experiment drives.
#![warn(missing_docs)]

pub mod creps;
pub mod fleet;
pub mod learner;
pub mod method;
pub mod selection;

pub use learner::{
    Episode, Evaluation, Learner, LearnerConfig, LearnerError, LearnerStats, LearningProgress, TellError,
    run_in_process, run_in_process_observed,
};
pub use method::{Method, SelectorConfig, UnknownMethod};
