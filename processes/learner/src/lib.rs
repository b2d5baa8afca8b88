//! The acps learner: C-REPS (paper Appendix A), context selection (D-UCB with intrinsic rewards,
//! baselines, SAGG-RIAC; paper Sections 2.2 and 3) and the deterministic ask/tell core that every
//! way of running an experiment drives.
#![warn(missing_docs)]

pub mod checkpoint;
pub mod creps;
pub mod learner;
pub mod method;
pub mod selection;

pub use learner::{
    Episode, Evaluation, Learner, LearnerConfig, LearnerCreateError, LearnerRestoreError, LearnerSnapshot,
    LearnerStats, LearnerTellError, LearningProgress, UpdateRecord, run_in_process,
};
pub use method::{BanditConfig, Baseline, Method, MethodParseError, SelectorConfig};
