//! Active context selection as the paper proposes it (Sec. 3.3): D-UCB over the K training
//! contexts, rewarded with an intrinsic reward.
//!
//! With several tasks in flight (P > 1), [`choose`](ContextSelector::choose) runs P - 1 choices
//! ahead of [`observe`](ContextSelector::observe). The selector keeps those pending choices in a
//! FIFO and lets D-UCB count them as pulls with a fantasy reward equal to the arm's current mean
//! ([`DUcb::select_with_pending`]), so the choices made in one window spread over arms with
//! similar bounds instead of repeating one arm P times. With P = 1 nothing is pending when a
//! choice is made, and the selector is exactly the paper's sequential D-UCB.
//!
//! With [`with_retirement`](BanditSelector::with_retirement), contexts whose return has reached
//! a plateau are left out of the bandit's choices and only probed now and then
//! ([`RetireConfig`]); without it nothing changes.

use super::{DUcb, DUcbConfig, FirstVisit, IntrinsicReward, IntrinsicTracker};
use crate::selection::validate::check_contexts;
use crate::selection::{
    Choice, ContextSelector, RetireConfig, Retirement, SelectorCreateError, SelectorRestoreError, SelectorState,
};
use rand::RngCore;
use std::collections::VecDeque;

/// D-UCB over the training contexts with one intrinsic reward.
#[derive(Debug, Clone)]
pub struct BanditSelector {
    contexts: Vec<Vec<f64>>,
    ducb: DUcb,
    intrinsic: IntrinsicTracker,
    /// Arms chosen but not yet observed, oldest first.
    pending: VecDeque<usize>,
    /// Solved contexts, when they are retired.
    retirement: Option<Retirement>,
}

impl BanditSelector {
    /// A selector over `contexts` (at least one, all of one dimension, finite).
    pub fn new(
        contexts: Vec<Vec<f64>>,
        ducb: DUcbConfig,
        heuristic: IntrinsicReward,
        first_visit: FirstVisit,
    ) -> Result<Self, SelectorCreateError> {
        check_contexts(&contexts, None)?;
        let arms = contexts.len();
        let bound = ducb.b;
        Ok(Self {
            ducb: DUcb::new(arms, ducb)?,
            intrinsic: IntrinsicTracker::new(heuristic, first_visit, arms, bound),
            contexts,
            pending: VecDeque::new(),
            retirement: None,
        })
    }

    /// The same selector, retiring solved contexts as `config` says.
    pub fn with_retirement(self, config: RetireConfig) -> Result<Self, SelectorCreateError> {
        let retirement = Retirement::new(config, self.contexts.len())?;
        Ok(Self {
            retirement: Some(retirement),
            ..self
        })
    }

    /// Which contexts are retired, when they are retired at all.
    pub fn retirement(&self) -> Option<&Retirement> {
        self.retirement.as_ref()
    }

    /// The training contexts, indexed by arm.
    pub fn contexts(&self) -> &[Vec<f64>] {
        &self.contexts
    }

    /// The bandit, for diagnostics.
    pub fn ducb(&self) -> &DUcb {
        &self.ducb
    }

    /// Discounted pull counts N_i per context.
    pub fn discounted_counts(&self) -> &[f64] {
        self.ducb.counts()
    }

    /// Discounted mean intrinsic rewards m_i per context.
    pub fn discounted_means(&self) -> &[f64] {
        self.ducb.means()
    }

    /// The intrinsic-reward bookkeeping (heuristic and per-context baselines).
    pub fn intrinsic(&self) -> &IntrinsicTracker {
        &self.intrinsic
    }

    /// Arms chosen but not yet observed, oldest first.
    pub fn pending(&self) -> &VecDeque<usize> {
        &self.pending
    }
}

impl ContextSelector for BanditSelector {
    fn choose(&mut self, _rng: &mut dyn RngCore) -> Choice {
        let pending = self.pending.make_contiguous();
        let arm = match &mut self.retirement {
            None => self.ducb.select_with_pending(pending),
            Some(retirement) => match retirement.probe() {
                Some(probe) => probe,
                None => self.ducb.select_among(pending, |arm| !retirement.is_retired(arm)),
            },
        };
        self.pending.push_back(arm);
        Choice {
            arm: Some(arm),
            context: self.contexts[arm].clone(),
        }
    }

    /// Credit the intrinsic reward of `reward` to the chosen arm. A choice without a valid arm
    /// (not made by this selector) or a non-finite return is ignored: there is no arm to credit,
    /// and a NaN would poison the arm's mean and baseline for good.
    ///
    /// The oldest pending choice of the arm is no longer pending, even for a non-finite return
    /// (the learner observes in task order, so that is the front of the FIFO).
    fn observe(&mut self, choice: &Choice, reward: f64) {
        let Some(arm) = choice.arm else { return };
        if let Some(index) = self.pending.iter().position(|&a| a == arm) {
            self.pending.remove(index);
        }
        if !reward.is_finite() || arm >= self.contexts.len() {
            return;
        }
        if let Some(retirement) = &mut self.retirement {
            retirement.observe(arm, reward);
        }
        if let Ok(r_beta) = self.intrinsic.reward(arm, reward) {
            // The arm is in range and r_beta finite (short of overflow in r - b_s, which is
            // then safely skipped), so this succeeds.
            let _ = self.ducb.update(arm, r_beta);
        }
    }

    /// Ignored for an arm out of range.
    fn prime(&mut self, arm: usize, initial_return: f64) {
        let _ = self.intrinsic.prime(arm, initial_return);
    }

    fn wants_initial_returns(&self) -> bool {
        self.intrinsic.wants_initial_returns()
    }

    fn save_state(&self) -> SelectorState {
        SelectorState::Bandit {
            ducb: self.ducb.state(),
            baselines: self.intrinsic.baselines().to_vec(),
            pending: self.pending.iter().copied().collect(),
            retirement: self.retirement.as_ref().map(Retirement::state),
        }
    }

    fn restore_state(&mut self, state: SelectorState) -> Result<(), SelectorRestoreError> {
        let SelectorState::Bandit {
            ducb,
            baselines,
            pending,
            retirement,
        } = state
        else {
            return Err(state.wrong_kind("D-UCB"));
        };
        let arms = self.contexts.len();
        if let Some(&arm) = pending.iter().find(|&&arm| arm >= arms) {
            return Err(SelectorRestoreError::PendingArm { arm, arms });
        }
        // Check everything before changing anything.
        let mut restored = self.clone();
        restored.ducb.restore(ducb)?;
        restored.intrinsic.restore_baselines(baselines)?;
        restored.pending = pending.into();
        match (&mut restored.retirement, retirement) {
            (None, None) => {}
            (Some(mine), Some(saved)) => mine.restore(saved)?,
            (mine, _) => {
                return Err(SelectorRestoreError::Retirement(format!(
                    "a state {} retirement for a selector {} it",
                    if mine.is_some() { "without" } else { "with" },
                    if mine.is_some() { "with" } else { "without" },
                )));
            }
        }
        *self = restored;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::selection::{DUcbCreateError, RetireConfig, RoundRobin};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use std::collections::VecDeque;

    fn grid(k: usize) -> Vec<Vec<f64>> {
        (0..k).map(|i| vec![i as f64]).collect()
    }

    fn paper_sec4(b: f64) -> DUcbConfig {
        DUcbConfig {
            gamma: 0.95,
            xi: 1e-8,
            b,
        }
    }

    #[test]
    fn chooses_training_contexts_and_credits_the_intrinsic_reward() {
        let mut selector = BanditSelector::new(
            grid(3),
            paper_sec4(0.25),
            IntrinsicReward::MonotonicProgress,
            FirstVisit::InitialReturn,
        )
        .unwrap();
        assert!(selector.wants_initial_returns());
        for arm in 0..3 {
            selector.prime(arm, 0.0);
        }
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let choices: Vec<Choice> = (0..3).map(|_| selector.choose(&mut rng)).collect();
        for (arm, choice) in choices.iter().enumerate() {
            assert_eq!(
                choice,
                &Choice {
                    arm: Some(arm),
                    context: vec![arm as f64]
                }
            );
        }
        selector.observe(&choices[0], 0.1);
        selector.observe(&choices[1], 0.3);
        selector.observe(&choices[2], -0.2);
        assert_eq!(selector.discounted_means(), [0.1, 0.3, 0.0]);
        assert_eq!(selector.intrinsic().baseline(2), Some(0.0));
        // Arm 1 has the largest progress; padding (~1e-5) cannot overturn a 0.2 gap.
        assert_eq!(selector.choose(&mut rng).arm, Some(1));
        // Foreign and non-finite observations change nothing.
        let before = selector.discounted_counts().to_vec();
        selector.observe(
            &Choice {
                arm: None,
                context: vec![0.5],
            },
            1.0,
        );
        selector.observe(
            &Choice {
                arm: Some(7),
                context: vec![7.0],
            },
            1.0,
        );
        selector.observe(&choices[0], f64::NAN);
        assert_eq!(selector.discounted_counts(), before);
    }

    #[test]
    fn constructor_refuses_bad_input() {
        let config = paper_sec4(1.0);
        let new =
            |contexts, config| BanditSelector::new(contexts, config, IntrinsicReward::BestReward, FirstVisit::Zero);
        assert_eq!(
            new(vec![], config.clone()).unwrap_err(),
            SelectorCreateError::NoContexts
        );
        let bad = DUcbConfig { gamma: 1.5, ..config };
        assert_eq!(
            new(grid(2), bad).unwrap_err(),
            SelectorCreateError::DUcb(DUcbCreateError::Gamma(1.5))
        );
        let best = new(grid(2), paper_sec4(1.0)).unwrap();
        assert!(!best.wants_initial_returns());
    }

    /// B carries the units of the intrinsic reward: returns and B scaled by the same factor make
    /// the same choices, returns scaled alone do not (for the progress heuristics). (The factor is a power of 2, so the scaled
    /// run's arithmetic is the original's, exactly.)
    #[test]
    fn b_scales_with_the_returns() {
        let rates = fastest_last(6);
        let choices = |heuristic, first_visit, returns: f64, b: f64| {
            let config = DUcbConfig {
                b,
                xi: 1e-2,
                ..DUcbConfig::default()
            };
            let mut selector = BanditSelector::new(grid(6), config, heuristic, first_visit).unwrap();
            let (mut problem, mut noise, mut rng) = start(&mut selector, &rates, 5);
            (0..300)
                .map(|_| {
                    let choice = selector.choose(&mut rng);
                    let arm = choice.arm.unwrap();
                    selector.observe(&choice, returns * problem.pull(arm, &mut noise));
                    arm
                })
                .collect::<Vec<_>>()
        };
        for heuristic in IntrinsicReward::ALL {
            for first_visit in [FirstVisit::InitialReturn, FirstVisit::Zero, FirstVisit::Optimistic] {
                let original = choices(heuristic, first_visit, 1.0, 0.25);
                let context = format!("{heuristic} {first_visit:?}");
                assert_eq!(choices(heuristic, first_visit, 1024.0, 256.0), original, "{context}");
                // Progress dies down as arms saturate, and the padding decides (best reward and
                // diversity stay on the highest or lowest return whatever the padding).
                if heuristic.has_baseline() {
                    assert_ne!(choices(heuristic, first_visit, 1024.0, 0.25), original, "{context}");
                }
            }
        }
    }

    /// A non-stationary toy problem: the return of arm i is min(1, rate_i * pulls_i) plus
    /// uniform noise, so pulling the fastest unsaturated arm is what makes
    /// progress, and that arm moves as arms saturate.
    struct Saturating {
        rates: Vec<f64>,
        pulls: Vec<u32>,
        noise: f64,
    }

    impl Saturating {
        fn value(&self, arm: usize) -> f64 {
            (self.rates[arm] * self.pulls[arm] as f64).min(1.0)
        }

        /// The arm whose next pull raises the total most (the lowest index among equals).
        fn most_improving(&self) -> usize {
            let gain = |i: usize| (self.rates[i] * (self.pulls[i] + 1) as f64).min(1.0) - self.value(i);
            (0..self.rates.len()).fold(0, |best, i| if gain(i) > gain(best) { i } else { best })
        }

        fn pull(&mut self, arm: usize, rng: &mut impl Rng) -> f64 {
            self.pulls[arm] += 1;
            self.value(arm) + self.noise * rng.random_range(-1.0..1.0)
        }

        fn performance(&self) -> f64 {
            (0..self.rates.len()).map(|i| self.value(i)).sum()
        }
    }

    /// A fresh problem with these rates, its noise and selector streams, and `selector` primed
    /// with initial returns of 0.
    fn start(selector: &mut dyn ContextSelector, rates: &[f64], seed: u64) -> (Saturating, ChaCha8Rng, ChaCha8Rng) {
        for arm in 0..rates.len() {
            selector.prime(arm, 0.0);
        }
        let problem = Saturating {
            rates: rates.to_vec(),
            pulls: vec![0; rates.len()],
            noise: 0.01,
        };
        (
            problem,
            ChaCha8Rng::seed_from_u64(seed),
            ChaCha8Rng::seed_from_u64(seed + 1000),
        )
    }

    /// Run `selector` for `steps` pulls; returns (area under the noise-free performance curve,
    /// fraction of pulls that went to the most-improving arm of that moment).
    fn run(selector: &mut dyn ContextSelector, rates: &[f64], steps: usize, seed: u64) -> (f64, f64) {
        let (mut problem, mut noise_rng, mut selector_rng) = start(selector, rates, seed);
        let (mut area, mut hits) = (0.0, 0);
        for _ in 0..steps {
            let target = problem.most_improving();
            let choice = selector.choose(&mut selector_rng);
            let arm = choice.arm.unwrap();
            hits += usize::from(arm == target);
            let reward = problem.pull(arm, &mut noise_rng);
            selector.observe(&choice, reward);
            area += problem.performance();
        }
        (area, hits as f64 / steps as f64)
    }

    fn monotonic(k: usize, xi: f64) -> BanditSelector {
        BanditSelector::new(
            grid(k),
            DUcbConfig { xi, ..paper_sec4(0.25) },
            IntrinsicReward::MonotonicProgress,
            FirstVisit::InitialReturn,
        )
        .unwrap()
    }

    /// Drive `selector` as the learner does with `in_flight` tasks in flight: choice t is made
    /// right after outcome t - in_flight is observed, outcomes are observed in choice order.
    /// Returns the chosen arms.
    fn run_in_flight(
        selector: &mut BanditSelector,
        rates: &[f64],
        steps: usize,
        in_flight: usize,
        seed: u64,
    ) -> Vec<usize> {
        let (mut problem, mut noise_rng, mut selector_rng) = start(selector, rates, seed);
        let mut window = VecDeque::new();
        let mut arms = Vec::with_capacity(steps);
        while arms.len() < steps {
            while window.len() < in_flight && arms.len() + window.len() < steps {
                let choice = selector.choose(&mut selector_rng);
                window.push_back(choice);
                assert_eq!(selector.pending().len(), window.len());
            }
            let choice = window.pop_front().unwrap();
            let arm = choice.arm.unwrap();
            let reward = problem.pull(arm, &mut noise_rng);
            selector.observe(&choice, reward);
            arms.push(arm);
        }
        assert!(selector.pending().is_empty());
        arms
    }

    /// Number of maximal runs of one arm.
    fn streaks(arms: &[usize]) -> usize {
        1 + arms.windows(2).filter(|w| w[0] != w[1]).count()
    }

    fn fastest_last(k: usize) -> Vec<f64> {
        (0..k).map(|i| 0.01 * 1.4f64.powi(i as i32)).collect()
    }

    #[test]
    fn one_in_flight_is_exactly_the_sequential_bandit() {
        // The pre-batching selector, spelled out: plain D-UCB selection, intrinsic reward, update.
        let rates = fastest_last(10);
        for seed in 0..3 {
            let mut selector = monotonic(rates.len(), XI);
            let arms = run_in_flight(&mut selector, &rates, 400, 1, seed);
            let mut ducb = DUcb::new(
                rates.len(),
                DUcbConfig {
                    xi: XI,
                    ..paper_sec4(0.25)
                },
            )
            .unwrap();
            let mut intrinsic = IntrinsicTracker::new(
                IntrinsicReward::MonotonicProgress,
                FirstVisit::InitialReturn,
                rates.len(),
                0.25,
            );
            let mut problem = Saturating {
                rates: rates.clone(),
                pulls: vec![0; rates.len()],
                noise: 0.01,
            };
            let mut noise_rng = ChaCha8Rng::seed_from_u64(seed);
            for arm in 0..rates.len() {
                intrinsic.prime(arm, 0.0).unwrap();
            }
            for (t, &chosen) in arms.iter().enumerate() {
                let arm = ducb.select();
                assert_eq!(chosen, arm, "seed {seed} step {t}");
                let r_beta = intrinsic.reward(arm, problem.pull(arm, &mut noise_rng)).unwrap();
                ducb.update(arm, r_beta).unwrap();
            }
            // Bit for bit the same statistics.
            assert_eq!(selector.discounted_counts(), ducb.counts());
            assert_eq!(selector.discounted_means(), ducb.means());
        }
    }

    /// Padding strong enough (2 B sqrt(xi) = 0.016) to matter against the progress rewards: the
    /// fantasy only moves padding, so it spreads choices only where the bandit explores at all.
    const XI: f64 = 1e-3;

    #[test]
    fn a_window_in_flight_spreads_over_arms_and_is_deterministic() {
        let rates = fastest_last(10);
        for in_flight in [4, 16] {
            let arms = run_in_flight(&mut monotonic(rates.len(), XI), &rates, 400, in_flight, 0);
            // A function of the choose/observe sequence only: the rng and a rerun change nothing.
            assert_eq!(
                run_in_flight(&mut monotonic(rates.len(), XI), &rates, 400, in_flight, 0),
                arms
            );
            let mut other_rng = monotonic(rates.len(), XI);
            let mut rng = ChaCha8Rng::seed_from_u64(99);
            let first: Vec<usize> = (0..in_flight)
                .map(|_| other_rng.choose(&mut rng).arm.unwrap())
                .collect();
            assert_eq!(first, arms[..in_flight]);
            // Plain D-UCB would repeat its favourite until a reward came back. Counting pending
            // pulls keeps runs of one arm about as short as in the sequential run (measured mean
            // run 1.21-1.25 for 1 in flight, 1.22-1.27 for 4, 1.39-1.44 for 16).
            let sequential = run_in_flight(&mut monotonic(rates.len(), XI), &rates, 400, 1, 0);
            let mean_run = |arms: &[usize]| arms.len() as f64 / streaks(arms) as f64;
            assert!(
                mean_run(&arms) < 1.25 * mean_run(&sequential),
                "{in_flight} in flight: mean run {} vs {} sequential",
                mean_run(&arms),
                mean_run(&sequential)
            );
            // Every arm is still pulled.
            assert!((0..rates.len()).all(|arm| arms.contains(&arm)));
        }
    }

    #[test]
    fn observing_releases_the_oldest_pending_choice_of_the_arm() {
        let mut selector = monotonic(3, 1e-8);
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let choices: Vec<Choice> = (0..3).map(|_| selector.choose(&mut rng)).collect();
        assert_eq!(selector.pending(), &[0, 1, 2]);
        // A foreign choice releases nothing; a non-finite return still releases its choice.
        let foreign = Choice {
            arm: None,
            context: vec![0.5],
        };
        selector.observe(&foreign, 1.0);
        assert_eq!(selector.pending(), &[0, 1, 2]);
        selector.observe(&choices[0], f64::NAN);
        assert_eq!(selector.pending(), &[1, 2]);
        assert_eq!(selector.discounted_counts(), [0.0, 0.0, 0.0]);
        selector.observe(&choices[1], 0.5);
        selector.observe(&choices[2], 0.5);
        assert!(selector.pending().is_empty());
    }

    #[test]
    fn monotonic_progress_follows_the_most_improving_arm_better_than_round_robin() {
        // Ten arms saturating after 100, 71, 51, ... 4.8 pulls, the fastest last, so neither the
        // initial sweep nor index order hands the bandit the right arm. 200 steps do not
        // suffice to saturate them all, so the order matters.
        let rates: Vec<f64> = (0..10).map(|i| 0.01 * 1.4f64.powi(i)).collect();
        let steps = 200;
        for seed in 0..6 {
            let mut bandit = BanditSelector::new(
                grid(rates.len()),
                paper_sec4(0.25),
                IntrinsicReward::MonotonicProgress,
                FirstVisit::InitialReturn,
            )
            .unwrap();
            let mut round_robin = RoundRobin::all(grid(rates.len())).unwrap();
            let (bandit_area, bandit_hits) = run(&mut bandit, &rates, steps, seed);
            let (rr_area, rr_hits) = run(&mut round_robin, &rates, steps, seed);
            // Round robin hits the most-improving arm about 1 time in 10; the bandit (measured
            // 0.40-0.67 over these seeds) at least 3 times as often.
            assert!(
                bandit_hits >= 0.35 && bandit_hits >= 3.0 * rr_hits,
                "seed {seed}: hit fraction {bandit_hits} vs round robin {rr_hits}"
            );
            // Following it pays: the area under the performance curve is larger by at least 3%
            // (measured 4.6-6.4%; an oracle that always pulls the right arm gets 27%).
            assert!(
                bandit_area > 1.03 * rr_area,
                "seed {seed}: area {bandit_area} vs round robin {rr_area}"
            );
        }
    }

    /// Retirement: the choices are the plain bandit's until a context retires; afterwards a
    /// retired context is chosen only as a probe; a fall brings it back; never all retire; and a
    /// restored selector continues exactly.
    #[test]
    fn retiring_selector_leaves_solved_contexts_to_probes() {
        let retire = RetireConfig {
            probe_every: 4,
            ..RetireConfig::default()
        };
        let config = DUcbConfig {
            xi: 1e-2,
            ..paper_sec4(1.0)
        };
        let new = || {
            BanditSelector::new(
                grid(5),
                config.clone(),
                IntrinsicReward::MonotonicProgress,
                FirstVisit::Zero,
            )
            .unwrap()
        };
        // Arm i climbs to level i + 1 after 10 (i + 1) pulls; from step 1500 on, arm 0 is
        // forgotten and returns 0.
        let reward = |arm: usize, pulls: u32, t: usize| {
            if arm == 0 && t >= 1500 {
                return 0.0;
            }
            (f64::from(pulls) / (10.0 * (arm + 1) as f64)).min(1.0) * (arm + 1) as f64
        };
        let drive = |selector: &mut BanditSelector, steps: std::ops::Range<usize>, pulls: &mut [u32; 5]| {
            let mut rng = ChaCha8Rng::seed_from_u64(0);
            steps
                .map(|t| {
                    let before: Vec<bool> = (0..5)
                        .map(|arm| selector.retirement().is_some_and(|r| r.is_retired(arm)))
                        .collect();
                    let choice = selector.choose(&mut rng);
                    let arm = choice.arm.unwrap();
                    pulls[arm] += 1;
                    selector.observe(&choice, reward(arm, pulls[arm], t));
                    (arm, before)
                })
                .collect::<Vec<_>>()
        };
        let mut plain = new();
        let plain_arms = drive(&mut plain, 0..2000, &mut [0; 5]);
        let mut retiring = new().with_retirement(retire.clone()).unwrap();
        let mut pulls = [0; 5];
        let mut steps = drive(&mut retiring, 0..1000, &mut pulls);
        // Interrupted at 1000 and continued by a selector restored from its state.
        let mut restored = new().with_retirement(retire).unwrap();
        restored.restore_state(retiring.save_state()).unwrap();
        steps.extend(drive(&mut restored, 1000..2000, &mut pulls));

        let first = steps
            .iter()
            .position(|(_, before)| before.iter().any(|&r| r))
            .expect("something retires");
        for t in 0..first {
            assert_eq!(steps[t].0, plain_arms[t].0, "step {t}: nothing retired yet");
        }
        assert_ne!(
            steps.iter().map(|s| s.0).collect::<Vec<_>>(),
            plain_arms.iter().map(|s| s.0).collect::<Vec<_>>()
        );
        for (t, (arm, before)) in steps.iter().enumerate() {
            assert!(before.iter().any(|&r| !r), "step {t}: every context retired");
            if before[*arm] {
                // A probe: at most one in every 4 choices.
                let window = &steps[t.saturating_sub(3)..t];
                assert!(!window.iter().any(|(a, b)| b[*a]), "step {t}: probes too close");
            }
        }
        // Arm 0 was retired before 1500 and active again after its fall.
        assert!(steps[1499].1[0], "arm 0 retired by step 1500");
        assert!(
            steps[1500..].iter().any(|(_, before)| !before[0]),
            "the fall brought arm 0 back"
        );
    }
}
