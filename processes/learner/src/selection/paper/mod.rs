//! The context selectors of the paper (Fabisch & Metzen, JMLR 2014), SAGG-RIAC included, which
//! the paper compares against.
//!
//! - `ducb`: [`DUcb`], discounted UCB (Algorithm 1).
//! - `intrinsic`: the [`IntrinsicReward`]s D-UCB is rewarded with, and their per-context
//!   baselines ([`IntrinsicTracker`]; Sec. 3.2).
//! - `bandit`: [`BanditSelector`], the paper's proposal: D-UCB over the training contexts with
//!   an intrinsic reward (Sec. 3.3).
//! - `baselines`: [`RoundRobin`], [`UniformDiscrete`] and [`UniformContinuous`], the paper's
//!   non-adaptive baselines (Sec. 4, 5).
//! - `sagg_riac`: [`SaggRiac`], goal generation by competence progress in regions (Baranes &
//!   Oudeyer 2013), as the paper describes it (Sec. 2.2, 4).

mod bandit;
mod baselines;
mod ducb;
mod intrinsic;
mod sagg_riac;

pub use bandit::BanditSelector;
pub use baselines::{RoundRobin, UniformContinuous, UniformDiscrete};
pub use ducb::{DUcb, DUcbConfig, DUcbCreateError, DUcbRestoreError, DUcbState, DUcbUpdateError};
pub use intrinsic::{
    FirstVisit, IntrinsicReward, IntrinsicRewardParseError, IntrinsicTracker, IntrinsicTrackerRestoreError,
    IntrinsicTrackerUpdateError,
};
pub use sagg_riac::{Goal, GoalMode, RegionSummary, SaggRiac, SaggRiacConfig, SaggRiacState};
