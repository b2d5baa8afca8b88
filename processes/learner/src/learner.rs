//! The learner core: a deterministic ask/tell state machine (pycma style: the caller owns the
//! loop). In-process runs and the worker fleet drive this same type.
//!
//! # Determinism
//! Task ids form one sequence. Training task `t` is created from the learner state right after
//! training outcome `t - P` has been consumed (P = `in_flight`), and outcomes are consumed strictly
//! in id order through a reorder buffer. Tasks are created eagerly inside [`Learner::tell`], never
//! lazily in [`Learner::ask`], so the time at which a caller asks cannot change what is created:
//! the whole run depends on (config, seed, P) only. P = 1 is the paper's sequential algorithm.
//!
//! # Task kinds
//! - `Baseline`: before training, one greedy rollout of the initial policy per training context
//!   when the selector uses first-visit baselines (progress heuristics).
//! - `Train`: an explorative rollout in the context the selector chose.
//! - `Evaluate`: greedy rollouts on every test context after 0, `eval_every`, 2 `eval_every`, ...
//!   consumed training episodes and after the last one.
//!
//! # Failed rollouts
//! A failed outcome (simulation failure or a non-finite return) is retried once: the same task,
//! same seed, is handed out again, so a transient failure (a crashed simulator) gets a second
//! chance and a deterministic one fails again. A failed training rollout after its retry is
//! counted, kept out of the policy search's memory, and the selector observes the lowest return consumed
//! so far in the run (0 before any). A failed evaluation rollout is left out of that evaluation's aggregate and
//! counted in [`Evaluation::failed`].
//!
//! # Records
//! What a run produces (every consumed episode, every update of the policy search, every complete
//! evaluation) accumulates in the learner until [`Learner::take_records`] takes it. A short run
//! can leave it there and read it at the end; a long one takes it as it goes (the run
//! directory's record files), so that the learner's memory and its snapshots stay the size of
//! its state however long the run. Taking records changes nothing the learner does.
//!
//! # Checkpoints
//! [`Learner::snapshot`] captures everything that evolves (policy, memory, selector, random
//! streams, counters, records not yet taken, tasks not yet consumed); [`Learner::restore`]
//! applies it to a learner freshly built from the same configuration, problem and selector,
//! which then continues exactly as the original would have. Tasks that were handed out but whose
//! outcome had not arrived are handed out again (same task, same seed), before the tasks never
//! handed out.

use crate::creps::Rejection;
use crate::search::{Search, SearchConfig, SearchCreateError, SearchReport, SearchRestoreError, SearchState};
use crate::selection::{Choice, ContextSelector, SelectorCreateError, SelectorRestoreError, SelectorState};
use crate::{Interrupted, SelectorConfig};
use acps_shared::{
    EnvironmentMatchError, EnvironmentSpec, Outcome, Problem, Stream, Task, TaskKind, derive_seed, nearest,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// How the learner runs, independent of the selection method.
///
/// [`Default`] is a sequential run of 1000 episodes with C-REPS at
/// [`CRepsConfig::default`](crate::creps::CRepsConfig::default); set the
/// fields that matter for the problem:
///
/// ```
/// use acps_learner::LearnerConfig;
///
/// let config = LearnerConfig { episodes: 2000, ..Default::default() };
/// assert_eq!((config.in_flight, config.eval_every), (1, 50));
/// ```
#[derive(Debug, Clone)]
pub struct LearnerConfig {
    /// Seed of every random stream of the run (default 0).
    pub seed: u64,
    /// Number of training episodes (rollouts), >= 1 (default 1000, the length of the paper's
    /// shortest runs, Sec. 4; its others run 2500 to 50,000).
    pub episodes: u64,
    /// Training tasks in flight, P >= 1: task t is created after outcome t - P is consumed
    /// (default 1, the paper's sequential algorithm; raise it to keep parallel simulators busy).
    pub in_flight: usize,
    /// Evaluate the greedy policy on the problem's test contexts every this many consumed
    /// training episodes, >= 1 (default 50, as the paper's Sec. 5.1.2; each evaluation costs one
    /// rollout per test context).
    pub eval_every: u64,
    /// The upper-level policy search (default C-REPS at its defaults); `None` for problems
    /// without policy parameters (an empty theta0).
    pub search: Option<SearchConfig>,
}

impl Default for LearnerConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            episodes: 1000,
            in_flight: 1,
            eval_every: 50,
            search: Some(SearchConfig::default()),
        }
    }
}

/// Why [`Learner::new`] or [`Learner::with_selector`] refuses to create a learner.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LearnerCreateError {
    /// A count of the [`LearnerConfig`] that must be at least 1 is 0.
    #[error("learner config: {field} must be >= 1, got 0")]
    Zero {
        /// The field: `episodes`, `in_flight` or `eval_every`.
        field: &'static str,
    },
    /// The problem has no training contexts to choose from.
    #[error("problem '{problem}' has no training contexts")]
    NoTrainingContexts {
        /// The problem's name.
        problem: String,
    },
    /// A training or test context whose dimension is not the context space's.
    #[error("problem '{problem}': context {context:?} does not have the space's dimension {dim}")]
    ContextDim {
        /// The problem's name.
        problem: String,
        /// The offending context.
        context: Vec<f64>,
        /// The context space's dimension.
        dim: usize,
    },
    /// The problem has no policy parameters (`theta0` is empty), but the config has a policy
    /// search: set `search` to `None`.
    #[error(
        "problem '{problem}' has no policy parameters (theta0 is empty), so the learner config must have no policy search"
    )]
    UnusedSearch {
        /// The problem's name.
        problem: String,
    },
    /// The problem has policy parameters, but the config has no policy search.
    #[error("problem '{problem}' has {n_theta} policy parameters but the learner config has no policy search")]
    MissingSearch {
        /// The problem's name.
        problem: String,
        /// The number of policy parameters.
        n_theta: usize,
    },
    /// The selector's context distribution moves with the policy (self-paced), but the
    /// problem has no policy parameters.
    #[error(
        "problem '{problem}' has no policy parameters (theta0 is empty), so it cannot use a self-paced selector, which C-REPS moves with the policy"
    )]
    PacedWithoutPolicy {
        /// The problem's name.
        problem: String,
    },
    /// The selector's context distribution moves with a C-REPS update (self-paced's joint
    /// dual), but the learner is C-CMA-ES, which has no dual to share.
    #[error(
        "problem '{problem}': the self-paced selector moves its context distribution in C-REPS' joint dual, which C-CMA-ES does not have; use learner c-reps or another method"
    )]
    PacedWithoutCReps {
        /// The problem's name.
        problem: String,
    },
    /// The policy search refuses its configuration for this problem.
    #[error(transparent)]
    Search(#[from] SearchCreateError),
    /// The selector cannot be built for this problem ([`Learner::with_selector`] only).
    #[error(transparent)]
    Selector(#[from] SelectorCreateError),
}

/// Why [`Learner::tell`] refuses an outcome. The learner is left unchanged, but for
/// [`Interrupted`](Self::Interrupted).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LearnerTellError {
    /// [`Learner::tell_until`]'s `stop` stopped the policy update that consuming task
    /// `task_id`'s outcome started. That outcome is dropped and the task handed out again
    /// (first), as if it had never come back; what was consumed before it stays.
    #[error(
        "the policy update that the outcome of task {task_id} started was interrupted; the task is handed out again"
    )]
    Interrupted {
        /// The task whose outcome started the update.
        task_id: u64,
    },
    /// No task with this id is waiting for its outcome (never issued, or already consumed).
    #[error("outcome for task {task_id}, which is not waiting for an outcome")]
    UnknownTask {
        /// The outcome's task id.
        task_id: u64,
    },
    /// An outcome for this task is already buffered.
    #[error("second outcome for task {task_id}")]
    Duplicate {
        /// The outcome's task id.
        task_id: u64,
    },
}

/// One evaluation of the greedy policy on the test contexts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Evaluation {
    /// Training episodes consumed before the policy was evaluated.
    pub episode: u64,
    /// The aggregated score (problem-defined), `None` while incomplete or if every rollout failed.
    pub score: Option<f64>,
    /// Failed rollouts, left out of the score.
    pub failed: usize,
    /// One entry per test context, in the problem's order, once consumed.
    pub outcomes: Vec<Option<Outcome>>,
    remaining: usize,
}

/// How far one learner, or several together, are: what a progress display shows.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LearningProgress {
    /// Training episodes consumed.
    pub episodes: u64,
    /// Training episodes to run.
    pub total_episodes: u64,
    /// Mean over the learners that have one of their latest evaluation score.
    pub score: Option<f64>,
    /// How many learners the score averages.
    pub scored: usize,
}

impl LearningProgress {
    /// The progress of several learners together.
    pub fn combine(parts: impl IntoIterator<Item = LearningProgress>) -> Self {
        let mut total = Self::default();
        let mut score_sum = 0.0;
        for part in parts {
            total.episodes += part.episodes;
            total.total_episodes += part.total_episodes;
            if let Some(score) = part.score {
                score_sum += score * part.scored as f64;
                total.scored += part.scored;
            }
        }
        total.score = (total.scored > 0).then(|| score_sum / total.scored as f64);
        total
    }
}

/// A consumed training episode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Episode {
    /// The chosen training context, `None` for a context drawn from the continuous space.
    pub arm: Option<usize>,
    /// The context.
    pub context: Vec<f64>,
    /// The return (NaN when the rollout failed).
    pub reward: f64,
}

/// Counters of a run.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LearnerStats {
    /// Policy updates applied.
    pub updates: u64,
    /// Policy updates rejected (old policy kept).
    pub rejected_updates: u64,
    /// Failed training rollouts (after their retry).
    pub failed_episodes: u64,
    /// Failed outcomes whose task was handed out once more.
    pub retries: u64,
    /// Why the latest rejected update was rejected.
    pub last_rejection: Option<Rejection>,
}

/// What a learner recorded since its records were last taken ([`Learner::take_records`]), in
/// the order it recorded them.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Records {
    /// Consumed training episodes.
    pub episodes: Vec<Episode>,
    /// Policy updates, applied or rejected.
    pub updates: Vec<UpdateRecord>,
    /// Complete evaluations (an evaluation is taken once its last rollout is consumed).
    pub evaluations: Vec<Evaluation>,
}

impl Records {
    /// Append `later`, records taken after these.
    pub fn extend(&mut self, later: Records) {
        self.episodes.extend(later.episodes);
        self.updates.extend(later.updates);
        self.evaluations.extend(later.evaluations);
    }
}

/// How many records of each kind a learner has handed over with [`Learner::take_records`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RecordCounts {
    /// Training episodes.
    pub episodes: u64,
    /// Policy updates.
    pub updates: u64,
    /// Evaluations.
    pub evaluations: u64,
}

impl RecordCounts {
    /// The counts of `records`.
    pub fn of(records: &Records) -> Self {
        Self {
            episodes: records.episodes.len() as u64,
            updates: records.updates.len() as u64,
            evaluations: records.evaluations.len() as u64,
        }
    }

    pub(crate) fn add(&mut self, other: Self) {
        self.episodes += other.episodes;
        self.updates += other.updates;
        self.evaluations += other.evaluations;
    }
}

/// One update of the policy search of a run and what it did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UpdateRecord {
    /// Training episodes consumed when it ran: it used rollouts up to this one.
    pub episode: u64,
    /// What it did.
    pub report: SearchReport,
}

/// Why [`Learner::restore`] refuses a snapshot: it does not belong to this learner. The learner
/// is left unchanged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LearnerRestoreError {
    /// The snapshot was taken of a learner of another configuration or problem.
    #[error("the checkpoint is of a learner with {what} {checkpoint}, this one has {what} {learner}")]
    Mismatch {
        /// What differs.
        what: &'static str,
        /// The snapshot's value.
        checkpoint: String,
        /// This learner's value.
        learner: String,
    },
    /// The selector refused its saved state.
    #[error(transparent)]
    Selector(#[from] SelectorRestoreError),
    /// The policy search refused its saved state.
    #[error(transparent)]
    Policy(#[from] SearchRestoreError),
    /// The snapshot contradicts itself.
    #[error("the checkpoint's learner state is inconsistent: {0}")]
    Inconsistent(String),
}

#[derive(Debug, Clone, Serialize, Deserialize)]
enum Role {
    Train { choice: Choice, bucket: usize },
    Evaluate { evaluation: usize, index: usize },
    Baseline { arm: usize },
}

/// A task created and not yet consumed, with where it stands.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Pending {
    task: Task,
    role: Role,
    /// In the outbox (to be handed out, again after a retry or a reissue).
    queued: bool,
    /// Its outcome, once it arrived ahead of an earlier task's.
    arrived: Option<Outcome>,
    /// Whether its failed outcome was already given a second chance.
    retried: bool,
}

/// What a learner must be to take a snapshot: the configuration and problem dimensions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Fit {
    seed: u64,
    episodes: u64,
    in_flight: u64,
    eval_every: u64,
    problem: String,
    environment: EnvironmentSpec,
    training_contexts: u64,
    test_contexts: u64,
    context_dim: u64,
    n_theta: u64,
}

impl Fit {
    fn of(learner: &Learner) -> Self {
        Self {
            seed: learner.config.seed,
            episodes: learner.config.episodes,
            in_flight: learner.config.in_flight as u64,
            eval_every: learner.config.eval_every,
            problem: learner.problem.name.clone(),
            environment: learner.problem.environment,
            training_contexts: learner.problem.training_contexts.len() as u64,
            test_contexts: learner.problem.test_contexts.len() as u64,
            context_dim: learner.problem.context_dim() as u64,
            n_theta: learner.problem.theta0.len() as u64,
        }
    }

    /// The first field in which `self` (the snapshot's) differs from `learner` (this one's).
    fn check(&self, learner: &Fit) -> Result<(), LearnerRestoreError> {
        let mismatch = |what, checkpoint: &dyn ToString, learner: &dyn ToString| {
            Err(LearnerRestoreError::Mismatch {
                what,
                checkpoint: checkpoint.to_string(),
                learner: learner.to_string(),
            })
        };
        let numbers = [
            ("seed", self.seed, learner.seed),
            ("episodes", self.episodes, learner.episodes),
            ("in_flight", self.in_flight, learner.in_flight),
            ("eval_every", self.eval_every, learner.eval_every),
            ("training contexts", self.training_contexts, learner.training_contexts),
            ("test contexts", self.test_contexts, learner.test_contexts),
            ("context dimension", self.context_dim, learner.context_dim),
            ("policy parameters", self.n_theta, learner.n_theta),
        ];
        if self.problem != learner.problem {
            return mismatch("problem", &self.problem, &learner.problem);
        }
        if self.environment != learner.environment {
            return mismatch("environment", &self.environment, &learner.environment);
        }
        match numbers.into_iter().find(|(_, a, b)| a != b) {
            Some((what, checkpoint, here)) => mismatch(what, &checkpoint, &here),
            None => Ok(()),
        }
    }
}

/// A learner's whole evolving state, taken by [`Learner::snapshot`] and applied by
/// [`Learner::restore`]. Serialise it with a format that keeps every bit of a float (bincode
/// does; JSON does not keep NaN payloads).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LearnerSnapshot {
    fit: Fit,
    selector: SelectorState,
    policy: Option<SearchState>,
    run: RunState,
}

impl LearnerSnapshot {
    /// The first rollout a C-REPS state remembers: its context, to forge in tests.
    #[cfg(test)]
    pub(crate) fn first_context_mut(&mut self) -> Option<&mut Vec<f64>> {
        match &mut self.policy {
            Some(SearchState::CReps(state)) => state.first_context_mut(),
            _ => None,
        }
    }
}

/// What of a learner changes as it runs, apart from its selector and policy: the learner holds
/// it and a snapshot saves it as it is, so the two cannot drift apart. Bincode writes a nested
/// struct as its fields in order, so a snapshot's bytes are those of these fields written after
/// the policy's; `VecDeque` and `BTreeSet` encode as the sequences they iterate.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct RunState {
    selection_rng: ChaCha8Rng,
    exploration_rng: ChaCha8Rng,
    next_id: u64,
    train_issued: u64,
    train_consumed: u64,
    next_to_consume: u64,
    /// Tasks to hand out, in order. In a snapshot, those out without an outcome come first, so
    /// that a restored learner hands them out again before the queue.
    outbox: VecDeque<u64>,
    /// Every task created and not consumed: ids `next_to_consume..next_id`, in order (tasks are
    /// numbered as created and consumed in that order, so the window has no gaps).
    pending: VecDeque<Pending>,
    /// Evaluations not taken: `Role::Evaluate`'s index minus `taken.evaluations`.
    evaluations: Vec<Evaluation>,
    episodes: Vec<Episode>,
    updates: Vec<UpdateRecord>,
    /// Records handed over by `take_records`.
    taken: RecordCounts,
    /// The score of the latest complete evaluation that has one.
    latest_score: Option<f64>,
    lowest_reward: Option<f64>,
    stats: LearnerStats,
}

impl RunState {
    /// Task `id`, if it is pending.
    fn pending(&self, id: u64) -> Option<&Pending> {
        let index = usize::try_from(id.checked_sub(self.next_to_consume)?).ok()?;
        self.pending.get(index)
    }

    fn pending_mut(&mut self, id: u64) -> Option<&mut Pending> {
        let index = usize::try_from(id.checked_sub(self.next_to_consume)?).ok()?;
        self.pending.get_mut(index)
    }

    /// A run that has not started, its random streams seeded from `seed`.
    fn start(seed: u64) -> Self {
        Self {
            selection_rng: ChaCha8Rng::seed_from_u64(derive_seed(seed, Stream::Selection, 0)),
            exploration_rng: ChaCha8Rng::seed_from_u64(derive_seed(seed, Stream::Exploration, 0)),
            next_id: 0,
            train_issued: 0,
            train_consumed: 0,
            next_to_consume: 0,
            outbox: VecDeque::new(),
            pending: VecDeque::new(),
            evaluations: Vec::new(),
            episodes: Vec::new(),
            updates: Vec::new(),
            taken: RecordCounts::default(),
            latest_score: None,
            lowest_reward: None,
            stats: LearnerStats::default(),
        }
    }
}

impl LearnerSnapshot {
    /// True when the run was complete when the snapshot was taken.
    pub fn is_done(&self) -> bool {
        self.run.train_consumed == self.fit.episodes && self.run.pending.is_empty()
    }

    /// Why the snapshot cannot be a state of a learner, if it cannot (ids and roles that point
    /// nowhere, counters that contradict each other).
    fn check(&self) -> Result<(), String> {
        let run = &self.run;
        let arms = self.fit.training_contexts as usize;
        if run.train_consumed != run.taken.episodes + run.episodes.len() as u64
            || run.train_consumed > run.train_issued
            || run.train_issued > self.fit.episodes
            || run.next_to_consume > run.next_id
        {
            return Err(format!(
                "counters (issued {}, consumed {}, episodes {} + {} taken, next id {}, next to consume {}) contradict each other",
                run.train_issued,
                run.train_consumed,
                run.episodes.len(),
                run.taken.episodes,
                run.next_id,
                run.next_to_consume
            ));
        }
        if run.taken.updates + run.updates.len() as u64 != run.stats.updates + run.stats.rejected_updates {
            return Err(format!(
                "{} update reports ({} taken) for {} applied and {} rejected updates",
                run.taken.updates + run.updates.len() as u64,
                run.taken.updates,
                run.stats.updates,
                run.stats.rejected_updates
            ));
        }
        if run.next_to_consume + run.pending.len() as u64 != run.next_id {
            return Err(format!(
                "{} tasks pending between task {} and task {}",
                run.pending.len(),
                run.next_to_consume,
                run.next_id
            ));
        }
        for (id, pending) in (run.next_to_consume..).zip(&run.pending) {
            let role_ok = match &pending.role {
                Role::Train { bucket, choice } => *bucket < arms && choice.arm.is_none_or(|a| a < arms),
                Role::Evaluate { evaluation, index } => evaluation
                    .checked_sub(run.taken.evaluations as usize)
                    .and_then(|e| run.evaluations.get(e))
                    .is_some_and(|e| *index < e.outcomes.len()),
                Role::Baseline { arm } => *arm < arms,
            };
            let queued = run.outbox.iter().filter(|&&queued| queued == id).count();
            if pending.task.id != id || !role_ok || queued != usize::from(pending.queued) {
                return Err(format!("pending task {id} does not fit the run"));
            }
        }
        if run.outbox.len() != run.pending.iter().filter(|p| p.queued).count() {
            return Err("a queued task is not pending".into());
        }
        Ok(())
    }
}

/// The learner: context selection plus a policy search (C-REPS or C-CMA-ES) behind an ask/tell interface.
///
/// A problem of your own, the defaults, and a loop that performs each task the learner asks
/// for (here a closure stands in for the simulator):
///
/// ```
/// use acps_learner::{Learner, LearnerConfig, SelectorConfig};
/// use acps_shared::{ContextSpace, EnvironmentSpec, Outcome, Problem, ScoreAggregate, Task};
///
/// // Learn theta(s) = (s, -s) for contexts s in [0, 1]; the return is minus the squared error.
/// let problem = Problem {
///     name: "line".into(),
///     training_contexts: (0..5).map(|i| vec![i as f64 / 4.0]).collect(),
///     test_contexts: vec![vec![0.1], vec![0.6]],
///     space: ContextSpace::new_box(vec![0.0], vec![1.0])?,
///     theta0: vec![0.0, 0.0],
///     score: ScoreAggregate::Mean,
///     metric: "mean squared error".into(),
///     // What performs the rollouts: a name and a hash of its settings (none here).
///     environment: EnvironmentSpec::new("line", [0; 3], &())?,
/// };
/// let simulate = |task: &Task| {
///     let s = task.context[0];
///     let error = (task.theta[0] - s).powi(2) + (task.theta[1] + s).powi(2);
///     Outcome::new(task.id, -error, error)
/// };
///
/// let config = LearnerConfig { episodes: 500, ..Default::default() };
/// // D-UCB with monotonic progress: the paper's proposal.
/// let mut learner = Learner::with_selector(config, problem, &SelectorConfig::default())?;
/// while let Some(task) = learner.ask() {
///     learner.tell(simulate(&task))?;
/// }
/// assert!(learner.is_done());
/// let before = learner.evaluations()[0].score.unwrap();
/// let after = learner.latest_score().unwrap();
/// assert!(after < before / 100.0, "{before} -> {after}");
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct Learner {
    config: LearnerConfig,
    problem: Problem,
    selector: Box<dyn ContextSelector>,
    policy: Option<Search>,
    run: RunState,
}

impl Learner {
    /// A learner for `problem` choosing contexts with the selector `selector` builds for it.
    pub fn with_selector(
        config: LearnerConfig,
        problem: Problem,
        selector: &SelectorConfig,
    ) -> Result<Self, LearnerCreateError> {
        let selector = selector.build(&problem)?;
        Self::new(config, problem, selector)
    }

    /// A learner for `problem` choosing contexts with `selector` (any [`ContextSelector`], a
    /// custom one included).
    pub fn new(
        config: LearnerConfig,
        problem: Problem,
        mut selector: Box<dyn ContextSelector>,
    ) -> Result<Self, LearnerCreateError> {
        let counts = [
            ("episodes", config.episodes),
            ("in_flight", config.in_flight as u64),
            ("eval_every", config.eval_every),
        ];
        if let Some((field, _)) = counts.into_iter().find(|&(_, count)| count == 0) {
            return Err(LearnerCreateError::Zero { field });
        }
        let name = || problem.name.clone();
        if problem.training_contexts.is_empty() {
            return Err(LearnerCreateError::NoTrainingContexts { problem: name() });
        }
        if let Some(bad) = problem
            .training_contexts
            .iter()
            .chain(&problem.test_contexts)
            .find(|s| s.len() != problem.context_dim())
        {
            return Err(LearnerCreateError::ContextDim {
                problem: name(),
                context: bad.clone(),
                dim: problem.context_dim(),
            });
        }
        let policy = match (&config.search, problem.theta0.is_empty()) {
            (Some(search), false) => Some(Search::new(
                search,
                problem.context_dim(),
                &problem.theta0,
                problem.training_contexts.len(),
            )?),
            (None, true) => None,
            (Some(_), true) => return Err(LearnerCreateError::UnusedSearch { problem: name() }),
            (None, false) => {
                return Err(LearnerCreateError::MissingSearch {
                    problem: name(),
                    n_theta: problem.theta0.len(),
                });
            }
        };
        if selector.paced().is_some() {
            match policy {
                None => return Err(LearnerCreateError::PacedWithoutPolicy { problem: name() }),
                Some(Search::CCmaes(_)) => return Err(LearnerCreateError::PacedWithoutCReps { problem: name() }),
                Some(Search::CReps(_)) => {}
            }
        }
        let mut learner = Self {
            run: RunState::start(config.seed),
            config,
            problem,
            selector,
            policy,
        };
        if learner.selector.wants_initial_returns() {
            for arm in 0..learner.problem.training_contexts.len() {
                let context = learner.problem.training_contexts[arm].clone();
                learner.create(TaskKind::Baseline, context, Role::Baseline { arm });
            }
        }
        learner.create_evaluation();
        while learner.run.train_issued < learner.config.episodes.min(learner.config.in_flight as u64) {
            learner.create_training_task();
        }
        Ok(learner)
    }

    /// The next task to perform, or `None` when every created task has been handed out (wait for
    /// outcomes, or the run is done).
    pub fn ask(&mut self) -> Option<Task> {
        let id = self.run.outbox.pop_front()?;
        let pending = self.run.pending_mut(id).expect("queued tasks are pending");
        pending.queued = false;
        Some(pending.task.clone())
    }

    /// Hand a task out again (for example after the worker that had it died). Returns false when
    /// the task is not waiting for an outcome.
    pub fn reissue(&mut self, task_id: u64) -> bool {
        let Some(pending) = self.run.pending_mut(task_id) else {
            return false;
        };
        let waiting = pending.arrived.is_none() && !pending.queued;
        if waiting {
            pending.queued = true;
            self.run.outbox.push_back(task_id);
        }
        waiting
    }

    /// Report the outcome of a task. Outcomes may arrive in any order; they are consumed in task
    /// order, and consuming them may create new tasks.
    pub fn tell(&mut self, outcome: Outcome) -> Result<(), LearnerTellError> {
        self.tell_until(outcome, &|| false)
    }

    /// [`tell`](Self::tell), asking `stop` between the steps of a policy update that consuming
    /// outcomes starts, so that Ctrl-C ends even the largest C-REPS update (seconds) within a
    /// fraction of a second. A stopped update leaves the learner as if the outcome of the task
    /// that started it had not come back ([`LearnerTellError::Interrupted`]): a snapshot then
    /// continues the run bit for bit.
    pub fn tell_until(&mut self, outcome: Outcome, stop: &dyn Fn() -> bool) -> Result<(), LearnerTellError> {
        let task_id = outcome.task_id;
        let run = &mut self.run;
        let Some(pending) = run.pending_mut(task_id) else {
            return Err(LearnerTellError::UnknownTask { task_id });
        };
        if pending.arrived.is_some() {
            return Err(LearnerTellError::Duplicate { task_id });
        }
        // Still queued only when it was handed out again (reissued, or restored) and an earlier
        // copy answered: it need not go out once more.
        let was_queued = std::mem::take(&mut pending.queued);
        if !outcome.is_ok() && !pending.retried {
            pending.retried = true;
            pending.queued = true;
            run.stats.retries += 1;
            if !was_queued {
                run.outbox.push_back(task_id);
            }
            return Ok(());
        }
        pending.arrived = Some(outcome);
        if was_queued {
            run.outbox.retain(|id| *id != task_id);
        }
        while self.run.pending.front().is_some_and(|p| p.arrived.is_some()) {
            let mut pending = self.run.pending.pop_front().expect("a front task");
            let outcome = pending.arrived.take().expect("its outcome arrived");
            // The update first: the one step that can be stopped, so a stop leaves no trace.
            let report = match self.record(&pending, &outcome, stop) {
                Ok(report) => report,
                Err(Interrupted) => {
                    let task_id = pending.task.id;
                    pending.queued = true;
                    self.run.pending.push_front(pending);
                    self.run.outbox.push_front(task_id);
                    return Err(LearnerTellError::Interrupted { task_id });
                }
            };
            self.run.next_to_consume += 1;
            self.consume(pending, outcome, report);
        }
        Ok(())
    }

    /// Hand a successful training outcome to the policy search; the report of the update it
    /// started, if any.
    fn record(
        &mut self,
        pending: &Pending,
        outcome: &Outcome,
        stop: &dyn Fn() -> bool,
    ) -> Result<Option<SearchReport>, Interrupted> {
        let (Role::Train { bucket, .. }, Some(policy), true) = (&pending.role, self.policy.as_mut(), outcome.is_ok())
        else {
            return Ok(None);
        };
        let task = &pending.task;
        policy.record(
            *bucket,
            &task.context,
            &task.theta,
            outcome.reward,
            self.selector.paced(),
            stop,
        )
    }

    /// Whether [`tell`](Self::tell) takes an outcome of `task_id` now: the task exists and no
    /// outcome of it has arrived. Lets a caller check a batch of outcomes before telling any.
    pub fn awaits(&self, task_id: u64) -> bool {
        self.run.pending(task_id).is_some_and(|p| p.arrived.is_none())
    }

    /// True when every training episode and every evaluation has been consumed.
    pub fn is_done(&self) -> bool {
        self.run.train_consumed == self.config.episodes && self.run.pending.is_empty()
    }

    /// Evaluations not yet taken with [`take_records`](Self::take_records), in episode order
    /// (all of them, if records are never taken); the last may be incomplete.
    pub fn evaluations(&self) -> &[Evaluation] {
        &self.run.evaluations
    }

    /// The score of the most recent complete evaluation that has one.
    pub fn latest_score(&self) -> Option<f64> {
        self.run.latest_score
    }

    /// How far this learner is, for progress displays.
    pub fn progress(&self) -> LearningProgress {
        LearningProgress {
            episodes: self.run.train_consumed,
            total_episodes: self.config.episodes,
            score: self.latest_score(),
            scored: usize::from(self.latest_score().is_some()),
        }
    }

    /// The consumed training episodes not yet taken with [`take_records`](Self::take_records),
    /// in order (all of them, if records are never taken).
    pub fn episodes(&self) -> &[Episode] {
        &self.run.episodes
    }

    /// The policy updates not yet taken with [`take_records`](Self::take_records), in order,
    /// with their reports (all of them, if records are never taken).
    pub fn updates(&self) -> &[UpdateRecord] {
        &self.run.updates
    }

    /// Hand over what was recorded since the last call: episodes, updates and complete
    /// evaluations. The learner keeps only its state and what it still needs (an evaluation
    /// with rollouts to come), so a run that takes its records as it goes has memory and
    /// snapshots of constant size. What the learner does next is the same either way.
    ///
    /// ```
    /// # use acps_learner::{Learner, LearnerConfig, SelectorConfig, Records};
    /// # use acps_shared::{ContextSpace, EnvironmentSpec, Outcome, Problem, ScoreAggregate};
    /// # let problem = Problem {
    /// #     name: "line".into(),
    /// #     training_contexts: vec![vec![0.0], vec![1.0]],
    /// #     test_contexts: vec![vec![0.5]],
    /// #     space: ContextSpace::new_box(vec![0.0], vec![1.0])?,
    /// #     theta0: vec![0.0],
    /// #     score: ScoreAggregate::Mean,
    /// #     metric: "squared error".into(),
    /// #     environment: EnvironmentSpec::new("line", [0; 3], &())?,
    /// # };
    /// let config = LearnerConfig { episodes: 300, ..Default::default() };
    /// let mut learner = Learner::with_selector(config, problem, &SelectorConfig::default())?;
    /// let mut all = Records::default();
    /// while let Some(task) = learner.ask() {
    ///     let error = (task.theta[0] - task.context[0]).powi(2);
    ///     learner.tell(Outcome::new(task.id, -error, error))?;
    ///     all.extend(learner.take_records()); // a long run would write these to a file
    /// }
    /// assert_eq!(all.episodes.len(), 300);
    /// assert_eq!(all.evaluations.len(), 7); // before training and every 50 episodes
    /// assert!(learner.episodes().is_empty() && learner.evaluations().is_empty());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn take_records(&mut self) -> Records {
        let run = &mut self.run;
        let complete = run.evaluations.iter().take_while(|e| e.remaining == 0).count();
        let records = Records {
            episodes: std::mem::take(&mut run.episodes),
            updates: std::mem::take(&mut run.updates),
            evaluations: run.evaluations.drain(..complete).collect(),
        };
        run.taken.add(RecordCounts::of(&records));
        records
    }

    /// How many records of each kind [`take_records`](Self::take_records) has handed over.
    pub fn records_taken(&self) -> RecordCounts {
        self.run.taken
    }

    /// Counters of the run.
    pub fn stats(&self) -> &LearnerStats {
        &self.run.stats
    }

    /// The seed of every random stream of the run.
    pub fn seed(&self) -> u64 {
        self.config.seed
    }

    /// The problem being learned.
    pub fn problem(&self) -> &Problem {
        &self.problem
    }

    /// The upper-level policy search, if the problem has parameters.
    pub fn policy(&self) -> Option<&Search> {
        self.policy.as_ref()
    }

    /// Tasks created but not yet consumed.
    pub fn tasks_in_flight(&self) -> usize {
        self.run.pending.len()
    }

    /// Learning rounds so far, the clock checkpoints are counted in: policy updates run
    /// (applied or rejected), or, for a problem without policy parameters, evaluations started
    /// (the first one, before training, included).
    pub fn rounds(&self) -> u64 {
        if self.policy.is_some() {
            self.run.stats.updates + self.run.stats.rejected_updates
        } else {
            self.run.taken.evaluations + self.run.evaluations.len() as u64
        }
    }

    /// The whole evolving state, for a checkpoint. Tasks handed out whose outcome has not
    /// arrived are recorded as to be handed out again, ahead of the queue.
    pub fn snapshot(&self) -> LearnerSnapshot {
        let mut run = self.run.clone();
        let out: Vec<u64> = run
            .pending
            .iter_mut()
            .filter(|p| p.arrived.is_none() && !p.queued)
            .map(|p| {
                p.queued = true;
                p.task.id
            })
            .collect();
        run.outbox = out.into_iter().chain(self.run.outbox.iter().copied()).collect();
        LearnerSnapshot {
            fit: Fit::of(self),
            selector: self.selector.save_state(),
            policy: self.policy.as_ref().map(Search::state),
            run,
        }
    }

    /// Continue from `snapshot`. The learner must have been built like the one the snapshot was
    /// taken of (configuration, problem, selector); nothing is kept of its own progress. A
    /// snapshot of another seed, length, P, problem or selector kind is refused and leaves the
    /// learner unchanged.
    pub fn restore(&mut self, snapshot: LearnerSnapshot) -> Result<(), LearnerRestoreError> {
        snapshot.fit.check(&Fit::of(self))?;
        snapshot.check().map_err(LearnerRestoreError::Inconsistent)?;
        if let Some(state) = &snapshot.policy {
            self.check_contexts(state)?;
        }
        let policy = match (&self.policy, snapshot.policy) {
            (Some(policy), Some(state)) => {
                let mut policy = policy.clone();
                policy.restore(state)?;
                Some(policy)
            }
            (None, None) => None,
            (_, saved) => {
                return Err(LearnerRestoreError::Inconsistent(format!(
                    "it {} a policy search state, this learner {} a policy",
                    if saved.is_some() { "has" } else { "lacks" },
                    if saved.is_some() { "has no" } else { "has" }
                )));
            }
        };
        self.selector.restore_state(snapshot.selector)?;
        self.policy = policy;
        self.run = snapshot.run;
        Ok(())
    }

    /// Refuse remembered rollouts whose contexts no run of this problem could have trained on:
    /// outside the box that holds its space and its training contexts (by more than rounding).
    /// A forged 1e300 there reached a self-paced update as an infinite log-density ratio.
    fn check_contexts(&self, state: &SearchState) -> Result<(), LearnerRestoreError> {
        let (mut low, mut high) = self.problem.space.bounding_box();
        for context in &self.problem.training_contexts {
            for ((l, h), x) in low.iter_mut().zip(high.iter_mut()).zip(context) {
                *l = l.min(*x);
                *h = h.max(*x);
            }
        }
        let inside = |context: &[f64]| {
            context.len() == low.len()
                && context.iter().zip(low.iter().zip(&high)).all(|(x, (l, h))| {
                    let slack = 1e-9 * (h - l).abs().max(1.0);
                    (l - slack..=h + slack).contains(x)
                })
        };
        match state.contexts().into_iter().find(|context| !inside(context)) {
            Some(context) => Err(LearnerRestoreError::Inconsistent(format!(
                "a remembered rollout's context {context:?} lies outside the problem's contexts ({low:?}..={high:?})"
            ))),
            None => Ok(()),
        }
    }

    fn create(&mut self, kind: TaskKind, context: Vec<f64>, role: Role) {
        let theta = match (&self.policy, kind) {
            (None, _) => Vec::new(),
            (Some(policy), TaskKind::Train) => policy.sample(&context, &mut self.run.exploration_rng),
            (Some(policy), _) => policy.greedy(&context),
        };
        let id = self.run.next_id;
        self.run.next_id += 1;
        let task = Task {
            id,
            kind,
            seed: derive_seed(self.config.seed, Stream::Environment, id),
            context,
            theta,
        };
        self.run.pending.push_back(Pending {
            task,
            role,
            queued: true,
            arrived: None,
            retried: false,
        });
        self.run.outbox.push_back(id);
    }

    fn create_training_task(&mut self) {
        let choice = self.selector.choose(&mut self.run.selection_rng);
        let bucket = choice
            .arm
            .unwrap_or_else(|| nearest(&self.problem.training_contexts, &choice.context));
        self.run.train_issued += 1;
        self.create(TaskKind::Train, choice.context.clone(), Role::Train { choice, bucket });
    }

    fn create_evaluation(&mut self) {
        let contexts = self.problem.test_contexts.clone();
        if contexts.is_empty() {
            return;
        }
        let evaluation = self.run.taken.evaluations as usize + self.run.evaluations.len();
        self.run.evaluations.push(Evaluation {
            episode: self.run.train_consumed,
            score: None,
            failed: 0,
            outcomes: vec![None; contexts.len()],
            remaining: contexts.len(),
        });
        for (index, context) in contexts.into_iter().enumerate() {
            self.create(TaskKind::Evaluate, context, Role::Evaluate { evaluation, index });
        }
    }

    fn consume(&mut self, pending: Pending, outcome: Outcome, report: Option<SearchReport>) {
        match pending.role {
            Role::Baseline { arm } => {
                if outcome.is_ok() {
                    self.selector.prime(arm, outcome.reward);
                }
            }
            Role::Evaluate { evaluation, index } => {
                let aggregate = self.problem.score;
                let evaluation = &mut self.run.evaluations[evaluation - self.run.taken.evaluations as usize];
                if !outcome.is_ok() {
                    evaluation.failed += 1;
                }
                evaluation.outcomes[index] = Some(outcome);
                evaluation.remaining -= 1;
                if evaluation.remaining == 0 {
                    let scores: Vec<f64> = evaluation
                        .outcomes
                        .iter()
                        .flatten()
                        .filter(|o| o.is_ok())
                        .map(|o| o.score)
                        .collect();
                    evaluation.score = aggregate.apply(&scores);
                    if evaluation.score.is_some() {
                        self.run.latest_score = evaluation.score;
                    }
                }
            }
            Role::Train { choice, .. } => self.consume_training(choice, &outcome, report),
        }
    }

    /// A training outcome, whose update (`report`) [`record`](Self::record) has run.
    fn consume_training(&mut self, choice: Choice, outcome: &Outcome, report: Option<SearchReport>) {
        self.run.train_consumed += 1;
        let reward = if outcome.is_ok() {
            self.run.lowest_reward = Some(
                self.run
                    .lowest_reward
                    .map_or(outcome.reward, |low| low.min(outcome.reward)),
            );
            if let Some(report) = report {
                match report.rejected() {
                    None => self.run.stats.updates += 1,
                    Some(reason) => {
                        tracing::debug!(seed = self.config.seed, episode = self.run.train_consumed, %reason, "policy update rejected; the old policy stays");
                        self.run.stats.rejected_updates += 1;
                        self.run.stats.last_rejection = Some(reason);
                    }
                }
                self.run.updates.push(UpdateRecord {
                    episode: self.run.train_consumed,
                    report,
                });
            }
            outcome.reward
        } else {
            self.run.stats.failed_episodes += 1;
            self.run.lowest_reward.unwrap_or(0.0)
        };
        self.selector.observe(&choice, reward);
        self.run.episodes.push(Episode {
            arm: choice.arm,
            context: choice.context,
            reward: if outcome.is_ok() { reward } else { f64::NAN },
        });
        if self.run.train_consumed.is_multiple_of(self.config.eval_every)
            || self.run.train_consumed == self.config.episodes
        {
            self.create_evaluation();
        }
        if self.run.train_issued < self.config.episodes {
            self.create_training_task();
        }
    }
}

/// Drive `learner` to the end with `environment` in this thread; an environment other than the
/// one the learner's problem is defined for is refused before any rollout.
pub fn run_in_process(
    learner: &mut Learner,
    environment: &mut dyn acps_shared::Environment,
) -> Result<(), EnvironmentMatchError> {
    learner.problem.check_environment(environment)?;
    while let Some(task) = learner.ask() {
        let outcome = environment.rollout(&task);
        learner
            .tell(outcome)
            .expect("the outcome answers a task just handed out");
    }
    debug_assert!(learner.is_done());
    Ok(())
}
