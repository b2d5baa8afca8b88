//! The non-adaptive baselines of the paper: round robin (Sec. 4, 5.2), corners (Sec. 5.1),
//! random over the training contexts (Sec. 5.1) and random over the continuous space
//! (Sec. 5.1.3, 5.2).

use crate::selection::validate::{check_contexts, check_space};
use crate::selection::{Choice, ContextSelector, SelectorCreateError, SelectorRestoreError, SelectorState};
use acps_shared::ContextSpace;
use rand::{Rng, RngCore};

/// Visits a fixed list of arms in a fixed cyclic order.
#[derive(Debug, Clone)]
pub struct RoundRobin {
    contexts: Vec<Vec<f64>>,
    order: Vec<usize>,
    next: usize,
}

impl RoundRobin {
    /// Cycle through `order`, a non-empty list of indices into `contexts`.
    pub fn new(contexts: Vec<Vec<f64>>, order: Vec<usize>) -> Result<Self, SelectorCreateError> {
        check_contexts(&contexts, None)?;
        if order.is_empty() {
            return Err(SelectorCreateError::EmptyOrder);
        }
        if let Some(&arm) = order.iter().find(|&&arm| arm >= contexts.len()) {
            return Err(SelectorCreateError::OrderOutOfRange {
                arm,
                arms: contexts.len(),
            });
        }
        Ok(Self {
            contexts,
            order,
            next: 0,
        })
    }

    /// Cycle through every context in index order.
    pub fn all(contexts: Vec<Vec<f64>>) -> Result<Self, SelectorCreateError> {
        let order = (0..contexts.len()).collect();
        Self::new(contexts, order)
    }

    /// Cycle, in index order, through the contexts of largest Euclidean norm (within 1e-12 of
    /// the largest). On the paper's 5x5 grid over [-1, 1]^2 these are the four corners, its
    /// "corners" baseline (Sec. 5.1).
    pub fn farthest(contexts: Vec<Vec<f64>>) -> Result<Self, SelectorCreateError> {
        check_contexts(&contexts, None)?;
        let norms: Vec<f64> = contexts
            .iter()
            .map(|c| c.iter().map(|x| x * x).sum::<f64>().sqrt())
            .collect();
        let largest = norms.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let order = (0..norms.len()).filter(|&i| norms[i] >= largest - 1e-12).collect();
        Self::new(contexts, order)
    }

    /// The arms visited, in order.
    pub fn order(&self) -> &[usize] {
        &self.order
    }
}

impl ContextSelector for RoundRobin {
    fn choose(&mut self, _rng: &mut dyn RngCore) -> Choice {
        let arm = self.order[self.next];
        self.next = (self.next + 1) % self.order.len();
        Choice {
            arm: Some(arm),
            context: self.contexts[arm].clone(),
        }
    }

    fn observe(&mut self, _choice: &Choice, _reward: f64) {}

    fn save_state(&self) -> SelectorState {
        SelectorState::RoundRobin { next: self.next }
    }

    fn restore_state(&mut self, state: SelectorState) -> Result<(), SelectorRestoreError> {
        match state {
            SelectorState::RoundRobin { next } if next < self.order.len() => {
                self.next = next;
                Ok(())
            }
            SelectorState::RoundRobin { next } => Err(SelectorRestoreError::Position {
                next,
                len: self.order.len(),
            }),
            other => Err(other.wrong_kind("round-robin")),
        }
    }
}

/// Draws a training context uniformly at random.
#[derive(Debug, Clone)]
pub struct UniformDiscrete {
    contexts: Vec<Vec<f64>>,
}

impl UniformDiscrete {
    /// Draw from `contexts` (at least one, all of one dimension, finite).
    pub fn new(contexts: Vec<Vec<f64>>) -> Result<Self, SelectorCreateError> {
        check_contexts(&contexts, None)?;
        Ok(Self { contexts })
    }
}

impl ContextSelector for UniformDiscrete {
    fn choose(&mut self, rng: &mut dyn RngCore) -> Choice {
        let arm = rng.random_range(0..self.contexts.len());
        Choice {
            arm: Some(arm),
            context: self.contexts[arm].clone(),
        }
    }

    fn observe(&mut self, _choice: &Choice, _reward: f64) {}

    fn save_state(&self) -> SelectorState {
        SelectorState::UniformDiscrete
    }

    fn restore_state(&mut self, state: SelectorState) -> Result<(), SelectorRestoreError> {
        match state {
            SelectorState::UniformDiscrete => Ok(()),
            other => Err(other.wrong_kind("uniform over the training contexts")),
        }
    }
}

/// Draws a context uniformly from the continuous context space; the choice names no arm.
#[derive(Debug, Clone)]
pub struct UniformContinuous {
    space: ContextSpace,
}

impl UniformContinuous {
    /// Draw from `space`.
    pub fn new(space: ContextSpace) -> Result<Self, SelectorCreateError> {
        check_space(&space)?;
        Ok(Self { space })
    }
}

impl ContextSelector for UniformContinuous {
    fn choose(&mut self, rng: &mut dyn RngCore) -> Choice {
        Choice {
            arm: None,
            context: self.space.sample(rng),
        }
    }

    fn observe(&mut self, _choice: &Choice, _reward: f64) {}

    fn save_state(&self) -> SelectorState {
        SelectorState::UniformContinuous
    }

    fn restore_state(&mut self, state: SelectorState) -> Result<(), SelectorRestoreError> {
        match state {
            SelectorState::UniformContinuous => Ok(()),
            other => Err(other.wrong_kind("uniform over the context space")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// The paper's 5x5 training grid over [-1, 1]^2, row-major.
    fn grid5() -> Vec<Vec<f64>> {
        let ticks = [-1.0, -0.5, 0.0, 0.5, 1.0];
        ticks
            .iter()
            .flat_map(|&x| ticks.iter().map(move |&y| vec![x, y]))
            .collect()
    }

    fn arms(selector: &mut dyn ContextSelector, n: usize) -> Vec<Option<usize>> {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        (0..n).map(|_| selector.choose(&mut rng).arm).collect()
    }

    #[test]
    fn round_robin_cycles_in_order() {
        let contexts = vec![vec![0.0], vec![1.0], vec![2.0]];
        let mut all = RoundRobin::all(contexts.clone()).unwrap();
        assert_eq!(arms(&mut all, 7), [0, 1, 2, 0, 1, 2, 0].map(Some));
        let mut custom = RoundRobin::new(contexts.clone(), vec![2, 0]).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        assert_eq!(
            custom.choose(&mut rng),
            Choice {
                arm: Some(2),
                context: vec![2.0]
            }
        );
        assert_eq!(custom.choose(&mut rng).arm, Some(0));
        assert_eq!(custom.choose(&mut rng).arm, Some(2));
        assert_eq!(
            RoundRobin::new(contexts.clone(), vec![]).unwrap_err(),
            SelectorCreateError::EmptyOrder
        );
        assert_eq!(
            RoundRobin::new(contexts, vec![0, 3]).unwrap_err().to_string(),
            "round robin order must name arms < 3 (the number of contexts), got 3"
        );
    }

    #[test]
    fn farthest_on_the_paper_grid_is_the_four_corners() {
        let grid = grid5();
        let mut corners = RoundRobin::farthest(grid.clone()).unwrap();
        assert_eq!(corners.order(), [0, 4, 20, 24]);
        let picked: Vec<Vec<f64>> = {
            let mut rng = ChaCha8Rng::seed_from_u64(0);
            (0..4).map(|_| corners.choose(&mut rng).context).collect()
        };
        assert_eq!(picked, [[-1.0, -1.0], [-1.0, 1.0], [1.0, -1.0], [1.0, 1.0]]);
    }

    #[test]
    fn uniform_discrete_counts_are_within_statistical_bounds() {
        let k = 25;
        let draws = 50_000;
        for seed in 0..3 {
            let mut selector = UniformDiscrete::new(grid5()).unwrap();
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let mut counts = vec![0usize; k];
            for _ in 0..draws {
                let choice = selector.choose(&mut rng);
                let arm = choice.arm.unwrap();
                assert_eq!(choice.context, grid5()[arm]);
                counts[arm] += 1;
            }
            // Binomial(50000, 1/25): mean 2000, sd 43.8; 5 sd covers all 25 counts with
            // probability > 1 - 25 * 6e-7.
            let (mean, sd) = (2000.0, (draws as f64 * (1.0 / 25.0) * (24.0 / 25.0)).sqrt());
            for (arm, &c) in counts.iter().enumerate() {
                assert!((c as f64 - mean).abs() < 5.0 * sd, "seed {seed} arm {arm}: {c}");
            }
            // And not suspiciously flat either: a chi-square with 24 degrees of freedom is
            // above 5 with probability > 0.9999.
            let chi2: f64 = counts.iter().map(|&c| (c as f64 - mean).powi(2) / mean).sum();
            assert!(chi2 > 5.0 && chi2 < 60.0, "seed {seed}: chi2 {chi2}");
        }
    }

    #[test]
    fn uniform_continuous_draws_lie_in_the_space_and_name_no_arm() {
        let spaces = [
            ContextSpace::new_box(vec![-5.0, -5.0], vec![-3.0, -3.0]).unwrap(),
            ContextSpace::new_ball(3, 1.0).unwrap(),
        ];
        for space in spaces {
            let mut selector = UniformContinuous::new(space.clone()).unwrap();
            let mut rng = ChaCha8Rng::seed_from_u64(7);
            let draws: Vec<Choice> = (0..2000).map(|_| selector.choose(&mut rng)).collect();
            assert!(draws.iter().all(|c| c.arm.is_none() && space.contains(&c.context)));
            // Not degenerate: the draws spread over the bounding box in every dimension.
            let (low, high) = space.bounding_box();
            for d in 0..space.dim() {
                let (min, max) = draws.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), c| {
                    (a.min(c.context[d]), b.max(c.context[d]))
                });
                assert!(min < low[d] + 0.1 * (high[d] - low[d]) && max > high[d] - 0.1 * (high[d] - low[d]));
            }
        }
        let inverted = ContextSpace::Box {
            low: vec![1.0],
            high: vec![0.0],
        };
        assert!(UniformContinuous::new(inverted).is_err());
    }
}
