//! The latency sweep on the single joint of Fig. 2: one point per strategy and latency, and the
//! ordering the paper's argument rests on.

use std::path::Path;
use vic::tools::sweep::{Strategy, SweepOptions, sweep_latency, write_figure};

const STRATEGIES: [Strategy; 3] = [
    Strategy::NaiveDelayed,
    Strategy::Predictor,
    Strategy::Stiffness,
];

#[test]
fn the_sweep_orders_the_strategies_as_the_paper_argues() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/single_joint_delay.toml");
    let opts = SweepOptions {
        latencies_ms: vec![0.0, 50.0, 200.0],
        strategies: STRATEGIES.to_vec(),
        trials: 40,
        seed: 3,
        divergence: None,
        pulse: None,
    };
    let sweep = sweep_latency(&path, &[], &opts, &|_| {}).expect("sweep");
    assert_eq!(sweep.points.len(), 9);
    for p in &sweep.points {
        eprintln!(
            "{:>13} {:>5} ms: final {:?} max {:?} rms {:?} diverged {:.2} cost {:?} predicted {:?} K {:.1}",
            p.strategy.name(),
            p.latency_ms,
            p.final_error_mean,
            p.final_error_max,
            p.rms_error,
            p.diverged_fraction,
            p.expected_cost_mc,
            p.expected_cost_predicted,
            p.mean_stiffness
        );
    }
    let at = |s: Strategy, ms: f64| {
        sweep
            .points
            .iter()
            .find(|p| p.strategy == s && p.latency_ms == ms)
            .expect("point")
    };
    // Eq. 13 fails at long latencies; the predictor does not.
    assert!(at(Strategy::NaiveDelayed, 200.0).diverged_fraction > 0.5);
    assert_eq!(at(Strategy::Predictor, 200.0).diverged_fraction, 0.0);
    // Stiffness does not care about the latency: the same plan, the same trials.
    let (s0, s200) = (at(Strategy::Stiffness, 0.0), at(Strategy::Stiffness, 200.0));
    assert_eq!(s0.final_error_mean, s200.final_error_mean);
    assert!(s0.mean_stiffness > 0.0);
    assert_eq!(at(Strategy::Predictor, 0.0).mean_stiffness, 0.0);
    let dir = std::env::temp_dir().join(format!("vic_sweep_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (png, svg) = (dir.join("sweep.png"), dir.join("sweep.svg"));
    write_figure(&sweep, &png, &svg).expect("figure");
    assert!(std::fs::metadata(&png).unwrap().len() > 1000);
    let text = std::fs::read_to_string(&svg).unwrap();
    for s in STRATEGIES {
        assert!(text.contains(s.name()), "legend lacks {}", s.name());
    }
    if std::env::var_os("VIC_KEEP_FIGURES").is_none() {
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
