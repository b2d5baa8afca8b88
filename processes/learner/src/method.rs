//! The context-selection methods by name (the paper's, and the teachers beyond it), their
//! configurations (each with only the parameters it uses), and how each is built for a problem.

use crate::selection::{
    AbsoluteProgress, AbsoluteProgressConfig, AlpGmm, AlpGmmConfig, BanditSelector, ContextSelector, DUcbConfig,
    FirstVisit, IntrinsicReward, RetireConfig, RoundRobin, SaggRiac, SaggRiacConfig, SelectorCreateError, SelfPaced,
    SelfPacedConfig, UniformContinuous, UniformDiscrete,
};
use acps_shared::Problem;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// A context-selection method. The four intrinsic rewards imply D-UCB.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Training contexts in a fixed cyclic order.
    RoundRobin,
    /// Uniform over the training contexts.
    Random,
    /// Uniform over the continuous context space.
    RandomContinuous,
    /// Round robin over the training contexts of largest norm (the corners of Section 5.1).
    Corners,
    /// D-UCB with the best-reward heuristic.
    BestReward,
    /// D-UCB with the diversity heuristic.
    Diversity,
    /// D-UCB with the 1-step progress heuristic.
    OneStepProgress,
    /// D-UCB with the monotonic progress heuristic.
    MonotonicProgress,
    /// SAGG-RIAC goal generation over the continuous space, snapped to the training contexts.
    SaggRiac,
    /// Training contexts in proportion to their absolute learning progress (beyond the paper).
    AbsoluteProgress,
    /// ALP-GMM over the continuous space (beyond the paper).
    AlpGmm,
    /// Self-paced contextual RL: a Gaussian over the continuous space moved by C-REPS itself
    /// (beyond the paper).
    SelfPaced,
}

impl Method {
    /// Every method, in the order of the paper's figures.
    pub const ALL: [Method; 12] = [
        Method::RoundRobin,
        Method::Random,
        Method::RandomContinuous,
        Method::Corners,
        Method::BestReward,
        Method::Diversity,
        Method::OneStepProgress,
        Method::MonotonicProgress,
        Method::SaggRiac,
        Method::AbsoluteProgress,
        Method::AlpGmm,
        Method::SelfPaced,
    ];

    /// The command-line and summary name.
    pub fn name(self) -> &'static str {
        match self {
            Method::RoundRobin => "round-robin",
            Method::Random => "random",
            Method::RandomContinuous => "random-continuous",
            Method::Corners => "corners",
            Method::BestReward => "best-reward",
            Method::Diversity => "diversity",
            Method::OneStepProgress => "one-step-progress",
            Method::MonotonicProgress => "monotonic-progress",
            Method::SaggRiac => "sagg-riac",
            Method::AbsoluteProgress => "absolute-progress",
            Method::AlpGmm => "alp-gmm",
            Method::SelfPaced => "self-paced",
        }
    }

    /// The intrinsic reward, for the D-UCB methods.
    pub fn intrinsic_reward(self) -> Option<IntrinsicReward> {
        match self {
            Method::BestReward => Some(IntrinsicReward::BestReward),
            Method::Diversity => Some(IntrinsicReward::Diversity),
            Method::OneStepProgress => Some(IntrinsicReward::OneStepProgress),
            Method::MonotonicProgress => Some(IntrinsicReward::MonotonicProgress),
            _ => None,
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A name that [`Method::from_str`] does not know.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown method '{0}'; known methods: round-robin, random, random-continuous, corners, best-reward, diversity, one-step-progress, monotonic-progress, sagg-riac, absolute-progress, alp-gmm, self-paced"
)]
pub struct MethodParseError(pub String);

impl FromStr for Method {
    type Err = MethodParseError;

    fn from_str(name: &str) -> Result<Self, Self::Err> {
        Method::ALL
            .into_iter()
            .find(|m| m.name() == name)
            .ok_or_else(|| MethodParseError(name.to_string()))
    }
}

/// One of the paper's non-adaptive baselines; they take no parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Baseline {
    /// Training contexts in a fixed cyclic order ([`RoundRobin::all`]).
    RoundRobin,
    /// Uniform over the training contexts ([`UniformDiscrete`]).
    Random,
    /// Uniform over the continuous context space ([`UniformContinuous`]).
    RandomContinuous,
    /// Round robin over the training contexts of largest norm ([`RoundRobin::farthest`]).
    Corners,
}

/// D-UCB over the training contexts, rewarded with an intrinsic reward (paper Sec. 3): the
/// paper's active context selection.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BanditConfig {
    /// What the bandit maximises.
    pub intrinsic_reward: IntrinsicReward,
    /// The bandit's parameters; their scale must match the intrinsic reward's (see
    /// [`DUcbConfig`]).
    pub ducb: DUcbConfig,
    /// What a progress heuristic compares a context's first return with (ignored by best
    /// reward and diversity, which have no baseline).
    pub first_visit: FirstVisit,
    /// Retire solved contexts (beyond the paper; default: no, as in the paper).
    #[serde(default)]
    pub retire: Option<RetireConfig>,
}

impl Default for BanditConfig {
    /// Monotonic progress, the heuristic the paper recommends (Sec. 5.1.2: "favorable in the long run"), with
    /// [`DUcbConfig::default`] and [`FirstVisit::default`].
    fn default() -> Self {
        Self::new(IntrinsicReward::MonotonicProgress)
    }
}

impl BanditConfig {
    /// `intrinsic_reward` with the default D-UCB parameters and first-visit rule.
    pub fn new(intrinsic_reward: IntrinsicReward) -> Self {
        Self {
            intrinsic_reward,
            ducb: DUcbConfig::default(),
            first_visit: FirstVisit::default(),
            retire: None,
        }
    }
}

/// A context-selection method with the parameters it needs, and only those. Build the selector
/// for a problem with [`build`](Self::build), or hand the configuration to
/// [`Learner::with_selector`](crate::Learner::with_selector).
///
/// ```
/// use acps_learner::selection::{
///     AbsoluteProgressConfig, AlpGmmConfig, DUcbConfig, IntrinsicReward, RetireConfig, SaggRiacConfig,
/// };
/// use acps_learner::{BanditConfig, Baseline, Method, SelectorConfig};
/// use acps_shared::{ContextSpace, EnvironmentSpec, Problem, ScoreAggregate};
///
/// let problem = Problem {
///     name: "five contexts".into(),
///     training_contexts: (0..5).map(|i| vec![i as f64 / 4.0]).collect(),
///     test_contexts: vec![],
///     space: ContextSpace::new_box(vec![0.0], vec![1.0])?,
///     theta0: vec![0.0],
///     score: ScoreAggregate::Mean,
///     metric: "error".into(),
///     environment: EnvironmentSpec::new("five-contexts", [0; 3], &())?,
/// };
///
/// // The paper's proposal with the defaults: D-UCB with monotonic progress.
/// let proposal = SelectorConfig::default();
/// assert_eq!(proposal, SelectorConfig::monotonic_progress());
/// assert_eq!(proposal.method(), Method::MonotonicProgress);
///
/// // A baseline takes no parameters; every method can also be named.
/// let random = SelectorConfig::from(Baseline::Random);
/// assert_eq!(random, SelectorConfig::from(Method::Random));
///
/// // D-UCB for returns that vary over about 100: B is their range (see DUcbConfig).
/// let scaled = SelectorConfig::from(BanditConfig {
///     ducb: DUcbConfig { b: 100.0, ..DUcbConfig::default() },
///     ..BanditConfig::new(IntrinsicReward::OneStepProgress)
/// });
///
/// // SAGG-RIAC with a longer interest window.
/// let sagg_riac = SelectorConfig::from(SaggRiacConfig { window: 20, ..SaggRiacConfig::default() });
///
/// // Beyond the paper: the paper's proposal retiring solved contexts, and absolute progress.
/// let retiring = SelectorConfig::from(BanditConfig {
///     retire: Some(RetireConfig::default()),
///     ..BanditConfig::default()
/// });
/// let progress = SelectorConfig::from(AbsoluteProgressConfig { random_share: 0.1, ..Default::default() });
///
/// for config in [proposal, random, scaled, sagg_riac, retiring, progress] {
///     assert!(!config.draws_from_space());
///     let mut selector = config.build(&problem)?;
///     let choice = selector.choose(&mut rand::rng());
///     assert!(choice.arm.is_some_and(|arm| arm < 5));
/// }
///
/// // ALP-GMM draws from the continuous space [0, 1] (refit every 100 contexts), unless it is
/// // snapped to the training contexts.
/// let alp_gmm = AlpGmmConfig { fit_rate: 100, ..AlpGmmConfig::default() };
/// let continuous = SelectorConfig::from(alp_gmm.clone());
/// assert!(continuous.draws_from_space());
/// let choice = continuous.build(&problem)?.choose(&mut rand::rng());
/// assert!(choice.arm.is_none() && problem.space.contains(&choice.context));
/// let snapped = SelectorConfig::AlpGmm { config: alp_gmm, snap: true };
/// assert!(snapped.build(&problem)?.choose(&mut rand::rng()).arm.is_some());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SelectorConfig {
    /// A non-adaptive baseline.
    Baseline(Baseline),
    /// D-UCB with an intrinsic reward.
    Bandit(BanditConfig),
    /// SAGG-RIAC goal generation over the continuous space, snapped to the training contexts
    /// (paper Sec. 2.2 and 4).
    SaggRiac(SaggRiacConfig),
    /// Absolute learning progress over the training contexts.
    AbsoluteProgress(AbsoluteProgressConfig),
    /// ALP-GMM over the continuous space.
    AlpGmm {
        /// Its parameters.
        config: AlpGmmConfig,
        /// Replace every context by the nearest training context, for problems that take only
        /// those (as SAGG-RIAC does).
        snap: bool,
    },
    /// Self-paced contextual RL over the continuous space; needs a policy (C-REPS) to move it.
    SelfPaced(SelfPacedConfig),
}

impl Default for SelectorConfig {
    /// [`SelectorConfig::monotonic_progress`], the paper's proposal.
    fn default() -> Self {
        Self::monotonic_progress()
    }
}

impl From<Baseline> for SelectorConfig {
    fn from(baseline: Baseline) -> Self {
        Self::Baseline(baseline)
    }
}

impl From<BanditConfig> for SelectorConfig {
    fn from(bandit: BanditConfig) -> Self {
        Self::Bandit(bandit)
    }
}

impl From<SaggRiacConfig> for SelectorConfig {
    fn from(config: SaggRiacConfig) -> Self {
        Self::SaggRiac(config)
    }
}

impl From<AbsoluteProgressConfig> for SelectorConfig {
    fn from(config: AbsoluteProgressConfig) -> Self {
        Self::AbsoluteProgress(config)
    }
}

impl From<AlpGmmConfig> for SelectorConfig {
    /// ALP-GMM over the continuous space, not snapped.
    fn from(config: AlpGmmConfig) -> Self {
        Self::AlpGmm { config, snap: false }
    }
}

impl From<SelfPacedConfig> for SelectorConfig {
    fn from(config: SelfPacedConfig) -> Self {
        Self::SelfPaced(config)
    }
}

impl From<Method> for SelectorConfig {
    /// The method with default parameters: [`BanditConfig::new`] for the D-UCB methods, and the
    /// `Default` of the others' configurations.
    fn from(method: Method) -> Self {
        match method {
            Method::RoundRobin => Baseline::RoundRobin.into(),
            Method::Random => Baseline::Random.into(),
            Method::RandomContinuous => Baseline::RandomContinuous.into(),
            Method::Corners => Baseline::Corners.into(),
            Method::SaggRiac => SaggRiacConfig::default().into(),
            Method::AbsoluteProgress => AbsoluteProgressConfig::default().into(),
            Method::AlpGmm => AlpGmmConfig::default().into(),
            Method::SelfPaced => SelfPacedConfig::default().into(),
            Method::BestReward | Method::Diversity | Method::OneStepProgress | Method::MonotonicProgress => {
                let reward = method
                    .intrinsic_reward()
                    .expect("a D-UCB method has an intrinsic reward");
                BanditConfig::new(reward).into()
            }
        }
    }
}

impl SelectorConfig {
    /// D-UCB with monotonic progress and default parameters ([`BanditConfig::default`]).
    pub fn monotonic_progress() -> Self {
        BanditConfig::default().into()
    }

    /// The method's name.
    pub fn method(&self) -> Method {
        match self {
            Self::Baseline(Baseline::RoundRobin) => Method::RoundRobin,
            Self::Baseline(Baseline::Random) => Method::Random,
            Self::Baseline(Baseline::RandomContinuous) => Method::RandomContinuous,
            Self::Baseline(Baseline::Corners) => Method::Corners,
            Self::Bandit(bandit) => match bandit.intrinsic_reward {
                IntrinsicReward::BestReward => Method::BestReward,
                IntrinsicReward::Diversity => Method::Diversity,
                IntrinsicReward::OneStepProgress => Method::OneStepProgress,
                IntrinsicReward::MonotonicProgress => Method::MonotonicProgress,
            },
            Self::SaggRiac(_) => Method::SaggRiac,
            Self::AbsoluteProgress(_) => Method::AbsoluteProgress,
            Self::AlpGmm { .. } => Method::AlpGmm,
            Self::SelfPaced(_) => Method::SelfPaced,
        }
    }

    /// Whether the selector draws contexts from the continuous space rather than among the
    /// training contexts: such a method cannot run on a problem that takes only those.
    pub fn draws_from_space(&self) -> bool {
        matches!(
            self,
            Self::Baseline(Baseline::RandomContinuous) | Self::AlpGmm { snap: false, .. } | Self::SelfPaced(_)
        )
    }

    /// Build the selector for `problem`: over its training contexts, or its context space for
    /// random (continuous), SAGG-RIAC, ALP-GMM and self-paced.
    pub fn build(&self, problem: &Problem) -> Result<Box<dyn ContextSelector>, SelectorCreateError> {
        let contexts = problem.training_contexts.clone();
        Ok(match self {
            Self::Baseline(Baseline::RoundRobin) => Box::new(RoundRobin::all(contexts)?),
            Self::Baseline(Baseline::Corners) => Box::new(RoundRobin::farthest(contexts)?),
            Self::Baseline(Baseline::Random) => Box::new(UniformDiscrete::new(contexts)?),
            Self::Baseline(Baseline::RandomContinuous) => Box::new(UniformContinuous::new(problem.space.clone())?),
            Self::Bandit(bandit) => {
                let selector = BanditSelector::new(
                    contexts,
                    bandit.ducb.clone(),
                    bandit.intrinsic_reward,
                    bandit.first_visit,
                )?;
                match &bandit.retire {
                    Some(retire) => Box::new(selector.with_retirement(retire.clone())?),
                    None => Box::new(selector),
                }
            }
            Self::SaggRiac(config) => Box::new(SaggRiac::new(problem.space.clone(), Some(contexts), config.clone())?),
            Self::AbsoluteProgress(config) => Box::new(AbsoluteProgress::new(contexts, config.clone())?),
            Self::AlpGmm { config, snap } => Box::new(AlpGmm::new(
                problem.space.clone(),
                snap.then_some(contexts),
                config.clone(),
            )?),
            Self::SelfPaced(config) => Box::new(SelfPaced::new(problem.space.clone(), config.clone())?),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_method_maps_to_a_config_and_back() {
        for method in Method::ALL {
            assert_eq!(SelectorConfig::from(method).method(), method);
        }
    }

    #[test]
    fn cli_and_serde_names_agree() {
        for method in Method::ALL {
            assert_eq!(method.name().parse::<Method>(), Ok(method));
            assert_eq!(
                serde_json::to_string(&method).unwrap(),
                format!("\"{}\"", method.name())
            );
        }
        let error = "monotonic".parse::<Method>().unwrap_err().to_string();
        assert!(
            error.contains("'monotonic'") && error.contains("monotonic-progress"),
            "{error}"
        );
    }
}
