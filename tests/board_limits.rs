//! Upper and lower bounds on every `[board]` limit (issue 14, finding 5: `--hold-stiffness 1e308`
//! and `0` were accepted). Every bounded key refuses values outside its range with the file, the
//! key, the value and the allowed range; the safe-hold stiffness is also checked against the
//! actuator's damping law and the board's integration step; the shipped scenarios pass; the
//! board binary refuses a bad flag or key with exit 2 before it touches shared memory.

use std::path::{Path, PathBuf};
use std::process::Command;
use vic_plan::scenario::{BOARD_RANGES, ConfigError, JOINT_LIMIT_RAD, Scenario};

fn config(stem: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config")
        .join(format!("{stem}.toml"))
}

fn load(stem: &str, set: &[String]) -> Result<Scenario, ConfigError> {
    Scenario::load(&config(stem), set)
}

/// Asserts that `[board] key = value` is refused naming the file, the key and `needles`.
fn refused(stem: &str, key: &str, value: &str, needles: &[&str]) {
    let set = vec![format!("board.{key}={value}")];
    match load(stem, &set) {
        Err(e @ ConfigError::Invalid { .. }) => {
            let ConfigError::Invalid {
                path,
                section,
                key: k,
                ..
            } = &e
            else {
                unreachable!()
            };
            assert_eq!(path, &config(stem), "{e}");
            assert_eq!((section.as_str(), k.as_str()), ("board", key), "{e}");
            for n in needles {
                assert!(e.to_string().contains(n), "{key}={value}: {e} lacks {n:?}");
            }
        }
        Err(e) => panic!("{key}={value}: wrong error {e}"),
        Ok(_) => panic!("{key}={value} was accepted"),
    }
}

/// Values a careless or hostile file might hold, written down independently of the ranges:
/// each is absurd for a human-scale arm.
const ABSURD: [(&str, &str); 16] = [
    ("watchdog", "3600"),
    ("watchdog", "0"),
    ("ramp", "3600"),
    ("hold_stiffness", "1e308"),
    ("hold_stiffness", "0"),
    ("hold_stiffness", "-100"),
    ("velocity_max", "1e6"),
    ("velocity_max", "0"),
    ("future_tolerance", "60"),
    ("max_pulse_torque", "1e4"),
    ("max_load_torque", "-1"),
    ("max_pulse_duration", "3600"),
    ("max_field_beta", "1e9"),
    ("max_noise_factor", "1e6"),
    ("max_noise_factor", "nan"),
    ("max_field_beta", "inf"),
];

#[test]
fn every_bounded_key_refuses_values_outside_its_range() {
    // The list above names every bounded key, and only those.
    let mut listed: Vec<&str> = ABSURD.iter().map(|(k, _)| *k).collect();
    listed.sort_unstable();
    listed.dedup();
    let mut keys: Vec<&str> = BOARD_RANGES.iter().map(|r| r.key).collect();
    keys.sort_unstable();
    assert_eq!(listed, keys);
    for (key, value) in ABSURD {
        let r = BOARD_RANGES.iter().find(|r| r.key == key).unwrap();
        refused("two_link_divergent", key, value, &[&r.describe(), "got "]);
    }
    // Just outside each end of each range, and non-finite values: refused with the range.
    for r in BOARD_RANGES {
        let range = r.describe();
        let below = if r.min_inclusive {
            r.min - 1e-3 * (r.max - r.min)
        } else {
            r.min
        };
        let above = r.max + 1e-3 * (r.max - r.min);
        for v in [below, above, -1e308, 1e308] {
            refused("two_link_divergent", r.key, &format!("{v:e}"), &[&range]);
        }
        for v in ["nan", "inf", "-inf"] {
            refused("two_link_divergent", r.key, v, &[&range]);
        }
        // The ends themselves are allowed (the hold stiffness's upper end is refused by the
        // stability check instead, below).
        let mut ends = vec![r.max];
        if r.min_inclusive {
            ends.push(r.min);
        }
        for v in ends.into_iter().filter(|_| r.key != "hold_stiffness") {
            let set = vec![format!("board.{}={v:e}", r.key)];
            load("two_link_divergent", &set).unwrap_or_else(|e| panic!("{}={v}: {e}", r.key));
        }
    }
}

#[test]
fn joint_limits_are_within_one_turn() {
    let out = format!("[{:e}, 0.0]", JOINT_LIMIT_RAD * 1.01);
    refused("two_link_divergent", "joint_max", &out, &["angle(s) in"]);
    refused(
        "two_link_divergent",
        "joint_min",
        "[-1e9, -1.0]",
        &["angle(s) in"],
    );
    refused(
        "two_link_divergent",
        "joint_min",
        "[nan, -1.0]",
        &["angle(s) in"],
    );
    let ok = vec!["board.joint_min=[-6.2, -6.2]".to_string()];
    load("two_link_divergent", &ok).unwrap();
}

#[test]
fn the_hold_stiffness_must_be_stable_under_the_damping_law() {
    // Two-link arm (K_D = 0.1 K): at 1000 N m/rad the damping rate K_D / I is far above 2 / h
    // for h = 1 ms at its smallest inertia (well below 0.05 kg m²).
    refused(
        "two_link_divergent",
        "hold_stiffness",
        "1000",
        &["unstable", "1000"],
    );
    // The identified iCub damping law K_D = 0.075 K − 0.0015 is negative below K = 0.02.
    refused(
        "icub_experiment",
        "hold_stiffness",
        "0.01",
        &["negative damping"],
    );
    load("icub_experiment", &["board.hold_stiffness=5".into()]).unwrap();
    // Independent check of the boundary on the two-link arm: the stable limit from the closed
    // form h · α k / I < 2 with I the smallest eigenvalue of M(q) over the task's postures lies
    // between the accepted and the refused value.
    let s = load("two_link_divergent", &[]).unwrap();
    assert_eq!(s.board.hold_stiffness, 100.0);
    let accepted = (10..=1000)
        .step_by(10)
        .filter(|k| load("two_link_divergent", &[format!("board.hold_stiffness={k}")]).is_ok())
        .max()
        .unwrap();
    // The smallest eigenvalue of M(q) over every elbow angle bounds the task's from both sides.
    let eig = |q1: f64| {
        let m = s.model.plant.mass_matrix(&[0.0, q1]);
        let (tr, det) = (m[0][0] + m[1][1], m[0][0] * m[1][1] - m[0][1] * m[1][0]);
        0.5 * (tr - (tr * tr - 4.0 * det).max(0.0).sqrt())
    };
    let grid: Vec<f64> = (0..=360)
        .map(|i| eig(-3.1 + 6.2 * f64::from(i) / 360.0))
        .collect();
    let (lo, hi) = grid
        .iter()
        .fold((f64::INFINITY, 0.0_f64), |(a, b), &v| (a.min(v), b.max(v)));
    // h α k / I < 2 with α = 0.1 and h = 1 ms; the spring term √(k/I) h < 2 binds far higher.
    let (k_lo, k_hi) = (2.0 * lo / (0.1 * 1e-3), 2.0 * hi / (0.1 * 1e-3));
    let k = f64::from(accepted);
    assert!(
        k >= 100.0 && k > k_lo - 10.0 && k < k_hi,
        "largest accepted hold stiffness {k}, closed form between {k_lo:.0} and {k_hi:.0}"
    );
}

/// The lower bound, from the closed form: the plant's own negative stiffness (gravity, the
/// divergent field) plus the largest accepted load within half the joint range.
#[test]
fn the_hold_stiffness_must_hold_the_arm_against_its_plant_and_the_largest_load() {
    use std::f64::consts::PI;
    // Two-link arm in the horizontal plane, field β = 50 N/m: β ((l1 + l2)² + l2²) with l1 = 0.3,
    // l2 = 0.33 m; the default largest load 10 N m within half the default range ±π.
    let arm = 50.0 * (0.63_f64.powi(2) + 0.33_f64.powi(2)) + 10.0 / PI;
    // The iCub forearm in the vertical plane, no field: m g l_c = 0.812 · 9.81 · 0.103.
    let forearm = 0.812 * 9.81 * 0.103 + 10.0 / PI;
    for (stem, k_min) in [("two_link_divergent", arm), ("icub_experiment", forearm)] {
        let below = format!("{:e}", k_min * 0.99);
        refused(stem, "hold_stiffness", &below, &["below", "raise it"]);
        let above = vec![format!("board.hold_stiffness={:e}", k_min * 1.01)];
        load(stem, &above).unwrap_or_else(|e| panic!("{stem}: {e}"));
    }
    // A larger accepted load raises the bound: 200 N m within ±π needs 200 / π more.
    let set = |k: f64| {
        vec![
            "board.max_load_torque=200".to_string(),
            format!("board.hold_stiffness={k:e}"),
        ]
    };
    let k_min = arm - 10.0 / PI + 200.0 / PI;
    assert!(load("two_link_divergent", &set(k_min * 0.99)).is_err());
    load("two_link_divergent", &set(k_min * 1.01)).unwrap();
}

#[test]
fn every_shipped_scenario_passes_its_board_checks() {
    let mut n = 0;
    for e in std::fs::read_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("config")).unwrap() {
        let path = e.unwrap().path();
        if path.extension().is_some_and(|x| x == "toml") {
            let s = Scenario::load(&path, &[]).unwrap_or_else(|e| panic!("{e}"));
            let b = &s.board;
            let values = [
                b.watchdog,
                b.ramp,
                b.hold_stiffness,
                b.velocity_max,
                b.future_tolerance,
                b.max_pulse_torque,
                b.max_load_torque,
                b.max_pulse_duration,
                b.max_field_beta,
                b.max_noise_factor,
            ];
            for (r, v) in BOARD_RANGES.iter().zip(values) {
                assert!(r.contains(v), "{}: {} = {v}", path.display(), r.key);
            }
            n += 1;
        }
    }
    assert!(n >= 10, "only {n} scenarios");
}

#[test]
fn the_board_refuses_a_bad_flag_or_key_with_exit_2() {
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_vic-board"))
            .arg("--config")
            .arg(config("two_link_divergent"))
            .args(["--namespace", "boardlimits", "--duration-s", "0.1"])
            .args(args)
            .output()
            .unwrap()
    };
    for (args, needles) in [
        (
            &["--hold-stiffness", "1e308"][..],
            &["--hold-stiffness", "0.001 to 1000"][..],
        ),
        (
            &["--hold-stiffness", "0"],
            &["--hold-stiffness", "0.001 to 1000"],
        ),
        // Within the flag's range, below what the scenario's arm needs (issue 66: 1e-9 was
        // accepted and a 2 N m push ran the arm into a fault).
        (
            &["--hold-stiffness", "1"],
            &["--hold-stiffness", "[board] hold_stiffness", "below"],
        ),
        (
            &["--set", "board.watchdog=3600"],
            &[
                "two_link_divergent.toml",
                "[board] watchdog",
                "[0.001, 1] s",
                "3600",
            ],
        ),
    ] {
        let o = run(args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        for n in needles {
            assert!(err.contains(n), "{args:?}: {err} lacks {n:?}");
        }
    }
}

/// The ends of the flags' ranges run (issue 66, item 8: values that passed the old checks
/// panicked later): the board at its fastest rate and longest spin, recording through the largest
/// queue; the recorder with the longest duration and the shortest wait, the operator tools with
/// the shortest timeout and the largest noise factor. Each ends by itself: the board with 0, the
/// tools with 1 (no board any more), never 101 or a signal.
#[test]
fn the_ends_of_the_flags_ranges_run() {
    let ns = crate::common::daemons::unique_namespace("flagends");
    let dir = std::env::temp_dir().join(&ns);
    std::fs::create_dir_all(&dir).unwrap();
    let board = Command::new(env!("CARGO_BIN_EXE_vic-board"))
        .arg("--config")
        .arg(config("two_link_divergent"))
        .args([
            "--namespace",
            &ns,
            "--duration-s",
            "0.3",
            "--no-rt",
            "--json",
        ])
        .args([
            "--rate-hz",
            "10000",
            "--spin-us",
            "10000",
            "--record-queue",
            "131072",
        ])
        .arg("--record")
        .arg(dir.join("run.csv"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&board.stderr);
    assert_eq!(board.status.code(), Some(0), "{stderr}");
    let stats: serde_json::Value = serde_json::from_slice(&board.stdout).unwrap();
    assert!(stats["ticks"].as_u64().unwrap() > 100, "{stats}");
    let out = dir.join("out.mcap");
    let out = out.to_str().unwrap();
    for args in [
        &[
            "record",
            "--out",
            out,
            "--duration",
            "604800",
            "--wait",
            "0.001",
        ][..],
        &["status", "--timeout-s", "0.001"],
        &["inject", "noise", "--factor", "100", "--timeout-s", "0.001"],
    ] {
        let o = Command::new(env!("CARGO_BIN_EXE_vic"))
            .args(args)
            .args(["--namespace", &ns])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {stderr}");
    }
    vic_rt::transport::remove_namespace(&ns);
    std::fs::remove_dir_all(&dir).unwrap();
}
