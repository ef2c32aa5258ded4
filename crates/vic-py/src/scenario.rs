//! `vic.Scenario`: a scenario file loaded and validated, with its `set=` overrides (the command
//! line's `--set section.key=value`).

use crate::convert::{json_to_py, toml_text};
use crate::errors::{Failure, OverrideError, detached, guarded};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};
use std::path::{Path, PathBuf};

/// A validated scenario (the private class under `vic.Scenario`).
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
    /// Loads and validates a scenario file, with `set` overrides.
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

    #[getter]
    fn path(&self) -> String {
        self.path.display().to_string()
    }
    #[getter]
    fn overrides(&self) -> Vec<String> {
        self.overrides.clone()
    }
    #[getter]
    fn dof(&self) -> usize {
        self.inner.model.dof()
    }
    #[getter]
    fn nx(&self) -> usize {
        self.inner.model.nx()
    }
    #[getter]
    fn nu(&self) -> usize {
        self.inner.model.nu()
    }
    #[getter]
    fn dt(&self) -> f64 {
        self.inner.task.dt
    }
    #[getter]
    fn steps(&self) -> usize {
        self.inner.task.steps
    }
    #[getter]
    fn duration(&self) -> f64 {
        self.inner.task.duration
    }
    #[getter]
    fn delay_ms(&self) -> f64 {
        self.inner.task.delay_ms
    }
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
