//! Absolute learning progress over the training contexts (Kanitscheider et al. 2021, "Multi-task
//! curriculum learning in a complex, visual, hard-exploration domain"; the "Learning Progress"
//! curriculum of the Syllabus library).
//!
//! Every context keeps a fast and a slow exponential moving average of its return; its progress
//! is |fast - slow|, which learning and forgetting both raise. The first K choices sweep the
//! contexts in index order (a context's progress is unknown until it has been visited twice, and
//! the sweep needs no randomness). Afterwards a share `random_share` of the choices is uniform
//! over the contexts, the rest proportional to progress (uniform while every progress is 0).
//! Proportional sampling does not change when the returns are scaled, and progress does not
//! change when they are shifted, so the choices do not depend on the returns' units.
//!
//! The original works on success rates in [0, 1] and reweights them to favour tasks of low
//! success, and samples through a sigmoid of standardised progress; returns in arbitrary units
//! have no such scale, so neither is done here.
//!
//! With [`retire`](AbsoluteProgressConfig::retire), solved contexts leave the draw (also the
//! uniform share) and are only probed now and then ([`RetireConfig`]).

use super::progress::{EmaRates, ReturnAverages, proportional};
use super::{RetireConfig, Retirement, RetirementState};
use crate::selection::validate::check_contexts;
use crate::selection::{Choice, ContextSelector, SelectorCreateError, SelectorRestoreError, SelectorState};
use rand::{Rng, RngCore};
use serde::{Deserialize, Serialize};

/// Absolute-progress parameters; `Default` gives Syllabus's rate and ALP-GMM's random share.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AbsoluteProgressConfig {
    /// The moving averages of each context's return ([`EmaRates::default`]: 0.1 and 0.05).
    pub rates: EmaRates,
    /// Share of choices drawn uniformly over the (active) contexts, in [0, 1] (0.2).
    pub random_share: f64,
    /// Retire solved contexts (default: no).
    pub retire: Option<RetireConfig>,
}

impl Default for AbsoluteProgressConfig {
    fn default() -> Self {
        Self {
            rates: EmaRates::default(),
            random_share: 0.2,
            retire: None,
        }
    }
}

impl AbsoluteProgressConfig {
    /// Check every parameter's range.
    pub fn validate(&self) -> Result<(), SelectorCreateError> {
        self.rates.validate("absolute-progress")?;
        if !(0.0..=1.0).contains(&self.random_share) {
            return Err(SelectorCreateError::RandomShare {
                teacher: "absolute-progress",
                share: self.random_share,
            });
        }
        self.retire.as_ref().map_or(Ok(()), RetireConfig::validate)
    }
}

/// The evolving state of an [`AbsoluteProgress`] selector, for checkpoints.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AbsoluteProgressState {
    averages: ReturnAverages,
    swept: usize,
    retirement: Option<RetirementState>,
}

/// Draws training contexts in proportion to their absolute learning progress.
#[derive(Debug, Clone)]
pub struct AbsoluteProgress {
    contexts: Vec<Vec<f64>>,
    config: AbsoluteProgressConfig,
    averages: ReturnAverages,
    /// Choices of the initial sweep made so far.
    swept: usize,
    retirement: Option<Retirement>,
}

impl AbsoluteProgress {
    /// A selector over `contexts` (at least one, all of one dimension, finite).
    pub fn new(contexts: Vec<Vec<f64>>, config: AbsoluteProgressConfig) -> Result<Self, SelectorCreateError> {
        check_contexts(&contexts, None)?;
        config.validate()?;
        let arms = contexts.len();
        let retirement = match &config.retire {
            Some(retire) => Some(Retirement::new(retire.clone(), arms)?),
            None => None,
        };
        Ok(Self {
            averages: ReturnAverages::new(config.rates, arms),
            contexts,
            config,
            swept: 0,
            retirement,
        })
    }

    /// The parameters.
    pub fn config(&self) -> &AbsoluteProgressConfig {
        &self.config
    }

    /// The moving averages whose difference is each context's progress.
    pub fn averages(&self) -> &ReturnAverages {
        &self.averages
    }

    /// Which contexts are retired, when they are retired at all.
    pub fn retirement(&self) -> Option<&Retirement> {
        self.retirement.as_ref()
    }

    fn is_retired(&self, arm: usize) -> bool {
        self.retirement.as_ref().is_some_and(|r| r.is_retired(arm))
    }

    /// An arm drawn uniformly among the active ones.
    fn uniform(&self, rng: &mut dyn RngCore) -> usize {
        let arms = self.contexts.len();
        let active = (0..arms).filter(|&arm| !self.is_retired(arm)).count();
        let index = rng.random_range(0..active);
        (0..arms)
            .filter(|&arm| !self.is_retired(arm))
            .nth(index)
            .expect("index < number of active arms")
    }

    /// An arm drawn from the active ones, uniformly with probability `random_share`, else in
    /// proportion to progress. Consumes one number, then one more for the arm.
    fn draw(&self, rng: &mut dyn RngCore) -> usize {
        if rng.random::<f64>() < self.config.random_share {
            return self.uniform(rng);
        }
        let weights = (0..self.contexts.len()).map(|arm| {
            if self.is_retired(arm) {
                0.0
            } else {
                self.averages.progress(arm)
            }
        });
        match proportional(weights, rng.random()) {
            Some(arm) => arm,
            // Every progress 0 (or not finite): nothing to prefer.
            None => self.uniform(rng),
        }
    }
}

impl ContextSelector for AbsoluteProgress {
    fn choose(&mut self, rng: &mut dyn RngCore) -> Choice {
        let arm = if self.swept < self.contexts.len() {
            self.swept += 1;
            self.swept - 1
        } else if let Some(probe) = self.retirement.as_mut().and_then(Retirement::probe) {
            probe
        } else {
            self.draw(rng)
        };
        Choice {
            arm: Some(arm),
            context: self.contexts[arm].clone(),
        }
    }

    /// Update the chosen context's averages. A choice without a valid arm (not made by this
    /// selector) or a non-finite return is ignored.
    fn observe(&mut self, choice: &Choice, reward: f64) {
        let Some(arm) = choice.arm.filter(|&arm| arm < self.contexts.len()) else {
            return;
        };
        if !reward.is_finite() {
            return;
        }
        self.averages.record(arm, reward);
        if let Some(retirement) = &mut self.retirement {
            retirement.observe(arm, reward);
        }
    }

    fn save_state(&self) -> SelectorState {
        SelectorState::AbsoluteProgress(AbsoluteProgressState {
            averages: self.averages.clone(),
            swept: self.swept,
            retirement: self.retirement.as_ref().map(Retirement::state),
        })
    }

    fn restore_state(&mut self, state: SelectorState) -> Result<(), SelectorRestoreError> {
        let SelectorState::AbsoluteProgress(state) = state else {
            return Err(state.wrong_kind("absolute progress"));
        };
        let arms = self.contexts.len();
        if state.swept > arms {
            return Err(SelectorRestoreError::AbsoluteProgress(format!(
                "a sweep of {} choices over {arms} contexts",
                state.swept
            )));
        }
        // Check everything before changing anything.
        let mut restored = self.clone();
        restored
            .averages
            .restore(state.averages)
            .map_err(SelectorRestoreError::AbsoluteProgress)?;
        restored.swept = state.swept;
        match (&mut restored.retirement, state.retirement) {
            (None, None) => {}
            (Some(mine), Some(saved)) => mine.restore(saved)?,
            _ => {
                return Err(SelectorRestoreError::Retirement(
                    "a state and a selector that disagree on retiring contexts".into(),
                ));
            }
        }
        *self = restored;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn line(k: usize) -> Vec<Vec<f64>> {
        (0..k).map(|i| vec![i as f64]).collect()
    }

    fn selector(k: usize, config: AbsoluteProgressConfig) -> AbsoluteProgress {
        AbsoluteProgress::new(line(k), config).unwrap()
    }

    fn observe(selector: &mut AbsoluteProgress, arm: usize, reward: f64) {
        selector.observe(
            &Choice {
                arm: Some(arm),
                context: vec![arm as f64],
            },
            reward,
        );
    }

    #[test]
    fn the_first_choices_sweep_the_contexts_without_randomness() {
        for seed in 0..3 {
            let mut selector = selector(5, AbsoluteProgressConfig::default());
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let arms: Vec<usize> = (0..5).map(|_| selector.choose(&mut rng).arm.unwrap()).collect();
            assert_eq!(arms, [0, 1, 2, 3, 4]);
            assert_eq!(rng, ChaCha8Rng::seed_from_u64(seed), "the sweep draws nothing");
        }
    }

    /// Choices (without observing) after arms 0..4 were visited with these returns.
    fn frequencies(config: AbsoluteProgressConfig, returns: [&[f64]; 4], draws: usize, seed: u64) -> Vec<f64> {
        let mut selector = selector(4, config);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        for _ in 0..4 {
            selector.choose(&mut rng);
        }
        for (arm, returns) in returns.iter().enumerate() {
            for &r in *returns {
                observe(&mut selector, arm, r);
            }
        }
        let mut counts = [0usize; 4];
        for _ in 0..draws {
            counts[selector.choose(&mut rng).arm.unwrap()] += 1;
        }
        counts.iter().map(|&c| c as f64 / draws as f64).collect()
    }

    #[test]
    fn choices_are_proportional_to_progress_plus_the_random_share() {
        // Rates 0.5 / 0.25 and two returns 0 then x: fast 0.5x, slow 0.25x, progress 0.25|x|.
        let config = AbsoluteProgressConfig {
            rates: EmaRates { fast: 0.5, slow: 0.25 },
            ..AbsoluteProgressConfig::default()
        };
        let returns: [&[f64]; 4] = [&[0.0, 4.0], &[0.0, -12.0], &[0.0, 0.0], &[3.0]];
        // Progress 1, 3, 0, 0: p = 0.2 / 4 + 0.8 * progress / 4.
        let expected = [0.05 + 0.2, 0.05 + 0.6, 0.05, 0.05];
        let draws = 100_000;
        for seed in 0..3 {
            let observed = frequencies(config.clone(), returns, draws, seed);
            for (arm, (&o, &p)) in observed.iter().zip(&expected).enumerate() {
                // 5 binomial standard deviations.
                let sd = (p * (1.0 - p) / draws as f64).sqrt();
                assert!((o - p).abs() < 5.0 * sd, "seed {seed} arm {arm}: {o} vs {p}");
            }
        }
        // No progress anywhere: uniform.
        let flat = frequencies(config, [&[1.0, 1.0], &[2.0], &[3.0, 3.0], &[4.0]], draws, 7);
        assert!(flat.iter().all(|&f| (f - 0.25).abs() < 0.01), "{flat:?}");
    }

    /// The arms chosen over a run on saturating curves, returns as `scale * level + shift`.
    fn run(config: &AbsoluteProgressConfig, seed: u64, scale: f64, shift: f64, steps: usize) -> Vec<usize> {
        let mut selector = selector(6, config.clone());
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut pulls = [0u32; 6];
        (0..steps)
            .map(|_| {
                let choice = selector.choose(&mut rng);
                let arm = choice.arm.unwrap();
                pulls[arm] += 1;
                let level = (0.005 * (arm as f64 + 1.0) * pulls[arm] as f64).min(1.0);
                selector.observe(&choice, scale * level + shift);
                arm
            })
            .collect()
    }

    #[test]
    fn same_seed_same_choices_and_the_units_of_the_returns_do_not_matter() {
        let config = AbsoluteProgressConfig::default();
        let original = run(&config, 3, 1.0, 0.0, 600);
        assert_eq!(run(&config, 3, 1.0, 0.0, 600), original);
        assert_ne!(run(&config, 4, 1.0, 0.0, 600), original);
        // A power of two scales every average exactly.
        assert_eq!(run(&config, 3, 1024.0, 0.0, 600), original);
        assert_eq!(run(&config, 3, 1.0 / 64.0, 0.0, 600), original);
    }

    #[test]
    fn progress_draws_a_learning_context_more_than_a_saturated_one() {
        // Arm 0 is saturated from the start, arm 1 improves by 0.01 per visit for ever: after the
        // averages have settled, arm 0 gets only its half of the random share.
        let mut selector = selector(2, AbsoluteProgressConfig::default());
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut visits = [0u32; 2];
        let mut late = [0usize; 2];
        for t in 0..2000 {
            let choice = selector.choose(&mut rng);
            let arm = choice.arm.unwrap();
            visits[arm] += 1;
            let reward = if arm == 0 { 1.0 } else { 0.01 * f64::from(visits[1]) };
            selector.observe(&choice, reward);
            if t >= 1000 {
                late[arm] += 1;
            }
        }
        // Expected 0.1 of 1000 (sd 9.5).
        assert!((late[0] as f64 - 100.0).abs() < 40.0, "{late:?}");
    }

    #[test]
    fn a_solved_context_is_retired_probed_and_brought_back_when_it_falls() {
        let retire = RetireConfig {
            rates: EmaRates { fast: 0.5, slow: 0.25 },
            tolerance: 0.05,
            probe_every: 5,
        };
        let config = AbsoluteProgressConfig {
            retire: Some(retire),
            ..AbsoluteProgressConfig::default()
        };
        let mut selector = selector(3, config);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        // Arm 0 is solved at once (return 10); arms 1 and 2 alternate between 0 and 10, so their
        // averages never settle.
        let mut pulls = [0u32; 3];
        let mut after_retirement = Vec::new();
        let mut forgotten = false;
        let mut back = false;
        for t in 0..600 {
            let choice = selector.choose(&mut rng);
            let arm = choice.arm.unwrap();
            pulls[arm] += 1;
            if selector.retirement().unwrap().is_retired(0) {
                after_retirement.push(arm);
            }
            let reward = match arm {
                // From choice 400 on, arm 0 is forgotten: its return drops to 0.
                0 if forgotten => 0.0,
                0 => 10.0,
                _ => f64::from(pulls[arm] % 2) * 10.0,
            };
            selector.observe(&choice, reward);
            back |= forgotten && !selector.retirement().unwrap().is_retired(0);
            if t == 400 {
                assert!(selector.retirement().unwrap().is_retired(0));
                forgotten = true;
            }
        }
        // While retired, arm 0 is chosen only as a probe: every 5th choice, it being the only
        // retired context.
        let probes = after_retirement.iter().filter(|&&a| a == 0).count();
        assert!(probes > 0);
        assert!(
            probes * 5 <= after_retirement.len() + 5,
            "{probes} of {}",
            after_retirement.len()
        );
        assert!(back, "the fall brought it back");
        // ... until its averages settled again, at the new level.
        let plateau = selector.retirement().unwrap().plateaus()[0];
        assert!(plateau.is_some_and(|p| p.abs() < 0.5), "{plateau:?}");
        assert!(!selector.retirement().unwrap().is_retired(1) && !selector.retirement().unwrap().is_retired(2));
    }

    #[test]
    fn save_and_restore_mid_run_continue_exactly() {
        let config = AbsoluteProgressConfig {
            retire: Some(RetireConfig::default()),
            ..AbsoluteProgressConfig::default()
        };
        let mut uninterrupted = selector(6, config.clone());
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let step = |selector: &mut AbsoluteProgress, rng: &mut ChaCha8Rng, t: usize| {
            let choice = selector.choose(rng);
            // Every context reaches its own level, arm + 1, at t = 100.
            let reward = (t as f64 / 100.0).min(1.0) * (choice.arm.unwrap() + 1) as f64;
            selector.observe(&choice, reward);
            choice.arm.unwrap()
        };
        let mut expected = Vec::new();
        for t in 0..500 {
            expected.push(step(&mut uninterrupted, &mut rng, t));
        }
        let mut first = selector(6, config.clone());
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let mut arms: Vec<usize> = (0..250).map(|t| step(&mut first, &mut rng, t)).collect();
        let mut second = selector(6, config);
        second.restore_state(first.save_state()).unwrap();
        arms.extend((250..500).map(|t| step(&mut second, &mut rng, t)));
        assert_eq!(arms, expected);
        assert_eq!(second.save_state(), uninterrupted.save_state());
        assert!(
            uninterrupted
                .retirement()
                .unwrap()
                .plateaus()
                .iter()
                .any(Option::is_some),
            "the run retired something"
        );
    }

    #[test]
    fn bad_input_is_refused() {
        let message = |config| AbsoluteProgress::new(line(2), config).unwrap_err().to_string();
        assert_eq!(
            message(AbsoluteProgressConfig {
                random_share: 1.5,
                ..AbsoluteProgressConfig::default()
            }),
            "absolute-progress random_share must be in [0, 1], got 1.5"
        );
        assert!(
            message(AbsoluteProgressConfig {
                rates: EmaRates { fast: 0.05, slow: 0.1 },
                ..AbsoluteProgressConfig::default()
            })
            .starts_with("absolute-progress ema_fast and ema_slow must satisfy")
        );
        assert!(
            message(AbsoluteProgressConfig {
                retire: Some(RetireConfig {
                    probe_every: 0,
                    ..RetireConfig::default()
                }),
                ..AbsoluteProgressConfig::default()
            })
            .contains("probe_every")
        );
        assert_eq!(
            AbsoluteProgress::new(vec![], AbsoluteProgressConfig::default()).unwrap_err(),
            SelectorCreateError::NoContexts
        );
        // States of another size, kind or retirement are refused and change nothing.
        let mut two = selector(2, AbsoluteProgressConfig::default());
        let before = two.save_state();
        assert!(
            two.restore_state(selector(3, AbsoluteProgressConfig::default()).save_state())
                .is_err()
        );
        assert!(two.restore_state(SelectorState::UniformDiscrete).is_err());
        let retiring = selector(
            2,
            AbsoluteProgressConfig {
                retire: Some(RetireConfig::default()),
                ..AbsoluteProgressConfig::default()
            },
        );
        assert!(two.restore_state(retiring.save_state()).is_err());
        assert_eq!(two.save_state(), before);
        // Foreign and non-finite observations change nothing.
        observe(&mut two, 5, 1.0);
        observe(&mut two, 0, f64::NAN);
        assert_eq!(two.save_state(), before);
    }
}
