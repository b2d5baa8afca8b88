//! `acps._native`, the extension module of the `acps` Python package: the learner core as
//! ask/tell over numpy arrays (`NativeLearner`), the acps command line (`cli`),
//! and the package's exceptions. The typed Python API in `python/acps/` wraps it.
#![warn(missing_docs)]

mod learner;
mod run;

use acps_experiments::file::LoadedFile;
use pyo3::prelude::*;
use std::path::Path;

pyo3::create_exception!(
    _native,
    AcpsError,
    pyo3::exceptions::PyException,
    "Every error acps raises."
);
pyo3::create_exception!(
    _native,
    SettingsError,
    AcpsError,
    "An experiment file, problem file or settings dict acps refuses: the message names the key, where it stands and the range it accepts."
);
pyo3::create_exception!(
    _native,
    TellError,
    AcpsError,
    "Outcomes the learner cannot take: arrays of different lengths, an unknown task or a task told twice. Nothing of the batch was taken."
);
pyo3::create_exception!(
    _native,
    CheckpointError,
    AcpsError,
    "A checkpoint that cannot be written, read or applied: another experiment's, another job's, truncated or corrupted."
);

/// The experiment or problem file at `path`.
fn read_file(path: &str) -> PyResult<LoadedFile> {
    LoadedFile::read(Path::new(path)).map_err(|e| SettingsError::new_err(e.to_string()))
}

/// An experiment file's keys given as a JSON object (a Python dict), named `origin` in errors.
fn parse_json(json: &str, origin: &str) -> PyResult<LoadedFile> {
    let refused = |e: &dyn std::fmt::Display| SettingsError::new_err(format!("{origin}: {e}"));
    let value: serde_json::Value = serde_json::from_str(json).map_err(|e| refused(&e))?;
    let text = toml::to_string(&value).map_err(|e| refused(&e))?;
    LoadedFile::parse(Path::new(origin), text).map_err(|e| SettingsError::new_err(e.to_string()))
}

/// Run the acps command line with `argv` (the program's name first) and return its exit
/// status. `program` is how the command starts itself again (its workers and relays), for
/// example `[sys.executable, "-m", "acps"]`; the console script passes it.
#[pyfunction]
#[pyo3(signature = (argv, program))]
fn cli(py: Python<'_>, argv: Vec<String>, program: Vec<String>) -> u8 {
    acps_experiments::workers::set_this_program(program.into_iter().map(Into::into).collect());
    // Without the interpreter's lock: the command's threads and its Ctrl-C handler run freely.
    py.detach(|| acps::main(argv))
}

/// The module: its classes, functions and exceptions.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<learner::NativeLearner>()?;
    m.add_function(wrap_pyfunction!(cli, m)?)?;
    m.add_function(wrap_pyfunction!(run::run, m)?)?;
    m.add("AcpsError", py.get_type::<AcpsError>())?;
    m.add("SettingsError", py.get_type::<SettingsError>())?;
    m.add("TellError", py.get_type::<TellError>())?;
    m.add("CheckpointError", py.get_type::<CheckpointError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
