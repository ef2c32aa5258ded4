//! `vic.Scenario`: a scenario file loaded and validated, with its `set=` overrides (the command
//! line's `--set section.key=value`).

use crate::convert::{json_to_py, toml_text};
use crate::errors::{Failure, OverrideError, detached, guarded};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};
use std::path::{Path, PathBuf};

/// A scenario: the plant, actuator, field, noise, cost and task of a TOML file (config/),
/// validated, with its overrides. `Scenario.load(path, set={"noise.sigma": 0.02})` reads one;
/// `dof`, `nx`, `nu`, `dt` [s], `steps`, `duration` [s], `delay_ms` [ms], `method` and `config`
/// (the configuration after the overrides) describe it.
#[pyclass(frozen, module = "vic._vic", name = "Scenario")]
pub(crate) struct Scenario {
    pub(crate) inner: vic_plan::scenario::Scenario,
    /// The file it was loaded from, as given.
    pub(crate) path: PathBuf,
    /// The overrides as the command line writes them (`section.key=value`), in order.
    pub(crate) overrides: Vec<String>,
}

/// The `set=` mapping as `section.key=value` assignments, in the mapping's order.
fn overrides(set: Option<&Bound<'_, PyAny>>) -> PyResult<Vec<String>> {
    let Some(set) = set.filter(|s| !s.is_none()) else {
        return Ok(Vec::new());
    };
    let dict = set.cast::<PyDict>().map_err(|_| {
        PyTypeError::new_err(format!(
            "set must be a dict of \"section.key\": value, not {}",
            set.get_type()
                .name()
                .map_or_else(|_| "?".into(), |n| n.to_string())
        ))
    })?;
    let mut out = Vec::with_capacity(dict.len());
    for (k, v) in dict.iter() {
        let key = k.cast::<PyString>().map_err(|_| {
            PyTypeError::new_err(format!(
                "set keys are \"section.key\" strings, not {}",
                k.repr().map_or_else(|_| "?".into(), |r| r.to_string())
            ))
        })?;
        let key = key.to_cow()?.trim().to_string();
        if key.contains('=') || key.split('.').count() != 2 || key.split('.').any(str::is_empty) {
            let err = OverrideError::new_err(format!(
                "set key {key:?}: expected \"section.key\" (e.g. \"noise.sigma\")"
            ));
            let value = err.value(set.py());
            let _ = value.setattr("override", &key);
            for attr in ["path", "section", "key"] {
                let _ = value.setattr(attr, set.py().None());
            }
            return Err(err);
        }
        let text = toml_text(&key, &v)?;
        out.push(format!("{key}={text}"));
    }
    Ok(out)
}

#[pymethods]
impl Scenario {
    /// Loads and validates the scenario file at `path` (a missing `config/NAME.toml` is the
    /// built-in copy), with `set` overrides `{"section.key": value}` (`vic plan --set
    /// section.key=value`): a bool, int, finite float, list of those, or a str read as the
    /// command line reads the text after `=`. Raises `ScenarioReadError`, `ScenarioSyntaxError`,
    /// `ScenarioKeyError` (naming the file and `[section] key`) or `OverrideError`.
    #[staticmethod]
    #[pyo3(signature = (path, set = None))]
    fn load(py: Python<'_>, path: PathBuf, set: Option<&Bound<'_, PyAny>>) -> PyResult<Scenario> {
        let overrides = overrides(set)?;
        let (p, o) = (path.clone(), overrides.clone());
        let inner = detached(py, move || {
            vic_plan::scenario::Scenario::load(&p, &o).map_err(Failure::Config)
        })?;
        Ok(Scenario {
            inner,
            path,
            overrides,
        })
    }

    /// A scenario from TOML text (`path` names it in messages only).
    #[staticmethod]
    #[pyo3(signature = (text, path = PathBuf::from("<string>"), set = None))]
    fn from_str(
        py: Python<'_>,
        text: &str,
        path: PathBuf,
        set: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Scenario> {
        let overrides = overrides(set)?;
        let inner = guarded(|| {
            vic_plan::scenario::Scenario::from_str(text, &path, &overrides)
                .map_err(|e| Failure::Config(e).into_py_err(py))
        })?;
        Ok(Scenario {
            inner,
            path,
            overrides,
        })
    }

    /// The file, as given.
    #[getter]
    fn path(&self) -> String {
        self.path.display().to_string()
    }
    /// The overrides as `section.key=value`, as `--set` takes them.
    #[getter]
    fn overrides(&self) -> Vec<String> {
        self.overrides.clone()
    }
    /// Joints: 1 (single joint) or 2 (two-link arm).
    #[getter]
    fn dof(&self) -> usize {
        self.inner.model.dof()
    }
    /// State dimension n: angles and velocities (and a VSA's motor angles and speeds).
    #[getter]
    fn nx(&self) -> usize {
        self.inner.model.nx()
    }
    /// Control dimension m: torques (and stiffnesses).
    #[getter]
    fn nu(&self) -> usize {
        self.inner.model.nu()
    }
    /// Time step Δ of the plan [s].
    #[getter]
    fn dt(&self) -> f64 {
        self.inner.task.dt
    }
    /// Steps N = duration / Δ.
    #[getter]
    fn steps(&self) -> usize {
        self.inner.task.steps
    }
    /// Movement duration [s].
    #[getter]
    fn duration(&self) -> f64 {
        self.inner.task.duration
    }
    /// The central feedback delay an ILQG plan is made for [ms].
    #[getter]
    fn delay_ms(&self) -> f64 {
        self.inner.task.delay_ms
    }
    /// The `[solver] method`: "ilqg" or "sooc".
    #[getter]
    fn method(&self) -> &'static str {
        self.inner.solver.method.name()
    }
    /// The configuration after the overrides, as written into plan files.
    #[getter]
    fn config<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let v = serde_json::to_value(&self.inner.resolved)
            .map_err(|e| pyo3::exceptions::PyValueError::new_err(e.to_string()))?;
        json_to_py(py, &v)
    }

    fn __repr__(&self) -> String {
        let set = if self.overrides.is_empty() {
            String::new()
        } else {
            format!(", set={:?}", self.overrides)
        };
        format!("Scenario.load({:?}{set})", self.path())
    }
}

impl Scenario {
    pub(crate) fn source(&self) -> &Path {
        &self.path
    }
}
