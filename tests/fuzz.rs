//! Property tests on bad input (issue 6): arbitrary messages through the board's state machine,
//! arbitrary scenario text and `--set` overrides through the configuration loader. Bounded case
//! counts keep them in `cargo test` (a few seconds in release).

use proptest::prelude::*;
use proptest::test_runner::Config as ProptestConfig;
use std::path::{Path, PathBuf};
use vic_plan::scenario::Scenario;
use vic_rt::board::{Board, BoardConfig, Inputs, Outputs};
use vic_rt::transport::{
    CommandSlice, Control, ControlKind, Disturbance, Header, Knot, MAX_JOINTS, MAX_KNOTS,
    PROTOCOL_VERSION,
};

const CONFIG: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/config/two_link_divergent.toml"
);
const MS: u64 = 1_000_000;

/// The board as `vic-board` builds it from the scenario (stiffness and torque bounds included).
fn board() -> (Board, [f64; 2], BoardConfig) {
    let scenario = Scenario::load(Path::new(CONFIG), &[]).unwrap();
    let setup = vic_plan::plan::setup(&scenario).unwrap();
    let cfg = vic::daemons::launch::board_config(&scenario, MS);
    let q0 = [setup.x0[0], setup.x0[1]];
    let b = Board::new(scenario.model.clone(), cfg.clone(), &q0).unwrap();
    (b, q0, cfg)
}

fn reset(q0: [f64; 2]) -> Control {
    Control {
        header: Header::new(1, 0),
        kind: ControlKind::Reset as u32,
        trial: 1,
        seed: 5,
        start_ns: 0,
        q0,
        ..Default::default()
    }
}

/// A valid slice holding `q0` with stiffness `k` over 200 ms of trial time from `start`.
fn slice(q0: [f64; 2], seq: u64, start: u64, k: f64) -> CommandSlice {
    let mut c = CommandSlice {
        header: Header::new(seq, 0),
        joints: 2,
        trial: 1,
        start_ns: start,
        knot_dt_ns: 10 * MS,
        count: 20,
        ..Default::default()
    };
    for knot in &mut c.knots[..20] {
        knot.q_d = q0;
        knot.tau_ff = [0.1, -0.1];
        knot.stiffness = [k, k];
    }
    c
}

/// Any f64, with the troublesome values over-represented.
fn float() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(f64::MAX),
        Just(-f64::MAX),
        Just(1e300),
        Just(-1e300),
        any::<f64>(),
        physical(),
    ]
}

/// Non-finite values, zeros and magnitudes up to 1000: everything but huge finite numbers.
fn physical() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        Just(0.0),
        Just(-0.0),
        Just(f64::MIN_POSITIVE),
        -1e3..1e3f64,
        -10.0..10.0f64,
    ]
}

/// `float()` when `huge`, else `physical()`.
fn value(huge: bool) -> BoxedStrategy<f64> {
    if huge {
        float().boxed()
    } else {
        physical().boxed()
    }
}

fn pair_of(huge: bool) -> impl Strategy<Value = [f64; 2]> {
    [value(huge), value(huge)]
}

fn u32_near(good: u32) -> impl Strategy<Value = u32> {
    prop_oneof![Just(good), 0..4u32, any::<u32>()]
}

fn u64_near(good: u64) -> impl Strategy<Value = u64> {
    prop_oneof![Just(good), 0..1000u64, 0..2_000_000_000u64, any::<u64>()]
}

/// A knot: torque and stiffness fully arbitrary (the board bounds them); the equilibrium has
/// huge finite values only when `huge`.
fn knot(huge: bool) -> impl Strategy<Value = Knot> {
    let torque = || prop_oneof![2 => -20.0..20.0f64, 1 => float()];
    let stiffness = || prop_oneof![2 => -10.0..250.0f64, 1 => float()];
    let angle = move || prop_oneof![2 => -3.0..3.0f64, 1 => value(huge)];
    (
        [torque(), torque()],
        [stiffness(), stiffness()],
        [angle(), angle()],
        [angle(), angle()],
    )
        .prop_map(|(tau_ff, stiffness, q_d, qd_d)| Knot {
            tau_ff,
            stiffness,
            q_d,
            qd_d,
        })
}

/// Arbitrary command slices: every field arbitrary, each often at its valid value so that the
/// later checks are reached.
fn command(huge: bool) -> impl Strategy<Value = CommandSlice> {
    (
        (
            u32_near(PROTOCOL_VERSION),
            u32_near(2),
            u64_near(2),
            u32_near(1),
            u32_near(0),
            u64_near(0),
            u64_near(10 * MS),
            u32_near(20),
        ),
        knot(huge),
        prop::collection::vec((0..MAX_KNOTS, knot(huge)), 0..4),
    )
        .prop_map(
            |((version, joints, seq, trial, interpolation, start, dt, count), k, odd)| {
                let mut c = CommandSlice {
                    header: Header {
                        version,
                        ..Header::new(seq, 0)
                    },
                    joints,
                    trial,
                    interpolation,
                    start_ns: start,
                    knot_dt_ns: dt,
                    count,
                    knots: [k; MAX_KNOTS],
                };
                for (i, k) in odd {
                    c.knots[i] = k;
                }
                c
            },
        )
}

fn control(huge: bool) -> impl Strategy<Value = Control> {
    (
        u32_near(PROTOCOL_VERSION),
        u32_near(ControlKind::Reset as u32),
        u32_near(1),
        any::<u64>(),
        u64_near(0),
        pair_of(huge),
        pair_of(huge),
    )
        .prop_map(|(version, kind, trial, seed, start_ns, q0, qd0)| Control {
            header: Header {
                version,
                ..Header::new(2, 0)
            },
            kind,
            trial,
            seed,
            start_ns,
            q0,
            qd0,
        })
}

fn disturbance(huge: bool) -> impl Strategy<Value = Disturbance> {
    (
        u32_near(PROTOCOL_VERSION),
        prop_oneof![0..4u32, any::<u32>()],
        any::<u64>(),
        pair_of(huge),
        u64_near(5 * MS),
        value(huge),
    )
        .prop_map(
            |(version, kind, seq, torque, duration_ns, value)| Disturbance {
                header: Header {
                    version,
                    ..Header::new(seq, 0)
                },
                kind,
                _pad: 0,
                torque,
                duration_ns,
                value,
            },
        )
}

#[derive(Debug, Clone)]
enum Message {
    Command(Box<CommandSlice>),
    Control(Control),
    Disturbance(Disturbance),
}

/// Arbitrary messages; with `huge`, equilibria, reset states, disturbance torques, field β and
/// noise factors include huge finite values too.
fn message(huge: bool) -> impl Strategy<Value = Message> {
    prop_oneof![
        3 => command(huge).prop_map(|c| Message::Command(Box::new(c))),
        1 => control(huge).prop_map(Message::Control),
        1 => disturbance(huge).prop_map(Message::Disturbance),
    ]
}

/// What must hold after every step, whatever came in: what the board applied is finite and within
/// its bounds, and the plant state is finite.
fn check_applied(board: &Board, out: &Outputs, cfg: &BoardConfig) -> Result<(), TestCaseError> {
    let s = &out.state;
    for j in 0..MAX_JOINTS {
        prop_assert!(
            s.stiffness[j].is_finite() && (0.0..=cfg.stiffness_max).contains(&s.stiffness[j]),
            "stiffness applied {:?}",
            s.stiffness
        );
        prop_assert!(s.tau[j].is_finite(), "torque applied {:?}", s.tau);
        prop_assert!(
            out.knot.tau_ff[j].abs() <= cfg.torque_max,
            "feedforward {:?}",
            out.knot.tau_ff
        );
        prop_assert!(
            s.q[j].is_finite() && s.qd[j].is_finite(),
            "state {:?} {:?}",
            s.q,
            s.qd
        );
    }
    prop_assert!(board.state().iter().all(|v| v.is_finite()));
    Ok(())
}

/// Reset, a valid slice, then the messages, each followed by its ticks (the first `late`).
fn run_messages(messages: Vec<(Message, u64, u64)>) -> Result<(), TestCaseError> {
    let (mut b, q0, cfg) = board();
    let mut inputs = Inputs::default();
    inputs.push_control(&reset(q0));
    inputs.push_command(&slice(q0, 1, 0, 80.0));
    let mut now = 0;
    let out = b.step(now, &mut inputs);
    check_applied(&b, &out, &cfg)?;
    for (m, ticks, late) in messages {
        match m {
            Message::Command(c) => inputs.push_command(&c),
            Message::Control(c) => inputs.push_control(&c),
            Message::Disturbance(d) => inputs.push_disturbance(&d),
        }
        for t in 0..ticks {
            now += if t == 0 { late * MS } else { MS };
            let out = b.step(now, &mut inputs);
            check_applied(&b, &out, &cfg)?;
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, failure_persistence: None, rng_seed: proptest::test_runner::RngSeed::Fixed(20261122), ..ProptestConfig::default() })]

    /// Up to eight arbitrary messages, each followed by one to three ticks (some late): the board
    /// never panics and nothing out of bounds reaches the plant. Every field is arbitrary except
    /// that the values stay within ±1000 when finite (realistic magnitudes); the next test takes
    /// huge ones.
    #[test]
    fn arbitrary_messages_never_reach_the_plant_out_of_bounds(
        messages in prop::collection::vec((message(false), 1..4u64, 1..4u64), 1..8)
    ) {
        run_messages(messages)?;
    }

    /// The same with huge finite values everywhere: a pulse of 1.8e308 N m or a command whose
    /// q_d is 1e300 rad would make the state infinite unless the board bounds disturbances,
    /// reset states and equilibria.
    #[test]
    fn arbitrary_huge_messages_never_reach_the_plant_out_of_bounds(
        messages in prop::collection::vec((message(true), 1..4u64, 1..4u64), 1..8)
    ) {
        run_messages(messages)?;
    }

    /// A valid command stays in force after an invalid one: the next ticks still use its knots.
    #[test]
    fn an_invalid_command_leaves_the_valid_one_in_force(bad in command(true)) {
        let (mut b, q0, cfg) = board();
        let mut inputs = Inputs::default();
        inputs.push_control(&reset(q0));
        let good = slice(q0, 1, 0, 80.0);
        inputs.push_command(&good);
        b.step(0, &mut inputs);
        b.step(MS, &mut inputs);
        prop_assume!(b.validate(&bad).is_err());
        let rejected = b.counters.rejected;
        inputs.push_command(&bad);
        for t in 2..6 {
            let out = b.step(t * MS, &mut inputs);
            check_applied(&b, &out, &cfg)?;
            prop_assert_eq!(out.state.command_seq, 1);
            prop_assert_eq!(out.knot, good.knots[0]);
            prop_assert_eq!(out.state.stiffness, [80.0, 80.0]);
        }
        prop_assert_eq!(b.counters.rejected, rejected + 1);
    }
}

// ---------------------------------------------------------------------------------------------
// Configuration
// ---------------------------------------------------------------------------------------------

/// Pieces of scenario files, valid and not.
fn toml_piece() -> impl Strategy<Value = String> {
    let sections = prop::sample::select(vec![
        "plant", "actuator", "field", "noise", "cost", "task", "solver", "bounds", "x", "",
    ]);
    let keys = prop::sample::select(vec![
        "kind",
        "dt",
        "duration",
        "sigma",
        "beta",
        "alpha",
        "damping",
        "stiffness_max",
        "substeps",
        "integrator",
        "mass",
        "inertia",
        "q0",
        "target",
        "iterations",
        "seed",
        "unknown",
        "",
    ]);
    let values = prop_oneof![
        Just("0".to_string()),
        Just("-1".to_string()),
        Just("1e400".to_string()),
        Just("nan".to_string()),
        Just("inf".to_string()),
        Just("-inf".to_string()),
        Just("\"two_link\"".to_string()),
        Just("\"single_joint\"".to_string()),
        Just("\"proportional\"".to_string()),
        Just("[1.0, 2.0]".to_string()),
        Just("[]".to_string()),
        Just("{ a = 1 }".to_string()),
        Just("true".to_string()),
        Just("\"unterminated".to_string()),
        Just("18446744073709551616".to_string()),
        any::<f64>().prop_map(|v| format!("{v:?}")),
        any::<i64>().prop_map(|v| v.to_string()),
        "[ -~]{0,12}",
    ];
    prop_oneof![
        sections.prop_map(|s| format!("[{s}]")),
        (keys, values).prop_map(|(k, v)| format!("{k} = {v}")),
        "[ -~\\n\\t]{0,30}",
        Just("[[plant]]".to_string()),
        Just("=".to_string()),
    ]
}

/// `--set` overrides, well-formed or not.
fn assignment() -> impl Strategy<Value = String> {
    prop_oneof![
        (
            prop::sample::select(vec!["noise", "task", "actuator", "plant", "field", "x", ""]),
            prop::sample::select(vec![
                "sigma",
                "dt",
                "stiffness_max",
                "kind",
                "beta",
                "a.b",
                ""
            ]),
            prop_oneof![
                Just("0.02".to_string()),
                Just("-1".to_string()),
                Just("nan".to_string()),
                Just("inf".to_string()),
                Just("[1,".to_string()),
                Just("".to_string()),
                any::<f64>().prop_map(|v| format!("{v:?}")),
                "[ -~]{0,10}",
            ],
        )
            .prop_map(|(s, k, v)| format!("{s}.{k}={v}")),
        "[ -~]{0,20}",
    ]
}

fn temp_file(tag: &str) -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("fuzz_{}_{tag}.toml", std::process::id()))
}

/// Loading never panics; an error names the file, or the `--set` assignment it is about.
fn check_load(path: &Path, overrides: &[String]) -> Result<(), TestCaseError> {
    match Scenario::load(path, overrides) {
        Ok(s) => {
            prop_assert!(s.task.dt > 0.0 && s.task.dt.is_finite());
        }
        Err(e) => {
            let msg = e.to_string();
            let names_file = msg.contains(&path.display().to_string());
            let names_override = overrides
                .iter()
                .any(|o| msg.starts_with(&format!("--set {o}:")));
            prop_assert!(names_file || names_override, "{msg}");
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, failure_persistence: None, rng_seed: proptest::test_runner::RngSeed::Fixed(20261122), ..ProptestConfig::default() })]

    /// Arbitrary scenario text with arbitrary overrides.
    #[test]
    fn arbitrary_scenario_text_loads_or_fails_with_a_message_naming_the_file(
        pieces in prop::collection::vec(toml_piece(), 0..20),
        overrides in prop::collection::vec(assignment(), 0..4),
    ) {
        let path = temp_file("text");
        std::fs::write(&path, pieces.join("\n")).unwrap();
        check_load(&path, &overrides)?;
    }

    /// The real scenario with arbitrary overrides and one line replaced or added: closer to a
    /// valid file, so the checks past the syntax are reached.
    #[test]
    fn a_damaged_real_scenario_loads_or_fails_with_a_message_naming_the_file(
        line in 0..200usize,
        piece in toml_piece(),
        replace in any::<bool>(),
        overrides in prop::collection::vec(assignment(), 0..3),
    ) {
        let text = std::fs::read_to_string(CONFIG).unwrap();
        let mut lines: Vec<String> = text.lines().map(String::from).collect();
        let i = line % (lines.len() + 1);
        if replace && i < lines.len() {
            lines[i] = piece;
        } else {
            lines.insert(i, piece);
        }
        let path = temp_file("damaged");
        std::fs::write(&path, lines.join("\n")).unwrap();
        check_load(&path, &overrides)?;
    }
}
