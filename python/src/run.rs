//! A whole experiment from Python: every (method, run) job in this process through the library
//! runner, writing the run directory `acps run` writes, with its pictures.

use crate::learner::{batch, outcome};
use crate::{AcpsError, SettingsError};
use acps_experiments::file::LoadedFile;
use acps_experiments::plan::Plan;
use acps_experiments::progress::{Observer, ProgressReport};
use acps_experiments::run_dir::{RunDir, RunDirError};
use acps_experiments::settings::ExperimentFile;
use acps_experiments::summary::Summary;
use acps_shared::{Outcome, Task};
use numpy::PyReadonlyArray1;
use pyo3::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

/// The pictures of a run directory, as `acps run` draws them.
fn pictures(summary: &Summary, dir: &Path) -> Result<(), Box<dyn std::error::Error>> {
    acps_reports::plot::write_all(summary, dir)
}

/// Run the experiment of the file at `path` or of the settings `json` (`origin` names them)
/// into `out` (default `runs/NAME`), and return its directory. With `perform`, a Python
/// callable `perform(ids, kinds, seeds, contexts, thetas) -> (rewards, scores, ok)`, every
/// ready task of every job goes to one call of it; without, the experiment's own environments
/// run in parallel in this process. `progress`, a Python callable, is called with
/// `(experiment, episodes, total, message, done)` at most every 100 ms and once when an
/// experiment is done (instead of the progress line when `line` is false). Ctrl-C
/// (KeyboardInterrupt), or an exception of `perform` or `progress`, stops the run after every
/// unfinished job wrote its checkpoint, and is raised here.
#[pyfunction]
#[pyo3(signature = (path, json, origin, out, perform, quiet, checkpoint_every, resume, force, progress, line))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn run(
    py: Python<'_>,
    path: Option<&str>,
    json: Option<&str>,
    origin: &str,
    out: Option<String>,
    perform: Option<Py<PyAny>>,
    quiet: bool,
    checkpoint_every: u64,
    resume: bool,
    force: bool,
    progress: Option<Py<PyAny>>,
    line: bool,
) -> PyResult<String> {
    let file = match (path, json) {
        (Some(path), _) => crate::read_file(path)?,
        (None, Some(json)) => crate::parse_json(json, origin)?,
        (None, None) => return Err(SettingsError::new_err("run: neither a file nor settings")),
    };
    let stop = Arc::new(AtomicBool::new(false));
    let failed: Arc<Mutex<Option<PyErr>>> = Arc::default();
    let run_dir = RunDir {
        progress_line: line,
        observer: progress.map(|progress| observer(progress, Arc::clone(&stop), Arc::clone(&failed))),
        ..plan(
            &file,
            path.map(Path::new),
            out.map(PathBuf::from),
            checkpoint_every,
            resume,
            force,
        )?
    };
    let mut raised: Option<PyErr> = None;
    let result = match perform {
        Some(perform) => {
            let mut call = |tasks: &[(usize, Task)]| match perform_batch(py, &perform, tasks) {
                Ok(outcomes) => Some(outcomes),
                Err(error) => {
                    raised = Some(error);
                    None
                }
            };
            run_dir.batched(quiet, &stop, &pictures, &mut call)
        }
        None => in_process(py, &run_dir, quiet, &stop, &mut raised),
    };
    if let Some(error) = raised.or_else(|| failed.lock().unwrap_or_else(PoisonError::into_inner).take()) {
        return Err(error);
    }
    result.map_err(|e| match e {
        RunDirError::Config(_) | RunDirError::Refused(_) => SettingsError::new_err(e.to_string()),
        _ => AcpsError::new_err(e.to_string()),
    })?;
    Ok(run_dir.out.display().to_string())
}

/// An observer that calls the Python `progress` with each report; its first exception is kept
/// in `failed` and stops the run.
fn observer(progress: Py<PyAny>, stop: Arc<AtomicBool>, failed: Arc<Mutex<Option<PyErr>>>) -> Observer {
    Arc::new(move |report: &ProgressReport<'_>| {
        Python::attach(|py| {
            let called = progress.call1(
                py,
                (
                    report.experiment,
                    report.episodes,
                    report.total,
                    report.message,
                    report.done,
                ),
            );
            if let Err(error) = called {
                let mut failed = failed.lock().unwrap_or_else(PoisonError::into_inner);
                if failed.is_none() {
                    *failed = Some(error);
                    stop.store(true, Ordering::Relaxed);
                }
            }
        })
    })
}

/// The checked run directory of `file` (read from `path`, if it was) writing into `out`,
/// replacing a finished run there when `force`.
fn plan(
    file: &LoadedFile,
    path: Option<&Path>,
    out: Option<PathBuf>,
    checkpoint_every: u64,
    resume: bool,
    force: bool,
) -> PyResult<RunDir> {
    let refused = |e: RunDirError| SettingsError::new_err(e.to_string());
    let plan = Plan::new(Some(file), &ExperimentFile::default()).map_err(|e| SettingsError::new_err(e.to_string()))?;
    let run_dir = RunDir::of(&plan, path, out)
        .and_then(|r| r.checkpointing(checkpoint_every, resume))
        .map(|r| RunDir { replace: force, ..r })
        .map_err(refused)?;
    run_dir.prepare().map_err(refused)?;
    Ok(run_dir)
}

/// One call of the Python `perform` for `tasks`: their outcomes, in order.
fn perform_batch(py: Python<'_>, perform: &Py<PyAny>, tasks: &[(usize, Task)]) -> PyResult<Vec<Outcome>> {
    // Ctrl-C between two batches stops the run here.
    py.check_signals()?;
    let first = &tasks[0].1;
    let (n_s, n_theta) = (first.context.len(), first.theta.len());
    let refs: Vec<&Task> = tasks.iter().map(|(_, task)| task).collect();
    let arrays = batch(py, &refs, n_s, n_theta)?;
    let returned = perform.call1(py, arrays)?;
    let (rewards, scores, ok): (
        PyReadonlyArray1<'_, f64>,
        PyReadonlyArray1<'_, f64>,
        PyReadonlyArray1<'_, bool>,
    ) = returned.extract(py)?;
    let (rewards, scores, ok) = (rewards.as_array(), scores.as_array(), ok.as_array());
    if [rewards.len(), scores.len(), ok.len()] != [tasks.len(); 3] {
        return Err(AcpsError::new_err(format!(
            "a batch of {} tasks got {} rewards, {} scores and {} ok flags",
            tasks.len(),
            rewards.len(),
            scores.len(),
            ok.len()
        )));
    }
    Ok(tasks
        .iter()
        .enumerate()
        .map(|(i, (_, task))| outcome(task.id, rewards[i], scores[i], ok[i]))
        .collect())
}

/// The experiment's own environments in this process, on a thread of their own, while this
/// one (without the interpreter's lock) looks for Ctrl-C every 50 ms: a KeyboardInterrupt
/// sets `stop` and is kept in `raised`.
fn in_process(
    py: Python<'_>,
    run_dir: &RunDir,
    quiet: bool,
    stop: &AtomicBool,
    raised: &mut Option<PyErr>,
) -> Result<Vec<Summary>, RunDirError> {
    py.detach(|| {
        std::thread::scope(|scope| {
            let running = scope.spawn(|| run_dir.in_process(quiet, stop, &pictures));
            while !running.is_finished() {
                std::thread::sleep(Duration::from_millis(50));
                if raised.is_none()
                    && let Err(error) = Python::attach(|py| py.check_signals())
                {
                    *raised = Some(error);
                    stop.store(true, Ordering::Relaxed);
                }
            }
            running.join().expect("the run's thread does not panic")
        })
    })
}
