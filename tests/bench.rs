//! The bench machinery can fail: the cyclictest parser on fixed text (and on broken text), the
//! percentile and ratio arithmetic on hand-computed cases, and short real runs of `vic bench
//! loop`, `vic bench ipc` and `vic bench sooc` whose JSON must have the documented keys and
//! consistent numbers.
//! No timing thresholds: these machines are noisy.

use std::process::Command;
use vic::bench::HistogramError;
use vic::bench::cyclictest::parse;
use vic::bench::{Dist, percentile_of_buckets, ratio};

/// A trimmed cyclictest 2.4 histogram (`-h 10 --histfile`): 20 samples in the buckets, one
/// overflow at 3123 µs.
const HIST: &str = "\
# Histogram
000000 000000
000001 000000
000002 000002
000003 000010
000004 000005
000005 000000
000006 000001
000007 000001
000008 000000
000009 000001
# Total: 000000020
# Min Latencies: 00002
# Avg Latencies: 00004
# Max Latencies: 03123
# Histogram Overflows: 00001
# Histogram Overflow at cycle number:
# Thread 0: 01501
";

#[test]
fn cyclictest_histogram_parses_into_the_right_percentiles() {
    let h = parse(HIST).unwrap();
    assert_eq!(h.total, 20);
    assert_eq!(h.overflows, 1);
    assert_eq!(h.max_us, 3123.0);
    assert_eq!(h.min_us, 2.0);
    let d = h.dist();
    // 21 samples: 2,2, 3×10, 4×5, 6, 7, 9, overflow(3123).
    assert_eq!(d.count, 21);
    assert_eq!(d.p50_us, 3.0); // rank 11
    assert_eq!(d.p99_us, 3123.0); // rank 21 is the overflow: the maximum
    assert_eq!(d.max_us, 3123.0);
    // Without the overflow the 99th percentile is the last bucket.
    let mut counts = h.counts.clone();
    counts.truncate(10);
    assert_eq!(percentile_of_buckets(&counts, 20, 0.99), Some(9.0));
    assert_eq!(percentile_of_buckets(&counts, 20, 0.9), Some(6.0)); // rank 18
}

#[test]
fn broken_cyclictest_output_is_an_error() {
    assert_eq!(parse(""), Err(HistogramError::Missing("Total")));
    assert_eq!(
        parse("000001 000002\n# Max Latencies: 00003\n"),
        Err(HistogramError::Missing("Total"))
    );
    let wrong_total = HIST.replace("# Total: 000000020", "# Total: 000000021");
    assert_eq!(
        parse(&wrong_total),
        Err(HistogramError::Total {
            in_buckets: 20,
            total: 21
        })
    );
    let garbage = HIST.replace("000004 000005", "000004 abc");
    let e = parse(&garbage).unwrap_err();
    assert!(
        matches!(&e, HistogramError::Number { line: 6, token, .. } if token == "abc"),
        "{e}"
    );
    assert!(e.to_string().contains("line 6"), "{e}");
    let short = HIST.replace("000004 000005", "000004");
    assert!(matches!(
        parse(&short),
        Err(HistogramError::Row { line: 6, .. })
    ));
}

#[test]
fn ratios_and_bucket_percentiles_by_hand() {
    // 4 samples 10, 20, 30, 40 µs: p50 = rank 2 → 20; p99 = rank 4 → 40.
    let mut counts = vec![0u64; 41];
    for v in [10, 20, 30, 40] {
        counts[v] = 1;
    }
    let d = Dist::from_buckets(&counts, 0, 40.0);
    assert_eq!(
        (d.p50_us, d.p99_us, d.p999_us, d.max_us),
        (20.0, 40.0, 40.0, 40.0)
    );
    assert_eq!(ratio(30.0, Some(20.0)), Some(1.5));
    assert_eq!(ratio(30.0, None), None);
}

fn assert_dist(v: &serde_json::Value, what: &str) {
    let f = |k: &str| {
        v[k].as_f64()
            .unwrap_or_else(|| panic!("{what}: no number at {k}: {v}"))
    };
    let (p50, p99, p999, max) = (f("p50_us"), f("p99_us"), f("p999_us"), f("max_us"));
    assert!(
        0.0 <= p50 && p50 <= p99 && p99 <= p999 && p999 <= max,
        "{what}: percentiles out of order: {v}"
    );
}

#[test]
fn a_short_loop_bench_reports_the_documented_keys() {
    let out = Command::new(env!("CARGO_BIN_EXE_vic"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args([
            "bench",
            "loop",
            "--seconds",
            "1",
            "--variant",
            "sleep,spin",
            "--json",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_dist(&v["vic"], "vic");
    let cpu = v["vic"]["cpu_percent"].as_f64().unwrap();
    assert!(cpu > 0.0 && cpu <= 100.0, "cpu_percent {cpu}");
    assert_eq!(v["variants"].as_array().unwrap().len(), 2);
    for var in v["variants"].as_array().unwrap() {
        assert_dist(&var["jitter"], "jitter");
        assert_dist(&var["work"], "work");
        // One second at 1 kHz, minus the periods a late wake-up skipped.
        let n = var["jitter"]["count"].as_u64().unwrap() + var["missed_periods"].as_u64().unwrap();
        assert!((990..=1001).contains(&n), "{n} ticks in one second");
    }
    if v["baseline"].is_null() {
        assert!(v["ratio_p99"].is_null());
        assert!(v["baseline_note"].as_str().unwrap().contains("rt-tests"));
    } else {
        assert_dist(&v["baseline"], "baseline");
        let r = v["ratio_p99"].as_f64().unwrap();
        let expect =
            v["vic"]["p99_us"].as_f64().unwrap() / v["baseline"]["p99_us"].as_f64().unwrap();
        assert!((r - expect).abs() < 1e-9 * expect.max(1.0));
    }
}

#[test]
fn a_short_ipc_bench_reports_the_documented_keys_and_cleans_up() {
    let before = shm_files();
    let out = Command::new(env!("CARGO_BIN_EXE_vic"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args([
            "bench",
            "ipc",
            "--iterations",
            "2000",
            "--pair-trials",
            "0",
            "--json",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_dist(&v["vic"], "vic");
    assert_dist(&v["baseline"], "baseline");
    assert_eq!(v["vic"]["count"].as_u64(), Some(2000));
    let r = v["ratio_p50"].as_f64().unwrap();
    let expect = v["vic"]["p50_us"].as_f64().unwrap() / v["baseline"]["p50_us"].as_f64().unwrap();
    assert!((r - expect).abs() < 1e-9 * expect.max(1.0));
    assert!(v["pair"].is_null());
    for ch in ["state_one_way", "command_one_way", "round_trip"] {
        assert_dist(&v["vic_channels"][ch], ch);
        assert_dist(&v["baseline_channels"][ch], ch);
    }
    let pid_files: Vec<_> = shm_files()
        .into_iter()
        // The ipc bench's namespaces (bi: vic, bb: bare, bp: pair); the loop bench's (bl) may
        // be running in parallel.
        .filter(|f| {
            !before.contains(f)
                && ["vic_bi", "vic_bb", "vic_bp"]
                    .iter()
                    .any(|p| f.starts_with(p))
        })
        .collect();
    assert!(pid_files.is_empty(), "left in /dev/shm: {pid_files:?}");
}

#[test]
fn bad_flags_exit_2_with_a_message() {
    for args in [
        &["bench", "loop", "--variant", "warp-speed"][..],
        &["bench", "loop", "--seconds", "0"],
        &["bench", "ipc", "--iterations", "many"],
        &["bench", "ipc", "--plan", "/nonexistent/plan.json"],
        &["bench", "loop", "--config", "/nonexistent.toml"],
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_vic"))
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .args(args)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(!out.stderr.is_empty(), "{args:?}: no message");
    }
}

fn shm_files() -> Vec<String> {
    std::fs::read_dir("/dev/shm")
        .map(|d| {
            d.flatten()
                .map(|e| e.file_name().to_string_lossy().to_string())
                .collect()
        })
        .unwrap_or_default()
}

/// `vic bench sooc --json` on the single joint and the two-link arm: each point's dimensions are
/// the plant's (2 and 4 states, moment dimension `n + n(n+1)/2`), the slopes are the least-squares
/// slopes of the points' own times (recomputed here), and the cold solve is `vic plan --method
/// sooc`'s (same iteration count and verdict); a missing scenario is the user's error (exit 2).
#[test]
fn the_sooc_scaling_bench_reports_the_plants_dimensions_slopes_and_plan() {
    let vic = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_vic"))
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .args(args)
            .output()
            .unwrap()
    };
    let out = vic(&[
        "bench",
        "sooc",
        "--config",
        "config/icub_elbow.toml,config/two_link_divergent.toml",
        "--passes",
        "3",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let points = v["points"].as_array().unwrap();
    let dims: Vec<(u64, u64)> = points
        .iter()
        .map(|p| (p["n"].as_u64().unwrap(), p["moment_dim"].as_u64().unwrap()))
        .collect();
    assert_eq!(dims, [(2, 5), (4, 14)], "{v}");
    for key in ["nominal", "first", "newton"] {
        let y: Vec<f64> = points
            .iter()
            .map(|p| p[format!("{key}_us")].as_f64().unwrap())
            .collect();
        assert!(y.iter().all(|&t| t > 0.0), "{key}: {y:?}");
        // Two points: the slope is the ratio of the logs.
        let expect = (y[1] / y[0]).ln() / (14.0f64 / 5.0).ln();
        let got = v["slopes"][key].as_f64().unwrap();
        assert!((got - expect).abs() < 1e-9, "{key}: {got} vs {expect}");
    }
    let solve = &points[0]["solve"];
    let plan = vic(&[
        "plan",
        "--config",
        "config/icub_elbow.toml",
        "--method",
        "sooc",
        "--json",
    ]);
    assert!(plan.status.success());
    let p: serde_json::Value = serde_json::from_slice(&plan.stdout).unwrap();
    assert_eq!(solve["iterations"], p["iterations"], "{solve} vs {p}");
    assert_eq!(solve["converged"], p["converged"], "{solve} vs {p}");
    let per = solve["ms"].as_f64().unwrap() / solve["iterations"].as_f64().unwrap();
    assert!((solve["ms_per_iteration"].as_f64().unwrap() - per).abs() < 1e-9 * per);

    let out = vic(&["bench", "sooc", "--config", "config/no_such.toml"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no_such.toml"));
}
