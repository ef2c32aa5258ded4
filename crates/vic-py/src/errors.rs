//! The package's exceptions, one per class of error, and the guard that runs vic's code with the
//! GIL released and turns a panic into `vic.InternalError`.
//!
//! ```text
//! VicError
//! ├── ScenarioError          a scenario file or a `set=` override (attributes below)
//! │   ├── ScenarioReadError      the file cannot be read (missing, too large, not UTF-8)
//! │   ├── ScenarioSyntaxError    not TOML, a missing or unknown section
//! │   ├── ScenarioKeyError       [section] key: unknown, missing or a bad value
//! │   └── OverrideError          a `set=` entry that is not "section.key": value
//! ├── PlanError              a scenario that cannot be planned, a plan that does not fit it
//! ├── PlanFileError          a plan file that cannot be read, parsed or written
//! ├── RecordingError         an MCAP file that cannot be read
//! └── InternalError          a bug in vic (a panic), never the caller's input
//! ```
//!
//! Wrong argument types raise `TypeError`, argument values out of range `ValueError`, as Python's
//! own functions do.

use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyValueError};
use pyo3::prelude::*;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;
use vic_plan::scenario::ConfigError;

create_exception!(
    vic,
    VicError,
    PyException,
    "Base class of the errors vic raises."
);
create_exception!(
    vic,
    ScenarioError,
    VicError,
    "A scenario that does not load. Attributes: path (the file), section and key (None when \
     the error is not one key's), override (the set= entry that wrote the key, if one did)."
);
create_exception!(
    vic,
    ScenarioReadError,
    ScenarioError,
    "The scenario file cannot be read (missing, unreadable, larger than 1 MiB, not UTF-8)."
);
create_exception!(
    vic,
    ScenarioSyntaxError,
    ScenarioError,
    "The scenario file is not TOML, or a section is missing or unknown."
);
create_exception!(
    vic,
    ScenarioKeyError,
    ScenarioError,
    "[section] key of the scenario is unknown, missing or has a bad value (the message says which)."
);
create_exception!(
    vic,
    OverrideError,
    ScenarioError,
    "A set= entry that is not \"section.key\": value."
);
create_exception!(
    vic,
    PlanError,
    VicError,
    "The scenario cannot be planned (the solver failed), or a plan does not fit the scenario."
);
create_exception!(
    vic,
    PlanFileError,
    VicError,
    "A plan file that cannot be read, parsed or written, or whose arrays are inconsistent."
);
create_exception!(
    vic,
    RecordingError,
    VicError,
    "An MCAP recording that cannot be read."
);
create_exception!(
    vic,
    InternalError,
    VicError,
    "A bug in vic (a panic caught at the boundary): please report it with the message."
);

/// Adds the exceptions to the module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("VicError", py.get_type::<VicError>())?;
    m.add("ScenarioError", py.get_type::<ScenarioError>())?;
    m.add("ScenarioReadError", py.get_type::<ScenarioReadError>())?;
    m.add("ScenarioSyntaxError", py.get_type::<ScenarioSyntaxError>())?;
    m.add("ScenarioKeyError", py.get_type::<ScenarioKeyError>())?;
    m.add("OverrideError", py.get_type::<OverrideError>())?;
    m.add("PlanError", py.get_type::<PlanError>())?;
    m.add("PlanFileError", py.get_type::<PlanFileError>())?;
    m.add("RecordingError", py.get_type::<RecordingError>())?;
    m.add("InternalError", py.get_type::<InternalError>())?;
    Ok(())
}

/// Runs `f` with the GIL released; a panic in it becomes `vic.InternalError` with the panic's
/// message.
pub(crate) fn detached<T: Send>(
    py: Python<'_>,
    f: impl FnOnce() -> Result<T, Failure> + Send,
) -> PyResult<T> {
    let result = py.detach(|| catch_unwind(AssertUnwindSafe(f)));
    match result {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(failure)) => Err(failure.into_py_err(py)),
        Err(panic) => Err(panic_error(panic)),
    }
}

/// Runs `f` (holding the GIL); a panic in it becomes `vic.InternalError`.
pub(crate) fn guarded<T>(f: impl FnOnce() -> PyResult<T>) -> PyResult<T> {
    catch_unwind(AssertUnwindSafe(f)).unwrap_or_else(|panic| Err(panic_error(panic)))
}

fn panic_error(panic: Box<dyn std::any::Any + Send>) -> PyErr {
    let message = panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic without a message".into());
    InternalError::new_err(format!(
        "internal error in vic (a bug, please report it): {message}"
    ))
}

/// An error made without the GIL, raised once it is held again.
pub(crate) enum Failure {
    Config(ConfigError),
    Plan(String),
    PlanFile(String),
    Recording(String),
    Value(String),
}

impl Failure {
    pub(crate) fn into_py_err(self, py: Python<'_>) -> PyErr {
        match self {
            Failure::Config(e) => config_error(py, e),
            Failure::Plan(m) => PlanError::new_err(m),
            Failure::PlanFile(m) => PlanFileError::new_err(m),
            Failure::Recording(m) => RecordingError::new_err(m),
            Failure::Value(m) => PyValueError::new_err(m),
        }
    }
}

/// The exception of a scenario that does not load, its message naming the file, the key and what
/// is wrong (and the `set=` entry that wrote the key, if one did), with those as attributes.
pub(crate) fn config_error(py: Python<'_>, e: ConfigError) -> PyErr {
    let (err, path, section, key, set): (PyErr, &Path, Option<&str>, Option<&str>, Option<&str>) =
        match &e {
            ConfigError::Io { path, source } => (
                ScenarioReadError::new_err(format!("{}: cannot read: {source}", path.display())),
                path,
                None,
                None,
                None,
            ),
            ConfigError::Syntax { path, message } => (
                ScenarioSyntaxError::new_err(format!("{}: {message}", path.display())),
                path,
                None,
                None,
                None,
            ),
            ConfigError::Invalid {
                path,
                section,
                key,
                message,
                set,
            } => {
                let by = set.as_deref().map_or_else(String::new, |a| {
                    let (k, v) = a.split_once('=').unwrap_or((a, ""));
                    format!(" (set by set={{\"{}\": {}}})", k.trim(), v.trim())
                });
                (
                    ScenarioKeyError::new_err(format!(
                        "{}: [{section}] {key}: {message}{by}",
                        path.display()
                    )),
                    path,
                    Some(section.as_str()),
                    Some(key.as_str()),
                    set.as_deref(),
                )
            }
            ConfigError::Override {
                assignment,
                message,
            } => {
                let err = OverrideError::new_err(format!("set entry {assignment:?}: {message}"));
                let value = err.value(py);
                let _ = value.setattr("path", py.None());
                let _ = value.setattr("section", py.None());
                let _ = value.setattr("key", py.None());
                let _ = value.setattr("override", assignment);
                return err;
            }
        };
    let value = err.value(py);
    let _ = value.setattr("path", path.display().to_string());
    let _ = value.setattr("section", section);
    let _ = value.setattr("key", key);
    let _ = value.setattr("override", set);
    err
}

/// Panics with `message`: the tests' way to check that a panic inside vic reaches Python as
/// `vic.InternalError` (with the GIL released, as in a solve), not as an abort.
#[pyfunction]
pub(crate) fn _panic(py: Python<'_>, message: String) -> PyResult<()> {
    detached(py, move || -> Result<(), Failure> { panic!("{message}") })
}
