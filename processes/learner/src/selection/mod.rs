//! Context selection: which training context to practise next.
//!
//! Every strategy implements [`ContextSelector`]; the learner core only talks to that trait, so a
//! new teacher plugs in without touching the learner loop.
//!
//! - [`BanditSelector`]: the paper's proposal, [`DUcb`] over the training contexts rewarded with
//!   an [`IntrinsicReward`] (Sec. 3).
//! - [`RoundRobin`], [`UniformDiscrete`], [`UniformContinuous`]: the paper's baselines.
//! - [`SaggRiac`]: goal generation by competence progress in regions (Sec. 2.2, 4).

mod bandit;
mod baselines;
mod ducb;
mod error;
mod intrinsic;
mod sagg_riac;
mod validate;

pub use bandit::BanditSelector;
pub use baselines::{RoundRobin, UniformContinuous, UniformDiscrete};
pub use ducb::{DUcb, DUcbConfig};
pub use error::SelectionError;
pub use intrinsic::{FirstVisit, IntrinsicReward, IntrinsicTracker};
pub use sagg_riac::{Goal, GoalMode, RegionSummary, SaggRiac, SaggRiacConfig};

use rand::RngCore;

/// A selected training context.
#[derive(Debug, Clone, PartialEq)]
pub struct Choice {
    /// Index of the chosen training context, or `None` for a context drawn from the continuous
    /// space that is not one of the training contexts.
    pub arm: Option<usize>,
    /// The context itself.
    pub context: Vec<f64>,
}

/// A context-selection strategy (the paper's pi_beta).
///
/// The learner calls [`choose`](ContextSelector::choose) once per training task, in task order,
/// and [`observe`](ContextSelector::observe) once per consumed training outcome, also in task
/// order. With several tasks in flight, `choose` runs before the outcomes of the pending tasks are
/// observed.
pub trait ContextSelector: Send {
    /// Pick the next training context. All randomness must come from `rng`.
    fn choose(&mut self, rng: &mut dyn RngCore) -> Choice;

    /// Learn from the return `reward` obtained for `choice`.
    fn observe(&mut self, choice: &Choice, reward: f64);

    /// The return of the initial greedy policy in training context `arm`, known before training
    /// starts. Progress heuristics use it as the baseline of a context's first visit.
    fn prime(&mut self, _arm: usize, _initial_return: f64) {}

    /// Whether this selector wants [`prime`](ContextSelector::prime) calls, so the learner knows
    /// whether the baseline rollouts are worth running.
    fn wants_initial_returns(&self) -> bool {
        false
    }
}
