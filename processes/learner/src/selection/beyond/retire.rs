//! Retiring solved contexts (the paper's outlook, Sec. 6: D-UCB "assumes that the progress could
//! rise again", so it keeps sampling tasks that are solved).
//!
//! Every context keeps a fast and a slow moving average of its return ([`ReturnAverages`]). A
//! context *converges* once it has been visited `1 / slow` times and its progress |fast - slow|
//! is at most `tolerance` times the spread of the contexts' slow averages (largest minus
//! smallest): a plateau, measured against how far apart the contexts are, so the test does not
//! depend on the units or the offset of the returns. A converged context is retired, unless it
//! is the last active one, and remembers its slow average as its plateau.
//!
//! A retired context is no longer chosen by its selector, but every `probe_every`-th choice
//! goes to one retired context (in turn, cyclically by index) as a probe. Its return updates its
//! averages; once the fast average has fallen below the plateau by more than the same band
//! (tolerance times the spread), the policy has forgotten it and it is active again. A rise
//! does not bring it back: a context that improves without being practised does not need
//! practice.

use super::progress::{EmaRates, ReturnAverages};
use crate::selection::{SelectorCreateError, SelectorRestoreError};
use serde::{Deserialize, Serialize};

/// When a context counts as solved, and how retired contexts are watched (see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RetireConfig {
    /// The moving averages the test is made on.
    pub rates: EmaRates,
    /// The band, as a fraction of the spread of the contexts' returns, in (0, 1]: progress
    /// within it is a plateau, a fall beyond it brings a retired context back.
    pub tolerance: f64,
    /// Every this many choices one retired context is probed (>= 2; while none is retired, no
    /// choice is a probe).
    pub probe_every: usize,
}

impl Default for RetireConfig {
    /// [`EmaRates::default`], a band of 5% of the spread, a probe every 10 choices.
    fn default() -> Self {
        Self {
            rates: EmaRates::default(),
            tolerance: 0.05,
            probe_every: 10,
        }
    }
}

impl RetireConfig {
    /// Check every parameter's range.
    pub fn validate(&self) -> Result<(), SelectorCreateError> {
        self.rates.validate("retire")?;
        if !(self.tolerance > 0.0 && self.tolerance <= 1.0) {
            return Err(SelectorCreateError::RetireTolerance(self.tolerance));
        }
        if self.probe_every < 2 {
            return Err(SelectorCreateError::ProbeEvery(self.probe_every));
        }
        Ok(())
    }
}

/// The evolving state of a [`Retirement`], for checkpoints.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RetirementState {
    averages: ReturnAverages,
    plateaus: Vec<Option<f64>>,
    cursor: usize,
    since_probe: usize,
}

/// Which training contexts are retired, and when to probe them.
#[derive(Debug, Clone)]
pub struct Retirement {
    config: RetireConfig,
    averages: ReturnAverages,
    /// The slow average at retirement, for every retired context.
    plateaus: Vec<Option<f64>>,
    /// Where the search for the next retired context to probe starts.
    cursor: usize,
    /// Choices since the last probe, while some context is retired.
    since_probe: usize,
}

impl Retirement {
    /// Nothing retired among `arms` contexts.
    pub(crate) fn new(config: RetireConfig, arms: usize) -> Result<Self, SelectorCreateError> {
        config.validate()?;
        Ok(Self {
            averages: ReturnAverages::new(config.rates, arms),
            config,
            plateaus: vec![None; arms],
            cursor: 0,
            since_probe: 0,
        })
    }

    /// The parameters.
    pub fn config(&self) -> &RetireConfig {
        &self.config
    }

    /// The moving averages the test is made on.
    pub fn averages(&self) -> &ReturnAverages {
        &self.averages
    }

    /// Whether `arm` is retired.
    pub fn is_retired(&self, arm: usize) -> bool {
        self.plateaus.get(arm).is_some_and(Option::is_some)
    }

    /// The plateau of every retired context, `None` for the active ones.
    pub fn plateaus(&self) -> &[Option<f64>] {
        &self.plateaus
    }

    fn retired_count(&self) -> usize {
        self.plateaus.iter().filter(|p| p.is_some()).count()
    }

    /// Called once per choice: the retired context to probe, when a probe is due.
    pub(crate) fn probe(&mut self) -> Option<usize> {
        let arms = self.plateaus.len();
        let next = (0..arms)
            .map(|step| (self.cursor + step) % arms)
            .find(|&arm| self.plateaus[arm].is_some());
        let Some(arm) = next else {
            self.since_probe = 0;
            return None;
        };
        self.since_probe += 1;
        if self.since_probe < self.config.probe_every {
            return None;
        }
        self.since_probe = 0;
        self.cursor = (arm + 1) % arms;
        Some(arm)
    }

    /// Learn from a finite return of `arm` (in range): retire it once converged, bring it back
    /// once fallen.
    pub(crate) fn observe(&mut self, arm: usize, reward: f64) {
        self.averages.record(arm, reward);
        let band = self.config.tolerance * self.averages.spread();
        match self.plateaus[arm] {
            Some(plateau) => {
                if plateau - self.averages.fast()[arm] > band {
                    self.plateaus[arm] = None;
                }
            }
            None => {
                let settled = self.averages.visits()[arm] >= self.config.rates.settled_after();
                let last_active = self.retired_count() + 1 == self.plateaus.len();
                if settled && !last_active && self.averages.progress(arm) <= band {
                    self.plateaus[arm] = Some(self.averages.slow()[arm]);
                }
            }
        }
    }

    /// The state, for a checkpoint.
    pub(crate) fn state(&self) -> RetirementState {
        RetirementState {
            averages: self.averages.clone(),
            plateaus: self.plateaus.clone(),
            cursor: self.cursor,
            since_probe: self.since_probe,
        }
    }

    /// Continue from `state`, refused unless it is of as many contexts and leaves one active.
    pub(crate) fn restore(&mut self, state: RetirementState) -> Result<(), SelectorRestoreError> {
        let arms = self.plateaus.len();
        let refuse = |why: String| Err(SelectorRestoreError::Retirement(why));
        if state.plateaus.len() != arms || state.cursor >= arms || state.since_probe >= self.config.probe_every {
            return refuse(format!(
                "{} contexts with the probe cursor at {} and {} choices since a probe, this selector has {arms} and probes every {}",
                state.plateaus.len(),
                state.cursor,
                state.since_probe,
                self.config.probe_every
            ));
        }
        if state.plateaus.iter().all(Option::is_some) {
            return refuse("every context retired".into());
        }
        let mut averages = self.averages.clone();
        averages
            .restore(state.averages)
            .map_err(SelectorRestoreError::Retirement)?;
        *self = Self {
            config: self.config.clone(),
            averages,
            plateaus: state.plateaus,
            cursor: state.cursor,
            since_probe: state.since_probe,
        };
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config() -> RetireConfig {
        RetireConfig {
            rates: EmaRates { fast: 0.5, slow: 0.25 },
            tolerance: 0.05,
            probe_every: 3,
        }
    }

    /// Arm 0 climbs to 10 and stays; arm 1 keeps climbing by 1 per visit from 0.
    fn plateau_and_climb(retirement: &mut Retirement, visits: usize) {
        for t in 0..visits {
            retirement.observe(0, (2.0 * t as f64).min(10.0));
            retirement.observe(1, t as f64);
        }
    }

    #[test]
    fn a_plateau_is_retired_and_a_climbing_context_is_not() {
        let mut retirement = Retirement::new(config(), 2).unwrap();
        // Visits 0..5 climb; afterwards arm 0's averages converge to 10 geometrically.
        plateau_and_climb(&mut retirement, 4);
        assert!(!retirement.is_retired(0), "still climbing");
        plateau_and_climb(&mut retirement, 20);
        assert!(retirement.is_retired(0));
        assert!(!retirement.is_retired(1), "the last active context is never retired");
        let plateau = retirement.plateaus()[0].unwrap();
        assert!((plateau - 10.0).abs() < 0.5, "{plateau}");
    }

    #[test]
    fn not_before_the_slow_average_has_settled() {
        let mut retirement = Retirement::new(config(), 2).unwrap();
        // Constant returns: progress 0 from the first visit, but 1 / 0.25 = 4 visits are needed.
        for visit in 1..=4 {
            retirement.observe(0, 1.0);
            retirement.observe(1, 5.0);
            assert_eq!(
                retirement.is_retired(0) || retirement.is_retired(1),
                visit >= 4,
                "visit {visit}"
            );
        }
    }

    #[test]
    fn a_fall_brings_a_retired_context_back_and_a_rise_does_not() {
        let mut retirement = Retirement::new(config(), 2).unwrap();
        plateau_and_climb(&mut retirement, 30);
        assert!(retirement.is_retired(0));
        // Arm 1 is at about 28, arm 0 at 10: the band is 0.05 * 18 = 0.9. A probe 20 above does
        // not reinstate it; one that pulls the fast average 1 below the plateau does.
        retirement.observe(0, 30.0);
        assert!(retirement.is_retired(0), "a rise keeps it retired");
        let fast = retirement.averages().fast()[0];
        let plateau = retirement.plateaus()[0].unwrap();
        // fast' = 0.5 fast + 0.5 r; choose r so that fast' = plateau - 1.
        retirement.observe(0, 2.0 * (plateau - 1.0) - fast);
        assert!(!retirement.is_retired(0), "a fall beyond the band brings it back");
    }

    #[test]
    fn the_test_is_the_same_whatever_the_units_of_the_returns() {
        let retired_at = |scale: f64, shift: f64| {
            let mut retirement = Retirement::new(RetireConfig::default(), 3).unwrap();
            let mut history = Vec::new();
            for t in 0..400 {
                let arm = t % 3;
                // Three saturating learning curves with different rates and levels.
                let level = (1.0 + arm as f64) * (1.0 - (-(t as f64) / (40.0 * (1.0 + arm as f64))).exp());
                retirement.observe(arm, scale * level + shift);
                history.push((0..3).map(|a| retirement.is_retired(a)).collect::<Vec<_>>());
            }
            history
        };
        let original = retired_at(1.0, 0.0);
        assert!(original.last().unwrap().iter().any(|&r| r), "something retires");
        assert_eq!(retired_at(1024.0, 0.0), original);
        assert_eq!(retired_at(1e-3, 5e3), original);
    }

    #[test]
    fn probes_come_every_probe_every_choices_in_turn_over_the_retired() {
        let mut retirement = Retirement::new(config(), 4).unwrap();
        assert_eq!((0..10).filter_map(|_| retirement.probe()).count(), 0, "nothing retired");
        retirement.plateaus = vec![Some(1.0), None, Some(2.0), None];
        let probes: Vec<Option<usize>> = (0..9).map(|_| retirement.probe()).collect();
        assert_eq!(probes, [None, None, Some(0), None, None, Some(2), None, None, Some(0)]);
    }

    #[test]
    fn never_all_retired() {
        let mut retirement = Retirement::new(config(), 3).unwrap();
        for _ in 0..50 {
            for arm in 0..3 {
                retirement.observe(arm, arm as f64);
            }
        }
        assert_eq!(retirement.retired_count(), 2);
        assert!(!retirement.is_retired(2), "the last to converge stays active");
    }

    #[test]
    fn bad_parameters_and_states_are_refused() {
        let bad = |c: RetireConfig| Retirement::new(c, 2).unwrap_err().to_string();
        assert_eq!(
            bad(RetireConfig {
                tolerance: 0.0,
                ..config()
            }),
            "retire tolerance must be in (0, 1], got 0"
        );
        assert_eq!(
            bad(RetireConfig {
                tolerance: f64::NAN,
                ..config()
            }),
            "retire tolerance must be in (0, 1], got NaN"
        );
        assert_eq!(
            bad(RetireConfig {
                probe_every: 1,
                ..config()
            }),
            "retire probe_every must be >= 2, got 1"
        );
        assert!(
            bad(RetireConfig {
                rates: EmaRates { fast: 0.1, slow: 0.2 },
                ..config()
            })
            .starts_with("retire ema_fast and ema_slow")
        );

        let mut retirement = Retirement::new(config(), 2).unwrap();
        let mut state = retirement.state();
        state.plateaus = vec![Some(1.0), Some(2.0)];
        assert!(retirement.restore(state).is_err());
        let other = Retirement::new(config(), 3).unwrap().state();
        assert!(retirement.restore(other).is_err());
        let mut late = retirement.state();
        late.since_probe = 3;
        assert!(retirement.restore(late).is_err(), "beyond probe_every");
        let mut moved = Retirement::new(config(), 2).unwrap();
        plateau_and_climb(&mut moved, 30);
        retirement.restore(moved.state()).unwrap();
        assert_eq!(retirement.state(), moved.state());
    }
}
