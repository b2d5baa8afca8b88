//! ALP-GMM (Portelas, Colas, Hofmann & Oudeyer, CoRL 2019): contexts drawn from the continuous
//! space where the absolute learning progress is high.
//!
//! Every observed context gets an absolute learning progress (ALP): |its return - the return of
//! the nearest earlier context| (0 while fewer than six contexts came before, as in the
//! original). Distances are taken in the context box scaled to the unit cube, so no dimension
//! dominates by its units. Every `fit_rate` observations, Gaussian mixtures of 2 ..=
//! `max_components` components are fitted to the last `fit_rate` (context, ALP) points, and the
//! one of lowest AIC is kept ([`gmm`](super::gmm)). A choice is then, with probability
//! `random_share`, uniform over the space; otherwise a component is drawn with probability
//! proportional to its mean ALP and a context from its Gaussian (clipped into the space).
//! Before the first fit every choice is uniform.
//!
//! Where the original knows the returns' bounds and scales them to [0, 1], here the ALP
//! coordinate of every fit is divided by the largest ALP among the fitted points: the fit, and
//! so every choice, is the same whatever the returns' units.
//!
//! A fit needs randomness (its k-means++ start), which only [`choose`](ContextSelector::choose)
//! receives: a fit that falls due in `observe` is made at the next choice.

use super::gmm::{Component, Mixture};
use super::neighbours::NeighbourIndex;
use super::progress::proportional;
use crate::selection::geometry::project;
use crate::selection::validate::check_space_and_snap;
use crate::selection::{Choice, ContextSelector, SelectorCreateError, SelectorRestoreError, SelectorState};
use acps_shared::{ContextSpace, nearest};
use rand::{Rng, RngCore};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::ops::RangeInclusive;

/// Earlier contexts needed before a context's ALP is measured (the original's `len > 5`).
const EARLIER_FOR_ALP: u64 = 6;

/// ALP-GMM parameters; `Default` gives the original's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AlpGmmConfig {
    /// Observations between two fits, and the number of latest points each fit uses (250).
    pub fit_rate: usize,
    /// Mixtures of 2 ..= this many components are fitted and compared by AIC (10).
    pub max_components: usize,
    /// Share of contexts drawn uniformly over the space, in [0, 1] (0.2).
    pub random_share: f64,
}

impl Default for AlpGmmConfig {
    fn default() -> Self {
        Self {
            fit_rate: 250,
            max_components: 10,
            random_share: 0.2,
        }
    }
}

impl AlpGmmConfig {
    /// Accepted `max_components`: at least the 2 the original starts from, at most twice its 10.
    pub const MAX_COMPONENTS: RangeInclusive<usize> = 2..=20;
    /// Most points a fit uses: each fit costs time in proportion to them.
    pub const MAX_FIT_RATE: usize = 100_000;
    /// Points per component of the largest mixture a fit needs at least, so that every
    /// covariance (up to 9 x 9 for 8 context dimensions and the ALP) rests on enough points.
    pub const POINTS_PER_COMPONENT: usize = 10;

    /// Check every parameter's range.
    pub fn validate(&self) -> Result<(), SelectorCreateError> {
        if !Self::MAX_COMPONENTS.contains(&self.max_components) {
            return Err(SelectorCreateError::MaxComponents(self.max_components));
        }
        let fewest = Self::POINTS_PER_COMPONENT * self.max_components;
        if !(fewest..=Self::MAX_FIT_RATE).contains(&self.fit_rate) {
            return Err(SelectorCreateError::FitRate {
                fit_rate: self.fit_rate,
                fewest,
            });
        }
        if !(0.0..=1.0).contains(&self.random_share) {
            return Err(SelectorCreateError::RandomShare {
                teacher: "alp-gmm",
                share: self.random_share,
            });
        }
        Ok(())
    }
}

/// The evolving state of an [`AlpGmm`] selector, for checkpoints.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AlpGmmState {
    /// Every distinct observed context (scaled to the unit cube), one after another.
    points: Vec<f64>,
    /// The latest return of each.
    returns: Vec<f64>,
    /// The last `fit_rate` (scaled context, ALP) points, oldest first.
    window: Vec<f64>,
    observations: u64,
    fit_due: bool,
    mixture: Option<Vec<Component>>,
}

/// ALP-GMM as a context selector, on the continuous space or snapped to training contexts.
#[derive(Debug, Clone)]
pub struct AlpGmm {
    space: ContextSpace,
    snap_to: Option<Vec<Vec<f64>>>,
    config: AlpGmmConfig,
    /// The bounding box's lower corner and widths: x -> (x - low) / width scales it to [0, 1].
    low: Vec<f64>,
    width: Vec<f64>,
    neighbours: NeighbourIndex,
    /// The last `fit_rate` (scaled context, ALP) points, oldest first, one after another.
    window: VecDeque<f64>,
    observations: u64,
    fit_due: bool,
    mixture: Option<Mixture>,
}

impl AlpGmm {
    /// ALP-GMM over `space`. With `snap_to`, every context is replaced by the nearest of these
    /// training contexts (Euclidean, ties to the lowest index) and the choice names its arm, as
    /// [`SaggRiac`](crate::selection::SaggRiac) does.
    pub fn new(
        space: ContextSpace,
        snap_to: Option<Vec<Vec<f64>>>,
        config: AlpGmmConfig,
    ) -> Result<Self, SelectorCreateError> {
        check_space_and_snap(&space, snap_to.as_deref())?;
        config.validate()?;
        let (low, high) = space.bounding_box();
        let width = low.iter().zip(&high).map(|(l, h)| h - l).collect();
        Ok(Self {
            neighbours: NeighbourIndex::new(space.dim()),
            window: VecDeque::with_capacity(config.fit_rate * (space.dim() + 1)),
            space,
            snap_to,
            config,
            low,
            width,
            observations: 0,
            fit_due: false,
            mixture: None,
        })
    }

    /// The parameters.
    pub fn config(&self) -> &AlpGmmConfig {
        &self.config
    }

    /// Observations so far.
    pub fn observations(&self) -> u64 {
        self.observations
    }

    /// The mixture of the last fit, over (scaled context, scaled ALP), if one succeeded.
    pub fn mixture(&self) -> Option<&[Component]> {
        self.mixture.as_ref().map(Mixture::components)
    }

    /// Number of coordinates of a point of the window and of the mixture.
    fn row(&self) -> usize {
        self.space.dim() + 1
    }

    /// Fit the mixtures to the window, its ALP coordinate divided by the largest ALP in it.
    fn refit(&mut self, rng: &mut dyn RngCore) {
        let row = self.row();
        let mut data: Vec<f64> = self.window.iter().copied().collect();
        let largest = data.iter().skip(row - 1).step_by(row).copied().fold(0.0, f64::max);
        if largest > 0.0 {
            data.iter_mut()
                .skip(row - 1)
                .step_by(row)
                .for_each(|alp| *alp /= largest);
        }
        let ks = *AlpGmmConfig::MAX_COMPONENTS.start()..=self.config.max_components;
        self.mixture = Mixture::fit_best(&data, row, ks, rng);
        self.fit_due = false;
    }

    /// A context drawn from the mixture: a component in proportion to its mean ALP (uniformly
    /// when every mean ALP is 0), then a point from its Gaussian, back in the space's units.
    fn draw_from(mixture: &Mixture, low: &[f64], width: &[f64], rng: &mut dyn RngCore) -> Vec<f64> {
        let components = mixture.components();
        let alp = components
            .iter()
            .map(|c| c.mean.last().copied().unwrap_or(0.0).max(0.0));
        let k = proportional(alp, rng.random()).unwrap_or_else(|| rng.random_range(0..components.len()));
        let scaled = mixture.sample_leading(k, low.len(), rng);
        scaled
            .iter()
            .zip(low.iter().zip(width))
            .map(|(x, (l, w))| l + x * w)
            .collect()
    }
}

impl ContextSelector for AlpGmm {
    /// Randomness is consumed in a fixed order: the fit, if one is due; one number for the
    /// random share; then the space's own sampler, or one number for the component and one
    /// normal per dimension.
    fn choose(&mut self, rng: &mut dyn RngCore) -> Choice {
        if self.fit_due {
            self.refit(rng);
        }
        let uniform = rng.random::<f64>() < self.config.random_share;
        let point = match &self.mixture {
            Some(mixture) if !uniform => project(&self.space, Self::draw_from(mixture, &self.low, &self.width, rng)),
            _ => self.space.sample(rng),
        };
        match &self.snap_to {
            Some(contexts) => {
                let arm = nearest(contexts, &point);
                Choice {
                    arm: Some(arm),
                    context: contexts[arm].clone(),
                }
            }
            None => Choice {
                arm: None,
                context: point,
            },
        }
    }

    /// Record the context practised and its ALP. The context is first clamped to the bounding
    /// box (a training context may lie outside the space). A context of the wrong dimension, or
    /// a non-finite context or return, is ignored.
    fn observe(&mut self, choice: &Choice, reward: f64) {
        let dim = self.space.dim();
        if choice.context.len() != dim || !choice.context.iter().all(|x| x.is_finite()) || !reward.is_finite() {
            return;
        }
        let scaled: Vec<f64> = (0..dim)
            .map(|d| (choice.context[d] - self.low[d]).clamp(0.0, self.width[d]) / self.width[d])
            .collect();
        let alp = match self.neighbours.nearest(&scaled) {
            // |r - r'| of two finite returns can overflow; f64::MAX keeps it finite.
            Some(previous) if self.observations >= EARLIER_FOR_ALP => (reward - previous).abs().min(f64::MAX),
            _ => 0.0,
        };
        self.neighbours.insert(&scaled, reward);
        if self.window.len() == self.config.fit_rate * self.row() {
            self.window.drain(..self.row());
        }
        self.window.extend(scaled);
        self.window.push_back(alp);
        self.observations += 1;
        if self.observations.is_multiple_of(self.config.fit_rate as u64) {
            self.fit_due = true;
        }
    }

    fn save_state(&self) -> SelectorState {
        SelectorState::AlpGmm(AlpGmmState {
            points: self.neighbours.points().to_vec(),
            returns: self.neighbours.values().to_vec(),
            window: self.window.iter().copied().collect(),
            observations: self.observations,
            fit_due: self.fit_due,
            mixture: self.mixture.as_ref().map(|m| m.components().to_vec()),
        })
    }

    fn restore_state(&mut self, state: SelectorState) -> Result<(), SelectorRestoreError> {
        let SelectorState::AlpGmm(state) = state else {
            return Err(state.wrong_kind("ALP-GMM"));
        };
        let refuse = |why: String| Err(SelectorRestoreError::AlpGmm(why));
        let (dim, row) = (self.space.dim(), self.row());
        if state.points.len() != state.returns.len() * dim {
            return refuse(format!(
                "{} coordinates for {} contexts of dimension {dim}",
                state.points.len(),
                state.returns.len()
            ));
        }
        if !state.window.len().is_multiple_of(row) || state.window.len() > self.config.fit_rate * row {
            return refuse(format!(
                "a window of {} numbers, not at most {} points of {row}",
                state.window.len(),
                self.config.fit_rate
            ));
        }
        // What a live selector holds: scaled contexts in the unit cube, finite returns, and
        // absolute learning progress (a distance of returns) that is finite and not negative.
        let unit = |x: &f64| (0.0..=1.0).contains(x);
        if let Some(x) = state.points.iter().find(|x| !unit(x)) {
            return refuse(format!("a context coordinate of {x}, outside the scaled unit cube"));
        }
        if let Some(r) = state.returns.iter().find(|r| !r.is_finite()) {
            return refuse(format!("a return of {r}"));
        }
        for point in state.window.chunks(row) {
            let (context, alp) = point.split_at(dim);
            if !(context.iter().all(unit) && alp[0].is_finite() && alp[0] >= 0.0) {
                return refuse(format!(
                    "a window point {point:?}, not a scaled context and its progress"
                ));
            }
        }
        let finite = |c: &Component| {
            c.weight.is_finite() && c.weight >= 0.0 && c.mean.iter().chain(&c.covariance).all(|x| x.is_finite())
        };
        if state.mixture.iter().flatten().any(|c| !finite(c)) {
            return refuse("a mixture component with a weight, mean or covariance no fit makes".into());
        }
        let mixture = match state.mixture {
            None => None,
            Some(components) => match Mixture::new(row, components) {
                Some(mixture) if mixture.components().len() <= self.config.max_components => Some(mixture),
                _ => return refuse("a mixture that is not one of this selector's".into()),
            },
        };
        let mut neighbours = NeighbourIndex::new(dim);
        for (point, &value) in state.points.chunks(dim).zip(&state.returns) {
            neighbours.insert(point, value);
        }
        if neighbours.len() != state.returns.len() {
            return refuse("repeated contexts".into());
        }
        self.neighbours = neighbours;
        self.window = state.window.into();
        self.observations = state.observations;
        self.fit_due = state.fit_due;
        self.mixture = mixture;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn square() -> ContextSpace {
        ContextSpace::new_box(vec![-4.0, 10.0], vec![4.0, 12.0]).unwrap()
    }

    fn small() -> AlpGmmConfig {
        AlpGmmConfig {
            fit_rate: 100,
            max_components: 4,
            ..AlpGmmConfig::default()
        }
    }

    /// A problem where only the left third of the square learns: the return of a context with
    /// x < -4/3 rises with the number of visits there, everywhere else it is 0 (plus a tiny
    /// deterministic ripple).
    #[derive(Default)]
    struct LeftThird {
        visits: f64,
    }

    impl LeftThird {
        fn reward(&mut self, context: &[f64], t: usize) -> f64 {
            if context[0] < -4.0 / 3.0 {
                self.visits += 1.0;
                self.visits * (1.0 + 0.1 * (t as f64).sin())
            } else {
                1e-3 * (t as f64).cos()
            }
        }
    }

    /// The contexts `selector` chooses at `steps` of `problem`, its returns times `scale`.
    fn run_on(
        selector: &mut AlpGmm,
        rng: &mut ChaCha8Rng,
        problem: &mut LeftThird,
        steps: std::ops::Range<usize>,
        scale: f64,
    ) -> Vec<Vec<f64>> {
        steps
            .map(|t| {
                let choice = selector.choose(rng);
                selector.observe(&choice, scale * problem.reward(&choice.context, t));
                choice.context
            })
            .collect()
    }

    /// `steps` choices on a fresh [`LeftThird`].
    fn run(selector: &mut AlpGmm, rng: &mut ChaCha8Rng, steps: usize, scale: f64) -> Vec<Vec<f64>> {
        run_on(selector, rng, &mut LeftThird::default(), 0..steps, scale)
    }

    #[test]
    fn contexts_concentrate_where_the_progress_is() {
        for seed in 0..3 {
            let mut selector = AlpGmm::new(square(), None, small()).unwrap();
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let contexts = run(&mut selector, &mut rng, 1000, 1.0);
            assert!(contexts.iter().all(|c| square().contains(c)));
            let left = |cs: &[Vec<f64>]| cs.iter().filter(|c| c[0] < -4.0 / 3.0).count() as f64 / cs.len() as f64;
            // Before the first fit: uniform, a third on the left.
            assert!((left(&contexts[..100]) - 1.0 / 3.0).abs() < 0.15, "seed {seed}");
            // Afterwards 80% of the choices follow the progress: most of them go left.
            assert!(left(&contexts[500..]) > 0.7, "seed {seed}: {}", left(&contexts[500..]));
            assert_eq!(selector.observations(), 1000);
            assert!(selector.mixture().is_some_and(|m| (2..=4).contains(&m.len())));
        }
    }

    #[test]
    fn same_seed_same_contexts_whatever_the_units_of_the_returns() {
        let contexts = |seed, scale| {
            let mut selector = AlpGmm::new(square(), None, small()).unwrap();
            run(&mut selector, &mut ChaCha8Rng::seed_from_u64(seed), 400, scale)
        };
        let original = contexts(1, 1.0);
        assert_eq!(contexts(1, 1.0), original);
        assert_ne!(contexts(2, 1.0), original);
        // A power of two scales every ALP exactly, so the scaled fits are the same.
        assert_eq!(contexts(1, 1024.0), original);
    }

    #[test]
    fn alp_is_the_distance_in_return_to_the_nearest_earlier_context() {
        let mut selector = AlpGmm::new(square(), None, small()).unwrap();
        let at = |x: f64, y: f64| Choice {
            arm: None,
            context: vec![x, y],
        };
        // Six contexts along the bottom edge, returns 0..5: no ALP yet.
        for i in 0..6 {
            selector.observe(&at(-4.0 + 1.6 * i as f64, 10.0), i as f64);
        }
        // Scaled, (-3.9, 10.1) is 0.0125 from the first context in x and 0.05 in y: nearest.
        selector.observe(&at(-3.9, 10.1), 10.0);
        // (0.9, 12.0) scales to (0.6125, 1): nearest is (-0.8, 10) -> (0.4, 0) at 1.02, or
        // (0.8, 10) -> (0.6, 0) at 1.0001: the latter, return 3.
        selector.observe(&at(0.9, 12.0), 3.5);
        // The same context again: its own return, 3.5.
        selector.observe(&at(0.9, 12.0), 1.5);
        let alps: Vec<f64> = selector.window.iter().skip(2).step_by(3).copied().collect();
        assert_eq!(alps, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 10.0, 0.5, 2.0]);
        // Contexts outside the box are clamped into it; foreign or non-finite ones are ignored.
        selector.observe(&at(100.0, 100.0), 0.0);
        assert_eq!(
            selector.window.iter().rev().skip(1).take(2).collect::<Vec<_>>(),
            [&1.0, &1.0]
        );
        let before = selector.save_state();
        selector.observe(&at(0.0, f64::NAN), 1.0);
        selector.observe(&at(0.0, 11.0), f64::INFINITY);
        selector.observe(
            &Choice {
                arm: None,
                context: vec![0.0],
            },
            1.0,
        );
        assert_eq!(selector.save_state(), before);
    }

    #[test]
    fn snapped_contexts_are_training_contexts_and_name_their_arm() {
        let contexts: Vec<Vec<f64>> = (0..5).map(|i| vec![-4.0 + 2.0 * i as f64, 11.0]).collect();
        let mut selector = AlpGmm::new(square(), Some(contexts.clone()), small()).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        for choice in run(&mut selector, &mut rng, 300, 1.0) {
            assert!(contexts.contains(&choice), "{choice:?}");
        }
        let choice = selector.choose(&mut rng);
        assert_eq!(choice.context, contexts[choice.arm.unwrap()]);
    }

    #[test]
    fn a_ball_keeps_its_draws_inside() {
        let ball = ContextSpace::new_ball(2, 0.5).unwrap();
        let mut selector = AlpGmm::new(ball.clone(), None, small()).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        for t in 0..600 {
            let choice = selector.choose(&mut rng);
            assert!(ball.contains(&choice.context), "{choice:?}");
            // Progress near the rim only.
            let norm = choice.context.iter().map(|x| x * x).sum::<f64>().sqrt();
            selector.observe(&choice, if norm > 0.4 { t as f64 } else { 0.0 });
        }
        assert!(selector.mixture().is_some());
    }

    #[test]
    fn save_and_restore_between_and_at_fits_continue_exactly() {
        let mut uninterrupted = AlpGmm::new(square(), None, small()).unwrap();
        let expected = run(&mut uninterrupted, &mut ChaCha8Rng::seed_from_u64(3), 450, 1.0);
        // Cut at 100 (a fit is due, not yet made), 250 (between fits) and 300 (due again).
        for cut in [100, 250, 300] {
            let (mut rng, mut problem) = (ChaCha8Rng::seed_from_u64(3), LeftThird::default());
            let mut first = AlpGmm::new(square(), None, small()).unwrap();
            let mut contexts = run_on(&mut first, &mut rng, &mut problem, 0..cut, 1.0);
            let mut second = AlpGmm::new(square(), None, small()).unwrap();
            second.restore_state(first.save_state()).unwrap();
            assert_eq!(second.save_state(), first.save_state());
            contexts.extend(run_on(&mut second, &mut rng, &mut problem, cut..450, 1.0));
            assert_eq!(contexts, expected, "cut at {cut}");
            assert_eq!(second.save_state(), uninterrupted.save_state());
        }
    }

    #[test]
    fn bad_input_and_foreign_states_are_refused() {
        let message = |config| AlpGmm::new(square(), None, config).unwrap_err().to_string();
        assert_eq!(
            message(AlpGmmConfig {
                max_components: 1,
                ..AlpGmmConfig::default()
            }),
            "alp-gmm max_components must be in 2..=20, got 1"
        );
        assert_eq!(
            message(AlpGmmConfig {
                fit_rate: 99,
                ..AlpGmmConfig::default()
            }),
            "alp-gmm fit_rate must be in 100..=100000 (10 points per component of the largest mixture), got 99"
        );
        assert_eq!(
            message(AlpGmmConfig {
                random_share: -0.1,
                ..AlpGmmConfig::default()
            }),
            "alp-gmm random_share must be in [0, 1], got -0.1"
        );
        assert!(AlpGmmConfig::default().validate().is_ok());
        assert!(matches!(
            AlpGmm::new(square(), Some(vec![vec![0.0]]), small()),
            Err(SelectorCreateError::InvalidContext { .. })
        ));
        let mut selector = AlpGmm::new(square(), None, small()).unwrap();
        run(&mut selector, &mut ChaCha8Rng::seed_from_u64(0), 50, 1.0);
        let before = selector.save_state();
        let line = ContextSpace::new_box(vec![0.0], vec![1.0]).unwrap();
        let mut other = AlpGmm::new(line, None, small()).unwrap();
        run(&mut other, &mut ChaCha8Rng::seed_from_u64(0), 50, 1.0);
        assert!(selector.restore_state(other.save_state()).is_err());
        assert!(selector.restore_state(SelectorState::UniformContinuous).is_err());
        assert_eq!(selector.save_state(), before);
    }

    #[test]
    fn restored_states_a_live_selector_cannot_have_are_refused() {
        let mut live = AlpGmm::new(square(), None, small()).unwrap();
        run(&mut live, &mut ChaCha8Rng::seed_from_u64(5), 250, 1.0);
        let SelectorState::AlpGmm(saved) = live.save_state() else {
            unreachable!("an ALP-GMM state")
        };
        assert!(saved.mixture.is_some(), "the forgeries below include a mixture's");
        type Forgery = (&'static str, fn(&mut AlpGmmState));
        let forged: [Forgery; 5] = [
            ("a context coordinate of 2, outside", |s| s.points[0] = 2.0),
            ("a return of NaN", |s| s.returns[1] = f64::NAN),
            ("a window point", |s| s.window[2] = -1.0),
            ("a window point", |s| s.window[0] = f64::NAN),
            ("a mixture component", |s| {
                s.mixture.as_mut().unwrap()[0].covariance[0] = f64::INFINITY;
            }),
        ];
        let mut selector = AlpGmm::new(square(), None, small()).unwrap();
        selector.restore_state(SelectorState::AlpGmm(saved.clone())).unwrap();
        let before = selector.save_state();
        for (said, forge) in forged {
            let mut state = saved.clone();
            forge(&mut state);
            let error = selector
                .restore_state(SelectorState::AlpGmm(state))
                .unwrap_err()
                .to_string();
            assert!(error.contains(said), "{said}: {error}");
            assert_eq!(selector.save_state(), before, "{said}: the selector changed");
        }
    }
}
