use super::*;
use std::path::Path;
use vic_core::model::Noise;

/// A valid elbow scenario with every optional `[task]`, `[solver]` and `[board]` key at its
/// default but the hold stiffness (shared with the documentation's test).
pub(super) const ELBOW: &str = r#"
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

/// The sub-step check for each integrator: at a stiff impedance (K_D = 0.2 · 200 N m s/rad on
/// the forearm's inertia) the number of sub-steps the refusal asks for is accepted and one fewer is refused, and RK4's larger stability interval
/// (2.78 against 2 for both Euler steps) asks for fewer; the Rosenbrock step needs one.
#[test]
fn sub_steps_are_refused_below_each_integrators_stability_limit() {
    let needed = |integrator: &str| -> usize {
        let e = load(&[
            "actuator.stiffness_max=200",
            &format!("task.integrator={integrator}"),
            "task.substeps=1",
        ])
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("[task] substeps") && e.contains(integrator),
            "{e}"
        );
        let n: usize = e
            .split("use substeps ≥ ")
            .nth(1)
            .and_then(|r| r.split_whitespace().next())
            .and_then(|n| n.parse().ok())
            .unwrap_or_else(|| panic!("no count in {e}"));
        let at = |substeps: usize| {
            load(&[
                "actuator.stiffness_max=200",
                &format!("task.integrator={integrator}"),
                &format!("task.substeps={substeps}"),
            ])
        };
        assert!(at(n).is_ok(), "{integrator}: {n} sub-steps refused");
        assert!(
            at(n - 1).is_err(),
            "{integrator}: {} sub-steps accepted",
            n - 1
        );
        n
    };
    let (euler, semi, rk4) = (needed("euler"), needed("semi_implicit"), needed("rk4"));
    assert_eq!(euler, semi);
    // The counts scale as 1 / limit: 2 / 2.78 of the Euler count, to within one.
    let expect = euler as f64 * 2.0 / 2.78;
    assert!((rk4 as f64 - expect).abs() <= 1.0, "{rk4} vs {expect:.1}");
    // The Rosenbrock step takes the spring and damper implicitly: one step per knot is accepted
    // at the stiffness that asks the Euler steps for several.
    assert!(euler > 1, "{euler}");
    let one_step = load(&[
        "actuator.stiffness_max=200",
        "task.integrator=rosenbrock",
        "task.substeps=1",
    ]);
    assert!(one_step.is_ok(), "{:?}", one_step.err());
}

/// The Rosenbrock step takes the stiffness as the control it is with ideal stiffness; a lagged
/// stiffness is a state, so that combination is refused, naming the key.
#[test]
fn the_rosenbrock_step_is_refused_for_a_lagged_stiffness() {
    let lagged = [
        "actuator.stiffness_dynamics=first_order",
        "actuator.stiffness_time_constant=0.1",
    ];
    assert!(load(&lagged).is_ok(), "{:?}", load(&lagged).err());
    let e = load(&[lagged[0], lagged[1], "task.integrator=rosenbrock"])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("[task] integrator") && e.contains("state"),
        "{e}"
    );
}
