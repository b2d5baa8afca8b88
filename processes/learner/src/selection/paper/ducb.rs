//! Discounted UCB (the paper's Algorithm 1) in an exact O(K)-per-step incremental form.
//!
//! Algorithm 1 recomputes, from the whole history, the discounted counts
//! n_i = sum_j gamma^(t - t_j) 1[i_j = i], their sum n, and the discounted means r_i. Here they
//! are kept up to date instead (project notes, algorithms.md section 3): after a reward r for arm
//! a, every N_i is multiplied by gamma, n <- gamma n + 1, N_a <- N_a + 1 and
//! m_a <- m_a + (r - m_a) / N_a. Decay scales a mean's numerator and denominator alike, so the
//! means of the other arms do not change; storing means rather than discounted sums also avoids
//! 0/0 once a count underflows.

use serde::{Deserialize, Serialize};

/// Why [`DUcb::new`] (or [`DUcbConfig::validate`]) refuses its arguments.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DUcbCreateError {
    /// The discount factor is outside (0, 1].
    #[error("D-UCB gamma must be in (0, 1], got {0}")]
    Gamma(f64),
    /// The padding strength is not finite and non-negative.
    #[error("D-UCB xi must be finite and >= 0, got {0}")]
    Xi(f64),
    /// The reward bound is not finite and positive.
    #[error("D-UCB b must be finite and > 0, got {0}")]
    RewardBound(f64),
    /// Zero arms.
    #[error("D-UCB number of arms must be >= 1, got 0")]
    NoArms,
}

/// Why [`DUcb::update`] refuses a reward. The bandit is left unchanged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DUcbUpdateError {
    /// An arm index that does not name one of the arms.
    #[error("arm must be < {arms} (the number of arms), got {arm}")]
    ArmOutOfRange {
        /// The offending index.
        arm: usize,
        /// The number of arms.
        arms: usize,
    },
    /// A reward that is NaN or infinite.
    #[error("reward must be finite, got {0}")]
    NonFiniteReward(f64),
}

/// Why [`DUcb::restore`] refuses saved statistics. The bandit is left unchanged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DUcbRestoreError {
    /// They are of a bandit with another number of arms.
    #[error("D-UCB statistics for {counts} counts and {means} means, this bandit has {arms} arms")]
    Arms {
        /// The number of saved counts.
        counts: usize,
        /// The number of saved means.
        means: usize,
        /// This bandit's number of arms.
        arms: usize,
    },
    /// They hold a value no bandit's updates make (a forged or corrupted checkpoint).
    #[error("D-UCB statistics no bandit has: {0}")]
    Values(String),
}

/// D-UCB parameters (paper Algorithm 1 and Sec. 3.3, in its notation).
///
/// The bandit picks the arm with the largest `m_i + 2 B sqrt(xi ln n / N_i)`: `m_i` is the
/// discounted mean of the arm's intrinsic rewards, `N_i` its discounted pull count and `n` the
/// discounted total. The intrinsic rewards are **not normalised**: they are in the units of the
/// environment's returns (`r`, `-r`, a difference of returns, or its positive part; see
/// [`IntrinsicReward`](super::IntrinsicReward)). Hence:
///
/// - `b` (B) carries the units of the intrinsic reward: the paper calls it "an upper bound on
///   the rewards"; the range the returns vary over bounds every heuristic's. Scaling every
///   return by c > 0 and B by c leaves every choice unchanged. B is also what a first visit
///   scores under [`FirstVisit::Optimistic`](super::FirstVisit::Optimistic).
/// - `xi` is dimensionless, and only `B sqrt(xi)` enters the padding: it is the exploration
///   bonus in reward units. With xi = 1e-8 (the paper's Sec. 4 and 5.1) the padding is
///   `2e-4 B sqrt(ln n / N_i)`, and D-UCB is greedy on its discounted means until an arm's
///   count has decayed by orders of magnitude (at gamma = 0.99 an arm left alone for ~900
///   selections gains a factor 100 of padding): the progress heuristics then stay on one
///   context for hundreds of episodes while the policy forgets the others.
/// - `gamma` sets the memory: rewards older than about `1 / (1 - gamma)` selections (100 at
///   0.99) weigh little, and the discounted counts settle at about `1 / ((1 - gamma) K)` per
///   arm for K arms, which should stay above 1.
///
/// The [`Default`] (gamma 0.99, xi 1e-2, B 1) is for returns that vary over about 1: B = 1
/// says so, and xi = 1e-2 makes the padding `0.2 sqrt(ln n / N_i)`, about a fifth of that
/// range, so contexts whose progress stalls are revisited. For returns of another scale set `b`
/// to their range. docs/DUCB-PARAMETERS.md gives the evidence; the paper's own settings
/// (gamma 0.95 or 0.99, xi 1e-8 or 1e-9, B 0.25 to 10,000) are what the `acps` experiments run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DUcbConfig {
    /// Discount factor gamma, in (0, 1]; 1 is plain UCB.
    pub gamma: f64,
    /// Padding strength xi >= 0 (dimensionless); 0 leaves no padding, so the bandit is greedy
    /// on its discounted means once every arm has been pulled.
    pub xi: f64,
    /// The bound B > 0 of the intrinsic rewards, in their units; scales the padding.
    pub b: f64,
}

impl Default for DUcbConfig {
    /// gamma 0.99 and B 1 as in the paper's Sec. 5.1; xi 1e-2 instead of its 1e-8, so that the
    /// padding matters against rewards of about 1 (see the type's docs).
    fn default() -> Self {
        Self {
            gamma: 0.99,
            xi: 1e-2,
            b: 1.0,
        }
    }
}

impl DUcbConfig {
    /// Check every parameter's range.
    pub fn validate(&self) -> Result<(), DUcbCreateError> {
        if !(self.gamma > 0.0 && self.gamma <= 1.0) {
            return Err(DUcbCreateError::Gamma(self.gamma));
        }
        if !(self.xi.is_finite() && self.xi >= 0.0) {
            return Err(DUcbCreateError::Xi(self.xi));
        }
        if !(self.b.is_finite() && self.b > 0.0) {
            return Err(DUcbCreateError::RewardBound(self.b));
        }
        Ok(())
    }
}

/// The statistics of a [`DUcb`], everything that changes while it runs (for checkpoints).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DUcbState {
    /// Discounted pull counts N_i.
    pub counts: Vec<f64>,
    /// Discounted mean rewards m_i.
    pub means: Vec<f64>,
    /// Discounted total n.
    pub total: f64,
    /// Selections made so far.
    pub selections: usize,
}

/// A discounted-UCB bandit over `K` arms.
#[derive(Debug, Clone)]
pub struct DUcb {
    config: DUcbConfig,
    /// Discounted pull counts N_i.
    counts: Vec<f64>,
    /// Discounted mean rewards m_i.
    means: Vec<f64>,
    /// Discounted total n = sum_i N_i.
    total: f64,
    /// Selections made so far; drives the initial sweep.
    selections: usize,
}

impl DUcb {
    /// A bandit over `arms` arms with no history.
    pub fn new(arms: usize, config: DUcbConfig) -> Result<Self, DUcbCreateError> {
        config.validate()?;
        if arms == 0 {
            return Err(DUcbCreateError::NoArms);
        }
        Ok(Self {
            config,
            counts: vec![0.0; arms],
            means: vec![0.0; arms],
            total: 0.0,
            selections: 0,
        })
    }

    /// The arm to pull next.
    ///
    /// The first K calls return 0, 1, ..., K-1. They count selections, not updates: with several
    /// tasks in flight, selections run ahead of updates, and counting updates would hand out
    /// arm 0 again and again until its first reward arrived. Afterwards the arm with the largest
    /// upper bound (see [`upper_bounds`](Self::upper_bounds)) wins, ties going to the lowest
    /// index.
    pub fn select(&mut self) -> usize {
        self.select_with_pending(&[])
    }

    /// The arm to pull next while the pulls `pending` (oldest first) have been selected but their
    /// rewards not yet [`update`](Self::update)d; arms out of range are ignored.
    ///
    /// With several tasks in flight the statistics do not change between selections, so plain
    /// [`select`](Self::select) would hand the same arm out again and again until its first
    /// reward came back. Here the bounds are taken instead from the state the bandit would be in
    /// had every pending pull been updated with a reward equal to its arm's current mean (a
    /// "fantasy" update, as GP-BUCB hallucinates observations at the posterior mean): every
    /// count and the total decay by gamma per pending pull and the pulled arm's count grows by
    /// 1, while no mean moves. Only the padding of arms in flight shrinks, so a run of
    /// selections spreads over arms whose bounds are close instead of repeating one. The real
    /// statistics are untouched; the fantasy is rebuilt at every call, in O(K |pending|).
    ///
    /// With nothing pending this is exactly [`select`](Self::select), i.e. Algorithm 1.
    pub fn select_with_pending(&mut self, pending: &[usize]) -> usize {
        self.select_among(pending, |_| true)
    }

    /// [`select_with_pending`](Self::select_with_pending) among the arms `eligible` accepts
    /// (at least one must be; the initial sweep ignores it). Retired contexts are left out this
    /// way; with every arm eligible the choice is exactly `select_with_pending`'s.
    pub fn select_among(&mut self, pending: &[usize], eligible: impl Fn(usize) -> bool) -> usize {
        let sweep = self.selections;
        self.selections = self.selections.saturating_add(1);
        if sweep < self.arms() {
            return sweep;
        }
        if pending.is_empty() {
            return self.best_arm(&self.counts, self.total, eligible);
        }
        let gamma = self.config.gamma;
        let mut counts = self.counts.clone();
        let mut total = self.total;
        for &arm in pending.iter().filter(|&&arm| arm < self.arms()) {
            counts.iter_mut().for_each(|n| *n *= gamma);
            total = gamma * total + 1.0;
            counts[arm] += 1.0;
        }
        self.best_arm(&counts, total, eligible)
    }

    /// The eligible arm with the largest upper bound for these counts and total, ties going to
    /// the lowest index (arm 0 if none is eligible).
    fn best_arm(&self, counts: &[f64], total: f64, eligible: impl Fn(usize) -> bool) -> usize {
        let mut best = 0;
        let mut best_value = f64::NEG_INFINITY;
        for (arm, &count) in counts.iter().enumerate().filter(|&(arm, _)| eligible(arm)) {
            let value = self.bound(arm, count, total);
            // Strictly greater keeps the lowest index among ties, as numpy's argmax does.
            if value > best_value {
                best = arm;
                best_value = value;
            }
        }
        best
    }

    /// The upper confidence bound of every arm: m_i + 2B sqrt(xi ln n / N_i), or +infinity when
    /// N_i is 0 (never pulled, or decayed to underflow: with gamma = 0.95 that takes about
    /// 14,000 steps without a pull).
    ///
    /// ln n is taken of max(n, 1). After the initial sweep has been observed, n >= 1 anyway; the
    /// clamp only matters while updates lag behind selections, where n < 1 would make the
    /// padding the square root of a negative number.
    pub fn upper_bounds(&self) -> Vec<f64> {
        (0..self.arms()).map(|arm| self.upper_bound(arm)).collect()
    }

    fn upper_bound(&self, arm: usize) -> f64 {
        self.bound(arm, self.counts[arm], self.total)
    }

    /// The upper bound of `arm` with discounted count `count` out of a total `total`.
    fn bound(&self, arm: usize, count: f64, total: f64) -> f64 {
        if count == 0.0 {
            return f64::INFINITY;
        }
        let log_total = total.max(1.0).ln();
        self.means[arm] + 2.0 * self.config.b * (self.config.xi * log_total / count).sqrt()
    }

    /// Credit `reward` to `arm`: decay every count and the total by gamma, then add the new
    /// sample with weight 1.
    pub fn update(&mut self, arm: usize, reward: f64) -> Result<(), DUcbUpdateError> {
        if arm >= self.arms() {
            return Err(DUcbUpdateError::ArmOutOfRange { arm, arms: self.arms() });
        }
        if !reward.is_finite() {
            return Err(DUcbUpdateError::NonFiniteReward(reward));
        }
        let gamma = self.config.gamma;
        self.counts.iter_mut().for_each(|n| *n *= gamma);
        self.total = gamma * self.total + 1.0;
        self.counts[arm] += 1.0;
        self.means[arm] += (reward - self.means[arm]) / self.counts[arm];
        Ok(())
    }

    /// Number of arms K.
    pub fn arms(&self) -> usize {
        self.counts.len()
    }

    /// The parameters.
    pub fn config(&self) -> &DUcbConfig {
        &self.config
    }

    /// Discounted pull counts N_i.
    pub fn counts(&self) -> &[f64] {
        &self.counts
    }

    /// Discounted mean rewards m_i (0 for arms never updated).
    pub fn means(&self) -> &[f64] {
        &self.means
    }

    /// Discounted total count n.
    pub fn total(&self) -> f64 {
        self.total
    }

    /// The statistics, for a checkpoint.
    pub fn state(&self) -> DUcbState {
        DUcbState {
            counts: self.counts.clone(),
            means: self.means.clone(),
            total: self.total,
            selections: self.selections,
        }
    }

    /// Continue from saved statistics, which must have one count and one mean per arm.
    ///
    /// Also refused: what [`DUcb::update`] cannot make. A count negative or not finite, a mean
    /// not finite, or a total that is not the counts' sum.
    pub fn restore(&mut self, state: DUcbState) -> Result<(), DUcbRestoreError> {
        if state.counts.len() != self.arms() || state.means.len() != self.arms() {
            return Err(DUcbRestoreError::Arms {
                counts: state.counts.len(),
                means: state.means.len(),
                arms: self.arms(),
            });
        }
        let refuse = |why: String| Err(DUcbRestoreError::Values(why));
        if let Some((i, n)) = state
            .counts
            .iter()
            .enumerate()
            .find(|(_, n)| !(n.is_finite() && **n >= 0.0))
        {
            return refuse(format!("count N_{i} = {n}"));
        }
        if let Some((i, m)) = state.means.iter().enumerate().find(|(_, m)| !m.is_finite()) {
            return refuse(format!("mean m_{i} = {m}"));
        }
        let sum: f64 = state.counts.iter().sum();
        // The total and the counts are discounted alike; they differ by rounding only.
        if !state.total.is_finite() || (state.total - sum).abs() > 1e-6 * (1.0 + sum) {
            return refuse(format!("total n = {} for counts summing to {sum}", state.total));
        }
        self.counts = state.counts;
        self.means = state.means;
        self.total = state.total;
        self.selections = state.selections;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn config(gamma: f64, xi: f64, b: f64) -> DUcbConfig {
        DUcbConfig { gamma, xi, b }
    }

    /// Algorithm 1 transcribed literally: the full history, everything recomputed with
    /// gamma^(t - t_j) at every step. Returns the chosen arm, and the gap between the best and
    /// the second-best upper bound (infinite when K = 1 or in the sweep).
    fn naive_select(k: usize, c: &DUcbConfig, history: &[(usize, f64)]) -> (usize, f64) {
        let t = history.len();
        if t < k {
            return (t, f64::INFINITY);
        }
        let weight = |tj: usize| c.gamma.powi((t - tj) as i32);
        let mut n_i = vec![0.0; k];
        let mut sums = vec![0.0; k];
        // t_j runs from 1 to t, as in the paper.
        for (j, &(arm, r)) in history.iter().enumerate() {
            n_i[arm] += weight(j + 1);
            sums[arm] += weight(j + 1) * r;
        }
        let n: f64 = n_i.iter().sum();
        let ucb: Vec<f64> = (0..k)
            .map(|i| sums[i] / n_i[i] + 2.0 * c.b * (c.xi * n.ln() / n_i[i]).sqrt())
            .collect();
        let mut best = 0;
        for i in 1..k {
            if ucb[i] > ucb[best] {
                best = i;
            }
        }
        let runner_up = (0..k)
            .filter(|&i| i != best)
            .map(|i| ucb[i])
            .fold(f64::NEG_INFINITY, f64::max);
        (best, ucb[best] - runner_up)
    }

    /// How a test sequence produces the reward of pulling `arm` at step `t`.
    enum Rewards {
        /// A fixed uniform random table, indexed by (arm, step).
        Table(Vec<Vec<f64>>),
        /// A drifting sinusoid per arm plus uniform noise from a seeded stream.
        Drifting(Box<ChaCha8Rng>),
    }

    impl Rewards {
        fn reward(&mut self, arm: usize, t: usize) -> f64 {
            match self {
                Self::Table(table) => table[arm][t],
                Self::Drifting(rng) => {
                    let phase = arm as f64 * 0.7 + t as f64 / 300.0;
                    0.5 + 0.4 * phase.sin() + rng.random_range(-0.1..0.1)
                }
            }
        }
    }

    #[test]
    fn incremental_form_selects_exactly_what_algorithm_1_selects() {
        const STEPS: usize = 3000;
        let configs = [
            config(0.95, 1e-8, 1.0),
            config(0.99, 1e-8, 1.0),
            config(0.99, 1e-9, 10_000.0),
            // Padding of the same order as the reward spread, so exploration is driven by it.
            config(0.97, 0.5, 1.0),
        ];
        let mut smallest_gap = f64::INFINITY;
        let mut compared = 0;
        for c in &configs {
            for k in [2, 10, 81] {
                for seed in 0..3u64 {
                    for drifting in [false, true] {
                        let mut rng = ChaCha8Rng::seed_from_u64(seed);
                        let mut rewards = if drifting {
                            Rewards::Drifting(Box::new(rng))
                        } else {
                            Rewards::Table((0..k).map(|_| (0..STEPS).map(|_| rng.random()).collect()).collect())
                        };
                        let mut ducb = DUcb::new(k, c.clone()).unwrap();
                        let mut history = Vec::with_capacity(STEPS);
                        for t in 0..STEPS {
                            let arm = ducb.select();
                            let (expected, gap) = naive_select(k, c, &history);
                            assert_eq!(arm, expected, "{c:?} K={k} seed={seed} drifting={drifting} step {t}");
                            smallest_gap = smallest_gap.min(gap);
                            compared += 1;
                            let r = rewards.reward(arm, t);
                            history.push((arm, r));
                            ducb.update(arm, r).unwrap();
                        }
                    }
                }
            }
        }
        assert_eq!(compared, 4 * 3 * 3 * 2 * STEPS);
        // Equal choices alone could hide luck: the two forms differ by rounding (~1e-15
        // relative), so a near-tie closer than that could flip. Show that none came close.
        assert!(smallest_gap > 1e-12, "smallest best-vs-runner-up gap {smallest_gap:e}");
    }

    #[test]
    fn pending_pulls_count_as_updates_with_the_arms_current_mean() {
        let c = config(0.97, 0.5, 1.0);
        let k = 6;
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut ducb = DUcb::new(k, c).unwrap();
        let mut compared = 0;
        for t in 0..2000 {
            let arm = ducb.select();
            ducb.update(arm, rng.random::<f64>() * (1.0 + arm as f64) / k as f64)
                .unwrap();
            if t < k {
                continue;
            }
            // Up to 9 pending pulls (0 included), plus one arm out of range that must be ignored.
            let pending: Vec<usize> = (0..t % 10).map(|_| rng.random_range(0..k)).collect();
            let mut fantasy = ducb.clone();
            for &arm in &pending {
                let mean = fantasy.means()[arm];
                fantasy.update(arm, mean).unwrap();
            }
            let expected = fantasy.select();
            let (counts, means, total) = (ducb.counts().to_vec(), ducb.means().to_vec(), ducb.total());
            let mut with_foreign = pending.clone();
            with_foreign.push(k);
            assert_eq!(
                ducb.select_with_pending(&with_foreign),
                expected,
                "step {t}, pending {pending:?}"
            );
            assert_eq!(fantasy.means(), &means[..], "a fantasy update must not move a mean");
            // The real statistics are untouched.
            assert_eq!(
                (ducb.counts(), ducb.means(), ducb.total()),
                (&counts[..], &means[..], total)
            );
            compared += 1;
        }
        assert_eq!(compared, 2000 - k);
    }

    #[test]
    fn pending_pulls_spread_a_window_over_tied_arms() {
        let mut plain = DUcb::new(4, config(0.99, 1e-8, 1.0)).unwrap();
        for arm in 0..4 {
            assert_eq!(plain.select(), arm);
            plain.update(arm, 0.5).unwrap();
        }
        let mut fantasy = plain.clone();
        // Four selections without an update: plain D-UCB repeats the first of the tied arms ...
        let repeated: Vec<usize> = (0..4).map(|_| plain.select()).collect();
        assert_eq!(repeated, [0, 0, 0, 0]);
        // ... while counting the pending pulls hands out each arm once.
        let mut pending = Vec::new();
        for _ in 0..4 {
            let arm = fantasy.select_with_pending(&pending);
            pending.push(arm);
        }
        assert_eq!(pending, [0, 1, 2, 3]);
    }

    #[test]
    fn first_k_selections_sweep_the_arms_even_before_any_update() {
        let mut ducb = DUcb::new(4, config(0.9, 1e-8, 1.0)).unwrap();
        let picks: Vec<usize> = (0..4).map(|_| ducb.select()).collect();
        assert_eq!(picks, [0, 1, 2, 3]);
        // No update yet: every count is 0, every bound infinite, the lowest index wins.
        assert_eq!(ducb.select(), 0);
    }

    #[test]
    fn invalid_configs_name_the_parameter_and_range() {
        let message = |c: DUcbConfig| DUcb::new(3, c).unwrap_err().to_string();
        assert_eq!(
            message(config(1.5, 1e-8, 1.0)),
            "D-UCB gamma must be in (0, 1], got 1.5"
        );
        assert_eq!(message(config(0.0, 1e-8, 1.0)), "D-UCB gamma must be in (0, 1], got 0");
        assert_eq!(
            message(config(f64::NAN, 1e-8, 1.0)),
            "D-UCB gamma must be in (0, 1], got NaN"
        );
        assert_eq!(
            message(config(1.0, -1.0, 1.0)),
            "D-UCB xi must be finite and >= 0, got -1"
        );
        assert!(
            DUcb::new(3, config(1.0, 0.0, 1.0)).is_ok(),
            "no padding is a valid bandit"
        );
        assert_eq!(
            message(config(1.0, 1e-8, -1.0)),
            "D-UCB b must be finite and > 0, got -1"
        );
        assert_eq!(
            message(config(1.0, 1e-8, f64::INFINITY)),
            "D-UCB b must be finite and > 0, got inf"
        );
        assert_eq!(
            DUcb::new(0, config(0.9, 1e-8, 1.0)).unwrap_err().to_string(),
            "D-UCB number of arms must be >= 1, got 0"
        );
        let mut ducb = DUcb::new(2, config(0.9, 1e-8, 1.0)).unwrap();
        assert_eq!(
            ducb.update(2, 0.0).unwrap_err().to_string(),
            "arm must be < 2 (the number of arms), got 2"
        );
        assert_eq!(
            ducb.update(0, f64::INFINITY),
            Err(DUcbUpdateError::NonFiniteReward(f64::INFINITY))
        );
        assert!(matches!(
            ducb.update(0, f64::NAN),
            Err(DUcbUpdateError::NonFiniteReward(_))
        ));
        assert_eq!(ducb.counts(), [0.0, 0.0], "a refused update must not decay anything");
    }

    #[test]
    fn underflowed_count_gives_an_infinite_bound() {
        let mut ducb = DUcb::new(2, config(0.5, 1e-8, 1.0)).unwrap();
        ducb.select();
        ducb.select();
        ducb.update(0, 1.0).unwrap();
        ducb.update(1, 0.0).unwrap();
        // 0.5^1100 underflows to exactly 0.
        for _ in 0..1100 {
            ducb.update(0, 1.0).unwrap();
        }
        assert_eq!(ducb.counts()[1], 0.0);
        assert_eq!(ducb.upper_bound(1), f64::INFINITY);
        assert_eq!(ducb.means()[1], 0.0);
        assert_eq!(ducb.select(), 1, "the starved arm must win despite its lower mean");
    }

    #[test]
    fn decay_leaves_the_other_means_unchanged() {
        let mut ducb = DUcb::new(3, config(0.9, 1e-8, 1.0)).unwrap();
        ducb.update(0, 0.25).unwrap();
        ducb.update(1, 0.75).unwrap();
        ducb.update(1, 0.25).unwrap();
        for _ in 0..50 {
            ducb.update(2, 3.0).unwrap();
        }
        assert_eq!(ducb.means()[0], 0.25);
        // Arm 1: weights 0.9 (for 0.75) and 1 (for 0.25): (0.675 + 0.25) / 1.9.
        let expected = (0.9 * 0.75 + 0.25) / 1.9;
        assert!((ducb.means()[1] - expected).abs() < 1e-15);
        assert_eq!(ducb.means()[2], 3.0);
        let expected_total = (1.0 - 0.9f64.powi(53)) / (1.0 - 0.9);
        assert!((ducb.total() - expected_total).abs() < 1e-12);
    }

    #[test]
    fn ties_go_to_the_lowest_index() {
        let mut ducb = DUcb::new(3, config(1.0, 1e-8, 1.0)).unwrap();
        for arm in 0..3 {
            assert_eq!(ducb.select(), arm);
            ducb.update(arm, 0.5).unwrap();
        }
        // Equal counts and means: all three bounds are identical.
        assert_eq!(ducb.upper_bound(0), ducb.upper_bound(2));
        assert_eq!(ducb.select(), 0);
        // Arm 0 pulled again with the same reward: its count grows, so its padding shrinks below
        // the others', and arm 1 is now the lowest index among the two tied maxima.
        ducb.update(0, 0.5).unwrap();
        assert_eq!(ducb.select(), 1);
    }

    #[test]
    fn selection_among_eligible_arms_skips_the_others_and_with_all_is_the_plain_selection() {
        let mut ducb = DUcb::new(4, config(0.99, 1e-2, 1.0)).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for t in 0..300 {
            let arm = ducb.select();
            ducb.update(arm, rng.random::<f64>() * (arm + 1) as f64 / 4.0).unwrap();
            if t < 4 {
                continue;
            }
            let pending = [t % 4, (t + 1) % 4];
            let best = ducb.clone().select_with_pending(&pending);
            assert_eq!(ducb.clone().select_among(&pending, |_| true), best);
            let second = ducb.clone().select_among(&pending, |arm| arm != best);
            assert_ne!(second, best);
            // The best of the others: removing it as well leaves neither.
            let third = ducb.clone().select_among(&pending, |arm| arm != best && arm != second);
            assert!(third != best && third != second);
        }
    }

    #[test]
    fn statistics_no_bandit_has_are_refused_and_leave_it_unchanged() {
        let mut bandit = DUcb::new(3, config(0.99, 1.0, 1.0)).unwrap();
        for step in 0..2000 {
            let arm = bandit.select();
            bandit.update(arm, f64::from(step % 7) - 3.0).unwrap();
        }
        let live = bandit.state();
        let mut restored = DUcb::new(3, config(0.99, 1.0, 1.0)).unwrap();
        restored.restore(live.clone()).unwrap();
        assert_eq!(restored.state(), live, "a live bandit's statistics restore exactly");
        type Forgery = (&'static str, fn(&mut DUcbState));
        let forged: [Forgery; 5] = [
            ("count N_1 = NaN", |s| s.counts[1] = f64::NAN),
            ("count N_0 = -1", |s| s.counts[0] = -1.0),
            ("mean m_2 = inf", |s| s.means[2] = f64::INFINITY),
            ("total n = 1000000000 for counts", |s| s.total = 1e9),
            ("total n = NaN", |s| s.total = f64::NAN),
        ];
        for (said, forge) in forged {
            let mut state = live.clone();
            forge(&mut state);
            let error = restored.restore(state).unwrap_err().to_string();
            assert!(error.contains(said), "{said}: {error}");
            assert_eq!(restored.state(), live, "{said}: the bandit changed");
        }
    }
}
