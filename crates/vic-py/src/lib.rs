//! `vic._vic`: the extension module under the Python package `vic` (python/vic). It plans,
//! simulates, sweeps and reads recordings with the library crates, the same calls `vic plan`,
//! `vic simulate` and `vic sweep latency` make, so that the numbers are the command line's to the
//! last bit.
//!
//! The module speaks plain Python: numbers, strings, lists, dicts, and arrays as
//! `(dtype, shape, bytearray)` triples of little-endian values that the package turns into NumPy arrays
//! without a copy (no NumPy C API here, so the wheel is one stable-ABI build for every CPython
//! ≥ 3.9 and every NumPy). Every error is a Python exception of the package's (see [`errors`]);
//! a panic inside vic is caught and raised as `vic.InternalError`, never unwound across the
//! boundary. Solves, trials and sweeps release the GIL.

mod convert;
mod errors;
mod mcap_columns;
mod plan;
mod scenario;
mod simulate;

use pyo3::prelude::*;

/// The extension module `vic._vic`.
#[pymodule]
fn _vic(m: &Bound<'_, PyModule>) -> PyResult<()> {
    errors::register(m)?;
    m.add_class::<scenario::Scenario>()?;
    m.add_class::<plan::Plan>()?;
    m.add_function(wrap_pyfunction!(plan::plan, m)?)?;
    m.add_function(wrap_pyfunction!(simulate::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(simulate::sweep_latency, m)?)?;
    m.add_function(wrap_pyfunction!(mcap_columns::read_mcap_columns, m)?)?;
    m.add_function(wrap_pyfunction!(errors::_panic, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
