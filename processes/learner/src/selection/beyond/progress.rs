//! A fast and a slow exponential moving average of every training context's return: their
//! absolute difference is the context's learning progress (Kanitscheider et al. 2021), and their
//! levels say how far apart the contexts are. Used by [`AbsoluteProgress`](super::AbsoluteProgress)
//! and by the retirement of solved contexts ([`RetireConfig`](super::RetireConfig)).

use crate::selection::SelectorCreateError;
use serde::{Deserialize, Serialize};

/// The rates of the two moving averages of a context's return: each visit moves an average by
/// `rate * (return - average)`, so it remembers about the last `1 / rate` visits of the context.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EmaRates {
    /// Rate of the fast average, in (0, 1]; 1 is the last return itself.
    pub fast: f64,
    /// Rate of the slow average, in (0, fast).
    pub slow: f64,
}

impl Default for EmaRates {
    /// Fast 0.1, Syllabus's `ema_alpha` for Kanitscheider et al.'s curriculum; slow 0.05. There
    /// the slow average smooths the fast one again with the same rate, which lags about
    /// 2 / 0.1 = 20 visits behind the returns; a single average with rate 0.05 lags as much.
    fn default() -> Self {
        Self { fast: 0.1, slow: 0.05 }
    }
}

impl EmaRates {
    /// Check `0 < slow < fast <= 1`; `teacher` names the owner in the message.
    pub(crate) fn validate(&self, teacher: &'static str) -> Result<(), SelectorCreateError> {
        if self.slow > 0.0 && self.slow < self.fast && self.fast <= 1.0 {
            Ok(())
        } else {
            Err(SelectorCreateError::EmaRates {
                teacher,
                fast: self.fast,
                slow: self.slow,
            })
        }
    }

    /// Visits after which the slow average has mostly forgotten where it started: 1 / slow,
    /// rounded up.
    pub(crate) fn settled_after(&self) -> u64 {
        (1.0 / self.slow).ceil() as u64
    }
}

/// The two moving averages of every context's return, and how often each was visited.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReturnAverages {
    rates: EmaRates,
    fast: Vec<f64>,
    slow: Vec<f64>,
    visits: Vec<u64>,
}

impl ReturnAverages {
    /// Averages for `arms` contexts, none visited yet.
    pub(crate) fn new(rates: EmaRates, arms: usize) -> Self {
        Self {
            rates,
            fast: vec![0.0; arms],
            slow: vec![0.0; arms],
            visits: vec![0; arms],
        }
    }

    /// Number of contexts.
    pub fn arms(&self) -> usize {
        self.visits.len()
    }

    /// The rates.
    pub fn rates(&self) -> EmaRates {
        self.rates
    }

    /// Record a finite return of `arm` (in range). The first return starts both averages, so
    /// a context's progress is 0 until its second visit.
    pub(crate) fn record(&mut self, arm: usize, reward: f64) {
        if self.visits[arm] == 0 {
            self.fast[arm] = reward;
            self.slow[arm] = reward;
        } else {
            // The convex form cannot overflow for finite inputs, unlike average + rate * (r - average).
            let (fast, slow) = (self.rates.fast, self.rates.slow);
            self.fast[arm] = (1.0 - fast) * self.fast[arm] + fast * reward;
            self.slow[arm] = (1.0 - slow) * self.slow[arm] + slow * reward;
        }
        self.visits[arm] += 1;
    }

    /// The fast average of every context (0 for contexts never visited).
    pub fn fast(&self) -> &[f64] {
        &self.fast
    }

    /// The slow average of every context (0 for contexts never visited).
    pub fn slow(&self) -> &[f64] {
        &self.slow
    }

    /// Visits of every context.
    pub fn visits(&self) -> &[u64] {
        &self.visits
    }

    /// |fast - slow| of `arm`: its learning progress, or forgetting, in the returns' units.
    pub fn progress(&self, arm: usize) -> f64 {
        (self.fast[arm] - self.slow[arm]).abs()
    }

    /// The spread of the contexts' slow averages (largest minus smallest over the contexts
    /// visited so far; 0 before two were). A scale in the returns' units that does not depend on
    /// how returns are shifted or scaled.
    pub fn spread(&self) -> f64 {
        let (low, high) = self
            .slow
            .iter()
            .zip(&self.visits)
            .filter(|(_, visits)| **visits > 0)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(low, high), (&s, _)| {
                (low.min(s), high.max(s))
            });
        if high > low { high - low } else { 0.0 }
    }

    /// Continue from saved averages, refused unless they are of as many contexts.
    pub(crate) fn restore(&mut self, saved: ReturnAverages) -> Result<(), String> {
        let arms = self.arms();
        if saved.fast.len() != arms || saved.slow.len() != arms || saved.visits.len() != arms {
            return Err(format!(
                "moving averages of {} contexts, this selector has {arms}",
                saved.visits.len()
            ));
        }
        *self = Self {
            rates: self.rates,
            ..saved
        };
        Ok(())
    }
}

/// The index drawn with probability proportional to `weights` (each >= 0), for `u` uniform in
/// [0, 1); `None` when the weights do not sum to a positive finite number.
pub(crate) fn proportional(weights: impl Iterator<Item = f64> + Clone, u: f64) -> Option<usize> {
    let total: f64 = weights.clone().sum();
    if !(total > 0.0 && total.is_finite()) {
        return None;
    }
    let target = u * total;
    let mut cumulative = 0.0;
    let mut last_positive = None;
    for (index, weight) in weights.enumerate() {
        if weight > 0.0 {
            cumulative += weight;
            last_positive = Some(index);
            if target < cumulative {
                break;
            }
        }
    }
    // Also the answer when rounding leaves target >= the running sum at the very end.
    last_positive
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn averages_follow_their_recurrences_on_a_known_sequence() {
        let mut averages = ReturnAverages::new(EmaRates { fast: 0.5, slow: 0.25 }, 2);
        for r in [4.0, 8.0, 0.0] {
            averages.record(1, r);
        }
        // fast: 4, then 0.5*4 + 0.5*8 = 6, then 0.5*6 + 0 = 3.
        // slow: 4, then 0.75*4 + 0.25*8 = 5, then 0.75*5 + 0 = 3.75.
        assert_eq!(averages.fast(), [0.0, 3.0]);
        assert_eq!(averages.slow(), [0.0, 3.75]);
        assert_eq!(averages.visits(), [0, 3]);
        assert_eq!(averages.progress(1), 0.75);
        assert_eq!(averages.progress(0), 0.0);
        // One visited context: no spread yet; arm 0 at 10 makes it 10 - 3.75.
        assert_eq!(averages.spread(), 0.0);
        averages.record(0, 10.0);
        assert_eq!(averages.spread(), 6.25);
    }

    #[test]
    fn progress_and_spread_scale_and_shift_with_the_returns() {
        let returns = [(0, 1.0), (1, 3.0), (0, 2.0), (1, 2.5), (0, 4.0), (2, -1.0)];
        let run = |scale: f64, shift: f64| {
            let mut averages = ReturnAverages::new(EmaRates::default(), 3);
            for (arm, r) in returns {
                averages.record(arm, scale * r + shift);
            }
            (
                (0..3).map(|arm| averages.progress(arm)).collect::<Vec<_>>(),
                averages.spread(),
            )
        };
        let (progress, spread) = run(1.0, 0.0);
        let (scaled, scaled_spread) = run(1000.0, -7.0);
        for (a, b) in progress.iter().zip(&scaled) {
            assert!((1000.0 * a - b).abs() <= 1e-9 * b.abs().max(1.0), "{a} {b}");
        }
        assert!((1000.0 * spread - scaled_spread).abs() < 1e-9 * scaled_spread);
    }

    #[test]
    fn extreme_finite_returns_keep_the_averages_finite() {
        let mut averages = ReturnAverages::new(EmaRates::default(), 1);
        for r in [f64::MAX, f64::MAX, -f64::MAX, f64::MAX] {
            averages.record(0, r);
            assert!(averages.fast()[0].is_finite() && averages.slow()[0].is_finite());
        }
    }

    #[test]
    fn rates_must_be_ordered_in_the_unit_interval() {
        assert!(EmaRates::default().validate("t").is_ok());
        assert!(EmaRates { fast: 1.0, slow: 0.5 }.validate("t").is_ok());
        for (fast, slow) in [
            (0.1, 0.1),
            (0.1, 0.2),
            (1.5, 0.1),
            (0.1, 0.0),
            (f64::NAN, 0.1),
            (0.1, f64::NAN),
        ] {
            let error = EmaRates { fast, slow }.validate("absolute-progress").unwrap_err();
            assert_eq!(
                error.to_string(),
                format!(
                    "absolute-progress ema_fast and ema_slow must satisfy 0 < ema_slow < ema_fast <= 1, got ema_fast {fast}, ema_slow {slow}"
                )
            );
        }
        assert_eq!(EmaRates::default().settled_after(), 20);
    }

    #[test]
    fn proportional_draws_follow_the_cumulative_weights() {
        let weights = [0.0, 1.0, 0.0, 3.0];
        let draw = |u| proportional(weights.iter().copied(), u);
        assert_eq!(draw(0.0), Some(1));
        assert_eq!(draw(0.2499), Some(1));
        assert_eq!(draw(0.25), Some(3));
        assert_eq!(draw(0.999_999), Some(3));
        // Rounding beyond the total still lands on a positive weight.
        assert_eq!(draw(1.0), Some(3));
        assert_eq!(proportional([0.0, 0.0].into_iter(), 0.5), None);
        assert_eq!(proportional([1.0, f64::INFINITY].into_iter(), 0.5), None);
        assert_eq!(proportional(std::iter::empty(), 0.5), None);
    }
}
