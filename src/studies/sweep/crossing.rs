//! Where the curves of a latency sweep cross: the latency beyond which a strategy that feeds the
//! state back late stops beating one that relies on planned stiffness. The sweep stores these
//! (`crossings` in its JSON), prints them under its table, and the demo's verdict and
//! `docs/RESULTS.md` read them.

use super::{Strategy, Sweep, SweepPoint};
use serde::{Deserialize, Serialize};

/// Where one strategy stops being better than another as the latency grows.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Crossing {
    /// The first strategy is better (lower) at every latency.
    AlwaysBetter,
    /// The first strategy is worse (or equal) at every latency.
    NeverBetter,
    /// Better at `below`, worse at `above` [ms]; `at`: the log-linear interpolation of the two
    /// curves' ratio, when both values are known on both sides.
    Between {
        #[serde(rename = "below_ms")]
        below: f64,
        #[serde(rename = "above_ms")]
        above: f64,
        #[serde(rename = "at_ms")]
        at: Option<f64>,
    },
}

impl Crossing {
    /// "up to ≈ 60 ms (between 50 and 100 ms)", "at every latency of the sweep", ...
    pub(crate) fn text(self) -> String {
        match self {
            Crossing::AlwaysBetter => "at every latency of the sweep".into(),
            Crossing::NeverBetter => "at no latency of the sweep".into(),
            Crossing::Between { below, above, at } => match at {
                Some(at) => format!("up to ≈ {at:.0} ms (between {below} and {above} ms)"),
                None => format!("up to {below} ms, not at {above} ms"),
            },
        }
    }
}

/// Where `a` stops being better than `b` by `metric` (lower is better; `None`, every trial
/// diverged, is worse than any number).
pub(crate) fn crossing(
    sweep: &Sweep,
    a: Strategy,
    b: Strategy,
    metric: fn(&SweepPoint) -> Option<f64>,
) -> Crossing {
    let value = |s: Strategy, l: f64| {
        sweep
            .points
            .iter()
            .find(|p| p.strategy == s && p.latency_ms == l)
            .and_then(metric)
    };
    // ln(a / b): negative where a is better; +∞ where a has no value.
    let log_ratio = |l: f64| match (value(a, l), value(b, l)) {
        (Some(x), Some(y)) if x > 0.0 && y > 0.0 => Some((x / y).ln()),
        (None, Some(_)) => Some(f64::INFINITY),
        (Some(_), None) => Some(f64::NEG_INFINITY),
        _ => None,
    };
    let mut latencies: Vec<f64> = sweep.points.iter().map(|p| p.latency_ms).collect();
    latencies.sort_by(f64::total_cmp);
    latencies.dedup();
    let known: Vec<(f64, f64)> = latencies
        .iter()
        .filter_map(|&l| log_ratio(l).map(|r| (l, r)))
        .collect();
    if known.iter().all(|(_, r)| *r < 0.0) {
        return Crossing::AlwaysBetter;
    }
    match known.first() {
        Some((_, r)) if *r >= 0.0 => return Crossing::NeverBetter,
        None => return Crossing::NeverBetter,
        _ => {}
    }
    let i = known.iter().position(|(_, r)| *r >= 0.0).expect("some ≥ 0");
    let ((l0, r0), (l1, r1)) = (known[i - 1], known[i]);
    let at = (r0.is_finite() && r1.is_finite()).then(|| l0 + (l1 - l0) * (-r0) / (r1 - r0));
    Crossing::Between {
        below: l0,
        above: l1,
        at,
    }
}

/// One pair's crossing by the mean final error: how far the `feedback` strategy's lead over the
/// `stiffness` one reaches.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FinalErrorCrossing {
    /// A strategy that feeds the state back across the latency.
    pub feedback: Strategy,
    /// A strategy whose planned stiffness acts without waiting for a measurement.
    pub stiffness: Strategy,
    /// Where `feedback` ends closer to the target than `stiffness` (mean final error).
    #[serde(flatten)]
    pub crossing: Crossing,
}

impl FinalErrorCrossing {
    /// "predictor ends closer to the target than stiffness up to ≈ 60 ms (between 50 and 100
    /// ms)".
    pub(crate) fn sentence(&self) -> String {
        format!(
            "{} ends closer to the target than {} {}",
            self.feedback.name(),
            self.stiffness.name(),
            self.crossing.text()
        )
    }
}

/// Every pair of a feedback strategy and a stiffness strategy that the sweep ran at two or more
/// latencies, by the mean final error.
pub(crate) fn final_error_crossings(sweep: &Sweep) -> Vec<FinalErrorCrossing> {
    let ran = |s: Strategy| sweep.points.iter().filter(|p| p.strategy == s).count() >= 2;
    let feedback = [
        Strategy::NaiveDelayed,
        Strategy::Predictor,
        Strategy::StiffnessPredictor,
    ];
    let stiffness = [Strategy::Stiffness, Strategy::Replan];
    let mut out = Vec::new();
    for &f in feedback.iter().filter(|&&f| ran(f)) {
        for &s in stiffness.iter().filter(|&&s| ran(s)) {
            out.push(FinalErrorCrossing {
                feedback: f,
                stiffness: s,
                crossing: crossing(sweep, f, s, |p| p.final_error_mean),
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use vic_plan::unit::Unit;

    fn sweep(pred: &[Option<f64>], stiff: &[Option<f64>]) -> Sweep {
        let point = |strategy, latency_ms, v: Option<f64>| SweepPoint {
            strategy,
            latency_ms,
            final_error_mean: v,
            final_error_max: v,
            final_error_se: None,
            rms_error: v,
            diverged: usize::from(v.is_none()),
            diverged_fraction: if v.is_some() { 0.0 } else { 1.0 },
            expected_cost_mc: v,
            expected_cost_predicted: v,
            mean_stiffness: 0.0,
            unit: Unit::Millimetre,
            live: None,
        };
        let lat = [0.0, 50.0, 100.0];
        let mut points = Vec::new();
        for (s, vs) in [(Strategy::Predictor, pred), (Strategy::Stiffness, stiff)] {
            points.extend(lat.iter().zip(vs).map(|(&l, &v)| point(s, l, v)));
        }
        Sweep {
            scenario: "x.toml".into(),
            trials: 2,
            seed: 1,
            execution: Default::default(),
            pulse: None,
            points,
            crossings: Vec::new(),
        }
    }

    fn cross(pred: &[Option<f64>], stiff: &[Option<f64>]) -> Crossing {
        let s = sweep(pred, stiff);
        crossing(&s, Strategy::Predictor, Strategy::Stiffness, |p| {
            p.final_error_mean
        })
    }

    #[test]
    fn the_crossing_is_interpolated_on_the_log_ratio() {
        // ln(2/4) at 50 ms, ln(8/4) at 100 ms: the ratio is 1 half-way, at 75 ms.
        let c = cross(&[Some(1.0), Some(2.0), Some(8.0)], &[Some(4.0); 3]);
        match c {
            Crossing::Between { below, above, at } => {
                assert_eq!((below, above), (50.0, 100.0));
                assert!((at.unwrap() - 75.0).abs() < 1e-9, "{at:?}");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn diverged_points_count_as_worse_and_have_no_interpolation() {
        let c = cross(&[Some(1.0), Some(2.0), None], &[Some(4.0); 3]);
        assert_eq!(
            c,
            Crossing::Between {
                below: 50.0,
                above: 100.0,
                at: None
            }
        );
        assert_eq!(
            cross(&[Some(1.0); 3], &[Some(4.0); 3]),
            Crossing::AlwaysBetter
        );
        assert_eq!(
            cross(&[Some(5.0); 3], &[Some(4.0); 3]),
            Crossing::NeverBetter
        );
        assert_eq!(cross(&[None; 3], &[Some(4.0); 3]), Crossing::NeverBetter);
    }

    #[test]
    fn the_pairs_are_those_the_sweep_ran_and_serialise_flat() {
        let s = sweep(&[Some(1.0), Some(2.0), Some(8.0)], &[Some(4.0); 3]);
        let c = final_error_crossings(&s);
        assert_eq!(c.len(), 1, "{c:?}");
        assert_eq!(
            (c[0].feedback, c[0].stiffness),
            (Strategy::Predictor, Strategy::Stiffness)
        );
        let v = serde_json::to_value(c[0]).unwrap();
        assert_eq!(v["feedback"], "predictor");
        assert_eq!(v["kind"], "between");
        assert_eq!(
            (v["below_ms"].as_f64(), v["above_ms"].as_f64()),
            (Some(50.0), Some(100.0))
        );
        assert!((v["at_ms"].as_f64().unwrap() - 75.0).abs() < 1e-9);
        let back: FinalErrorCrossing = serde_json::from_value(v).unwrap();
        assert_eq!(back, c[0]);
        assert_eq!(
            c[0].sentence(),
            "predictor ends closer to the target than stiffness up to ≈ 75 ms (between 50 and 100 ms)"
        );
    }
}
