//! The acps learner: active contextual policy search (Fabisch & Metzen, JMLR 2014) as a
//! library. You bring a [`Problem`](acps_shared::Problem) and something that performs rollouts;
//! a [`Learner`] asks for tasks and is told their outcomes (see its docs for a complete example).
//!
//! - [`learner`]: the deterministic ask/tell core, [`Learner`] and [`LearnerConfig`].
//! - [`method`]: the methods by name ([`Method`]) and their configurations ([`SelectorConfig`]:
//!   baselines, D-UCB with an intrinsic reward, SAGG-RIAC, and beyond the paper absolute
//!   progress, ALP-GMM, self-paced and the retirement of solved contexts).
//! - [`selection`]: the context selectors themselves and the
//!   [`ContextSelector`](selection::ContextSelector) trait for selectors of your own; the
//!   paper's in [`selection::paper`] (D-UCB, intrinsic rewards, baselines, SAGG-RIAC; paper
//!   Sections 2.2 and 3), the later teachers in [`selection::beyond`] (absolute progress,
//!   ALP-GMM, self-paced, retirement).
//! - [`creps`]: contextual relative entropy policy search (paper Appendix A): the upper-level
//!   policy, its sample memory and its update; and SPRL's joint update of the policy with a
//!   context distribution ([`creps::joint`]).
//! - [`search`]: which of the two a learner runs ([`SearchConfig`]).
//! - [`ccmaes`]: contextual CMA-ES (Abdolmaleki et al. 2017), the second upper-level learner,
//!   with the same policy class.
//! - [`checkpoint`]: a learner's state in a file, to resume a run bit for bit.
//!
//! Every fallible operation has an error type of its own, named after the object and the
//! operation (`LearnerCreateError`, `SelectorCreateError`, `CRepsUpdateError`, ...).
#![warn(missing_docs)]

pub mod ccmaes;
pub mod checkpoint;
pub mod creps;
pub mod learner;
pub mod method;
pub mod search;
pub mod selection;
mod stop;

pub use learner::{
    Episode, Evaluation, Learner, LearnerConfig, LearnerCreateError, LearnerRestoreError, LearnerSnapshot,
    LearnerStats, LearnerTellError, LearningProgress, RecordCounts, Records, UpdateRecord, run_in_process,
};
pub use method::{BanditConfig, Baseline, Method, MethodParseError, SelectorConfig};
pub use search::{Search, SearchConfig, SearchReport, SearchState};
pub use stop::Interrupted;
