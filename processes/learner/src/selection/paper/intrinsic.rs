//! Intrinsic rewards r_beta = f(r - b_s) of the paper's Section 3.2, with their per-context
//! baselines b_s.

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// A name that [`IntrinsicReward::from_str`] does not know.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("intrinsic reward must be one of best-reward, diversity, one-step-progress, monotonic-progress, got {0:?}")]
pub struct IntrinsicRewardParseError(pub String);

/// Why [`IntrinsicTracker::prime`] or [`IntrinsicTracker::reward`] refuses an arm: it does not
/// name one of the tracker's arms. The tracker is left unchanged.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("arm must be < {arms} (the number of arms), got {arm}")]
pub struct IntrinsicTrackerUpdateError {
    /// The offending index.
    pub arm: usize,
    /// The number of arms.
    pub arms: usize,
}

/// Why [`IntrinsicTracker::restore_baselines`] refuses saved baselines: they are of a tracker
/// with another number of arms. The tracker is left unchanged.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{saved} intrinsic-reward baselines, this tracker has {arms} arms")]
pub struct IntrinsicTrackerRestoreError {
    /// The number of saved baselines.
    pub saved: usize,
    /// This tracker's number of arms.
    pub arms: usize,
}

/// Which proxy for learning progress the bandit maximises.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum IntrinsicReward {
    /// r_beta = r (Sec. 3.2.1).
    BestReward,
    /// r_beta = -r (Sec. 3.2.2).
    Diversity,
    /// r_beta = r - (previous return in the same context) (Sec. 3.2.3).
    OneStepProgress,
    /// r_beta = max(0, r - max of the previous returns in the same context) (Sec. 3.2.4).
    MonotonicProgress,
}

impl IntrinsicReward {
    /// Every heuristic, in the paper's order.
    pub const ALL: [Self; 4] = [
        Self::BestReward,
        Self::Diversity,
        Self::OneStepProgress,
        Self::MonotonicProgress,
    ];

    /// The kebab-case name, as in configuration files.
    pub fn name(self) -> &'static str {
        match self {
            Self::BestReward => "best-reward",
            Self::Diversity => "diversity",
            Self::OneStepProgress => "one-step-progress",
            Self::MonotonicProgress => "monotonic-progress",
        }
    }

    /// Whether the heuristic compares a return with earlier returns in the same context.
    pub fn has_baseline(self) -> bool {
        matches!(self, Self::OneStepProgress | Self::MonotonicProgress)
    }
}

impl fmt::Display for IntrinsicReward {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for IntrinsicReward {
    type Err = IntrinsicRewardParseError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|h| h.name() == s)
            .ok_or_else(|| IntrinsicRewardParseError(s.to_owned()))
    }
}

/// What a progress heuristic compares the first return of a context with. The paper does not
/// say (project notes, algorithms.md section 4), and the choice matters: in the Section 4 model,
/// the initial-return rule reproduces the narrative of the paper's Fig. 2 (monotonic progress
/// first focuses on the context that learns fastest), whereas scoring first visits 0 makes
/// D-UCB stick to the contexts in index order.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FirstVisit {
    /// The baseline starts at the return of the initial greedy policy in that context, given
    /// through [`ContextSelector::prime`](crate::selection::ContextSelector::prime). A context that was
    /// never primed falls back to [`Zero`](Self::Zero).
    #[default]
    InitialReturn,
    /// The first visit scores r_beta = 0 and only sets the baseline.
    Zero,
    /// The first visit scores the optimistic value given to the tracker (D-UCB's reward bound
    /// B) and sets the baseline.
    Optimistic,
}

/// Turns returns into intrinsic rewards, keeping each context's baseline.
#[derive(Debug, Clone)]
pub struct IntrinsicTracker {
    heuristic: IntrinsicReward,
    first_visit: FirstVisit,
    /// What a first visit scores under [`FirstVisit::Optimistic`].
    optimistic_value: f64,
    /// Per arm: the previous return (1-step) or the running maximum of the previous returns
    /// (monotonic); `None` until the arm is primed or first visited. Unused otherwise.
    baselines: Vec<Option<f64>>,
}

impl IntrinsicTracker {
    /// A tracker for `arms` contexts, none of which has a baseline yet.
    pub fn new(heuristic: IntrinsicReward, first_visit: FirstVisit, arms: usize, optimistic_value: f64) -> Self {
        Self {
            heuristic,
            first_visit,
            optimistic_value,
            baselines: vec![None; arms],
        }
    }

    /// Whether [`prime`](Self::prime) has any effect.
    pub fn wants_initial_returns(&self) -> bool {
        self.heuristic.has_baseline() && self.first_visit == FirstVisit::InitialReturn
    }

    /// Start `arm`'s baseline at the initial policy's return. Ignored when initial returns are
    /// not wanted, for a non-finite return, or once the arm has a baseline.
    pub fn prime(&mut self, arm: usize, initial_return: f64) -> Result<(), IntrinsicTrackerUpdateError> {
        let wanted = self.wants_initial_returns();
        let arms = self.baselines.len();
        let baseline = self
            .baselines
            .get_mut(arm)
            .ok_or(IntrinsicTrackerUpdateError { arm, arms })?;
        if wanted && initial_return.is_finite() && baseline.is_none() {
            *baseline = Some(initial_return);
        }
        Ok(())
    }

    /// The intrinsic reward for return `r` in `arm`; the baseline is updated afterwards, so a
    /// return is never part of its own baseline.
    pub fn reward(&mut self, arm: usize, r: f64) -> Result<f64, IntrinsicTrackerUpdateError> {
        let arms = self.baselines.len();
        let baseline = self
            .baselines
            .get_mut(arm)
            .ok_or(IntrinsicTrackerUpdateError { arm, arms })?;
        let first = if self.first_visit == FirstVisit::Optimistic {
            self.optimistic_value
        } else {
            0.0
        };
        Ok(match self.heuristic {
            IntrinsicReward::BestReward => r,
            IntrinsicReward::Diversity => -r,
            IntrinsicReward::OneStepProgress => {
                let progress = baseline.map_or(first, |previous| r - previous);
                *baseline = Some(r);
                progress
            }
            IntrinsicReward::MonotonicProgress => {
                let progress = baseline.map_or(first, |best| (r - best).max(0.0));
                *baseline = Some(baseline.map_or(r, |best| best.max(r)));
                progress
            }
        })
    }

    /// The heuristic.
    pub fn heuristic(&self) -> IntrinsicReward {
        self.heuristic
    }

    /// The first-visit rule.
    pub fn first_visit(&self) -> FirstVisit {
        self.first_visit
    }

    /// `arm`'s current baseline, if it has one (always `None` for best reward and diversity).
    pub fn baseline(&self, arm: usize) -> Option<f64> {
        self.baselines.get(arm).copied().flatten()
    }

    /// Every arm's baseline, for a checkpoint.
    pub fn baselines(&self) -> &[Option<f64>] {
        &self.baselines
    }

    /// Continue from saved baselines, one per arm.
    pub fn restore_baselines(&mut self, baselines: Vec<Option<f64>>) -> Result<(), IntrinsicTrackerRestoreError> {
        if baselines.len() != self.baselines.len() {
            return Err(IntrinsicTrackerRestoreError {
                saved: baselines.len(),
                arms: self.baselines.len(),
            });
        }
        self.baselines = baselines;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::de::IntoDeserializer;
    use serde::de::value::{Error as ValueError, StrDeserializer};

    const RETURNS: [f64; 4] = [1.0, 3.0, 2.0, 5.0];

    /// Rewards for RETURNS in arm 0, with arm 0 primed at `primed` (if any).
    fn rewards(heuristic: IntrinsicReward, first_visit: FirstVisit, primed: Option<f64>) -> Vec<f64> {
        let mut tracker = IntrinsicTracker::new(heuristic, first_visit, 2, 7.0);
        if let Some(r0) = primed {
            tracker.prime(0, r0).unwrap();
        }
        RETURNS.iter().map(|&r| tracker.reward(0, r).unwrap()).collect()
    }

    #[test]
    fn hand_computed_sequences() {
        use FirstVisit::{InitialReturn, Optimistic, Zero};
        use IntrinsicReward::*;
        for first_visit in [InitialReturn, Zero, Optimistic] {
            for primed in [None, Some(0.5)] {
                // No baseline: priming and the first-visit rule change nothing.
                assert_eq!(rewards(BestReward, first_visit, primed), [1.0, 3.0, 2.0, 5.0]);
                assert_eq!(rewards(Diversity, first_visit, primed), [-1.0, -3.0, -2.0, -5.0]);
                let mut tracker = IntrinsicTracker::new(BestReward, first_visit, 1, 7.0);
                tracker.prime(0, 0.5).unwrap();
                assert_eq!(tracker.baseline(0), None);
            }
        }
        // First visit scores 0: with the Zero rule, or with InitialReturn but never primed.
        for (first_visit, primed) in [(Zero, None), (Zero, Some(0.5)), (InitialReturn, None)] {
            // 1-step: 0, 3-1, 2-3, 5-2.
            assert_eq!(rewards(OneStepProgress, first_visit, primed), [0.0, 2.0, -1.0, 3.0]);
            // Monotonic: 0, max(0, 3-1), max(0, 2-3), max(0, 5-max(1,3,2)).
            assert_eq!(rewards(MonotonicProgress, first_visit, primed), [0.0, 2.0, 0.0, 2.0]);
        }
        // Optimistic: the first visit scores the optimistic value (7 here), priming is ignored.
        for primed in [None, Some(0.5)] {
            assert_eq!(rewards(OneStepProgress, Optimistic, primed), [7.0, 2.0, -1.0, 3.0]);
            assert_eq!(rewards(MonotonicProgress, Optimistic, primed), [7.0, 2.0, 0.0, 2.0]);
        }
        // Primed at 0.5: the first visit is compared with the initial return.
        assert_eq!(
            rewards(OneStepProgress, InitialReturn, Some(0.5)),
            [0.5, 2.0, -1.0, 3.0]
        );
        assert_eq!(
            rewards(MonotonicProgress, InitialReturn, Some(0.5)),
            [0.5, 2.0, 0.0, 2.0]
        );
        // Primed above every return: monotonic progress never pays, 1-step goes negative.
        assert_eq!(
            rewards(MonotonicProgress, InitialReturn, Some(6.0)),
            [0.0, 0.0, 0.0, 0.0]
        );
        assert_eq!(
            rewards(OneStepProgress, InitialReturn, Some(6.0)),
            [-5.0, 2.0, -1.0, 3.0]
        );
    }

    #[test]
    fn baselines_are_per_arm_and_priming_only_sets_a_missing_one() {
        let mut tracker = IntrinsicTracker::new(IntrinsicReward::MonotonicProgress, FirstVisit::InitialReturn, 2, 7.0);
        assert!(tracker.wants_initial_returns());
        tracker.prime(1, 2.0).unwrap();
        assert_eq!(tracker.reward(0, 4.0), Ok(0.0));
        assert_eq!(tracker.reward(1, 3.0), Ok(1.0));
        tracker.prime(1, -10.0).unwrap();
        assert_eq!(
            tracker.baseline(1),
            Some(3.0),
            "a late prime must not overwrite a baseline"
        );
        assert_eq!(tracker.baseline(0), Some(4.0));
        assert_eq!(
            tracker.reward(2, 1.0).unwrap_err().to_string(),
            "arm must be < 2 (the number of arms), got 2"
        );
        assert!(tracker.prime(5, 1.0).is_err());
    }

    #[test]
    fn initial_returns_are_wanted_only_by_progress_heuristics_with_the_initial_return_rule() {
        for heuristic in IntrinsicReward::ALL {
            for first_visit in [FirstVisit::InitialReturn, FirstVisit::Zero, FirstVisit::Optimistic] {
                let wanted = IntrinsicTracker::new(heuristic, first_visit, 1, 7.0).wants_initial_returns();
                assert_eq!(
                    wanted,
                    heuristic.has_baseline() && first_visit == FirstVisit::InitialReturn
                );
            }
        }
        assert_eq!(FirstVisit::default(), FirstVisit::InitialReturn);
    }

    #[test]
    fn names_parse_display_and_deserialize_alike() {
        let names = ["best-reward", "diversity", "one-step-progress", "monotonic-progress"];
        for (heuristic, name) in IntrinsicReward::ALL.into_iter().zip(names) {
            assert_eq!(heuristic.name(), name);
            assert_eq!(heuristic.to_string(), name);
            assert_eq!(name.parse::<IntrinsicReward>(), Ok(heuristic));
            let deserializer: StrDeserializer<'_, ValueError> = name.into_deserializer();
            assert_eq!(IntrinsicReward::deserialize(deserializer), Ok(heuristic));
        }
        assert_eq!(
            "monotonic".parse::<IntrinsicReward>().unwrap_err().to_string(),
            "intrinsic reward must be one of best-reward, diversity, one-step-progress, \
             monotonic-progress, got \"monotonic\""
        );
        for (rule, name) in [
            (FirstVisit::InitialReturn, "initial-return"),
            (FirstVisit::Zero, "zero"),
            (FirstVisit::Optimistic, "optimistic"),
        ] {
            let deserializer: StrDeserializer<'_, ValueError> = name.into_deserializer();
            assert_eq!(FirstVisit::deserialize(deserializer), Ok(rule));
        }
    }
}
