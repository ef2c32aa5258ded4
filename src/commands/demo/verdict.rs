//! The demo's verdict: what the run found, in numbers from the run. At the demo's latency, the
//! best feedback without stiffness against planned stiffness without feedback, and the best row
//! of all; then, from an offline sweep of the same scenario and seed (the Monte Carlo of `vic
//! sweep latency`, a few seconds), the latency up to which the predictor ends closer to the
//! target than the stiffness plan: where the curves cross.

use crate::studies::sweep::{
    Crossing, Engine, FinalErrorCrossing, Strategy, Sweep, SweepOptions, sweep_latency,
};
use crate::views::report::StrategyResult;
use serde_json::{Value, json};
use std::path::Path;

/// Latencies of the offline curve [ms] (the demo's own is added): those of `docs/RESULTS.md`.
const OFFLINE_LATENCIES_MS: [f64; 7] = [0.0, 20.0, 50.0, 100.0, 150.0, 200.0, 300.0];
/// Monte Carlo trials per point of the offline curve.
const OFFLINE_TRIALS: usize = 20;

/// The offline curve of the predictor and the stiffness plan on the demo's scenario.
pub(super) fn offline_curve(
    config: &Path,
    overrides: &[String],
    latency_ms: f64,
    seed: u64,
) -> anyhow::Result<Sweep> {
    let mut latencies_ms = OFFLINE_LATENCIES_MS.to_vec();
    if !latencies_ms.contains(&latency_ms) {
        latencies_ms.push(latency_ms);
        latencies_ms.sort_by(f64::total_cmp);
    }
    let opts = SweepOptions {
        latencies_ms,
        strategies: vec![Strategy::Predictor, Strategy::Stiffness],
        trials: OFFLINE_TRIALS,
        seed,
        divergence: None,
        pulse: None,
        execution: Engine::Offline,
    };
    Ok(sweep_latency(config, overrides, &opts, &|_| {})?)
}

/// The verdict's lines and its JSON.
pub(super) struct Verdict {
    pub(super) lines: Vec<String>,
    pub(super) json: Value,
}

/// How a row ranks: fewer diverged trials first, then the lower mean final error (a row whose
/// every trial diverged has none and comes last among equals).
fn rank(r: &StrategyResult) -> (usize, f64) {
    (r.diverged, r.final_error_mean.unwrap_or(f64::INFINITY))
}

/// "6.2 mm, none diverged" / "38.0 mm, 1 of 3 trials diverged" / "every trial diverged".
fn outcome(r: &StrategyResult) -> String {
    match r.final_error_mean {
        None => format!("every trial diverged ({} of {})", r.diverged, r.trials),
        Some(e) if r.diverged == 0 => format!("{e:.1} {}, none diverged", r.unit),
        Some(e) => format!(
            "{e:.1} {}, {} of {} trials diverged",
            r.unit, r.diverged, r.trials
        ),
    }
}

/// The verdict of the rows at `latency_ms` (the reference row at 0 ms is left out) and of the
/// offline curve, when there is one.
pub(super) fn verdict(
    results: &[StrategyResult],
    latency_ms: f64,
    offline: Option<&Sweep>,
) -> Verdict {
    let at: Vec<&StrategyResult> = results
        .iter()
        .filter(|r| r.latency_ms == latency_ms)
        .collect();
    let named = |names: &[Strategy]| {
        at.iter()
            .copied()
            .filter(|r| names.iter().any(|s| s.name() == r.name))
            .min_by(|a, b| rank(a).partial_cmp(&rank(b)).expect("no NaN in a rank"))
    };
    let feedback = named(&[Strategy::NaiveDelayed, Strategy::Predictor]);
    let stiffness = named(&[Strategy::Stiffness]);
    let best = at
        .iter()
        .copied()
        .min_by(|a, b| rank(a).partial_cmp(&rank(b)).expect("no NaN in a rank"));
    let plain = |r: &StrategyResult| Strategy::from_name(&r.name).map_or("", |s| s.plain());
    let mut lines = Vec::new();
    let mut winner = Value::Null;
    if let (Some(f), Some(s)) = (feedback, stiffness) {
        let stiffness_wins = rank(s) < rank(f);
        winner = json!(if stiffness_wins {
            "stiffness"
        } else {
            "feedback"
        });
        lines.push(format!(
            "at {latency_ms} ms (mean final error of the trials that did not diverge): feedback \
             without stiffness at best {} ({}); planned stiffness without any feedback {}. {} \
             wins at this latency.",
            outcome(f),
            f.name,
            outcome(s),
            if stiffness_wins {
                "Stiffness"
            } else {
                "Feedback"
            }
        ));
    }
    if let Some(b) = best {
        lines.push(format!(
            "best at {latency_ms} ms: {} ({}), {}.",
            b.name,
            plain(b),
            outcome(b)
        ));
    }
    let crossing: Option<&FinalErrorCrossing> = offline.and_then(|s| {
        s.crossings
            .iter()
            .find(|c| c.feedback == Strategy::Predictor && c.stiffness == Strategy::Stiffness)
    });
    if let (Some(sweep), Some(c)) = (offline, crossing) {
        let (lo, hi) = latency_range(sweep);
        let beyond = match c.crossing {
            Crossing::Between { .. } => "; beyond it planned stiffness ends closer",
            _ => "",
        };
        lines.push(format!(
            "offline, {} trials a latency from {lo} to {hi} ms: {}{beyond}.",
            sweep.trials,
            c.sentence()
        ));
    }
    let json = json!({
        "latency_ms": latency_ms,
        "best": best.map(|b| b.name.clone()),
        "best_final_error_mean": best.and_then(|b| b.final_error_mean),
        "feedback": feedback.map(|f| f.name.clone()),
        "feedback_final_error_mean": feedback.and_then(|f| f.final_error_mean),
        "feedback_diverged": feedback.map(|f| f.diverged),
        "stiffness_final_error_mean": stiffness.and_then(|s| s.final_error_mean),
        "stiffness_diverged": stiffness.map(|s| s.diverged),
        "winner": winner,
        "offline": offline.map(|s| json!({
            "trials": s.trials,
            "latencies_ms": latencies(s),
            "crossings": s.crossings,
        })),
        "text": lines,
    });
    Verdict { lines, json }
}

fn latencies(sweep: &Sweep) -> Vec<f64> {
    let mut l: Vec<f64> = sweep.points.iter().map(|p| p.latency_ms).collect();
    l.sort_by(f64::total_cmp);
    l.dedup();
    l
}

fn latency_range(sweep: &Sweep) -> (f64, f64) {
    let l = latencies(sweep);
    (
        l.first().copied().unwrap_or(0.0),
        l.last().copied().unwrap_or(0.0),
    )
}

/// One line per strategy that ran: its id and what it does.
pub(super) fn legend(results: &[StrategyResult]) -> Vec<String> {
    let mut seen: Vec<&str> = Vec::new();
    results
        .iter()
        .filter(|r| {
            let new = !seen.contains(&r.name.as_str());
            seen.push(&r.name);
            new
        })
        .filter_map(|r| Strategy::from_name(&r.name).ok())
        .map(|s| format!("  {:<19} {}", s.name(), s.plain()))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(name: &str, latency_ms: f64, mean: Option<f64>, diverged: usize) -> StrategyResult {
        serde_json::from_value(json!({
            "name": name, "latency_ms": latency_ms, "sensor_latency_ms": 0.0,
            "command_latency_ms": 0.0, "trials": 3, "unit": "mm", "rms_error": mean,
            "final_error_mean": mean, "final_error_max": mean, "final_errors": [mean],
            "max_error": mean, "diverged": diverged, "safe_hold_trials": 0, "fault_trials": 0,
            "stale_feedback": 0, "missing_states": 0, "expected_cost": mean
        }))
        .expect("a row")
    }

    #[test]
    fn the_verdict_compares_the_best_feedback_with_stiffness_at_the_latency() {
        let rows = [
            // The reference row at 0 ms is better than everything and must be left out.
            row("naive-delayed", 0.0, Some(1.0), 0),
            row("naive-delayed", 200.0, None, 3),
            row("predictor", 200.0, Some(38.0), 1),
            row("stiffness", 200.0, Some(6.2), 0),
            row("replan", 200.0, Some(2.5), 0),
        ];
        let v = verdict(&rows, 200.0, None);
        assert_eq!(v.json["feedback"], "predictor");
        assert_eq!(v.json["winner"], "stiffness");
        assert_eq!(v.json["best"], "replan");
        assert_eq!(v.json["best_final_error_mean"], 2.5);
        assert!(
            v.lines[0].contains("38.0 mm, 1 of 3 trials diverged (predictor)"),
            "{:?}",
            v.lines
        );
        assert!(v.lines[0].contains("Stiffness wins"), "{:?}", v.lines);
        // Fewer diverged trials rank first: a predictor with a small mean over the trials
        // that survived does not beat a stiffness plan that lost none.
        let rows = [
            row("predictor", 50.0, Some(3.0), 0),
            row("stiffness", 50.0, Some(5.3), 0),
        ];
        let v = verdict(&rows, 50.0, None);
        assert_eq!(v.json["winner"], "feedback");
        assert_eq!(v.json["best"], "predictor");
    }

    #[test]
    fn the_legend_names_each_strategy_once() {
        let rows = [
            row("naive-delayed", 0.0, Some(1.0), 0),
            row("naive-delayed", 200.0, None, 3),
            row("stiffness", 200.0, Some(6.2), 0),
        ];
        let l = legend(&rows);
        assert_eq!(l.len(), 2, "{l:?}");
        assert!(l[1].contains("no feedback at all"), "{l:?}");
    }
}
