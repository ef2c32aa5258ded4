//! The live view without a terminal: the state an [`App`] keeps, the actions of its keys, and what
//! [`draw`] puts on the screen, read back from ratatui's `TestBackend`.

use super::*;
use ratatui::Terminal;
use ratatui::backend::TestBackend;
use vic_rt::board::{FaultReason, Rejection};
use vic_rt::transport::{Header, Mode};

/// The screen's rows as text.
fn screen(app: &App, width: u16, height: u16) -> Vec<String> {
    let mut t = Terminal::new(TestBackend::new(width, height)).unwrap();
    t.draw(|f| draw(f, app)).unwrap();
    let buf = t.backend().buffer().clone();
    (0..height)
        .map(|y| (0..width).map(|x| buf[(x, y)].symbol()).collect())
        .collect()
}

fn telemetry(mode: Mode, time_s: f64) -> Telemetry {
    Telemetry {
        header: Header::new(1, (time_s * 1e9) as u64),
        mode: mode as u32,
        joints: 2,
        tick: (time_s * 1e3) as u64,
        tick_rate_hz: 1000.0,
        noise_factor: 1.0,
        ..Default::default()
    }
}

fn state(time_s: f64, k: f64) -> StateMsg {
    StateMsg {
        header: Header::new(1, (time_s * 1e9) as u64),
        joints: 2,
        q: [0.3, 2.0],
        stiffness: [k, 5.0],
        ..Default::default()
    }
}

#[test]
fn the_banner_names_the_mode_and_a_fault_its_reason() {
    let mut app = App::new("lab", Settings::default());
    assert!(screen(&app, 100, 30)[1].contains("NO BOARD"));
    app.on_telemetry(&telemetry(Mode::SafeHold, 1.0));
    let rows = screen(&app, 100, 30);
    assert!(rows[1].contains("SAFE HOLD"), "{}", rows[1]);
    assert!(!rows.iter().any(|r| r.contains("FAULT")));
    let mut t = telemetry(Mode::Fault, 1.1);
    t.fault_reason = FaultReason::VelocityLimit as u32;
    app.on_telemetry(&t);
    let rows = screen(&app, 100, 30);
    assert!(rows[1].contains("FAULT: velocity-limit"), "{}", rows[1]);
    let mut t = telemetry(Mode::Idle, 1.2);
    app.on_telemetry(&t);
    assert!(screen(&app, 100, 30)[1].contains("IDLE: PLANT FROZEN"));
    t.stiffness = [100.0, 100.0];
    app.on_telemetry(&t);
    assert!(screen(&app, 100, 30)[1].contains("IDLE: HOLDING POSTURE"));
    // Idle with a central process connected: between its trials, not abandoned.
    let node = |name: &str, state| vic_rt::transport::NodeInfo {
        name: name.into(),
        pid: 1,
        state,
        id: "0".into(),
    };
    use vic_rt::transport::NodeLiveness::{Alive, Dead};
    app.on_nodes(&[node("vic-board", Alive), node("vic-planner", Alive)]);
    let banner = &screen(&app, 100, 30)[1];
    assert!(
        banner.contains("IDLE: BETWEEN TRIALS (vic-planner connected)"),
        "{banner}"
    );
    // A planner that died, or only other tools: no central process.
    app.on_nodes(&[node("vic-board", Alive), node("vic-planner", Dead)]);
    assert!(screen(&app, 100, 30)[1].contains("IDLE: HOLDING POSTURE (no central process)"));
    app.on_nodes(&[node("vic-observer", Alive)]);
    assert!(screen(&app, 100, 30)[1].contains("no central process"));
    app.on_silence();
    assert!(screen(&app, 100, 30)[1].contains("(board silent)"));
}

#[test]
fn a_plots_bounds_follow_the_data_in_its_window() {
    let settings = Settings {
        window_s: 10.0,
        ..Settings::default()
    };
    let mut app = App::new("lab", settings);
    // Joint 1's stiffness ramps 10 → 50 N m/rad over 4 s (joint 2 stays at 5).
    for i in 0..=4000 {
        app.on_state(&state(100.0 + i as f64 * 1e-3, 10.0 + 0.01 * i as f64));
    }
    // One sample per 10 ms of board time.
    assert_eq!(app.stiffness[0].points().len(), 401);
    let b = bounds(&[&app.stiffness[0], &app.stiffness[1]], 1.0);
    // Range 5..50 padded by 10 % of the span (4.5) on each side.
    assert!(
        (b[0] - 0.5).abs() < 1e-9 && (b[1] - 54.5).abs() < 1e-9,
        "{b:?}"
    );
    let rows = screen(&app, 120, 40);
    assert!(rows.iter().any(|r| r.contains("54.50")), "{rows:#?}");
    // 12 s later at 200 N m/rad: the ramp has left the window and the axis follows.
    for i in 0..=1200 {
        app.on_state(&state(116.0 + i as f64 * 1e-2, 200.0));
    }
    let first = app.stiffness[0].points()[0].0;
    assert!(first >= app.now_s - 10.0 - 1e-9, "{first} {}", app.now_s);
    assert_eq!(app.stiffness[0].range(), Some((200.0, 200.0)));
    let b = bounds(&[&app.stiffness[0], &app.stiffness[1]], 1.0);
    assert!(
        (b[0] + 14.5).abs() < 1e-9 && (b[1] - 219.5).abs() < 1e-9,
        "{b:?}"
    );
    let rows = screen(&app, 120, 40);
    assert!(rows.iter().any(|r| r.contains("220")), "{rows:#?}");
    assert!(!rows.iter().any(|r| r.contains("54.50")));
    // A flat series sits in the middle of the smallest span.
    let mut flat = Series::default();
    flat.push(0.0, 3.0, 10.0);
    assert_eq!(bounds(&[&flat], 1.0), [2.5, 3.5]);
}

#[test]
fn the_rejections_table_lists_each_reason_with_its_count() {
    let mut app = App::new("lab", Settings::default());
    let mut t = telemetry(Mode::Running, 1.0);
    t.rejected_by_reason[Rejection::Stale as usize] = 3;
    t.rejected_by_reason[Rejection::TorqueOutOfBounds as usize] = 117;
    t.rejected_messages = 120;
    t.dropped_messages = 45;
    app.on_telemetry(&t);
    let rows = screen(&app, 120, 40);
    let row_of = |name: &str| {
        rows.iter()
            .find(|r| r.contains(name))
            .unwrap_or_else(|| panic!("no row for {name}: {rows:#?}"))
            .clone()
    };
    let stale = row_of(Rejection::Stale.name());
    assert!(stale.contains(" 3 "), "{stale}");
    let torque = row_of(Rejection::TorqueOutOfBounds.name());
    assert!(torque.contains(" 117 "), "{torque}");
    assert!(row_of("rejected messages: 120").contains("120"));
    let dropped = row_of("dropped (sequence gaps)");
    assert!(dropped.contains(" 45 "), "{dropped}");
    // Reasons with no rejection are not listed.
    assert!(!rows.iter().any(|r| r.contains(Rejection::Faulted.name())));
}

#[test]
fn keys_turn_into_the_configured_actions() {
    let settings = Settings {
        pulse_torque: 3.5,
        pulse_duration: 0.04,
        field_beta: 80.0,
        window_s: 10.0,
    };
    let mut app = App::new("lab", settings);
    let pulse = |t: [f64; MAX_JOINTS]| Request::Pulse {
        torque: t,
        duration: 0.04,
    };
    let requests = |a: Action| match a {
        Action::Send { requests, .. } => requests,
        a => panic!("expected a send, got {a:?}"),
    };
    assert_eq!(requests(app.on_key(Key::Char('p'))), [pulse([3.5, 0.0])]);
    assert_eq!(requests(app.on_key(Key::Char('P'))), [pulse([-3.5, 0.0])]);
    // A one-joint board (no telemetry yet) has no joint 2.
    assert_eq!(app.on_key(Key::Char('2')), Action::None);
    assert_eq!(requests(app.on_key(Key::Char('p'))), [pulse([3.5, 0.0])]);
    app.on_telemetry(&telemetry(Mode::Idle, 1.0));
    app.on_key(Key::Char('2'));
    assert_eq!(requests(app.on_key(Key::Char('-'))), [pulse([0.0, -3.5])]);
    // f toggles: on at the configured β when off, off when on.
    assert_eq!(
        requests(app.on_key(Key::Char('f'))),
        [Request::Field { beta: 80.0 }]
    );
    let mut t = telemetry(Mode::Idle, 1.1);
    t.field_beta = 80.0;
    app.on_telemetry(&t);
    assert_eq!(
        requests(app.on_key(Key::Char('f'))),
        [Request::Field { beta: 0.0 }]
    );
    // r takes every disturbance away and clears the plots.
    app.on_state(&state(1.2, 20.0));
    assert!(!app.stiffness[0].points().is_empty());
    let r = requests(app.on_key(Key::Char('r')));
    assert!(r.contains(&Request::Field { beta: 0.0 }), "{r:?}");
    assert!(r.contains(&Request::Noise { factor: 1.0 }), "{r:?}");
    assert!(r.contains(&Request::Load { torque: [0.0; 2] }), "{r:?}");
    assert!(app.stiffness[0].points().is_empty() && app.tracking_error.points().is_empty());
    for quit in [Key::Char('q'), Key::Esc, Key::CtrlC] {
        assert_eq!(app.on_key(quit), Action::Quit);
    }
    assert_eq!(app.on_key(Key::Char('x')), Action::None);
}

#[test]
fn answers_count_acknowledged_pulses_and_show_refusals() {
    let mut app = App::new("lab", Settings::default());
    let Action::Send { label, requests } = app.on_key(Key::Char('p')) else {
        panic!("p sends")
    };
    app.on_sent(&requests);
    let ack = Ack {
        namespace: "lab".into(),
        seq: 7,
        tick: 4321,
        board_time_ns: 0,
        latency_us: 250.0,
        effect_tick: Some(4321),
        effect_after_ticks: Some(0),
        tau_ext: [2.0, 0.0],
        mode: "idle".into(),
    };
    app.on_answer(&label, &requests[0], Ok(ack));
    app.on_answer(
        &label,
        &requests[0],
        Err(OperatorError::Rejected {
            namespace: "lab".into(),
            reason: "stale".into(),
            hint: String::new(),
        }),
    );
    assert_eq!((app.pulses_sent, app.pulses_acked), (1, 1));
    let rows = screen(&app, 120, 40).join("\n");
    assert!(rows.contains("pulses sent 1, acknowledged 1"), "{rows}");
    assert!(rows.contains("tick 4321"), "{rows}");
    assert!(rows.contains("NOT") && rows.contains("(stale)"), "{rows}");
}
