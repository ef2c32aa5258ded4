//! The stiffness actuator's lag against the delay-versus-stiffness trade: for each time constant
//! `τ_K` of a first-order stiffness mechanism (`[actuator] stiffness_dynamics = "first_order"`;
//! `τ_K = 0` is the ideal actuator), the stiffness the SOOC plan realises and where the latency
//! sweep's `predictor` stops beating `stiffness` (the delay crossing).

use super::{Crossing, Strategy, SweepError, SweepOptions, sweep_latency};
use serde::{Deserialize, Serialize};
use std::path::Path;
use vic_plan::plan::{Method, plan};
use vic_plan::scenario::Scenario;

/// One time constant's plan and crossing.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LagPoint {
    /// `τ_K` [s]; 0: the ideal actuator.
    pub time_constant_s: f64,
    /// Per knot, per joint: the stiffness the SOOC plan realises [N m/rad] (its state with a
    /// lag, its command without).
    pub stiffness: Vec<Vec<f64>>,
    /// The SOOC plan's expected cost (Eq. 14).
    pub expected_cost: f64,
    /// Where `predictor` stops ending closer to the target than `stiffness`.
    pub crossing: Crossing,
}

/// The whole study.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LagSweep {
    pub scenario: String,
    pub trials: usize,
    pub latencies_ms: Vec<f64>,
    /// Knot times [s].
    pub time: Vec<f64>,
    pub points: Vec<LagPoint>,
}

/// The overrides that give `base` a first-order stiffness of time constant `tau` (none for 0).
fn lag_overrides(base: &[String], tau: f64) -> Vec<String> {
    let mut o = base.to_vec();
    if tau > 0.0 {
        o.push("actuator.stiffness_dynamics=first_order".into());
        o.push(format!("actuator.stiffness_time_constant={tau}"));
    } else {
        o.push("actuator.stiffness_dynamics=ideal".into());
    }
    o
}

/// Runs the study on the scenario at `path` (an impedance actuator), with `overrides`: per time
/// constant, the SOOC plan and a latency sweep of `predictor` and `stiffness` with `opts`.
pub fn sweep_stiffness_lag(
    path: &Path,
    overrides: &[String],
    time_constants: &[f64],
    opts: &SweepOptions,
    progress: &dyn Fn(&str),
) -> Result<LagSweep, SweepError> {
    let mut opts = opts.clone();
    opts.strategies = vec![Strategy::Predictor, Strategy::Stiffness];
    let mut points = Vec::new();
    let mut time = Vec::new();
    for &tau in time_constants {
        progress(&format!("τ_K = {tau} s"));
        let o = lag_overrides(overrides, tau);
        let s = Scenario::load(path, &o)?;
        let p = plan(&s, Method::Sooc, None).map_err(|source| SweepError::Plan {
            strategy: Strategy::Stiffness.name(),
            latency_ms: 0.0,
            source,
        })?;
        let dof = s.model.dof();
        let stiffness = match s.model.actuator.stiffness_state_offset(dof) {
            Some(off) => p.x.iter().map(|x| x[off..off + dof].to_vec()).collect(),
            // The ideal stiffness acts at once: the command over each step, the last held.
            None => {
                let mut k: Vec<Vec<f64>> = p.u.iter().map(|u| u[dof..2 * dof].to_vec()).collect();
                k.push(k.last().cloned().unwrap_or_default());
                k
            }
        };
        time.clone_from(&p.time);
        let sweep = sweep_latency(path, &o, &opts, &|_| {})?;
        let crossing = sweep
            .crossings
            .iter()
            .find(|c| c.feedback == Strategy::Predictor && c.stiffness == Strategy::Stiffness)
            .map_or(Crossing::NeverBetter, |c| c.crossing);
        points.push(LagPoint {
            time_constant_s: tau,
            stiffness,
            expected_cost: p.summary.expected_cost,
            crossing,
        });
    }
    Ok(LagSweep {
        scenario: path.display().to_string(),
        trials: opts.trials,
        latencies_ms: opts.latencies_ms,
        time,
        points,
    })
}

impl LagSweep {
    /// One line per time constant.
    pub fn table(&self) -> String {
        let mut out = format!(
            "{:>8}  {:>12}  {:>12}  {:>10}  crossing (predictor vs stiffness)\n",
            "τ_K [s]", "peak K1", "peak K2", "E[C] SOOC"
        );
        for p in &self.points {
            let peak = |j: usize| p.stiffness.iter().map(|k| k[j]).fold(0.0, f64::max);
            let k2 = if p.stiffness.first().is_some_and(|k| k.len() > 1) {
                format!("{:12.1}", peak(1))
            } else {
                format!("{:>12}", "-")
            };
            out += &format!(
                "{:8.3}  {:12.1}  {k2}  {:10.4e}  {}\n",
                p.time_constant_s,
                peak(0),
                p.expected_cost,
                p.crossing.text()
            );
        }
        out
    }

    /// The crossing latency [ms] to draw: the interpolated one, else the middle of its bracket;
    /// the sweep's ends for always and never.
    pub(crate) fn crossing_ms(&self, c: Crossing) -> f64 {
        let last = self.latencies_ms.iter().copied().fold(0.0, f64::max);
        match c {
            Crossing::AlwaysBetter => last,
            Crossing::NeverBetter => 0.0,
            Crossing::Between { below, above, at } => at.unwrap_or((below + above) / 2.0),
        }
    }
}

/// Writes `stiffness_lag.png`, `.svg` and `.json` into `dir` (created if missing).
pub fn write_lag_outputs(sweep: &LagSweep, dir: &Path) -> Result<(), SweepError> {
    let failed = |path: &Path| {
        let path = path.to_path_buf();
        move |e: Box<dyn std::error::Error + Send + Sync>| SweepError::Write { path, source: e }
    };
    std::fs::create_dir_all(dir).map_err(|e| failed(dir)(e.into()))?;
    let (png, svg, json) = (
        dir.join("stiffness_lag.png"),
        dir.join("stiffness_lag.svg"),
        dir.join("stiffness_lag.json"),
    );
    let plot = crate::views::plot::LagPlot {
        time: sweep.time.clone(),
        stiffness: sweep
            .points
            .iter()
            .map(|p| {
                (
                    p.time_constant_s,
                    p.stiffness.iter().map(|k| k[0]).collect(),
                )
            })
            .collect(),
        crossing: sweep
            .points
            .iter()
            .map(|p| {
                let bracket = match p.crossing {
                    Crossing::Between { below, above, .. } => Some((below, above)),
                    _ => None,
                };
                (p.time_constant_s, sweep.crossing_ms(p.crossing), bracket)
            })
            .collect(),
    };
    crate::views::plot::lag_figure(&plot, &png, &svg)?;
    let text = serde_json::to_string_pretty(sweep).map_err(|e| failed(&json)(e.into()))?;
    std::fs::write(&json, text).map_err(|e| failed(&json)(e.into()))
}
