//! Between Rust values and Python ones: JSON values as Python objects, arrays as
//! `(dtype, shape, bytearray)` triples of little-endian `float64` (the package wraps them in NumPy arrays
//! without a copy), and arrays back from the package.

use pyo3::IntoPyObjectExt;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyBytes, PyDict, PyList, PyTuple};

/// A JSON value as the Python object `json.loads` would make of it.
pub(crate) fn json_to_py<'py>(
    py: Python<'py>,
    v: &serde_json::Value,
) -> PyResult<Bound<'py, PyAny>> {
    use serde_json::Value;
    match v {
        Value::Null => Ok(py.None().into_bound(py)),
        Value::Bool(b) => b.into_bound_py_any(py),
        Value::Number(n) => {
            if let Some(u) = n.as_u64() {
                u.into_bound_py_any(py)
            } else if let Some(i) = n.as_i64() {
                i.into_bound_py_any(py)
            } else {
                n.as_f64().unwrap_or(f64::NAN).into_bound_py_any(py)
            }
        }
        Value::String(s) => s.into_bound_py_any(py),
        Value::Array(a) => {
            let items = a
                .iter()
                .map(|x| json_to_py(py, x))
                .collect::<PyResult<Vec<_>>>()?;
            PyList::new(py, items)?.into_bound_py_any(py)
        }
        Value::Object(o) => {
            let d = PyDict::new(py);
            for (k, x) in o {
                d.set_item(k, json_to_py(py, x)?)?;
            }
            d.into_bound_py_any(py)
        }
    }
}

/// An array of `shape` (row-major `data`) as `("<f8", shape, bytearray)`.
pub(crate) fn array<'py>(
    py: Python<'py>,
    shape: &[usize],
    data: &[f64],
) -> PyResult<Bound<'py, PyAny>> {
    debug_assert_eq!(shape.iter().product::<usize>(), data.len());
    let mut bytes = Vec::with_capacity(data.len() * 8);
    for v in data {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    let shape = PyTuple::new(py, shape)?;
    ("<f8", shape, PyByteArray::new(py, &bytes)).into_bound_py_any(py)
}

/// Rows of equal length as a 2-D array (`cols` columns, also when there is no row).
pub(crate) fn matrix<'py>(
    py: Python<'py>,
    rows: &[Vec<f64>],
    cols: usize,
) -> PyResult<Bound<'py, PyAny>> {
    let data: Vec<f64> = rows.iter().flatten().copied().collect();
    array(py, &[rows.len(), cols], &data)
}

/// An array the package passes in (`numpy.ascontiguousarray(a, float64).tobytes()`), checked
/// against the `shape` expected and for finite entries; `name` names it in errors.
pub(crate) fn array_in(
    name: &str,
    expected: &[usize],
    shape: &[usize],
    bytes: &Bound<'_, PyBytes>,
) -> PyResult<Vec<f64>> {
    if shape != expected {
        return Err(PyValueError::new_err(format!(
            "{name} has shape {}, expected {}",
            shape_text(shape),
            shape_text(expected)
        )));
    }
    let raw = bytes.as_bytes();
    let n: usize = expected.iter().product();
    if raw.len() != n * 8 {
        return Err(PyValueError::new_err(format!(
            "{name}: {} bytes for {n} float64 values",
            raw.len()
        )));
    }
    let data: Vec<f64> = raw
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
        .collect();
    if let Some(i) = data.iter().position(|v| !v.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "{name}{} is {}: every entry must be a finite number",
            index_text(expected, i),
            data[i]
        )));
    }
    Ok(data)
}

fn shape_text(shape: &[usize]) -> String {
    let parts: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    if parts.len() == 1 {
        format!("({},)", parts[0])
    } else {
        format!("({})", parts.join(", "))
    }
}

/// `[i, j, …]` of the flat index `flat` in a row-major array of `shape`.
fn index_text(shape: &[usize], mut flat: usize) -> String {
    let mut idx = vec![0; shape.len()];
    for (d, &n) in shape.iter().enumerate().rev() {
        idx[d] = flat % n.max(1);
        flat /= n.max(1);
    }
    let parts: Vec<String> = idx.iter().map(|i| i.to_string()).collect();
    format!("[{}]", parts.join(", "))
}

/// A `set=` value as the text after `=` of `vic plan --set section.key=VALUE`: booleans, whole
/// numbers, finite floats (written so that they read back to the same `f64`), lists of those, and
/// strings as they are (taken as the command line takes them: a TOML value if the text is one,
/// else a bare string).
pub(crate) fn toml_text(key: &str, v: &Bound<'_, PyAny>) -> PyResult<String> {
    use pyo3::types::{PyBool, PyFloat, PyInt, PyString};
    if v.is_instance_of::<PyBool>() {
        return Ok(if v.extract::<bool>()? {
            "true"
        } else {
            "false"
        }
        .into());
    }
    if let Ok(s) = v.cast::<PyString>() {
        return Ok(s.to_cow()?.into_owned());
    }
    if v.is_instance_of::<PyInt>() {
        return v.extract::<i64>().map(|i| i.to_string()).map_err(|_| {
            PyValueError::new_err(format!("set[{key:?}]: {v} does not fit in 64 bits"))
        });
    }
    if v.is_instance_of::<PyFloat>() || v.hasattr("__float__")? && !v.hasattr("__len__")? {
        let x: f64 = v.extract()?;
        if !x.is_finite() {
            return Err(PyValueError::new_err(format!(
                "set[{key:?}]: {x} is not a finite number"
            )));
        }
        return Ok(format!("{x:?}"));
    }
    if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() || v.hasattr("tolist")? {
        let seq = if v.hasattr("tolist")? {
            v.call_method0("tolist")?
        } else {
            v.clone()
        };
        if !(seq.is_instance_of::<PyList>() || seq.is_instance_of::<PyTuple>()) {
            return toml_text(key, &seq);
        }
        let items = seq
            .try_iter()?
            .map(|item| {
                let item = item?;
                if item.is_instance_of::<PyString>() {
                    Ok(serde_json::to_string(&item.extract::<String>()?).expect("a string"))
                } else {
                    toml_text(key, &item)
                }
            })
            .collect::<PyResult<Vec<_>>>()?;
        return Ok(format!("[{}]", items.join(", ")));
    }
    Err(PyTypeError::new_err(format!(
        "set[{key:?}]: a bool, int, float, str or list, not {}",
        v.get_type().name()?
    )))
}
