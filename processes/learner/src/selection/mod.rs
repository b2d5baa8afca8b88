//! Context selection: which training context to practise next.
//!
//! Every strategy implements [`ContextSelector`]; the learner core only talks to that trait, so a
//! new teacher plugs in without touching the learner loop. A selector's evolving state is a
//! [`SelectorState`], the checkpoints' encoding of it.
//!
//! - [`paper`]: the paper's selectors (Fabisch & Metzen 2014): its proposal [`BanditSelector`],
//!   [`DUcb`] over the training contexts rewarded with an [`IntrinsicReward`] (Sec. 3); its
//!   baselines [`RoundRobin`], [`UniformDiscrete`] and [`UniformContinuous`]; and [`SaggRiac`],
//!   goal generation by competence progress in regions (Baranes & Oudeyer 2013; Sec. 2.2, 4).
//! - [`beyond`]: teachers beyond the paper (issue 22): [`AbsoluteProgress`] (Kanitscheider et
//!   al. 2021), [`AlpGmm`] (Portelas et al. 2019), [`SelfPaced`] (SPRL, Klink et al. 2019), and
//!   [`RetireConfig`], the retirement of solved contexts the paper's outlook asks for (Sec. 6).
//!
//! Every public name of both is re-exported here: `selection::DUcb` is `selection::paper::DUcb`.
//! Shared by both: the errors ([`SelectorCreateError`], [`SelectorRestoreError`]) and, inside
//! the crate, the checks of contexts and spaces (`validate`) and projections onto the space
//! (`geometry`).

pub mod beyond;
mod error;
mod geometry;
pub mod paper;
mod validate;

pub use beyond::*;
pub use error::{SelectorCreateError, SelectorRestoreError};
pub use paper::*;

use crate::creps::PacedContexts;
use rand::RngCore;
use serde::{Deserialize, Serialize};

/// A selected training context.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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

    /// The context distribution C-REPS moves together with the policy, for a selector that has
    /// one (SPRL): the learner then runs every C-REPS update through
    /// [`CReps::record_paced`](crate::creps::CReps::record_paced).
    fn paced(&mut self) -> Option<&mut dyn PacedContexts> {
        None
    }

    /// Everything about this selector that changes while it runs, for a checkpoint. Whatever
    /// its constructor derives from the configuration and the problem is left out.
    fn save_state(&self) -> SelectorState;

    /// Continue from `state`, saved by [`save_state`](ContextSelector::save_state) of a selector
    /// built the same way. A state of another kind of selector, or one that does not fit this
    /// selector's arms or space, is refused and leaves the selector unchanged.
    fn restore_state(&mut self, state: SelectorState) -> Result<(), SelectorRestoreError>;
}

/// The evolving state of a context selector (see [`ContextSelector::save_state`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum SelectorState {
    /// [`RoundRobin`]: the position in its cycle.
    RoundRobin {
        /// Index into the order of the next arm.
        next: usize,
    },
    /// [`UniformDiscrete`]: nothing; its choices come from the learner's random stream only.
    UniformDiscrete,
    /// [`UniformContinuous`]: nothing; its choices come from the learner's random stream only.
    UniformContinuous,
    /// [`BanditSelector`]: the bandit's statistics, the intrinsic-reward baselines and the
    /// choices not yet observed.
    Bandit {
        /// The bandit's statistics.
        ducb: DUcbState,
        /// Per-arm intrinsic-reward baselines.
        baselines: Vec<Option<f64>>,
        /// Arms chosen but not yet observed, oldest first.
        pending: Vec<usize>,
        /// The retired contexts and their statistics, when the selector retires contexts.
        retirement: Option<RetirementState>,
    },
    /// [`SaggRiac`]: the region tree with its samples.
    SaggRiac(SaggRiacState),
    /// [`AbsoluteProgress`]: the moving averages, the initial sweep and the retired contexts.
    AbsoluteProgress(AbsoluteProgressState),
    /// [`AlpGmm`]: the contexts seen with their returns, the points of the next fit and the
    /// mixture of the last.
    AlpGmm(AlpGmmState),
    /// [`SelfPaced`]: the context distribution and the number of updates.
    SelfPaced(SelfPacedState),
    /// A selector defined elsewhere, in an encoding of its own.
    Custom(Vec<u8>),
}

impl SelectorState {
    /// The kind of selector the state belongs to, for messages.
    pub fn kind(&self) -> &'static str {
        match self {
            SelectorState::RoundRobin { .. } => "round-robin",
            SelectorState::UniformDiscrete => "uniform over the training contexts",
            SelectorState::UniformContinuous => "uniform over the context space",
            SelectorState::Bandit { .. } => "D-UCB",
            SelectorState::SaggRiac(_) => "SAGG-RIAC",
            SelectorState::AbsoluteProgress(_) => "absolute progress",
            SelectorState::AlpGmm(_) => "ALP-GMM",
            SelectorState::SelfPaced(_) => "self-paced",
            SelectorState::Custom(_) => "custom",
        }
    }

    /// The error for restoring this state into a selector of kind `expected`.
    pub(crate) fn wrong_kind(&self, expected: &'static str) -> SelectorRestoreError {
        SelectorRestoreError::WrongKind {
            state: self.kind(),
            selector: expected,
        }
    }
}
