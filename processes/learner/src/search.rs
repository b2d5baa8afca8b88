//! The upper-level policy search a learner runs: C-REPS (the paper's, the default) or
//! contextual CMA-ES. Both learn the same policy class, `N(theta | W^T phi(s), Sigma)`, so
//! everything downstream of the search (tasks, policies on disk, `acps evaluate`) is the same.

use rand::RngCore;
use serde::{Deserialize, Serialize};

use crate::Interrupted;
use crate::ccmaes::{CCmaes, CCmaesConfig, CCmaesCreateError, CCmaesReport, CCmaesRestoreError, CCmaesState};
use crate::creps::{
    CReps, CRepsConfig, CRepsCreateError, CRepsRestoreError, CRepsState, LinearGaussianPolicy, PacedContexts,
    PolicySnapshot, Rejection, UpdateReport,
};

/// Which upper-level learner a run uses, with its settings.
///
/// ```
/// use acps_learner::SearchConfig;
/// use acps_learner::ccmaes::CCmaesConfig;
///
/// let search = SearchConfig::CCmaes(CCmaesConfig { population: Some(50), ..Default::default() });
/// assert_eq!(search.name(), "c-cmaes");
/// assert_eq!(SearchConfig::default().name(), "c-reps");
/// ```
#[derive(Clone, Debug)]
pub enum SearchConfig {
    /// C-REPS (the paper's learner).
    CReps(CRepsConfig),
    /// Contextual CMA-ES (Abdolmaleki et al. 2017).
    CCmaes(CCmaesConfig),
}

impl Default for SearchConfig {
    /// C-REPS with [`CRepsConfig::default`].
    fn default() -> Self {
        SearchConfig::CReps(CRepsConfig::default())
    }
}

impl SearchConfig {
    /// The learner's name, as a problem file and the command line spell it: `c-reps` or
    /// `c-cmaes`.
    pub fn name(&self) -> &'static str {
        match self {
            SearchConfig::CReps(_) => "c-reps",
            SearchConfig::CCmaes(_) => "c-cmaes",
        }
    }

    /// `Sigma_0 = initial_sigma I`, either learner's.
    pub fn initial_sigma(&self) -> f64 {
        match self {
            SearchConfig::CReps(c) => c.initial_sigma,
            SearchConfig::CCmaes(c) => c.initial_sigma,
        }
    }
}

/// Why a search cannot be built for a problem.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SearchCreateError {
    /// C-REPS refuses its configuration.
    #[error(transparent)]
    CReps(#[from] CRepsCreateError),
    /// C-CMA-ES refuses its configuration.
    #[error("c-cmaes: {0}")]
    CCmaes(#[from] CCmaesCreateError),
}

/// Why a saved search state does not fit.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SearchRestoreError {
    /// C-REPS refuses its state.
    #[error(transparent)]
    CReps(#[from] CRepsRestoreError),
    /// C-CMA-ES refuses its state.
    #[error(transparent)]
    CCmaes(#[from] CCmaesRestoreError),
    /// The state is of the other learner.
    #[error("the checkpoint's policy search is {checkpoint}, this learner's is {learner}")]
    Learner {
        /// The state's learner.
        checkpoint: &'static str,
        /// This learner's.
        learner: &'static str,
    },
}

/// A running upper-level policy search.
#[derive(Clone, Debug)]
pub enum Search {
    /// C-REPS.
    CReps(Box<CReps>),
    /// Contextual CMA-ES.
    CCmaes(Box<CCmaes>),
}

/// A [`Search`]'s evolving state, for a checkpoint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum SearchState {
    /// C-REPS'.
    CReps(CRepsState),
    /// C-CMA-ES'.
    CCmaes(CCmaesState),
}

impl SearchState {
    /// The contexts of the rollouts a C-REPS state remembers (none for C-CMA-ES, whose
    /// generation is refit by regression alone).
    pub(crate) fn contexts(&self) -> Vec<&[f64]> {
        match self {
            Self::CReps(state) => state.contexts().collect(),
            Self::CCmaes(_) => Vec::new(),
        }
    }
}

/// What one update of either learner did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum SearchReport {
    /// A C-REPS update.
    CReps(UpdateReport),
    /// A C-CMA-ES generation.
    CCmaes(CCmaesReport),
}

impl SearchReport {
    /// Why the update was rejected; `None` when it was applied.
    pub fn rejected(&self) -> Option<Rejection> {
        match self {
            SearchReport::CReps(r) => r.rejected,
            SearchReport::CCmaes(r) => r.rejected,
        }
    }

    /// The effective sample size `1 / sum d_i^2` of the update's weights: C-REPS' from its
    /// dual, C-CMA-ES' (mu_eff) from its ranks.
    pub fn ess(&self) -> f64 {
        match self {
            SearchReport::CReps(r) => r.ess,
            SearchReport::CCmaes(r) => r.ess,
        }
    }

    /// `trace Sigma` of the policy in force after the update.
    pub fn trace_sigma(&self) -> f64 {
        match self {
            SearchReport::CReps(r) => r.trace_sigma,
            SearchReport::CCmaes(r) => r.trace_sigma,
        }
    }
}

impl Search {
    /// The search `config` describes for `context_dim`-dimensional contexts, initial mean
    /// `theta0` and `n_tasks` training contexts.
    pub fn new(
        config: &SearchConfig,
        context_dim: usize,
        theta0: &[f64],
        n_tasks: usize,
    ) -> Result<Self, SearchCreateError> {
        Ok(match config {
            SearchConfig::CReps(c) => Search::CReps(Box::new(CReps::new(c.clone(), context_dim, theta0, n_tasks)?)),
            SearchConfig::CCmaes(c) => Search::CCmaes(Box::new(CCmaes::new(c.clone(), context_dim, theta0)?)),
        })
    }

    /// The learner's name: `c-reps` or `c-cmaes`.
    pub fn name(&self) -> &'static str {
        match self {
            Search::CReps(_) => "c-reps",
            Search::CCmaes(_) => "c-cmaes",
        }
    }

    /// An explorative sample for `context`, drawn from `rng`.
    pub fn sample(&self, context: &[f64], rng: &mut dyn RngCore) -> Vec<f64> {
        match self {
            Search::CReps(s) => s.sample(context, rng),
            Search::CCmaes(s) => s.sample(context, rng),
        }
    }

    /// The policy's mean for `context`.
    pub fn greedy(&self, context: &[f64]) -> Vec<f64> {
        match self {
            Search::CReps(s) => s.greedy(context),
            Search::CCmaes(s) => s.greedy(context),
        }
    }

    /// Records a rollout of training context `task` and returns the report of the update it
    /// triggers. `paced` moves with a C-REPS update; a C-CMA-ES learner is never built with a
    /// paced selector. The update asks `stop` between its steps and, stopped, leaves everything
    /// as it was before this rollout.
    pub fn record(
        &mut self,
        task: usize,
        context: &[f64],
        theta: &[f64],
        reward: f64,
        paced: Option<&mut dyn PacedContexts>,
        stop: &dyn Fn() -> bool,
    ) -> Result<Option<SearchReport>, Interrupted> {
        Ok(match self {
            Search::CReps(s) => s
                .record_stopping(task, context, theta, reward, paced, stop)?
                .map(SearchReport::CReps),
            Search::CCmaes(s) => {
                debug_assert!(
                    paced.is_none(),
                    "the learner refuses self-paced selection with C-CMA-ES"
                );
                s.record_stopping(context, theta, reward, stop)?
                    .map(SearchReport::CCmaes)
            }
        })
    }

    /// The current policy.
    pub fn policy(&self) -> &LinearGaussianPolicy {
        match self {
            Search::CReps(s) => s.policy(),
            Search::CCmaes(s) => s.policy(),
        }
    }

    /// The policy as data; `None` for a user-supplied feature map.
    pub fn snapshot(&self) -> Option<PolicySnapshot> {
        match self {
            Search::CReps(s) => s.snapshot(),
            Search::CCmaes(s) => s.snapshot(),
        }
    }

    /// The evolving state, for a checkpoint.
    pub fn state(&self) -> SearchState {
        match self {
            Search::CReps(s) => SearchState::CReps(s.state()),
            Search::CCmaes(s) => SearchState::CCmaes(s.state()),
        }
    }

    /// Continue from `state` (see [`CReps::restore`] and [`CCmaes::restore`]).
    pub fn restore(&mut self, state: SearchState) -> Result<(), SearchRestoreError> {
        match (self, state) {
            (Search::CReps(s), SearchState::CReps(state)) => Ok(s.restore(state)?),
            (Search::CCmaes(s), SearchState::CCmaes(state)) => Ok(s.restore(state)?),
            (search, state) => Err(SearchRestoreError::Learner {
                checkpoint: match state {
                    SearchState::CReps(_) => "c-reps",
                    SearchState::CCmaes(_) => "c-cmaes",
                },
                learner: search.name(),
            }),
        }
    }
}
