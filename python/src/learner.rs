//! One learner of an experiment, driven from Python: the tasks of `ask` and the outcomes of
//! `tell` cross as numpy arrays, one call per batch.

use crate::{AcpsError, CheckpointError, SettingsError, TellError};
use acps_experiments::experiment::Job;
use acps_experiments::file::LoadedFile;
use acps_experiments::plan::Plan;
use acps_experiments::settings::ExperimentFile;
use acps_learner::checkpoint::{self, Checkpoint, Stamp};
use acps_learner::{Learner, LearnerTellError, Search};
use acps_shared::{Outcome, OutcomeStatus, Task};
use acps_wire::wire::kind_code;
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::cell::Cell;
use std::collections::HashSet;
use std::path::Path;
use std::sync::{Mutex, MutexGuard, PoisonError};

/// The arrays of a batch of tasks: ids, kinds (0 train, 1 evaluate, 2 baseline), seeds,
/// contexts `(n, n_s)` and parameters `(n, n_theta)`.
pub(crate) type Batch<'py> = (
    Bound<'py, PyArray1<u64>>,
    Bound<'py, PyArray1<u32>>,
    Bound<'py, PyArray1<u64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
);

/// A learner of one (method, run) of an experiment, as `acps run` runs it.
#[pyclass(module = "acps._native")]
pub struct NativeLearner {
    inner: Mutex<Inner>,
}

struct Inner {
    job: Job,
    stamp: Stamp,
    experiment: String,
    method: String,
    run: usize,
    runs: usize,
}

/// The learner of `method` (the only one when `None`) and `run` of the experiment in `file`.
fn build(file: &LoadedFile, method: Option<&str>, run: usize) -> PyResult<Inner> {
    let settings = |e: &dyn std::fmt::Display| SettingsError::new_err(e.to_string());
    let plan = Plan::new(Some(file), &ExperimentFile::default()).map_err(|e| settings(&e))?;
    let mut jobs = plan.jobs(Path::new(""));
    if jobs.len() != 1 {
        return Err(SettingsError::new_err(format!(
            "{}: experiment '{}' runs {} experiments (its panels or context dimensions); a learner is one of them: set `panel` (toy) or `n_s` (dims)",
            file.path().display(),
            plan.name(),
            jobs.len()
        )));
    }
    let experiment = jobs.pop().expect("one job").experiment;
    experiment.check_methods().map_err(|e| settings(&e))?;
    let names: Vec<&str> = experiment.methods.iter().map(|m| m.method().name()).collect();
    let index = match method {
        Some(wanted) => names.iter().position(|name| *name == wanted).ok_or_else(|| {
            SettingsError::new_err(format!(
                "{}: method {wanted} is not one of the experiment's methods ({})",
                file.path().display(),
                names.join(", ")
            ))
        })?,
        None if names.len() == 1 => 0,
        None => {
            return Err(SettingsError::new_err(format!(
                "{}: the experiment has {} methods ({}); choose one with method=",
                file.path().display(),
                names.len(),
                names.join(", ")
            )));
        }
    };
    if run >= experiment.runs {
        return Err(SettingsError::new_err(format!(
            "{}: run must be in 0..{} (the experiment's runs = {}), got {run}",
            file.path().display(),
            experiment.runs,
            experiment.runs
        )));
    }
    let seed = experiment.base_seed + run as u64;
    let job = experiment
        .job(&experiment.methods[index], seed)
        .map_err(|e| settings(&e))?;
    Ok(Inner {
        job,
        // The job's index as `acps run` numbers them: method-major.
        stamp: Stamp {
            identity: experiment.identity(),
            job: (index * experiment.runs + run) as u64,
        },
        experiment: experiment.name.clone(),
        method: names[index].to_string(),
        run,
        runs: experiment.runs,
    })
}

impl NativeLearner {
    fn lock(&self) -> MutexGuard<'_, Inner> {
        // A panic inside a call (a bug) is raised in Python; the learner stays usable as it
        // was left, rather than every later call failing on the poisoned lock.
        self.inner.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn of(inner: Inner) -> Self {
        Self {
            inner: Mutex::new(inner),
        }
    }
}

/// The arrays of `tasks`, whose contexts have `n_s` values and parameters `n_theta`.
pub(crate) fn batch<'py>(py: Python<'py>, tasks: &[&Task], n_s: usize, n_theta: usize) -> PyResult<Batch<'py>> {
    let count = tasks.len();
    let ids = PyArray1::from_vec(py, tasks.iter().map(|t| t.id).collect());
    let kinds = PyArray1::from_vec(py, tasks.iter().map(|t| kind_code(t.kind)).collect());
    let seeds = PyArray1::from_vec(py, tasks.iter().map(|t| t.seed).collect());
    let contexts: Vec<f64> = tasks.iter().flat_map(|t| t.context.iter().copied()).collect();
    let thetas: Vec<f64> = tasks.iter().flat_map(|t| t.theta.iter().copied()).collect();
    let contexts = PyArray1::from_vec(py, contexts).reshape([count, n_s])?;
    let thetas = PyArray1::from_vec(py, thetas).reshape([count, n_theta])?;
    Ok((ids, kinds, seeds, contexts, thetas))
}

/// The learner's policy, or the error of a problem without one (the Section 4 model's).
fn policy(learner: &Learner) -> PyResult<&Search> {
    learner
        .policy()
        .ok_or_else(|| AcpsError::new_err(format!("problem '{}' has no policy", learner.problem().name)))
}

/// The outcome of task `id`: a failed one when `ok` is false (a non-finite reward or score
/// fails it too, in `Outcome::new`).
pub(crate) fn outcome(id: u64, reward: f64, score: f64, ok: bool) -> Outcome {
    let mut outcome = Outcome::new(id, reward, score);
    if !ok {
        outcome.status = OutcomeStatus::Failed;
    }
    outcome
}

/// A 1-D array's values, contiguous or not.
fn values<T: numpy::Element + Copy>(array: &PyReadonlyArray1<'_, T>) -> Vec<T> {
    match array.as_slice() {
        Ok(slice) => slice.to_vec(),
        Err(_) => array.as_array().iter().copied().collect(),
    }
}

#[pymethods]
impl NativeLearner {
    /// The learner of `method` and `run` of the experiment or problem file at `path`.
    #[staticmethod]
    #[pyo3(signature = (path, method, run))]
    fn from_path(path: &str, method: Option<&str>, run: usize) -> PyResult<Self> {
        Ok(Self::of(build(&crate::read_file(path)?, method, run)?))
    }

    /// The learner of `method` and `run` of the settings `json` (an experiment file's keys as
    /// a JSON object); `origin` names them in errors.
    #[staticmethod]
    #[pyo3(signature = (json, origin, method, run))]
    fn from_json(json: &str, origin: &str, method: Option<&str>, run: usize) -> PyResult<Self> {
        Ok(Self::of(build(&crate::parse_json(json, origin)?, method, run)?))
    }

    /// Up to `n` tasks: every task the learner has ready, at most `n`. Fewer (even none) when
    /// the rest wait for outcomes of tasks out.
    fn ask<'py>(&self, py: Python<'py>, n: usize) -> PyResult<Batch<'py>> {
        let mut inner = self.lock();
        let learner = &mut inner.job.learner;
        let (n_s, n_theta) = (learner.problem().context_dim(), learner.problem().theta0.len());
        let mut tasks = Vec::new();
        while tasks.len() < n {
            match learner.ask() {
                Some(task) => tasks.push(task),
                None => break,
            }
        }
        batch(py, &tasks.iter().collect::<Vec<_>>(), n_s, n_theta)
    }

    /// Take the outcomes of tasks `ids`: their `rewards` (what the learner maximises) and
    /// `scores` (the problem's measure), and whether each rollout succeeded (`ok`; a non-finite
    /// reward or score fails it too). The whole batch is checked before any of it is taken.
    ///
    /// Ctrl-C during the policy update an outcome starts (seconds at the largest sizes) raises
    /// `KeyboardInterrupt` at once: the outcomes before that one are taken, that one and the
    /// rest are not, and `save` continues the run bit for bit.
    #[pyo3(signature = (ids, rewards, scores, ok=None))]
    fn tell(
        &self,
        py: Python<'_>,
        ids: PyReadonlyArray1<'_, u64>,
        rewards: PyReadonlyArray1<'_, f64>,
        scores: PyReadonlyArray1<'_, f64>,
        ok: Option<PyReadonlyArray1<'_, bool>>,
    ) -> PyResult<()> {
        let (ids, rewards, scores) = (values(&ids), values(&rewards), values(&scores));
        let ok = ok.as_ref().map(values);
        let lengths = [Some(rewards.len()), Some(scores.len()), ok.as_ref().map(Vec::len)];
        if lengths.into_iter().flatten().any(|len| len != ids.len()) {
            return Err(TellError::new_err(format!(
                "tell: {} ids but {} rewards, {} scores{}; every array has one entry per task",
                ids.len(),
                rewards.len(),
                scores.len(),
                ok.as_ref()
                    .map_or(String::new(), |ok| format!(", {} ok flags", ok.len()))
            )));
        }
        let mut inner = self.lock();
        let learner = &mut inner.job.learner;
        let mut seen = HashSet::with_capacity(ids.len());
        for &id in &ids {
            if !seen.insert(id) {
                return Err(TellError::new_err(format!(
                    "tell: task {id} appears twice in the batch"
                )));
            }
            if !learner.awaits(id) {
                return Err(TellError::new_err(format!(
                    "tell: the learner waits for no outcome of task {id} (unknown, or told already)"
                )));
            }
        }
        // Python's signal handlers run here, between the steps of an update: what they raise
        // (KeyboardInterrupt) stops it and is raised in its place.
        let raised = Cell::new(None);
        let stop = || match py.check_signals() {
            Ok(()) => false,
            Err(error) => {
                raised.set(Some(error));
                true
            }
        };
        for (i, &id) in ids.iter().enumerate() {
            let ok = ok.as_ref().is_none_or(|ok| ok[i]);
            match learner.tell_until(outcome(id, rewards[i], scores[i], ok), &stop) {
                Ok(()) => {}
                Err(LearnerTellError::Interrupted { .. }) => {
                    return Err(raised.take().expect("stopped by a raised signal handler"));
                }
                Err(error) => {
                    return Err(AcpsError::new_err(format!(
                        "tell: {error} (after the batch was checked: a bug)"
                    )));
                }
            }
        }
        Ok(())
    }

    /// Whether every training episode and evaluation has been consumed.
    #[getter]
    fn done(&self) -> bool {
        self.lock().job.learner.is_done()
    }

    /// Training episodes consumed, and the run's total.
    #[getter]
    fn episodes(&self) -> (u64, u64) {
        let progress = self.lock().job.learner.progress();
        (progress.episodes, progress.total_episodes)
    }

    /// Tasks handed out or ready whose outcomes have not been consumed.
    #[getter]
    fn tasks_in_flight(&self) -> usize {
        self.lock().job.learner.tasks_in_flight()
    }

    /// Every evaluation so far: (training episodes before it, its score or `None` while
    /// incomplete or when every rollout failed, its failed rollouts).
    #[getter]
    fn evaluations(&self) -> Vec<(u64, Option<f64>, usize)> {
        let inner = self.lock();
        let evaluations = inner.job.learner.evaluations();
        evaluations.iter().map(|e| (e.episode, e.score, e.failed)).collect()
    }

    /// The experiment's name, the method's, the run's index and the experiment's runs.
    #[getter]
    fn identity(&self) -> (String, String, usize, usize) {
        let inner = self.lock();
        (inner.experiment.clone(), inner.method.clone(), inner.run, inner.runs)
    }

    /// The run's seed, and the sizes of a context and of the parameters.
    #[getter]
    fn sizes(&self) -> (u64, usize, usize) {
        let inner = self.lock();
        let learner = &inner.job.learner;
        (
            learner.seed(),
            learner.problem().context_dim(),
            learner.problem().theta0.len(),
        )
    }

    /// The problem's training contexts (`test` false) or test contexts (`test` true), one row
    /// each.
    fn contexts<'py>(&self, py: Python<'py>, test: bool) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let inner = self.lock();
        let problem = inner.job.learner.problem();
        let set = if test {
            &problem.test_contexts
        } else {
            &problem.training_contexts
        };
        PyArray1::from_vec(py, set.iter().flatten().copied().collect()).reshape([set.len(), problem.context_dim()])
    }

    /// The greedy policy's parameters at each row of `contexts` `(m, n_s)`: `(m, n_theta)`.
    fn mean<'py>(&self, py: Python<'py>, contexts: PyReadonlyArray2<'_, f64>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let inner = self.lock();
        let learner = &inner.job.learner;
        let policy = policy(learner)?;
        let n_s = learner.problem().context_dim();
        let contexts = contexts.as_array();
        if contexts.ncols() != n_s {
            return Err(PyValueError::new_err(format!(
                "mean: contexts of {} values, the problem's have {n_s}",
                contexts.ncols()
            )));
        }
        let rows = contexts.nrows();
        let means: Vec<f64> = contexts
            .rows()
            .into_iter()
            .flat_map(|row| policy.greedy(&row.to_vec()))
            .collect();
        PyArray1::from_vec(py, means).reshape([rows, learner.problem().theta0.len()])
    }

    /// The policy's covariance of the parameters, `(n_theta, n_theta)`.
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let inner = self.lock();
        let covariance = policy(&inner.job.learner)?.policy().covariance();
        let n = covariance.nrows();
        // nalgebra is column-major; the matrix is symmetric, so the order of its entries is moot.
        PyArray1::from_vec(py, covariance.as_slice().to_vec()).reshape([n, n])
    }

    /// Write the learner's whole state to `path` (a checkpoint `restore` continues from).
    fn save(&self, path: &str) -> PyResult<()> {
        let inner = self.lock();
        let environment = inner
            .job
            .environment
            .as_deref()
            .map(|e| e.save_state())
            .unwrap_or_default();
        let checkpoint = Checkpoint {
            learner: inner.job.learner.snapshot(),
            environment,
            records: None,
        };
        checkpoint::write(Path::new(path), inner.stamp, &checkpoint)
            .map_err(|e| CheckpointError::new_err(e.to_string()))
    }

    /// Continue from the checkpoint at `path`, written by `save` of a learner of the same
    /// experiment, method and run.
    fn restore(&self, path: &str) -> PyResult<()> {
        let mut inner = self.lock();
        let refused = |e: &dyn std::fmt::Display| CheckpointError::new_err(e.to_string());
        let checkpoint = checkpoint::read(Path::new(path), inner.stamp)
            .map_err(|e| refused(&e))?
            .ok_or_else(|| CheckpointError::new_err(format!("checkpoint {path}: no such file")))?;
        // A run's checkpoint keeps its learner's records in a record file beside it: restored
        // here, the evaluations before it would be missing without a word.
        if checkpoint.records.is_some() {
            return Err(CheckpointError::new_err(format!(
                "checkpoint {path} belongs to a run directory (its records are in {}); continue that run with `acps run --resume` or acps.run(..., resume=True)",
                acps_experiments::checkpoints::Checkpoints::records_file(Path::new(path)).display()
            )));
        }
        let Inner { job, .. } = &mut *inner;
        job.learner.restore(checkpoint.learner).map_err(|e| refused(&e))?;
        if let Some(environment) = job.environment.as_deref_mut() {
            environment
                .restore_state(&checkpoint.environment)
                .map_err(|e| refused(&e))?;
        }
        Ok(())
    }
}
