use super::*;
use std::path::Path;
use vic_core::model::Noise;

const ELBOW: &str = r#"
[plant]
kind = "single_joint"
inertia = 5.08e-3
mass = 0.812
com = 0.103
length = 0.273
gravity = 9.81
[actuator]
type = "impedance"
alpha = 0.2
[field]
kind = "none"
[noise]
kind = "state"
sigma = 0.03
[cost]
w_torque = 1.0
w_stiffness = 1e-4
w_p = 1e6
w_v = 1e5
[task]
kind = "joint"
start_deg = [-60.0]
target_deg = [-30.0]
duration = 1.5
dt = 0.01
[board]
hold_stiffness = 40.0
"#;

fn load(extra: &[&str]) -> Result<Scenario, ConfigError> {
    let o: Vec<String> = extra.iter().map(|s| s.to_string()).collect();
    Scenario::from_str(ELBOW, Path::new("elbow.toml"), &o)
}

#[test]
fn parses_a_valid_scenario() {
    let s = load(&[]).unwrap();
    assert_eq!(s.task.steps, 150);
    assert_eq!(s.model.nu(), 2);
    assert_eq!(s.bounds.lower[1], 0.0);
}

#[test]
fn overrides_change_values_and_errors_name_the_key() {
    let s = load(&["noise.sigma=0.1", "task.delay_ms=200"]).unwrap();
    assert_eq!(
        s.model.noise,
        Noise::StateProportional {
            sigma: 0.1,
            component: 1
        }
    );
    assert_eq!(s.task.delay_steps(), 20);
    let e = load(&["cost.w_p=abc"]).unwrap_err().to_string();
    assert!(e.contains("elbow.toml") && e.contains("[cost] w_p"), "{e}");
    // A key an override wrote is blamed on the override, not on the file.
    assert!(e.contains("(--set cost.w_p=abc)"), "{e}");
    assert!(!e.contains('\n') && !e.contains("in `"), "{e}");
    let e = load(&["cost.bogus=1"]).unwrap_err().to_string();
    assert!(
        e.contains("bogus") && e.contains("(--set cost.bogus=1)"),
        "{e}"
    );
    let e = load(&["noise.sigma=0.1", "cost.w_p=abc"])
        .unwrap_err()
        .to_string();
    assert!(!e.contains("noise.sigma"), "{e}");
    // A fault in the file itself names no override.
    let bad = Scenario::from_str(
        "[plant]\nkind = \"bogus\"\n",
        Path::new("bad.toml"),
        &["cost.w_p=1".to_string()],
    )
    .unwrap_err()
    .to_string();
    assert!(!bad.contains("--set"), "{bad}");
    let e = load(&["actuator.type=spring"]).unwrap_err().to_string();
    assert!(e.contains("[actuator] type") && e.contains("spring"), "{e}");
    let e = load(&["task.dt=0.007"]).unwrap_err().to_string();
    assert!(e.contains("[task] dt"), "{e}");
    let e = load(&["novalue"]).unwrap_err().to_string();
    assert!(e.contains("section.key=value"), "{e}");
    let e = load(&["task.delay_ms=15"]).unwrap_err().to_string();
    assert!(e.contains("delay_ms"), "{e}");
}

#[test]
fn syntax_errors_name_the_file() {
    let e = Scenario::from_str("[plant\n", Path::new("bad.toml"), &[]).unwrap_err();
    assert!(matches!(e, ConfigError::Syntax { .. }));
    assert!(e.to_string().starts_with("bad.toml"));
    let e = Scenario::from_str("", Path::new("empty.toml"), &[])
        .unwrap_err()
        .to_string();
    assert!(e.contains("missing section [plant]"), "{e}");
}

#[test]
fn setting_a_sections_kind_starts_it_afresh() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/icub_elbow.toml");
    let s = Scenario::load(&path, &["noise.kind=none".to_string()]).expect("noise switched off");
    assert_eq!(s.model.nw(), 0);
    // The same kind keeps the file's keys.
    let same = Scenario::load(&path, &["noise.kind=state".to_string()]).expect("same kind");
    assert!(same.model.nw() > 0);
}
