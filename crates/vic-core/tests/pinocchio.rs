//! Every URDF chain of `config/` against Pinocchio (the pip package `pin` 4.0.0, through the
//! peer script `tests/peers/pinocchio_dynamics.py`): mass matrix, bias torques, forward dynamics
//! and the tip's position on random states, to 1e-10 (relative to the value, or absolute below
//! 1). Pinocchio's chain is its reduced model with every other joint locked at 0, and gravity is
//! turned from the base link's frame into its world frame.
//!
//! Runs with the Python in `VIC_PYTHON` (`.ci/run` makes a venv with `pin==4.0.0`); without it
//! the test says why it skips (outside CI only).

use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use serde_json::{Value, json};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use vic_core::model::serial::{DEFAULT_GRAVITY, SerialChain};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The chains compared: every URDF file of `config/` at least once, in default gravity and in
/// gravity along another axis of the base (the planar arm then moves in a vertical plane).
const CHAINS: [(&str, &str, &str, [f64; 3]); 8] = [
    ("single_joint.urdf", "upper_arm", "hand", DEFAULT_GRAVITY),
    ("two_link.urdf", "torso", "hand", DEFAULT_GRAVITY),
    ("two_link.urdf", "torso", "hand", [0.0, -9.81, 0.0]),
    (
        "three_link_planar.urdf",
        "torso",
        "fingertips",
        [3.0, -9.0, 1.0],
    ),
    ("panda.urdf", "panda_link0", "panda_hand", DEFAULT_GRAVITY),
    ("panda.urdf", "panda_link2", "panda_link6", [1.0, 2.0, -9.0]),
    ("icub.urdf", "chest", "r_hand", [0.0, -9.81, 0.0]),
    ("icub.urdf", "root_link", "l_elbow_1", DEFAULT_GRAVITY),
];

fn python() -> Option<String> {
    match std::env::var("VIC_PYTHON") {
        Ok(p) => Some(p),
        Err(_) => {
            assert!(
                std::env::var_os("CI").is_none(),
                "CI must set VIC_PYTHON (a Python with pin==4.0.0 and numpy)"
            );
            eprintln!(
                "VIC_PYTHON not set: the Pinocchio comparison is skipped (make a venv with \
                 `pip install pin==4.0.0 numpy` and point VIC_PYTHON at its python)"
            );
            None
        }
    }
}

fn numbers(v: &Value) -> Vec<f64> {
    match v {
        Value::Array(a) => a.iter().flat_map(numbers).collect(),
        v => vec![v.as_f64().expect("a number")],
    }
}

#[test]
fn every_config_urdf_is_compared() {
    let mut found: Vec<String> = std::fs::read_dir(root().join("config"))
        .expect("config directory")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".urdf"))
        .collect();
    found.sort();
    let mut listed: Vec<String> = CHAINS.iter().map(|c| c.0.to_string()).collect();
    listed.sort();
    listed.dedup();
    assert_eq!(found, listed);
}

#[test]
fn the_dynamics_agree_with_pinocchio() {
    let Some(python) = python() else { return };
    let mut rng = StdRng::seed_from_u64(4);
    let mut cases = Vec::new();
    let mut chains = Vec::new();
    for (file, base, tip, gravity) in CHAINS {
        let path = root().join("config").join(file);
        let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{file}: {e}"));
        let chain = SerialChain::from_urdf(&text, file, base, tip)
            .unwrap_or_else(|e| panic!("{e}"))
            .with_gravity(gravity);
        let n = chain.dof();
        let mut draw =
            |scale: f64| -> Vec<f64> { (0..n).map(|_| rng.random_range(-scale..scale)).collect() };
        let states: Vec<Value> = (0..20)
            .map(|_| json!({"q": draw(2.5), "v": draw(3.0), "tau": draw(10.0)}))
            .collect();
        cases.push(json!({
            "file": path.to_str().unwrap(), "base": base, "tip": tip,
            "gravity": gravity, "states": states,
        }));
        chains.push(chain);
    }
    let script = root().join("tests/peers/pinocchio_dynamics.py");
    let mut child = Command::new(&python)
        .arg(&script)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("python starts");
    let input = serde_json::to_vec(&cases).unwrap();
    child.stdin.take().unwrap().write_all(&input).unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let peers: Vec<Value> = serde_json::from_slice(&out.stdout).expect("JSON from the script");
    assert_eq!(peers.len(), chains.len());
    let mut worst = 0.0_f64;
    for ((chain, case), peer) in chains.iter().zip(&cases).zip(&peers) {
        let n = chain.dof();
        let names: Vec<&str> = peer["joints"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_str().unwrap())
            .collect();
        assert_eq!(chain.joint_names().collect::<Vec<_>>(), names);
        let damping = numbers(&peer["damping"]);
        for (i, d) in damping.iter().enumerate() {
            assert_eq!(chain.limits(i).damping, *d);
        }
        let mut max_err = [0.0_f64; 4];
        for (state, res) in case["states"]
            .as_array()
            .unwrap()
            .iter()
            .zip(peer["results"].as_array().unwrap())
        {
            let (q, v, tau) = (
                numbers(&state["q"]),
                numbers(&state["v"]),
                numbers(&state["tau"]),
            );
            let m = chain.mass_matrix(&q);
            let ours = [
                m[..n]
                    .iter()
                    .flat_map(|r| r[..n].to_vec())
                    .collect::<Vec<_>>(),
                chain.bias(&q, &v)[..n].to_vec(),
                chain.forward_dynamics(&q, &v, &tau)[..n].to_vec(),
                chain.tip_position(&q).to_vec(),
            ];
            for (k, key) in ["M", "bias", "aba", "tip"].into_iter().enumerate() {
                let theirs = numbers(&res[key]);
                assert_eq!(theirs.len(), ours[k].len(), "{key}");
                for (a, b) in ours[k].iter().zip(&theirs) {
                    let err = (a - b).abs() / b.abs().max(1.0);
                    max_err[k] = max_err[k].max(err);
                }
            }
        }
        eprintln!(
            "{} {}→{}: max error M {:.1e}, bias {:.1e}, q'' {:.1e}, tip {:.1e}",
            case["file"].as_str().unwrap().rsplit('/').next().unwrap(),
            case["base"].as_str().unwrap(),
            case["tip"].as_str().unwrap(),
            max_err[0],
            max_err[1],
            max_err[2],
            max_err[3]
        );
        worst = max_err.iter().fold(worst, |a, b| a.max(*b));
    }
    assert!(worst < 1e-10, "the largest difference is {worst:e}");
}
