//! The paper's context-selection methods by name, and how each is built for a problem.

use crate::selection::{
    BanditSelector, ContextSelector, DUcbConfig, FirstVisit, IntrinsicReward, RoundRobin, SaggRiac, SaggRiacConfig,
    SelectorCreateError, UniformContinuous, UniformDiscrete,
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
}

impl Method {
    /// Every method, in the order of the paper's figures.
    pub const ALL: [Method; 9] = [
        Method::RoundRobin,
        Method::Random,
        Method::RandomContinuous,
        Method::Corners,
        Method::BestReward,
        Method::Diversity,
        Method::OneStepProgress,
        Method::MonotonicProgress,
        Method::SaggRiac,
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
    "unknown method '{0}'; known methods: round-robin, random, random-continuous, corners, best-reward, diversity, one-step-progress, monotonic-progress, sagg-riac"
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

/// A method with its parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SelectorConfig {
    /// Which method.
    pub method: Method,
    /// D-UCB parameters (used by the intrinsic-reward methods).
    pub ducb: DUcbConfig,
    /// Baseline of a context's first visit (progress heuristics).
    pub first_visit: FirstVisit,
    /// SAGG-RIAC parameters.
    pub sagg_riac: SaggRiacConfig,
}

impl SelectorConfig {
    /// Build the selector for `problem`.
    pub fn build(&self, problem: &Problem) -> Result<Box<dyn ContextSelector>, SelectorCreateError> {
        let contexts = problem.training_contexts.clone();
        Ok(match self.method {
            Method::RoundRobin => Box::new(RoundRobin::all(contexts)?),
            Method::Corners => Box::new(RoundRobin::farthest(contexts)?),
            Method::Random => Box::new(UniformDiscrete::new(contexts)?),
            Method::RandomContinuous => Box::new(UniformContinuous::new(problem.space.clone())?),
            Method::SaggRiac => Box::new(SaggRiac::new(
                problem.space.clone(),
                Some(contexts),
                self.sagg_riac.clone(),
            )?),
            Method::BestReward | Method::Diversity | Method::OneStepProgress | Method::MonotonicProgress => {
                let heuristic = self
                    .method
                    .intrinsic_reward()
                    .expect("a D-UCB method has an intrinsic reward");
                Box::new(BanditSelector::new(
                    contexts,
                    self.ducb.clone(),
                    heuristic,
                    self.first_visit,
                )?)
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
