//! SAGG-RIAC goal generation (Baranes & Oudeyer 2013) as the paper describes it (Sec. 2.2, 4).
//!
//! The bounding box of the context space is partitioned into axis-aligned regions (the leaves
//! of a binary tree). Each leaf keeps the (context, return) pairs observed in it, in
//! chronological order, and has an interest: the absolute difference between the older and the
//! newer half of its last `window` returns, divided by `window`. A leaf holding more than
//! `split_threshold` samples is split where the two halves differ most in interest. Goals come
//! from three modes with fixed probabilities: uniform over the whole space; uniform inside a leaf
//! drawn with probability proportional to (interest - minimum interest); or near the
//! lowest-return context of such a leaf.
//!
//! Gaps in the paper are filled from the original method as the project notes list them
//! (algorithms.md section 4): the mode probabilities 0.7 / 0.2 / 0.1, the split criterion
//! |R1| |R2| |interest(R1) - interest(R2)| and the (interest - minimum) leaf weights.

use crate::selection::geometry::project;
use crate::selection::validate::check_space_and_snap;
use crate::selection::{Choice, ContextSelector, SelectorCreateError, SelectorRestoreError, SelectorState};
use acps_shared::{ContextSpace, nearest};
use rand::{Rng, RngCore};
use serde::{Deserialize, Serialize};

/// SAGG-RIAC parameters; `Default` gives the paper's Section 4 values and the original
/// method's mode probabilities.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SaggRiacConfig {
    /// A leaf holding more than this many samples splits (paper: 8).
    pub split_threshold: usize,
    /// Number of recent returns in the interest, zeta (paper: 10).
    pub window: usize,
    /// Probability of a uniform goal inside a leaf drawn by interest (0.7).
    pub p_interest_uniform: f64,
    /// Probability of a uniform goal over the whole space (0.2).
    pub p_global: f64,
    /// Probability of a goal near the lowest-return context of a leaf drawn by interest (0.1).
    pub p_near_lowest: f64,
    /// Half-width of the neighbourhood of the lowest-return context, as a fraction of the
    /// leaf's width in each dimension (0.05).
    pub near_radius: f64,
}

impl Default for SaggRiacConfig {
    fn default() -> Self {
        Self {
            split_threshold: 8,
            window: 10,
            p_interest_uniform: 0.7,
            p_global: 0.2,
            p_near_lowest: 0.1,
            near_radius: 0.05,
        }
    }
}

impl SaggRiacConfig {
    /// Check every parameter's range.
    pub fn validate(&self) -> Result<(), SelectorCreateError> {
        if self.split_threshold == 0 {
            return Err(SelectorCreateError::SplitThreshold);
        }
        if self.window < 2 {
            return Err(SelectorCreateError::Window(self.window));
        }
        let p = [self.p_interest_uniform, self.p_global, self.p_near_lowest];
        if !p.iter().all(|p| (0.0..=1.0).contains(p)) || (p.iter().sum::<f64>() - 1.0).abs() > 1e-9 {
            return Err(SelectorCreateError::ModeProbabilities {
                p_interest_uniform: self.p_interest_uniform,
                p_global: self.p_global,
                p_near_lowest: self.p_near_lowest,
            });
        }
        if !(self.near_radius.is_finite() && self.near_radius >= 0.0) {
            return Err(SelectorCreateError::NearRadius(self.near_radius));
        }
        Ok(())
    }
}

/// How a goal was generated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum GoalMode {
    /// Uniform over the whole context space.
    Global,
    /// Uniform inside a leaf drawn by interest (also the fallback of
    /// [`NearLowest`](Self::NearLowest) when the drawn leaf holds no sample).
    InterestUniform,
    /// Near the lowest-return context of a leaf drawn by interest.
    NearLowest,
}

/// The last generated goal, before snapping to a training context.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Goal {
    /// How it was generated.
    pub mode: GoalMode,
    /// The goal itself, inside the context space.
    pub point: Vec<f64>,
}

/// A leaf region as seen from outside, for diagnostics.
#[derive(Debug, Clone, PartialEq)]
pub struct RegionSummary {
    /// Lower corner.
    pub low: Vec<f64>,
    /// Upper corner.
    pub high: Vec<f64>,
    /// Number of samples it holds.
    pub samples: usize,
    /// Its current interest.
    pub interest: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Sample {
    context: Vec<f64>,
    reward: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
enum Node {
    /// A leaf and its samples in chronological order.
    Leaf(Vec<Sample>),
    /// An inner node: points with `x[dim] < cut` belong to `children[0]`, the others to
    /// `children[1]`.
    Split { dim: usize, cut: f64, children: [usize; 2] },
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Region {
    low: Vec<f64>,
    high: Vec<f64>,
    node: Node,
}

/// The evolving state of a [`SaggRiac`]: its region tree with the samples, and the last goal.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SaggRiacState {
    regions: Vec<Region>,
    last_goal: Option<Goal>,
}

/// SAGG-RIAC as a context selector, on a continuous space or snapped to training contexts.
#[derive(Debug, Clone)]
pub struct SaggRiac {
    space: ContextSpace,
    snap_to: Option<Vec<Vec<f64>>>,
    config: SaggRiacConfig,
    /// The region tree; index 0 is the root (the bounding box of the space).
    regions: Vec<Region>,
    last_goal: Option<Goal>,
}

impl SaggRiac {
    /// SAGG-RIAC over `space`. With `snap_to`, every goal is replaced by the nearest of these
    /// training contexts (Euclidean, ties to the lowest index) and the choice names its arm; this
    /// is how the Section 4 model's ten discrete contexts are used (space = box [-0.5, 9.5],
    /// contexts 0..9).
    pub fn new(
        space: ContextSpace,
        snap_to: Option<Vec<Vec<f64>>>,
        config: SaggRiacConfig,
    ) -> Result<Self, SelectorCreateError> {
        check_space_and_snap(&space, snap_to.as_deref())?;
        config.validate()?;
        let (low, high) = space.bounding_box();
        Ok(Self {
            space,
            snap_to,
            config,
            regions: vec![Region {
                low,
                high,
                node: Node::Leaf(Vec::new()),
            }],
            last_goal: None,
        })
    }

    /// The parameters.
    pub fn config(&self) -> &SaggRiacConfig {
        &self.config
    }

    /// Why `regions` cannot be this selector's region tree, if it cannot: the root must be the
    /// space's bounding box, every region and sample must have the space's dimension, and every
    /// inner node's children must come after it (so the tree has no cycles).
    fn check_regions(&self, regions: &[Region]) -> Result<(), String> {
        let dim = self.space.dim();
        let root = regions.first().ok_or("an empty region tree")?;
        if root.low != self.regions[0].low || root.high != self.regions[0].high {
            return Err(format!(
                "the root region {:?}..{:?} is not this space's bounding box {:?}..{:?}",
                root.low, root.high, self.regions[0].low, self.regions[0].high
            ));
        }
        // Inside the root's box: what every region, sample and cut of a live tree lies in.
        let inside = |x: &[f64]| (0..dim).all(|d| (root.low[d]..=root.high[d]).contains(&x[d]));
        for (index, region) in regions.iter().enumerate() {
            if region.low.len() != dim || region.high.len() != dim {
                return Err(format!("region {index} does not have the space's dimension {dim}"));
            }
            if !inside(&region.low) || !inside(&region.high) || (0..dim).any(|d| region.low[d] > region.high[d]) {
                return Err(format!(
                    "region {index} {:?}..{:?} is not a box inside the root's",
                    region.low, region.high
                ));
            }
            match &region.node {
                Node::Leaf(samples) => {
                    if samples.iter().any(|s| s.context.len() != dim) {
                        return Err(format!("a sample of region {index} does not have dimension {dim}"));
                    }
                    if let Some(sample) = samples.iter().find(|s| !inside(&s.context) || !s.reward.is_finite()) {
                        return Err(format!(
                            "a sample of region {index} at {:?} with return {}, which no run observes",
                            sample.context, sample.reward
                        ));
                    }
                }
                Node::Split {
                    dim: cut_dim,
                    cut,
                    children,
                } => {
                    if *cut_dim >= dim
                        || children.iter().any(|&c| c <= index || c >= regions.len())
                        || !(region.low[*cut_dim]..=region.high[*cut_dim]).contains(cut)
                    {
                        return Err(format!("region {index} is split inconsistently"));
                    }
                }
            }
        }
        Ok(())
    }

    /// The last goal generated by [`choose`](ContextSelector::choose), before snapping.
    pub fn last_goal(&self) -> Option<&Goal> {
        self.last_goal.as_ref()
    }

    /// The current leaf regions, in a fixed order (the order of their creation).
    pub fn regions(&self) -> Vec<RegionSummary> {
        self.leaves()
            .map(|(i, samples)| RegionSummary {
                low: self.regions[i].low.clone(),
                high: self.regions[i].high.clone(),
                samples: samples.len(),
                interest: self.interest_of(samples),
            })
            .collect()
    }

    /// (region index, samples) of every leaf, in arena order.
    fn leaves(&self) -> impl Iterator<Item = (usize, &[Sample])> {
        self.regions
            .iter()
            .enumerate()
            .filter_map(|(i, region)| match &region.node {
                Node::Leaf(samples) => Some((i, samples.as_slice())),
                Node::Split { .. } => None,
            })
    }

    fn interest_of(&self, samples: &[Sample]) -> f64 {
        let returns: Vec<f64> = samples.iter().map(|s| s.reward).collect();
        interest(&returns, self.config.window)
    }

    /// The index of the leaf that contains `point` (a point of the bounding box).
    fn locate(&self, point: &[f64]) -> usize {
        let mut index = 0;
        while let Node::Split { dim, cut, children } = &self.regions[index].node {
            index = children[usize::from(point[*dim] >= *cut)];
        }
        index
    }

    /// Draw a goal. Randomness is consumed in a fixed order: one number for the mode, then
    /// either the space's own sampler (global mode) or one number for the leaf and one per
    /// dimension for the point.
    fn draw_goal(&self, rng: &mut dyn RngCore) -> Goal {
        let u: f64 = rng.random();
        if u < self.config.p_global {
            return Goal {
                mode: GoalMode::Global,
                point: self.space.sample(rng),
            };
        }
        let (leaf, samples) = self.pick_leaf(rng.random());
        let Region { low, high, .. } = &self.regions[leaf];
        let lowest = samples.iter().reduce(|a, b| if b.reward < a.reward { b } else { a });
        let (mode, point) = match lowest {
            Some(lowest) if u >= self.config.p_global + self.config.p_interest_uniform => {
                let point = (0..low.len())
                    .map(|d| {
                        let radius = self.config.near_radius * (high[d] - low[d]);
                        let centre = lowest.context[d];
                        lerp(low[d].max(centre - radius), high[d].min(centre + radius), rng.random())
                    })
                    .collect();
                (GoalMode::NearLowest, point)
            }
            _ => {
                let point = (0..low.len()).map(|d| lerp(low[d], high[d], rng.random())).collect();
                (GoalMode::InterestUniform, point)
            }
        };
        Goal {
            mode,
            point: project(&self.space, point),
        }
    }

    /// A leaf drawn with probability proportional to (interest - minimum interest), or uniformly
    /// when all interests are equal; `u` is uniform in [0, 1).
    fn pick_leaf(&self, u: f64) -> (usize, &[Sample]) {
        let leaves: Vec<(usize, &[Sample], f64)> = self
            .leaves()
            .map(|(i, samples)| (i, samples, self.interest_of(samples)))
            .collect();
        let min = leaves.iter().map(|l| l.2).fold(f64::INFINITY, f64::min);
        let total: f64 = leaves.iter().map(|l| l.2 - min).sum();
        if !(total > 0.0 && total.is_finite()) {
            let (index, samples, _) = leaves[((u * leaves.len() as f64) as usize).min(leaves.len() - 1)];
            return (index, samples);
        }
        let target = u * total;
        let mut cumulative = 0.0;
        let mut last_positive = (leaves[0].0, leaves[0].1);
        for (index, samples, interest) in leaves {
            let weight = interest - min;
            if weight > 0.0 {
                cumulative += weight;
                last_positive = (index, samples);
                if target < cumulative {
                    break;
                }
            }
        }
        // Also the answer when rounding leaves target >= the running sum at the very end.
        last_positive
    }

    /// Split leaf `index` and, recursively, its children while they hold more than
    /// `split_threshold` samples. A leaf whose samples all sit at one point is left alone: no
    /// cut can separate them, and splitting it would never end (snapped goals make this the
    /// normal case for a leaf around a single training context).
    fn split(&mut self, index: usize) {
        let mut pending = vec![index];
        while let Some(index) = pending.pop() {
            let first = self.regions.len();
            let region = &mut self.regions[index];
            let Node::Leaf(samples) = &mut region.node else {
                continue;
            };
            let separable = samples.iter().any(|s| s.context != samples[0].context);
            if samples.len() <= self.config.split_threshold || !separable {
                continue;
            }
            let (dim, cut) = best_cut(&region.low, &region.high, samples, self.config.window);
            let samples = std::mem::take(samples);
            region.node = Node::Split {
                dim,
                cut,
                children: [first, first + 1],
            };
            // partition keeps each child's samples in chronological order.
            let (left, right): (Vec<Sample>, Vec<Sample>) = samples.into_iter().partition(|s| s.context[dim] < cut);
            let (low, high) = (region.low.clone(), region.high.clone());
            let mut left_high = high.clone();
            left_high[dim] = cut;
            let mut right_low = low.clone();
            right_low[dim] = cut;
            self.regions.push(Region {
                low,
                high: left_high,
                node: Node::Leaf(left),
            });
            self.regions.push(Region {
                low: right_low,
                high,
                node: Node::Leaf(right),
            });
            pending.extend([first, first + 1]);
        }
    }
}

impl ContextSelector for SaggRiac {
    fn choose(&mut self, rng: &mut dyn RngCore) -> Choice {
        let goal = self.draw_goal(rng);
        let choice = match &self.snap_to {
            Some(contexts) => {
                let arm = nearest(contexts, &goal.point);
                Choice {
                    arm: Some(arm),
                    context: contexts[arm].clone(),
                }
            }
            None => Choice {
                arm: None,
                context: goal.point.clone(),
            },
        };
        self.last_goal = Some(goal);
        choice
    }

    fn save_state(&self) -> SelectorState {
        SelectorState::SaggRiac(SaggRiacState {
            regions: self.regions.clone(),
            last_goal: self.last_goal.clone(),
        })
    }

    fn restore_state(&mut self, state: SelectorState) -> Result<(), SelectorRestoreError> {
        let SelectorState::SaggRiac(state) = state else {
            return Err(state.wrong_kind("SAGG-RIAC"));
        };
        self.check_regions(&state.regions)
            .map_err(SelectorRestoreError::Regions)?;
        self.regions = state.regions;
        self.last_goal = state.last_goal;
        Ok(())
    }

    /// Record the chosen context and its return in the leaf containing it. The context is first
    /// clamped to the bounding box, so a context outside it (say a training context given
    /// outside the space) lands in the nearest leaf instead of stretching cuts out of the box.
    /// A context of the wrong dimension, or a non-finite context or return, is ignored.
    fn observe(&mut self, choice: &Choice, reward: f64) {
        if choice.context.len() != self.space.dim()
            || !choice.context.iter().all(|x| x.is_finite())
            || !reward.is_finite()
        {
            return;
        }
        let Region { low, high, .. } = &self.regions[0];
        let context: Vec<f64> = (0..low.len())
            .map(|d| choice.context[d].clamp(low[d], high[d]))
            .collect();
        let leaf = self.locate(&context);
        if let Node::Leaf(samples) = &mut self.regions[leaf].node {
            samples.push(Sample { context, reward });
        }
        self.split(leaf);
    }
}

/// The paper's interest: (1/window) |sum of the older half - sum of the newer half| of the last
/// `window` returns. With fewer returns, the ones there are; with an odd count, the middle one
/// is left out so both halves have equal length (otherwise the raw size of the returns, not
/// their change, would dominate). Zero with fewer than two returns.
fn interest(returns: &[f64], window: usize) -> f64 {
    let recent = &returns[returns.len().saturating_sub(window)..];
    let half = recent.len() / 2;
    let older: f64 = recent[..half].iter().sum();
    let newer: f64 = recent[recent.len() - half..].iter().sum();
    (older - newer).abs() / window as f64
}

/// The cut maximising |R1| |R2| |interest(R1) - interest(R2)| over every dimension and every
/// midpoint between consecutive distinct sample coordinates (ties: first dimension, first cut).
/// When every score is 0, the middle of the widest dimension.
fn best_cut(low: &[f64], high: &[f64], samples: &[Sample], window: usize) -> (usize, f64) {
    let mut best = None;
    let mut best_score = 0.0;
    for dim in 0..low.len() {
        let mut coordinates: Vec<f64> = samples.iter().map(|s| s.context[dim]).collect();
        coordinates.sort_by(f64::total_cmp);
        coordinates.dedup();
        for pair in coordinates.windows(2) {
            let middle = 0.5 * (pair[0] + pair[1]);
            // Adjacent floats have no midpoint strictly between them; cutting at the upper one
            // still separates the two.
            let cut = if middle > pair[0] { middle } else { pair[1] };
            let (mut left, mut right) = (Vec::new(), Vec::new());
            for s in samples {
                if s.context[dim] < cut { &mut left } else { &mut right }.push(s.reward);
            }
            let score = (left.len() * right.len()) as f64 * (interest(&left, window) - interest(&right, window)).abs();
            if score > best_score {
                best_score = score;
                best = Some((dim, cut));
            }
        }
    }
    best.unwrap_or_else(|| {
        let widest = (0..low.len()).fold(0, |w, d| if high[d] - low[d] > high[w] - low[w] { d } else { w });
        (widest, 0.5 * (low[widest] + high[widest]))
    })
}

/// `low + t (high - low)`: a uniform draw in [low, high] for t uniform in [0, 1), and safe for
/// zero-width intervals, unlike `random_range`.
fn lerp(low: f64, high: f64, t: f64) -> f64 {
    low + t * (high - low)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn unit_box(dim: usize) -> ContextSpace {
        ContextSpace::new_box(vec![0.0; dim], vec![1.0; dim]).unwrap()
    }

    fn observe_at(sagg: &mut SaggRiac, context: &[f64], reward: f64) {
        sagg.observe(
            &Choice {
                arm: None,
                context: context.to_vec(),
            },
            reward,
        );
    }

    #[test]
    fn interest_follows_the_papers_formula() {
        // Last 4 of 5 returns: older half 1 + 2, newer half 3 + 7: |3 - 10| / 4.
        assert_eq!(interest(&[5.0, 1.0, 2.0, 3.0, 7.0], 4), 1.75);
        // A decrease is as interesting as an increase.
        assert_eq!(interest(&[5.0, 7.0, 3.0, 2.0, 1.0], 4), 1.75);
        // Fewer returns than the window: the ones there are, still divided by the window; an
        // odd count leaves the middle one out: |1 - 3| / 4.
        assert_eq!(interest(&[1.0, 100.0, 3.0], 4), 0.5);
        assert_eq!(interest(&[1.0, 4.0], 10), 0.3);
        assert_eq!(interest(&[1.0], 10), 0.0);
        assert_eq!(interest(&[], 10), 0.0);
        // The paper's window of 10 on 12 returns: the first two fall out.
        let returns = [9.0, 9.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0];
        assert_eq!(interest(&returns, 10), 0.5);
    }

    #[test]
    fn a_split_happens_after_threshold_plus_one_samples_and_partitions_them() {
        let config = SaggRiacConfig {
            split_threshold: 3,
            window: 4,
            ..SaggRiacConfig::default()
        };
        let space = ContextSpace::new_box(vec![0.0], vec![4.0]).unwrap();
        let mut sagg = SaggRiac::new(space, None, config).unwrap();
        let returns = [0.0, 0.0, 0.0, 4.0];
        for (x, &r) in returns.iter().enumerate().take(3) {
            observe_at(&mut sagg, &[x as f64], r);
        }
        assert_eq!(sagg.regions().len(), 1, "3 samples do not exceed the threshold");
        observe_at(&mut sagg, &[3.0], returns[3]);
        // Cuts at 0.5, 1.5, 2.5 score 1*3*|0 - 1|, 2*2*|0 - 1| and 3*1*|0 - 0|
        // (interest of [0, 0, 4] with window 4 is |0 - 4| / 4 = 1): the cut is 1.5.
        let regions = sagg.regions();
        assert_eq!(
            regions,
            [
                RegionSummary {
                    low: vec![0.0],
                    high: vec![1.5],
                    samples: 2,
                    interest: 0.0
                },
                RegionSummary {
                    low: vec![1.5],
                    high: vec![4.0],
                    samples: 2,
                    interest: 1.0
                },
            ]
        );
        // Every sample sits in its region, in chronological order.
        let leaves: Vec<Vec<(f64, f64)>> = sagg
            .leaves()
            .map(|(_, samples)| samples.iter().map(|s| (s.context[0], s.reward)).collect())
            .collect();
        assert_eq!(leaves, [vec![(0.0, 0.0), (1.0, 0.0)], vec![(2.0, 0.0), (3.0, 4.0)]]);
    }

    /// The root's (dim, cut) after `samples` (threshold 5, window 4), and the leaves' returns.
    fn split_once(samples: &[([f64; 2], f64)]) -> ((usize, f64), Vec<Vec<f64>>) {
        let config = SaggRiacConfig {
            split_threshold: 5,
            window: 4,
            ..SaggRiacConfig::default()
        };
        let mut sagg = SaggRiac::new(unit_box(2), None, config).unwrap();
        for (context, reward) in samples {
            observe_at(&mut sagg, context, *reward);
        }
        let Node::Split { dim, cut, .. } = sagg.regions[0].node else {
            panic!("the root must have split")
        };
        let returns = sagg
            .leaves()
            .map(|(_, samples)| samples.iter().map(|s| s.reward).collect())
            .collect();
        ((dim, cut), returns)
    }

    #[test]
    fn split_picks_the_dimension_and_cut_of_largest_score_and_children_keep_order() {
        // Returns 0, 5, 10 at y > 0.5 and 0, 0, 0 below; x increases with time. Cutting y at
        // 0.5 scores 3 * 3 * |2.5 - 0| = 22.5 (interest of [0, 5, 10]: |0 - 10| / 4). The best
        // cut in x (between the 5th and 6th sample) scores 5 * 1 * |2.5 - 0| = 12.5.
        let samples = [
            ([0.1, 0.9], 0.0),
            ([0.2, 0.2], 0.0),
            ([0.3, 0.8], 5.0),
            ([0.4, 0.1], 0.0),
            ([0.5, 0.7], 10.0),
            ([0.6, 0.3], 0.0),
        ];
        let (cut, returns) = split_once(&samples);
        assert_eq!(cut, (1, 0.5));
        assert_eq!(returns, [vec![0.0, 0.0, 0.0], vec![0.0, 5.0, 10.0]]);
        // Mirror x so that it separates the same two groups as y: equal scores, and the first
        // dimension must win the tie.
        let mirrored = samples.map(|([_, y], r)| ([1.0 - y, y], r));
        let (cut, returns) = split_once(&mirrored);
        assert_eq!(cut, (0, 0.5));
        assert_eq!(returns, [vec![0.0, 5.0, 10.0], vec![0.0, 0.0, 0.0]]);
    }

    #[test]
    fn all_zero_scores_cut_the_widest_dimension_in_the_middle() {
        let config = SaggRiacConfig {
            split_threshold: 2,
            ..SaggRiacConfig::default()
        };
        let space = ContextSpace::new_box(vec![0.0, 0.0], vec![1.0, 4.0]).unwrap();
        let mut sagg = SaggRiac::new(space, None, config).unwrap();
        for context in [[0.1, 0.1], [0.2, 0.3], [0.3, 0.2]] {
            observe_at(&mut sagg, &context, 1.0);
        }
        let regions = sagg.regions();
        // Equal returns: every interest 0, so the root (widths 1 and 4) is cut on dimension 1
        // at 2. All samples fall below; that child and its descendants are cut the same way
        // until the samples separate.
        let Node::Split { dim, cut, .. } = &sagg.regions[0].node else {
            panic!("root must split")
        };
        assert_eq!((*dim, *cut), (1, 2.0));
        assert!(regions.iter().all(|r| r.samples <= 2));
        assert_eq!(regions.iter().map(|r| r.samples).sum::<usize>(), 3);
    }

    #[test]
    fn samples_at_a_single_point_never_split() {
        let config = SaggRiacConfig {
            split_threshold: 2,
            ..SaggRiacConfig::default()
        };
        let mut sagg = SaggRiac::new(unit_box(1), None, config).unwrap();
        for r in 0..50 {
            observe_at(&mut sagg, &[0.25], r as f64);
        }
        assert_eq!(sagg.regions().len(), 1);
        assert_eq!(sagg.regions()[0].samples, 50);
    }

    /// Three 1-D leaves [0, 1), [1, 2), [2, 3] holding the given returns (at their centres).
    fn three_leaves(returns: [&[f64]; 3]) -> SaggRiac {
        let space = ContextSpace::new_box(vec![0.0], vec![3.0]).unwrap();
        let mut sagg = SaggRiac::new(
            space,
            None,
            SaggRiacConfig {
                window: 4,
                ..SaggRiacConfig::default()
            },
        )
        .unwrap();
        let leaf = |low: f64, returns: &[f64]| Region {
            low: vec![low],
            high: vec![low + 1.0],
            node: Node::Leaf(
                returns
                    .iter()
                    .map(|&reward| Sample {
                        context: vec![low + 0.5],
                        reward,
                    })
                    .collect(),
            ),
        };
        sagg.regions = vec![
            Region {
                low: vec![0.0],
                high: vec![3.0],
                node: Node::Split {
                    dim: 0,
                    cut: 1.0,
                    children: [1, 2],
                },
            },
            leaf(0.0, returns[0]),
            Region {
                low: vec![1.0],
                high: vec![3.0],
                node: Node::Split {
                    dim: 0,
                    cut: 2.0,
                    children: [3, 4],
                },
            },
            leaf(1.0, returns[1]),
            leaf(2.0, returns[2]),
        ];
        sagg
    }

    /// Fraction of an even grid of u in [0, 1) for which `pick_leaf` returns each region.
    fn leaf_shares(sagg: &SaggRiac) -> [f64; 3] {
        let n = 10_000;
        let mut counts = [0usize; 3];
        for i in 0..n {
            let (region, _) = sagg.pick_leaf((i as f64 + 0.5) / n as f64);
            counts[[1, 3, 4].iter().position(|&r| r == region).unwrap()] += 1;
        }
        counts.map(|c| c as f64 / n as f64)
    }

    #[test]
    fn leaves_are_drawn_in_proportion_to_interest_above_the_minimum() {
        // Interests 0.25 (|1 - 2| / 4), 0.75 and 1.75: weights 0, 0.5, 1.5.
        let sagg = three_leaves([&[1.0, 2.0], &[0.0, 3.0], &[7.0, 0.0]]);
        let interests: Vec<f64> = sagg.regions().iter().map(|r| r.interest).collect();
        assert_eq!(interests, [0.25, 0.75, 1.75]);
        let shares = leaf_shares(&sagg);
        assert_eq!(shares[0], 0.0, "the least interesting leaf has weight 0");
        assert!(
            (shares[1] - 0.25).abs() < 1e-3 && (shares[2] - 0.75).abs() < 1e-3,
            "{shares:?}"
        );
        // All interests equal (0.25): uniform.
        let shares = leaf_shares(&three_leaves([&[1.0, 2.0], &[3.0, 4.0], &[6.0, 5.0]]));
        assert!(shares.iter().all(|s| (s - 1.0 / 3.0).abs() < 1e-3), "{shares:?}");
    }

    #[test]
    fn modes_occur_with_their_probabilities_and_place_goals_as_described() {
        for seed in 0..3 {
            // Leaves [0, 1) and [1, 2) are flat, [2, 3] holds returns 0 then 4 (interest 1):
            // every interest-driven goal falls in [2, 3].
            let sagg = three_leaves([&[1.0, 1.0], &[2.0, 2.0], &[0.0, 4.0]]);
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let n = 30_000;
            let mut counts = [0usize; 3];
            let mut global_in_first_leaf = 0;
            for _ in 0..n {
                let Goal { mode, point } = sagg.draw_goal(&mut rng);
                let x = point[0];
                match mode {
                    GoalMode::Global => {
                        counts[0] += 1;
                        global_in_first_leaf += usize::from(x < 1.0);
                    }
                    GoalMode::InterestUniform => {
                        counts[1] += 1;
                        assert!((2.0..=3.0).contains(&x), "{x}");
                    }
                    GoalMode::NearLowest => {
                        counts[2] += 1;
                        // Lowest return at 2.5; radius 0.05 * width 1.
                        assert!((2.45..=2.55).contains(&x), "{x}");
                    }
                }
            }
            // Binomial bounds at 5 standard deviations.
            for (count, p) in counts.iter().zip([0.2, 0.7, 0.1]) {
                let sd = (n as f64 * p * (1.0 - p)).sqrt();
                assert!(
                    (*count as f64 - n as f64 * p).abs() < 5.0 * sd,
                    "seed {seed}: {counts:?}"
                );
            }
            // Global goals cover the whole space: a third of them in [0, 1).
            let share = global_in_first_leaf as f64 / counts[0] as f64;
            assert!(
                (share - 1.0 / 3.0).abs() < 5.0 * (2.0 / 9.0 / counts[0] as f64).sqrt(),
                "{share}"
            );
        }
    }

    #[test]
    fn goals_lie_in_the_space() {
        let spaces = [
            ContextSpace::new_box(vec![-1.0, 2.0], vec![1.0, 3.0]).unwrap(),
            ContextSpace::new_ball(2, 1.0).unwrap(),
        ];
        for space in spaces {
            let config = SaggRiacConfig {
                p_interest_uniform: 0.4,
                p_global: 0.2,
                p_near_lowest: 0.4,
                ..Default::default()
            };
            let mut sagg = SaggRiac::new(space.clone(), None, config).unwrap();
            let mut rng = ChaCha8Rng::seed_from_u64(3);
            for t in 0..3000 {
                let choice = sagg.choose(&mut rng);
                assert!(choice.arm.is_none() && space.contains(&choice.context), "{choice:?}");
                // A return that improves fastest near one corner, so regions split unevenly.
                let reward = t as f64 * (choice.context[0] + choice.context[1]).exp() / 1000.0;
                sagg.observe(&choice, reward);
            }
            assert!(sagg.regions().len() > 10, "the tree must have grown");
        }
    }

    #[test]
    fn snapped_goals_become_the_nearest_training_context() {
        // The Section 4 setup: contexts 0..9 in the box [-0.5, 9.5].
        let contexts: Vec<Vec<f64>> = (0..10).map(|s| vec![s as f64]).collect();
        let space = ContextSpace::new_box(vec![-0.5], vec![9.5]).unwrap();
        let mut sagg = SaggRiac::new(space, Some(contexts.clone()), SaggRiacConfig::default()).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for t in 0..2000 {
            let choice = sagg.choose(&mut rng);
            let goal = sagg.last_goal().unwrap().point[0];
            let arm = choice.arm.unwrap();
            assert_eq!(choice.context, contexts[arm]);
            assert!(
                (0..10).all(|j| (goal - arm as f64).abs() <= (goal - j as f64).abs()),
                "goal {goal} -> {arm}"
            );
            sagg.observe(&choice, (arm as f64 * t as f64).sqrt().sin());
        }
        // Every over-full leaf holds a single training context (it cannot be split further),
        // and the tree stays small.
        for (_, samples) in sagg.leaves() {
            if samples.len() > sagg.config().split_threshold {
                assert!(samples.iter().all(|s| s.context == samples[0].context));
            }
        }
        assert!(sagg.regions().len() < 60, "{} regions", sagg.regions().len());
    }

    #[test]
    fn same_seed_same_goals() {
        let run = |seed: u64| {
            let mut sagg = SaggRiac::new(unit_box(2), None, SaggRiacConfig::default()).unwrap();
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            (0..500)
                .map(|t| {
                    let choice = sagg.choose(&mut rng);
                    sagg.observe(&choice, (t as f64 / 50.0) * choice.context[0] - choice.context[1]);
                    choice.context
                })
                .collect::<Vec<_>>()
        };
        assert_eq!(run(5), run(5));
        assert_ne!(run(5), run(6));
    }

    #[test]
    fn invalid_input_is_refused_with_the_parameter_named() {
        let new = |config| SaggRiac::new(unit_box(1), None, config);
        let message = |config| new(config).unwrap_err().to_string();
        let default = SaggRiacConfig::default();
        assert_eq!(
            message(SaggRiacConfig {
                split_threshold: 0,
                ..default.clone()
            }),
            "SAGG-RIAC split_threshold must be >= 1, got 0"
        );
        assert_eq!(
            message(SaggRiacConfig {
                window: 1,
                ..default.clone()
            }),
            "SAGG-RIAC window must be >= 2, got 1"
        );
        assert_eq!(
            message(SaggRiacConfig {
                p_global: 0.3,
                ..default.clone()
            }),
            "SAGG-RIAC p_interest_uniform, p_global and p_near_lowest must each be in [0, 1] and sum to 1, \
             got 0.7 + 0.3 + 0.1"
        );
        let negative = SaggRiacConfig {
            p_interest_uniform: 1.1,
            p_global: -0.1,
            p_near_lowest: 0.0,
            ..default.clone()
        };
        assert!(matches!(
            new(negative),
            Err(SelectorCreateError::ModeProbabilities { .. })
        ));
        assert_eq!(
            message(SaggRiacConfig {
                near_radius: -0.1,
                ..default.clone()
            }),
            "SAGG-RIAC near_radius must be finite and >= 0, got -0.1"
        );
        assert!(new(default.clone()).is_ok());
        let wrong_dim = SaggRiac::new(unit_box(2), Some(vec![vec![0.5]]), default.clone());
        assert!(matches!(
            wrong_dim,
            Err(SelectorCreateError::InvalidContext {
                index: 0,
                expected_dim: 2,
                ..
            })
        ));
        let inverted = ContextSpace::Box {
            low: vec![1.0],
            high: vec![0.0],
        };
        assert!(matches!(
            SaggRiac::new(inverted, None, default),
            Err(SelectorCreateError::Space(_))
        ));
    }

    #[test]
    fn default_config_has_the_papers_values() {
        let config = SaggRiacConfig::default();
        assert_eq!((config.split_threshold, config.window), (8, 10));
        assert_eq!(
            (config.p_interest_uniform, config.p_global, config.p_near_lowest),
            (0.7, 0.2, 0.1)
        );
        assert!(config.validate().is_ok());
    }

    #[test]
    fn restored_trees_a_live_selector_cannot_have_are_refused() {
        let mut live = SaggRiac::new(unit_box(2), None, SaggRiacConfig::default()).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        for t in 0..300 {
            let choice = live.choose(&mut rng);
            live.observe(&choice, (t as f64 / 50.0) * choice.context[0] - choice.context[1]);
        }
        let SelectorState::SaggRiac(saved) = live.save_state() else {
            unreachable!("a SAGG-RIAC state")
        };
        let split = saved
            .regions
            .iter()
            .position(|r| matches!(r.node, Node::Split { .. }))
            .unwrap();
        let leaf = saved
            .regions
            .iter()
            .rposition(|r| matches!(&r.node, Node::Leaf(s) if !s.is_empty()))
            .unwrap();
        let mut selector = SaggRiac::new(unit_box(2), None, SaggRiacConfig::default()).unwrap();
        selector.restore_state(SelectorState::SaggRiac(saved.clone())).unwrap();
        let before = selector.save_state();
        type Forgery = (&'static str, Box<dyn Fn(&mut SaggRiacState)>);
        let forgeries: Vec<Forgery> = vec![
            (
                "is not a box inside the root's",
                Box::new(move |s| s.regions[leaf].high[0] = 1e300),
            ),
            (
                "is not a box inside the root's",
                Box::new(move |s| s.regions[leaf].low[1] = f64::NAN),
            ),
            (
                "which no run observes",
                Box::new(move |s| {
                    if let Node::Leaf(samples) = &mut s.regions[leaf].node {
                        samples[0].reward = f64::INFINITY;
                    }
                }),
            ),
            (
                "which no run observes",
                Box::new(move |s| {
                    if let Node::Leaf(samples) = &mut s.regions[leaf].node {
                        samples[0].context[0] = -7.0;
                    }
                }),
            ),
            (
                "is split inconsistently",
                Box::new(move |s| {
                    if let Node::Split { cut, .. } = &mut s.regions[split].node {
                        *cut = f64::NAN;
                    }
                }),
            ),
        ];
        for (said, forge) in forgeries {
            let mut state = saved.clone();
            forge(&mut state);
            let error = selector
                .restore_state(SelectorState::SaggRiac(state))
                .unwrap_err()
                .to_string();
            assert!(error.contains(said), "{said}: {error}");
            assert_eq!(selector.save_state(), before, "{said}: the selector changed");
        }
    }
}
