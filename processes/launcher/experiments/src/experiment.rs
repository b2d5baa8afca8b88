//! Running an experiment: every (method, run) pair is an independent learner run, executed in
//! parallel with rayon and summarised into `summary.json`.
//!
//! Run `r` of every method uses the seed `base_seed + r` for both the problem instance and the
//! learner, so methods are compared on the same problem instances (paired runs).

use crate::checkpoints::{Checkpoints, CheckpointsError, Writer, restore};
use crate::progress::{Progress, ScoreFormat};
use crate::summary::{BestPolicy, MethodSummary, RunResult, Summary, UserProblem, mean, standard_error};
use acps_fleet::{
    Fleet, FleetError, FleetJob, FleetJobBuildError, FleetProgress, Learners, ObserveError, Observer, Remote,
};
use acps_learner::checkpoint::Stamp;
use acps_learner::{
    Episode, Interrupted, Learner, LearnerConfig, LearnerCreateError, LearnerTellError, LearningProgress, Records,
    SelectorConfig, run_in_process,
};
use acps_shared::{Environment, EnvironmentMatchError, Outcome, Problem, Task};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, PoisonError};
use std::time::Duration;

/// One problem instance: what the learner sees, the environment, and a known optimal score.
pub struct Instance {
    /// The problem description.
    pub problem: Problem,
    /// The environment that performs rollouts; `None` for a problem only the user's workers
    /// simulate (a problem file's), which runs on a fleet only.
    pub environment: Option<Box<dyn Environment>>,
    /// The best achievable score, when the problem knows it (the Section 4 model's J_opt).
    pub optimal_score: Option<f64>,
    /// Whether the environment keeps state between rollouts (the Section 4 model): a fleet cannot
    /// serve it, since a rollout would depend on which worker performed the ones before.
    pub keeps_state: bool,
}

/// What performs a batched run's rollouts ([`Experiment::run_batched`]): every ready task,
/// with its job's index, in one call; one outcome per task in their order, or `None` to stop.
pub type Perform<'a> = dyn FnMut(&[(usize, Task)]) -> Option<Vec<Outcome>> + 'a;

/// Builds the problem instance of a run from the run's seed.
pub type InstanceFactory = Box<dyn Fn(u64) -> Instance + Send + Sync>;

/// Problem-specific results of one method, computed from its runs and merged into its summary
/// (for example the dartboard's hits per ring).
pub type MethodDetail = Box<dyn Fn(&[RunResult]) -> serde_json::Map<String, serde_json::Value> + Send + Sync>;

/// A complete experiment definition.
pub struct Experiment {
    /// Name, as on the command line.
    pub name: String,
    /// The methods to compare.
    pub methods: Vec<SelectorConfig>,
    /// Runs per method.
    pub runs: usize,
    /// Run `r` uses seed `base_seed + r`.
    pub base_seed: u64,
    /// Learner settings (the seed is set per run).
    pub learner: LearnerConfig,
    /// The problem instance of a run.
    pub instance: InstanceFactory,
    /// Training episodes counted in the selection ratios (paper Fig. 5 uses 250).
    pub selection_window: usize,
    /// Settings to record in the summary, for readers and for re-running.
    pub settings: serde_json::Value,
    /// Problem-specific results per method, if any.
    pub detail: Option<MethodDetail>,
    /// Whether the summary names the best policy of all runs (Fig. 8's "Best Policy" line); only
    /// for scores where lower is better.
    pub best_policy: bool,
    /// For a problem file's problem: how its scores read. Such a problem has no environment in
    /// this process; only a fleet of the user's workers runs it.
    pub user_problem: Option<UserProblem>,
    /// Whether the environment takes contexts other than the training contexts. The Section 4
    /// model does not (its ten contexts are indices), nor does the dartboard (a throw counts only
    /// at a field): a method that draws contexts from the continuous space is refused before the
    /// run instead of failing every rollout.
    pub continuous_contexts: bool,
}

/// A fleet run's observer: shows the progress and writes every job's checkpoints.
struct Checkpointing<F> {
    writers: Vec<Option<Writer>>,
    environments: Vec<Option<Box<dyn Environment>>>,
    observe: F,
}

impl<F: FnMut(&FleetProgress)> Observer for Checkpointing<F> {
    fn progress(&mut self, progress: &FleetProgress) {
        (self.observe)(progress)
    }

    fn told(&mut self, job: usize, learner: &mut Learner) -> Result<(), ObserveError> {
        match &mut self.writers[job] {
            Some(writer) => writer
                .after_tell(learner, self.environments[job].as_deref())
                .map_err(ObserveError::new),
            None => Ok(()),
        }
    }
}

/// What the progress line of an in-process run last showed: each job's progress and the
/// rollouts of all.
struct Shown {
    jobs: Vec<LearningProgress>,
    rollouts: u64,
}

/// One learner of an experiment with its environment.
pub struct Job {
    /// The learner core.
    pub learner: Learner,
    /// Its environment, for in-process runs (`None`: the user's workers simulate it).
    pub environment: Option<Box<dyn Environment>>,
    /// Whether the environment keeps state between rollouts.
    pub keeps_state: bool,
    /// The instance's optimal score, if known.
    pub optimal_score: Option<f64>,
}

impl Job {
    /// The result of the finished job, whose learner recorded `records`.
    fn result(&self, records: Records) -> RunResult {
        let learner = &self.learner;
        let evaluations = &records.evaluations;
        RunResult {
            seed: learner.seed(),
            problem: learner.problem().clone(),
            policy: learner.policy().and_then(|p| p.snapshot()),
            eval_episodes: evaluations.iter().map(|e| e.episode).collect(),
            scores: evaluations.iter().map(|e| e.score).collect(),
            stats: learner.stats().clone(),
            optimal_score: self.optimal_score,
            // Every evaluation rolls out every test context once (a record file's keeps the
            // outcomes of its first and last evaluations only).
            evaluation_rollouts: (
                (evaluations.len() * learner.problem().test_contexts.len()) as u64,
                evaluations.iter().map(|e| e.failed as u64).sum(),
            ),
            final_outcomes: evaluations.last().map(|e| e.outcomes.clone()).unwrap_or_default(),
            episodes: records.episodes,
            updates: records.updates,
        }
    }
}

/// A run that could not start or complete.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// A learner refused its configuration.
    #[error(transparent)]
    Learner(#[from] LearnerCreateError),
    /// An instance's environment is not the one its problem is defined for.
    #[error(transparent)]
    Environment(#[from] EnvironmentMatchError),
    /// Checkpoints could not be written or resumed from.
    #[error(transparent)]
    Checkpoints(#[from] CheckpointsError),
    /// A learner's tasks do not fit the fleet's wire.
    #[error(transparent)]
    FleetJob(#[from] FleetJobBuildError),
    /// The fleet failed.
    #[error(transparent)]
    Fleet(#[from] FleetError),
    /// An in-process run was stopped (Ctrl-C); with checkpoints on, every unfinished job wrote one.
    #[error("interrupted")]
    Interrupted,
    /// The experiment cannot run on a fleet.
    #[error(
        "experiment '{0}' cannot run on a worker fleet: its environment keeps state between rollouts (use `acps experiment`)"
    )]
    Stateful(String),
    /// The experiment cannot run in this process: its problem is the user's.
    #[error(
        "problem '{0}' is a problem of your own, simulated by your workers: use `acps run --config FILE --worker-command CMD` (or --workers 0 and start them yourself)"
    )]
    NeedsWorkers(String),
    /// A method that cannot work on the experiment's environment.
    #[error(
        "method {method} draws contexts from the continuous space, but experiment '{experiment}' takes only its training contexts; choose a method that selects among them (round-robin, random, corners, best-reward, diversity, one-step-progress, monotonic-progress, sagg-riac, absolute-progress, or alp-gmm with snap = true)"
    )]
    Method {
        /// The method's name.
        method: &'static str,
        /// The experiment's name.
        experiment: String,
    },
    /// The outcomes of [`Experiment::run_batched`]'s `perform` were not one per task in the
    /// tasks' order.
    #[error("the batch's outcomes do not answer its tasks: {what}")]
    Performed {
        /// What does not match.
        what: String,
    },
    /// A run whose every training rollout, or every rollout of every evaluation, failed: it
    /// learnt or measured nothing.
    #[error("experiment '{experiment}', method {method}, run {run} (seed {seed}): {what}")]
    AllFailed {
        /// The experiment's name.
        experiment: String,
        /// The method's name.
        method: &'static str,
        /// The run's index.
        run: usize,
        /// The run's seed.
        seed: u64,
        /// Which rollouts failed, and where the first did.
        what: String,
    },
}

/// Why `outcomes` do not answer `tasks` one by one, if they do not.
fn mismatched(tasks: &[(usize, Task)], outcomes: &[Outcome]) -> Option<String> {
    if tasks.len() != outcomes.len() {
        return Some(format!("{} outcomes for {} tasks", outcomes.len(), tasks.len()));
    }
    tasks
        .iter()
        .zip(outcomes)
        .find(|((_, task), outcome)| task.id != outcome.task_id)
        .map(|((job, task), outcome)| {
            format!(
                "the outcome of task {} where task {} of job {job} belongs",
                outcome.task_id, task.id
            )
        })
}

/// Tell `learner` the outcome of a task it just handed out, its update stopped once `stop` is
/// set: `Err` then, with the learner as if the outcome had not come back.
fn told(learner: &mut Learner, outcome: Outcome, stop: &AtomicBool) -> Result<(), Interrupted> {
    match learner.tell_until(outcome, &|| stop.load(Ordering::Relaxed)) {
        Err(LearnerTellError::Interrupted { .. }) => Err(Interrupted),
        told => {
            told.expect("the outcome answers a task just handed out");
            Ok(())
        }
    }
}

impl Experiment {
    /// Training episodes over all its (method, run) jobs.
    pub fn total_episodes(&self) -> u64 {
        self.learner.episodes * (self.methods.len() * self.runs) as u64
    }

    /// Its progress line (hidden when `quiet`; when stderr is not a terminal, a plain line
    /// every `every`), in its scores' unit.
    pub fn progress(&self, quiet: bool, every: Duration) -> Progress {
        Progress::of(
            &self.name,
            self.total_episodes(),
            self.user_problem.as_ref(),
            quiet,
            every,
        )
    }

    /// How its scores read.
    pub fn score_format(&self) -> ScoreFormat {
        ScoreFormat::of(&self.name, self.user_problem.as_ref())
    }

    /// Every (method, run) learner of the experiment, method-major, after refusing a method
    /// that cannot work on its environment.
    pub fn jobs(&self) -> Result<Vec<Job>, RunError> {
        self.check_methods()?;
        (0..self.methods.len())
            .flat_map(|m| (0..self.runs).map(move |r| (m, r)))
            .map(|(method, run)| self.job(&self.methods[method], self.base_seed + run as u64))
            .collect()
    }

    /// The learner of `selector` with `seed` (run `seed - base_seed` of the experiment) and its
    /// environment: what [`run`](Self::run) runs as that job, for a caller that drives the
    /// learner itself.
    pub fn job(&self, selector: &SelectorConfig, seed: u64) -> Result<Job, RunError> {
        let Instance {
            problem,
            environment,
            optimal_score,
            keeps_state,
        } = (self.instance)(seed);
        if let Some(environment) = &environment {
            problem.check_environment(environment.as_ref())?;
        }
        let learner = Learner::with_selector(
            LearnerConfig {
                seed,
                ..self.learner.clone()
            },
            problem,
            selector,
        )?;
        Ok(Job {
            learner,
            environment,
            keeps_state,
            optimal_score,
        })
    }

    /// Refuse a method that cannot work on this experiment (random-continuous, or alp-gmm
    /// without snapping, where contexts are not points of a continuous space).
    pub fn check_methods(&self) -> Result<(), RunError> {
        match self
            .methods
            .iter()
            .find(|s| !self.continuous_contexts && s.draws_from_space())
        {
            Some(selector) => Err(RunError::Method {
                method: selector.method().name(),
                experiment: self.name.clone(),
            }),
            None => Ok(()),
        }
    }

    /// Refuse to run in this process a problem only the user's workers simulate.
    pub fn check_in_process(&self) -> Result<(), RunError> {
        match self.user_problem {
            Some(_) => Err(RunError::NeedsWorkers(self.name.clone())),
            None => Ok(()),
        }
    }

    /// Run every (method, run) pair in parallel in this process and summarise.
    pub fn run(&self, progress: &Progress) -> Result<Summary, RunError> {
        self.run_until(progress, None, &AtomicBool::new(false))
    }

    /// [`run`](Self::run), stopping with [`RunError::Interrupted`] once `stop` is set (by
    /// Ctrl-C). With `checkpoints`, every job continues from its checkpoint when resuming and
    /// writes checkpoints as it goes, and an unfinished job writes one when stopped; the summary
    /// is the same bit for bit.
    pub fn run_until(
        &self,
        progress: &Progress,
        checkpoints: Option<&Checkpoints>,
        stop: &AtomicBool,
    ) -> Result<Summary, RunError> {
        self.run_jobs(self.jobs_writing(checkpoints)?, progress, stop)
    }

    /// Run every (method, run) job in this thread, handing `perform` every task all jobs have
    /// ready at once, tagged with its job's index (method-major): one call per round, for a
    /// vectorised simulator of the caller's (the jobs need no environment of their own).
    /// `perform` returns one outcome per task in their order, or `None` to stop: every
    /// unfinished job then writes its checkpoint, as when `stop` is set, and the run ends with
    /// [`RunError::Interrupted`]. The summary is the same bit for bit as that of any other way
    /// of running the jobs.
    pub fn run_batched(
        &self,
        progress: &Progress,
        checkpoints: Option<&Checkpoints>,
        stop: &AtomicBool,
        perform: &mut Perform<'_>,
    ) -> Result<Summary, RunError> {
        let mut jobs = self.jobs_writing(checkpoints)?;
        let mut rollouts = 0;
        loop {
            let mut tasks = Vec::new();
            for (index, (job, _)) in jobs.iter_mut().enumerate() {
                tasks.extend(std::iter::from_fn(|| job.learner.ask()).map(|task| (index, task)));
            }
            if tasks.is_empty() {
                break;
            }
            // Tasks handed out when the run stops are asked again after a restore.
            let outcomes = match stop.load(Ordering::Relaxed) {
                true => None,
                false => perform(&tasks),
            };
            let Some(outcomes) = outcomes else {
                for (job, writer) in &mut jobs {
                    if let Some(writer) = writer.as_mut().filter(|w| w.enabled()) {
                        writer.write(&mut job.learner, job.environment.as_deref())?;
                    }
                }
                return Err(RunError::Interrupted);
            };
            if let Some(what) = mismatched(&tasks, &outcomes) {
                return Err(RunError::Performed { what });
            }
            for ((index, _), outcome) in tasks.iter().zip(outcomes) {
                let (job, writer) = &mut jobs[*index];
                if told(&mut job.learner, outcome, stop).is_err() {
                    // Stopped half-way through an update: the loop's next pass writes the
                    // checkpoints, and the tasks whose outcomes are left are asked again.
                    break;
                }
                if let Some(writer) = writer {
                    writer.after_tell(&mut job.learner, job.environment.as_deref())?;
                }
            }
            rollouts += tasks.len() as u64;
            let learning = LearningProgress::combine(jobs.iter().map(|(job, _)| job.learner.progress()));
            progress.show(&learning, rollouts, None);
        }
        self.finished(jobs)
    }

    fn run_jobs(
        &self,
        mut jobs: Vec<(Job, Option<Writer>)>,
        progress: &Progress,
        stop: &AtomicBool,
    ) -> Result<Summary, RunError> {
        // Rollouts between two updates of the progress line by one job.
        const REPORT_EVERY: u64 = 256;
        let shown = Mutex::new(Shown {
            jobs: jobs.iter().map(|(job, _)| job.learner.progress()).collect(),
            rollouts: 0,
        });
        let report = |index: usize, learner: &Learner, rollouts: u64| {
            let mut shown = shown.lock().unwrap_or_else(PoisonError::into_inner);
            shown.jobs[index] = learner.progress();
            shown.rollouts += rollouts;
            progress.show(
                &LearningProgress::combine(shown.jobs.iter().copied()),
                shown.rollouts,
                None,
            );
        };
        jobs.par_iter_mut()
            .enumerate()
            .map(|(index, (job, writer))| {
                let environment = job
                    .environment
                    .as_mut()
                    .ok_or_else(|| RunError::NeedsWorkers(self.name.clone()))?;
                let mut unreported = 0;
                loop {
                    if stop.load(Ordering::Relaxed) {
                        if let Some(writer) = writer.as_mut().filter(|w| w.enabled()) {
                            writer.write(&mut job.learner, Some(environment.as_ref()))?;
                        }
                        return Err(RunError::Interrupted);
                    }
                    let Some(task) = job.learner.ask() else { break };
                    let outcome = environment.rollout(&task);
                    if told(&mut job.learner, outcome, stop).is_err() {
                        // Stopped half-way through an update: the check above writes the
                        // checkpoint.
                        continue;
                    }
                    if let Some(writer) = writer {
                        writer.after_tell(&mut job.learner, Some(environment.as_ref()))?;
                    }
                    unreported += 1;
                    if unreported == REPORT_EVERY {
                        report(index, &job.learner, unreported);
                        unreported = 0;
                    }
                }
                report(index, &job.learner, unreported);
                Ok(())
            })
            .collect::<Result<Vec<()>, RunError>>()?;
        self.finished(jobs)
    }

    /// The summary of the finished `jobs` (method-major, as [`jobs`](Self::jobs) made them),
    /// their records read back from their writers' record files or taken from their learners,
    /// refused when one of them learnt or measured nothing.
    fn finished(&self, jobs: Vec<(Job, Option<Writer>)>) -> Result<Summary, RunError> {
        let mut results = Vec::with_capacity(jobs.len());
        for (index, (mut job, writer)) in jobs.into_iter().enumerate() {
            let records = match writer {
                Some(writer) => writer.finish(&mut job.learner)?,
                None => job.learner.take_records(),
            };
            let method = self.methods[index / self.runs].method().name();
            self.check_rollouts(method, index % self.runs, &job.learner, &records)?;
            results.push(job.result(records));
        }
        Ok(self.summary(results))
    }

    /// Refuse a finished run whose every training rollout failed, or whose every evaluation had
    /// no successful rollout. Outcomes carry no reason for a failure, so the error says where
    /// the first one happened.
    fn check_rollouts(
        &self,
        method: &'static str,
        run: usize,
        learner: &Learner,
        records: &Records,
    ) -> Result<(), RunError> {
        let problem = learner.problem();
        let episodes = &records.episodes;
        let evaluations = &records.evaluations;
        let what = if !episodes.is_empty() && episodes.iter().all(|e| !e.reward.is_finite()) {
            let off = if problem.training_contexts.contains(&episodes[0].context) {
                ""
            } else {
                ", not one of the problem's training contexts"
            };
            format!(
                "every one of its {} training rollouts failed, so it learnt nothing; the first at episode 0, context ({}){off} (the environment gives no reason for a failed rollout)",
                episodes.len(),
                coordinates(&episodes[0].context)
            )
        } else if !evaluations.is_empty() && evaluations.iter().all(|e| e.score.is_none()) {
            let first = evaluations[0]
                .outcomes
                .iter()
                .position(|o| !o.as_ref().is_some_and(|o| o.is_ok()));
            let context = first
                .and_then(|i| problem.test_contexts.get(i))
                .map_or(String::new(), |s| {
                    format!("; the first at test context ({})", coordinates(s))
                });
            format!(
                "every rollout of its {} evaluations failed, so no score was measured{context} (the environment gives no reason for a failed rollout)",
                evaluations.len()
            )
        } else {
            return Ok(());
        };
        Err(RunError::AllFailed {
            experiment: self.name.clone(),
            method,
            run,
            seed: learner.seed(),
            what,
        })
    }

    /// Every job, each with its checkpoint writer and continued from its checkpoint when
    /// `checkpoints` resume; without checkpoints, fresh jobs without writers.
    fn jobs_writing(&self, checkpoints: Option<&Checkpoints>) -> Result<Vec<(Job, Option<Writer>)>, RunError> {
        Ok(match checkpoints {
            Some(checkpoints) => self
                .resumed_jobs(checkpoints)?
                .into_iter()
                .map(|(job, writer)| (job, Some(writer)))
                .collect(),
            None => self.jobs()?.into_iter().map(|job| (job, None)).collect(),
        })
    }

    /// The checkpoint stamp of job `index`.
    fn stamp(&self, index: usize) -> Stamp {
        Stamp {
            identity: self.identity(),
            job: index as u64,
        }
    }

    /// Every job with its checkpoint writer, each continued from its checkpoint (and its record
    /// file from the checkpoint's mark) when resuming.
    fn resumed_jobs(&self, checkpoints: &Checkpoints) -> Result<Vec<(Job, Writer)>, RunError> {
        let files: Vec<_> = self
            .methods
            .iter()
            .flat_map(|m| (0..self.runs).map(move |r| checkpoints.file(m.method().name(), r)))
            .collect();
        let jobs = self.jobs()?;
        checkpoints.prepare(&files)?;
        jobs.into_par_iter()
            .zip(files)
            .enumerate()
            .map(|(index, (mut job, file))| {
                let resumed = match checkpoints.resume {
                    true => restore(&file, self.stamp(index), &mut job.learner, job.environment.as_mut())?,
                    false => None,
                };
                let writer = Writer::open(file, self.stamp(index), checkpoints.every, &job.learner, resumed)?;
                Ok((job, writer))
            })
            .collect()
    }

    /// One learner run of `selector` with `seed`, in this thread.
    pub fn run_one(&self, selector: &SelectorConfig, seed: u64) -> Result<RunResult, RunError> {
        let mut job = self.job(selector, seed)?;
        let environment = job
            .environment
            .as_mut()
            .ok_or_else(|| RunError::NeedsWorkers(self.name.clone()))?;
        run_in_process(&mut job.learner, environment.as_mut())?;
        let run = seed.wrapping_sub(self.base_seed) as usize;
        let records = job.learner.take_records();
        self.check_rollouts(selector.method().name(), run, &job.learner, &records)?;
        Ok(job.result(records))
    }

    /// Serve every (method, run) learner through `fleet` and summarise; `observe` sees the
    /// fleet's progress every tick. With `checkpoints`, jobs continue from their checkpoints
    /// when resuming and write checkpoints between outcomes, and every unfinished job writes one
    /// when the run is interrupted.
    pub fn run_fleet(
        &self,
        fleet: &mut Fleet,
        checkpoints: Option<&Checkpoints>,
        remote: Option<&mut dyn Remote>,
        observe: impl FnMut(&FleetProgress),
    ) -> Result<(Summary, FleetProgress), RunError> {
        let (jobs, writers): (Vec<Job>, Vec<Option<Writer>>) = self.jobs_writing(checkpoints)?.into_iter().unzip();
        let mut fleet_jobs = Vec::with_capacity(jobs.len());
        let mut optimal = Vec::with_capacity(jobs.len());
        for job in jobs {
            if job.keeps_state {
                return Err(RunError::Stateful(self.name.clone()));
            }
            optimal.push(job.optimal_score);
            fleet_jobs.push((FleetJob::new(job.learner)?, job.environment));
        }
        let (mut learners, environments): (Vec<FleetJob>, Vec<_>) = fleet_jobs.into_iter().unzip();
        let mut observer = Checkpointing {
            writers,
            environments,
            observe,
        };
        let served = fleet.serve_with(&mut Learners(&mut learners), &mut observer, remote);
        let Checkpointing {
            writers, environments, ..
        } = observer;
        let mut jobs: Vec<(Job, Option<Writer>)> = learners
            .into_iter()
            .zip(environments)
            .zip(optimal)
            .zip(writers)
            .map(|(((fleet_job, environment), optimal_score), writer)| {
                let job = Job {
                    learner: fleet_job.into_learner(),
                    environment,
                    keeps_state: false,
                    optimal_score,
                };
                (job, writer)
            })
            .collect();
        if let Err(FleetError::Interrupted) = served {
            // Tasks out with workers are handed out again after a restore, so nothing is lost.
            for (job, writer) in &mut jobs {
                if let Some(writer) = writer.as_mut().filter(|w| w.enabled() && !job.learner.is_done()) {
                    writer.write(&mut job.learner, job.environment.as_deref())?;
                }
            }
        }
        let progress = served?;
        Ok((self.finished(jobs)?, progress))
    }

    /// A hash of everything that determines the run's results: workers of another run are
    /// refused instead of mixed in.
    pub fn identity(&self) -> u64 {
        let description = serde_json::json!({
            "name": self.name,
            "methods": self.methods,
            "runs": self.runs,
            "base_seed": self.base_seed,
            "episodes": self.learner.episodes,
            "in_flight": self.learner.in_flight,
            "eval_every": self.learner.eval_every,
            "settings": self.settings,
        })
        .to_string();
        acps_shared::fnv1a(acps_shared::FNV_OFFSET, description.as_bytes())
    }

    fn summary(&self, mut results: Vec<RunResult>) -> Summary {
        let problem = results[0].problem.clone();
        let optimal: Vec<f64> = results[..self.runs].iter().filter_map(|r| r.optimal_score).collect();
        let mut methods = BTreeMap::new();
        let mut run_results = BTreeMap::new();
        for selector in &self.methods {
            let runs: Vec<RunResult> = results.drain(..self.runs).collect();
            let name = selector.method().name().to_string();
            methods.insert(name.clone(), self.summarise(&runs, problem.training_contexts.len()));
            run_results.insert(name, runs);
        }
        let best_policy = if self.best_policy {
            // In the methods' order, so ties do not depend on the map's.
            BestPolicy::find(self.methods.iter().map(|selector| {
                let name = selector.method().name();
                (name, run_results[name].as_slice())
            }))
        } else {
            None
        };
        Summary {
            experiment: self.name.clone(),
            metric: problem.metric.clone(),
            user_problem: self.user_problem.clone(),
            runs: self.runs,
            base_seed: self.base_seed,
            training_episodes: self.learner.episodes,
            in_flight: self.learner.in_flight,
            selection_window: self.selection_window,
            training_contexts: problem.training_contexts.clone(),
            j_opt_mean: (!optimal.is_empty()).then(|| mean(&optimal)),
            settings: self.settings.clone(),
            best_policy,
            methods,
            run_results,
        }
    }

    fn summarise(&self, runs: &[RunResult], contexts: usize) -> MethodSummary {
        let points = runs[0].eval_episodes.len();
        let (mean, sem): (Vec<_>, Vec<_>) = (0..points)
            .map(|i| {
                let values: Vec<f64> = runs.iter().filter_map(|r| r.scores[i]).collect();
                if values.is_empty() {
                    (None, None)
                } else {
                    (Some(self::mean(&values)), Some(standard_error(&values)))
                }
            })
            .unzip();
        let mut counts = vec![0.0; contexts];
        for run in runs {
            for arm in run.episodes.iter().take(self.selection_window).filter_map(|e| e.arm) {
                counts[arm] += 1.0;
            }
        }
        let window = (self.selection_window.min(runs[0].episodes.len()) * runs.len()) as f64;
        MethodSummary {
            episodes: runs[0].eval_episodes.clone(),
            final_mean: mean.last().copied().flatten(),
            final_sem: sem.last().copied().flatten(),
            final_scores: runs.iter().map(|r| r.scores.last().copied().flatten()).collect(),
            longest_stay: runs.iter().map(|r| longest_stay(&r.episodes)).collect(),
            mean,
            sem,
            selections_run0: runs[0].episodes.iter().map(|e| e.arm).collect(),
            selection_ratio: counts.into_iter().map(|c| c / window).collect(),
            updates: runs.iter().map(|r| r.stats.updates).sum(),
            rejected_updates: runs.iter().map(|r| r.stats.rejected_updates).sum(),
            failed_episodes: runs.iter().map(|r| r.stats.failed_episodes).sum(),
            evaluation_rollouts: runs.iter().map(|r| r.evaluation_rollouts.0).sum(),
            failed_evaluation_rollouts: runs.iter().map(|r| r.evaluation_rollouts.1).sum(),
            detail: self.detail.as_ref().map(|detail| detail(runs)).unwrap_or_default(),
        }
    }
}

/// The most consecutive episodes with the same training context (episodes without one end a
/// stay).
fn longest_stay(episodes: &[Episode]) -> usize {
    let (mut longest, mut current, mut previous) = (0, 0, None);
    for arm in episodes.iter().map(|e| e.arm) {
        current = if arm.is_some() && arm == previous {
            current + 1
        } else {
            usize::from(arm.is_some())
        };
        longest = longest.max(current);
        previous = arm;
    }
    longest
}

/// A context as `x, y, ...` for messages.
fn coordinates(s: &[f64]) -> String {
    s.iter().map(|x| format!("{x:.4}")).collect::<Vec<_>>().join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_longest_stay_counts_consecutive_episodes_on_one_context() {
        let episodes = |arms: &[Option<usize>]| -> Vec<Episode> {
            arms.iter()
                .map(|&arm| Episode {
                    arm,
                    context: vec![],
                    reward: 0.0,
                })
                .collect()
        };
        assert_eq!(longest_stay(&episodes(&[])), 0);
        assert_eq!(longest_stay(&episodes(&[None, None, None])), 0);
        assert_eq!(longest_stay(&episodes(&[Some(0), Some(1), Some(0)])), 1);
        let arms = [Some(2), Some(2), Some(1), Some(1), Some(1), None, Some(1), Some(1)];
        assert_eq!(longest_stay(&episodes(&arms)), 3);
    }
}
