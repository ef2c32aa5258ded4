//! `vic.plan` and the plan (the private class under `vic.Plan`): what `vic plan --out` writes,
//! with its arrays checked for shape on the way in.

use crate::convert::{array, array_in, json_to_py, matrix};
use crate::errors::{Failure, detached, guarded};
use crate::scenario::Scenario;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use std::path::PathBuf;
use vic_plan::plan::{Method, PlanFile};
use vic_plan::strategy::Latency;

/// The command line's range of a latency [ms] (`vic plan --latency-ms`, `vic simulate`).
pub(crate) const MAX_LATENCY_MS: f64 = 1_000.0;

/// A plan (the private class under `vic.Plan`).
#[pyclass(frozen, module = "vic._vic", name = "Plan")]
pub(crate) struct Plan {
    pub(crate) file: PlanFile,
    /// The file as JSON (for the fields the library keeps to itself: the predicted covariances).
    json: serde_json::Value,
}

impl Plan {
    /// A plan whose arrays are consistent (else the reason, naming the field).
    pub(crate) fn new(file: PlanFile) -> Result<Plan, String> {
        check_shapes(&file)?;
        let json = serde_json::to_value(&file).map_err(|e| e.to_string())?;
        let plan = Plan { file, json };
        for (name, n) in [
            ("open_loop_final_covariance", plan.nx()),
            ("open_loop_final_position_covariance", plan.position_dim()),
        ] {
            let rows = plan.json_matrix(name);
            if rows.len() != n || rows.iter().any(|r| r.len() != n) {
                return Err(format!("`{name}` is not {n}×{n}"));
            }
        }
        Ok(plan)
    }

    fn nx(&self) -> usize {
        self.file.state_names.len()
    }
    fn nu(&self) -> usize {
        self.file.control_names.len()
    }
    fn steps(&self) -> usize {
        self.file.u.len()
    }
    /// Joints: the torque controls (`tau1`, …).
    fn dof(&self) -> usize {
        self.file
            .control_names
            .iter()
            .filter(|n| n.starts_with("tau"))
            .count()
    }
    /// 1 for a single joint (the angle), 2 for the arm (the hand).
    fn position_dim(&self) -> usize {
        if self.dof() == 1 { 1 } else { 2 }
    }
    fn json_matrix(&self, name: &str) -> Vec<Vec<f64>> {
        self.json[name]
            .as_array()
            .map(|rows| {
                rows.iter()
                    .map(|r| {
                        r.as_array()
                            .map(|r| r.iter().map(|v| v.as_f64().unwrap_or(f64::NAN)).collect())
                            .unwrap_or_default()
                    })
                    .collect()
            })
            .unwrap_or_default()
    }
}

/// Every array of a plan file has the shape its names and steps say: `time` and `x` N + 1 knots,
/// `u` N steps, the gains nu × nx per step (or none), the reference N + 1 knots.
fn check_shapes(p: &PlanFile) -> Result<(), String> {
    let (n, nx, nu) = (p.u.len(), p.state_names.len(), p.control_names.len());
    if n == 0 || nx == 0 || nu == 0 {
        return Err(format!(
            "{n} steps, {nx} state names, {nu} control names: a plan has at least one of each"
        ));
    }
    let dof = p
        .control_names
        .iter()
        .filter(|c| c.starts_with("tau"))
        .count();
    if !(1..=2).contains(&dof) {
        return Err(format!(
            "{dof} torque controls (tau1, …): vic plans 1 or 2 joints"
        ));
    }
    let rows = |name: &str, rows: &[Vec<f64>], len: usize, width: usize| {
        if rows.len() != len {
            return Err(format!("`{name}` has {} rows, not {len}", rows.len()));
        }
        match rows.iter().position(|r| r.len() != width) {
            Some(i) => Err(format!(
                "`{name}` row {i} has {} entries, not {width}",
                rows[i].len()
            )),
            None => Ok(()),
        }
    };
    if p.time.len() != n + 1 {
        return Err(format!("`time` has {} knots, not {}", p.time.len(), n + 1));
    }
    rows("x", &p.x, n + 1, nx)?;
    rows("u", &p.u, n, nu)?;
    if !p.gains.is_empty() {
        if p.gains.len() != n {
            return Err(format!("`gains` has {} steps, not {n}", p.gains.len()));
        }
        for (k, g) in p.gains.iter().enumerate() {
            rows(&format!("gains[{k}]"), g, nu, nx)?;
        }
    }
    if p.reference.len() != n + 1 {
        return Err(format!(
            "`reference` has {} knots, not {}",
            p.reference.len(),
            n + 1
        ));
    }
    if !(p.dt.is_finite() && p.dt > 0.0) {
        return Err(format!("`dt` is {}, not a positive number", p.dt));
    }
    Ok(())
}

#[pymethods]
impl Plan {
    /// Reads a plan file (`vic plan --out`, `Plan.save`).
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Plan> {
        detached(py, move || {
            let file = PlanFile::read(&path).map_err(|e| Failure::PlanFile(e.to_string()))?;
            Plan::new(file).map_err(|e| {
                Failure::PlanFile(format!("{}: not a consistent plan: {e}", path.display()))
            })
        })
    }

    /// Writes the plan file (the format of `vic plan --out`).
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let file = &self.file;
        detached(py, move || {
            file.write(&path)
                .map_err(|e| Failure::PlanFile(e.to_string()))
        })
    }

    /// The arrays, each as `("<f8", shape, bytearray)`.
    fn arrays<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let f = &self.file;
        let (n, nx, nu, dof) = (self.steps(), self.nx(), self.nu(), self.dof());
        let d = PyDict::new(py);
        d.set_item("time", array(py, &[n + 1], &f.time)?)?;
        d.set_item("x", matrix(py, &f.x, nx)?)?;
        d.set_item("u", matrix(py, &f.u, nu)?)?;
        let gains: Vec<f64> = if f.gains.is_empty() {
            vec![0.0; n * nu * nx]
        } else {
            f.gains.iter().flatten().flatten().copied().collect()
        };
        d.set_item("gains", array(py, &[n, nu, nx], &gains)?)?;
        let q: Vec<f64> = f
            .reference
            .iter()
            .flat_map(|r| r.q_d[..dof].to_vec())
            .collect();
        let qd: Vec<f64> = f
            .reference
            .iter()
            .flat_map(|r| r.qd_d[..dof].to_vec())
            .collect();
        d.set_item("reference_q", array(py, &[n + 1, dof], &q)?)?;
        d.set_item("reference_qd", array(py, &[n + 1, dof], &qd)?)?;
        let pd = self.position_dim();
        d.set_item(
            "open_loop_final_covariance",
            matrix(py, &self.json_matrix("open_loop_final_covariance"), nx)?,
        )?;
        d.set_item(
            "open_loop_final_position_covariance",
            matrix(
                py,
                &self.json_matrix("open_loop_final_position_covariance"),
                pd,
            )?,
        )?;
        Ok(d)
    }

    /// The summary, as `vic plan --json` prints it.
    fn summary<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &self.json["summary"])
    }

    /// The resolved configuration the plan was made with.
    #[getter]
    fn config<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &self.file.config)
    }
    #[getter]
    fn scenario(&self) -> String {
        self.file.scenario.clone()
    }
    #[getter]
    fn dt(&self) -> f64 {
        self.file.dt
    }
    #[getter]
    fn state_names(&self) -> Vec<String> {
        self.file.state_names.clone()
    }
    #[getter]
    fn control_names(&self) -> Vec<String> {
        self.file.control_names.clone()
    }
    #[getter]
    fn version(&self) -> u32 {
        self.file.version
    }

    /// The plan's commands executed open loop on `scenario`, predicted by mean and covariance
    /// propagation (the moments of Eq. 10): the mean states at the knots `("<f8", (N+1, n), …)`,
    /// the final covariance `(n, n)` and the expected cost.
    fn predict_open_loop<'py>(
        &self,
        py: Python<'py>,
        scenario: PyRef<'py, Scenario>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (s, file) = (&scenario.inner, &self.file);
        let prediction = detached(py, move || {
            let fail = |e: vic_plan::plan::PlanError| {
                Failure::Plan(format!("the plan on {}: {e}", s.source.display()))
            };
            let setup = vic_plan::plan::setup(s).map_err(fail)?;
            let policy = file.policy(&setup).map_err(fail)?;
            Ok(vic_plan::plan::predict_open_loop(&setup, &policy.acting))
        })?;
        let nx = self.nx();
        let mean: Vec<f64> = prediction
            .mean
            .iter()
            .flat_map(|m| m.iter().copied())
            .collect();
        let cov: Vec<f64> = prediction
            .final_covariance
            .row_iter()
            .flat_map(|r| r.iter().copied().collect::<Vec<_>>())
            .collect();
        let d = PyDict::new(py);
        d.set_item("mean", array(py, &[prediction.mean.len(), nx], &mean)?)?;
        d.set_item("final_covariance", array(py, &[nx, nx], &cov)?)?;
        d.set_item("expected_cost", prediction.expected_cost)?;
        Ok(d)
    }

    /// The same plan with some arrays replaced (each `(shape, bytes)` of float64, the shape of
    /// the one it replaces, every entry finite); the summary stays the original's.
    #[pyo3(signature = (u = None, x = None, gains = None))]
    fn with_arrays(
        &self,
        u: Option<(Vec<usize>, Bound<'_, PyBytes>)>,
        x: Option<(Vec<usize>, Bound<'_, PyBytes>)>,
        gains: Option<(Vec<usize>, Bound<'_, PyBytes>)>,
    ) -> PyResult<Plan> {
        guarded(|| {
            let (n, nx, nu) = (self.steps(), self.nx(), self.nu());
            let mut file = self.file.clone();
            if let Some((shape, bytes)) = u {
                let data = array_in("u", &[n, nu], &shape, &bytes)?;
                file.u = data.chunks(nu).map(<[f64]>::to_vec).collect();
            }
            if let Some((shape, bytes)) = x {
                let data = array_in("x", &[n + 1, nx], &shape, &bytes)?;
                file.x = data.chunks(nx).map(<[f64]>::to_vec).collect();
            }
            if let Some((shape, bytes)) = gains {
                let data = array_in("gains", &[n, nu, nx], &shape, &bytes)?;
                file.gains = data
                    .chunks(nu * nx)
                    .map(|g| g.chunks(nx).map(<[f64]>::to_vec).collect())
                    .collect();
            }
            Plan::new(file).map_err(PyValueError::new_err)
        })
    }
}

/// The method named `method` (`None`: the scenario's `[solver] method`).
fn method_of(scenario: &Scenario, method: Option<&str>) -> PyResult<Method> {
    match method {
        None => Ok(scenario.inner.solver.method),
        Some("ilqg") => Ok(Method::Ilqg),
        Some("sooc") => Ok(Method::Sooc),
        Some(other) => Err(PyValueError::new_err(format!(
            "method must be \"ilqg\" or \"sooc\", not {other:?}"
        ))),
    }
}

/// A latency [ms] given as `name`, on the grid of `dt` [s]: in the command line's range and a
/// whole number of steps.
pub(crate) fn latency_of(name: &str, ms: f64, dt: f64) -> PyResult<Latency> {
    if !(ms.is_finite() && (0.0..=MAX_LATENCY_MS).contains(&ms)) {
        return Err(PyValueError::new_err(format!(
            "{name}={ms}: a latency is 0 to {MAX_LATENCY_MS} ms"
        )));
    }
    Latency::from_ms(ms, dt).map_err(|e| {
        PyValueError::new_err(format!(
            "{name}={}: not a whole number of {} ms plan steps",
            e.ms, e.step_ms
        ))
    })
}

/// Plans the scenario (`vic plan`): ILQG for its feedback delay (or `delay_ms`), or SOOC.
#[pyfunction]
#[pyo3(signature = (scenario, method = None, delay_ms = None))]
pub(crate) fn plan(
    py: Python<'_>,
    scenario: PyRef<'_, Scenario>,
    method: Option<&str>,
    delay_ms: Option<f64>,
) -> PyResult<Plan> {
    let method = method_of(&scenario, method)?;
    let mut s = scenario.inner.clone();
    if let Some(ms) = delay_ms {
        let latency = latency_of("delay_ms", ms, s.task.dt)?;
        s = s.with_delay(latency);
    }
    let source = scenario.source().to_path_buf();
    detached(py, move || {
        let file = vic_plan::plan::plan(&s, method, None)
            .map_err(|e| Failure::Plan(format!("{}: {e}", source.display())))?;
        Plan::new(file).map_err(Failure::Plan)
    })
}
