//! Active context selection as the paper proposes it (Sec. 3.3): D-UCB over the K training
//! contexts, rewarded with an intrinsic reward.

use super::validate::check_contexts;
use super::{Choice, ContextSelector, DUcb, DUcbConfig, FirstVisit, IntrinsicReward, IntrinsicTracker, SelectionError};
use rand::RngCore;

/// D-UCB over the training contexts with one intrinsic reward.
#[derive(Debug, Clone)]
pub struct BanditSelector {
    contexts: Vec<Vec<f64>>,
    ducb: DUcb,
    intrinsic: IntrinsicTracker,
}

impl BanditSelector {
    /// A selector over `contexts` (at least one, all of one dimension, finite).
    pub fn new(
        contexts: Vec<Vec<f64>>,
        ducb: DUcbConfig,
        heuristic: IntrinsicReward,
        first_visit: FirstVisit,
    ) -> Result<Self, SelectionError> {
        check_contexts(&contexts, None)?;
        let arms = contexts.len();
        let bound = ducb.b;
        Ok(Self {
            ducb: DUcb::new(arms, ducb)?,
            intrinsic: IntrinsicTracker::new(heuristic, first_visit, arms, bound),
            contexts,
        })
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
}

impl ContextSelector for BanditSelector {
    fn choose(&mut self, _rng: &mut dyn RngCore) -> Choice {
        let arm = self.ducb.select();
        Choice {
            arm: Some(arm),
            context: self.contexts[arm].clone(),
        }
    }

    /// Credit the intrinsic reward of `reward` to the chosen arm. A choice without a valid arm
    /// (not made by this selector) or a non-finite return is ignored: there is no arm to credit,
    /// and a NaN would poison the arm's mean and baseline for good.
    fn observe(&mut self, choice: &Choice, reward: f64) {
        let Some(arm) = choice.arm else { return };
        if !reward.is_finite() {
            return;
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::selection::RoundRobin;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

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
        assert_eq!(new(vec![], config.clone()).unwrap_err(), SelectionError::NoContexts);
        let bad = DUcbConfig { gamma: 1.5, ..config };
        assert_eq!(new(grid(2), bad).unwrap_err(), SelectionError::Gamma(1.5));
        let best = new(grid(2), paper_sec4(1.0)).unwrap();
        assert!(!best.wants_initial_returns());
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

    /// Run `selector` for `steps` pulls; returns (area under the noise-free performance curve,
    /// fraction of pulls that went to the most-improving arm of that moment).
    fn run(selector: &mut dyn ContextSelector, rates: &[f64], steps: usize, seed: u64) -> (f64, f64) {
        let mut problem = Saturating {
            rates: rates.to_vec(),
            pulls: vec![0; rates.len()],
            noise: 0.01,
        };
        let mut noise_rng = ChaCha8Rng::seed_from_u64(seed);
        let mut selector_rng = ChaCha8Rng::seed_from_u64(seed + 1000);
        for arm in 0..rates.len() {
            selector.prime(arm, 0.0);
        }
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
}
