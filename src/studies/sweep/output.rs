//! What a sweep leaves behind: its table and notes for the terminal, its figure and its numbers
//! in a folder, and the pulse of its flags.

use super::{Sweep, SweepError};
use std::path::Path;
use vic_plan::montecarlo::Pulse;
use vic_plan::strategy::Strategy;

/// The pulse of `--pulse T1[,T2] --pulse-at-ms MS --pulse-ms MS` (`None` without a torque; the
/// second joint's torque is 0 when one is given).
pub(crate) fn pulse_from_flags(
    torque: &[f64],
    at_ms: f64,
    ms: f64,
) -> Result<Option<Pulse>, SweepError> {
    if torque.is_empty() {
        return Ok(None);
    }
    let valid = torque.iter().all(|t| t.is_finite())
        && at_ms.is_finite()
        && at_ms >= 0.0
        && ms.is_finite()
        && ms > 0.0;
    if !valid || torque.len() > 2 {
        return Err(SweepError::Pulse);
    }
    Ok(Some(Pulse {
        torque: [torque[0], torque.get(1).copied().unwrap_or(0.0)],
        start: at_ms * 1e-3,
        duration: ms * 1e-3,
    }))
}

/// Writes `sweep.png`, `sweep.svg` and `sweep.json` into `dir` (created if missing).
pub(crate) fn write_outputs(sweep: &Sweep, dir: &Path) -> Result<(), SweepError> {
    let failed = |path: &Path| {
        let path = path.to_path_buf();
        move |e: Box<dyn std::error::Error + Send + Sync>| SweepError::Write { path, source: e }
    };
    std::fs::create_dir_all(dir).map_err(|e| failed(dir)(e.into()))?;
    let (png, svg, json) = (
        dir.join("sweep.png"),
        dir.join("sweep.svg"),
        dir.join("sweep.json"),
    );
    write_figure(sweep, &png, &svg)?;
    let text = serde_json::to_string_pretty(sweep).map_err(|e| failed(&json)(e.into()))?;
    std::fs::write(&json, text).map_err(|e| failed(&json)(e.into()))
}

impl Sweep {
    /// The points as a table, one line per strategy and latency (`diverged` where every trial
    /// diverged: a diverged trial is never averaged in).
    pub(crate) fn table(&self) -> String {
        let unit = self.points.first().map_or("", |p| p.unit.name());
        let show = |v: Option<f64>| v.map_or("diverged".to_string(), |v| format!("{v:.3}"));
        let mut out = format!(
            "{:<19} {:>8} {:>14} {:>14} {:>10} {:>12} {:>9}\n",
            "strategy",
            "latency",
            format!("final [{unit}]"),
            "final max",
            "diverged",
            "E[C] MC",
            "mean K"
        );
        for p in &self.points {
            out += &format!(
                "{:<19} {:>5} ms {:>14} {:>14} {:>9.0}% {:>12} {:>9.1}\n",
                p.strategy.name(),
                p.latency_ms,
                show(p.final_error_mean),
                show(p.final_error_max),
                100.0 * p.diverged_fraction,
                p.expected_cost_mc
                    .map_or("-".into(), |c| format!("{c:.4e}")),
                p.mean_stiffness
            );
        }
        out
    }

    /// Live: one line for each point the schedule touched (a late state changes what the
    /// feedback saw, so that point is not the run lockstep computes).
    pub(crate) fn schedule_notes(&self) -> Vec<String> {
        let off = |p: &&super::SweepPoint| p.live.is_some_and(|t| !t.on_schedule());
        self.points
            .iter()
            .filter(off)
            .map(|p| {
                let t = p.live.unwrap_or_default();
                format!(
                    "{} at {} ms ran off schedule: {} stale feedback knots, {} missing and {} \
                     off-knot states, {} late knots, {} central overruns, {} safe-hold and {} \
                     stalled trials",
                    p.strategy.name(),
                    p.latency_ms,
                    t.stale_feedback,
                    t.missing_states,
                    t.off_knot_states,
                    t.late_knots,
                    t.central_overruns,
                    t.safe_hold_trials,
                    t.stalled_trials
                )
            })
            .collect()
    }
}

/// The sweep's figure: final error (mean, bar to the worst trial) against the latency, one line
/// per strategy, PNG and SVG, with a title and a caption that says what each strategy is.
pub fn write_figure(
    sweep: &Sweep,
    png: &Path,
    svg: &Path,
) -> Result<(), crate::views::plot::PlotError> {
    let mut curves: Vec<crate::views::plot::Curve> = Vec::new();
    let mut strategies = Vec::new();
    for p in &sweep.points {
        let name = p.strategy.name();
        let i = match curves.iter().position(|c| c.name == name) {
            Some(i) => i,
            None => {
                curves.push(crate::views::plot::Curve {
                    name: name.into(),
                    points: Vec::new(),
                });
                strategies.push(p.strategy);
                curves.len() - 1
            }
        };
        curves[i].points.push((
            p.latency_ms,
            p.final_error_mean,
            p.final_error_max,
            p.diverged_fraction,
        ));
    }
    let unit = sweep.points.first().map_or("", |p| p.unit.name());
    crate::views::plot::curve_figure(
        &curves,
        &figure_caption(sweep, &strategies),
        &format!("final error [{unit}]"),
        png,
        svg,
    )
}

/// The sweep figure's title (scenario, where the trials ran, how many) and caption (how to read
/// it, what each strategy is).
fn figure_caption(sweep: &Sweep, strategies: &[Strategy]) -> crate::views::plot::Caption {
    let scenario = Path::new(&sweep.scenario)
        .file_stem()
        .map_or_else(|| sweep.scenario.clone(), |s| s.to_string_lossy().into());
    let names: Vec<String> = strategies
        .iter()
        .map(|s| format!("{}: {}", s.name(), s.plain()))
        .collect();
    crate::views::plot::Caption {
        title: format!(
            "Delay versus stiffness: {scenario} ({}, {} trials per point, seed {})",
            match sweep.execution {
                super::Engine::Offline => "offline Monte Carlo",
                super::Engine::Lockstep => "board and controller in lockstep",
                super::Engine::Live => "live",
            },
            sweep.trials,
            sweep.seed
        ),
        text: format!(
            "Final distance to the target against the feedback latency: the mean over the trials \
             that did not diverge (line), a bar up to the worst of them at each latency run \
             (neighbouring strategies' bars side by side). {}.",
            names.join("; ")
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::studies::sweep::{Engine, LiveTiming, SweepPoint};
    use vic_core::policy::Strategy;
    use vic_plan::unit::Unit;

    fn point(strategy: Strategy, error: Option<f64>, live: Option<LiveTiming>) -> SweepPoint {
        SweepPoint {
            strategy,
            latency_ms: 200.0,
            final_error_mean: error,
            final_error_max: error.map(|e| 2.0 * e),
            final_error_se: None,
            rms_error: error,
            diverged: usize::from(error.is_none()) * 20,
            diverged_fraction: if error.is_none() { 1.0 } else { 0.0 },
            expected_cost_mc: error.map(|e| 1e3 * e),
            expected_cost_predicted: None,
            mean_stiffness: 12.5,
            unit: Unit::Millimetre,
            live,
        }
    }

    #[test]
    fn the_pulse_flags_are_checked_and_the_second_joint_defaults_to_zero() {
        assert!(matches!(pulse_from_flags(&[], f64::NAN, 0.0), Ok(None)));
        let p = pulse_from_flags(&[1.5], 400.0, 50.0).unwrap().unwrap();
        assert_eq!((p.torque, p.start, p.duration), ([1.5, 0.0], 0.4, 0.05));
        for (torque, at, ms) in [
            (&[f64::NAN][..], 400.0, 50.0),
            (&[1.0, f64::INFINITY], 400.0, 50.0),
            (&[1.0], -1.0, 50.0),
            (&[1.0], f64::NAN, 50.0),
            (&[1.0], 400.0, 0.0),
            (&[1.0, 2.0, 3.0], 400.0, 50.0),
        ] {
            let e = pulse_from_flags(torque, at, ms).unwrap_err();
            assert!(
                matches!(e, SweepError::Pulse) && e.is_input(),
                "{torque:?} {at} {ms}"
            );
        }
    }

    #[test]
    fn the_table_says_diverged_and_the_notes_name_only_points_off_schedule() {
        let late = LiveTiming {
            stale_feedback: 3,
            ..LiveTiming::default()
        };
        let sweep = Sweep {
            scenario: "s.toml".into(),
            trials: 20,
            seed: 1,
            execution: Engine::Live,
            pulse: None,
            points: vec![
                point(Strategy::NaiveDelayed, None, Some(LiveTiming::default())),
                point(Strategy::Stiffness, Some(6.25), Some(late)),
            ],
            crossings: Vec::new(),
        };
        let table = sweep.table();
        let lines: Vec<&str> = table.lines().collect();
        assert_eq!(lines.len(), 3, "{table}");
        assert!(lines[0].contains("final [mm]"), "{table}");
        assert!(lines[1].starts_with("naive-delayed") && lines[1].contains("diverged"));
        assert!(lines[1].contains("100%"), "{table}");
        assert!(lines[2].starts_with("stiffness") && lines[2].contains("6.250"));
        assert!(
            lines[2].contains("12.500") && lines[2].contains("6.2500e3"),
            "{table}"
        );
        let notes = sweep.schedule_notes();
        assert_eq!(notes.len(), 1, "{notes:?}");
        assert!(notes[0].starts_with("stiffness at 200 ms") && notes[0].contains("3 stale"));
    }
}
