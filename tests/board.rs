//! The board's state machine driven tick by tick with the scenario of the demo: validation,
//! watchdog, safe hold, plant guard, disturbances.

use std::path::Path;
use vic_plan::scenario::Scenario;
use vic_rt::board::*;
use vic_rt::transport::*;

fn scenario() -> Scenario {
    Scenario::load(
        Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/config/two_link_divergent.toml"
        )),
        &[],
    )
    .unwrap()
}

fn board() -> (Board, [f64; 2]) {
    let s = scenario();
    let setup = vic_plan::plan::setup(&s).unwrap();
    let q0 = [setup.x0[0], setup.x0[1]];
    let b = Board::new(
        s.model.clone(),
        vic::daemons::launch::board_config(&s, 1_000_000),
        &q0,
    )
    .unwrap();
    (b, q0)
}

fn reset(q0: [f64; 2], start: u64) -> Control {
    Control {
        header: Header::new(1, 0),
        kind: ControlKind::Reset as u32,
        trial: 1,
        seed: 5,
        start_ns: start,
        q0,
        ..Default::default()
    }
}

fn hold_slice(q0: [f64; 2], seq: u64, start: u64, k: f64) -> CommandSlice {
    let mut c = CommandSlice {
        header: Header::new(seq, 0),
        joints: 2,
        trial: 1,
        start_ns: start,
        knot_dt_ns: 10_000_000,
        count: 10,
        ..Default::default()
    };
    for knot in &mut c.knots[..10] {
        knot.q_d = q0;
        knot.stiffness = [k, k];
    }
    c
}

#[test]
fn watchdog_keeps_the_last_command_then_ramps_to_the_safe_hold() {
    let (mut b, q0) = board();
    let cfg = b.config().clone();
    let mut inp = Inputs::default();
    let ms = 1_000_000;
    inp.push_control(&reset(q0, 5 * ms));
    let o = b.step(ms, &mut inp);
    assert_eq!(o.state.mode, Mode::Idle as u32);
    inp.push_command(&hold_slice(q0, 1, 0, 150.0));
    let o = b.step(5 * ms, &mut inp);
    assert_eq!(o.state.mode, Mode::Running as u32);
    assert_eq!(o.state.trial_time_ns, 0);
    // The slice covers trial time [0, 100 ms); the last covered period starts at 99 ms. A
    // sender keeps sending it, fresh, every tick: what trips the watchdog is that nothing
    // covers the present any more.
    let mut t = 5;
    let mut entered = None;
    while t < 5 + 400 {
        t += 1;
        let mut again = hold_slice(q0, t, 0, 150.0);
        again.header.time_ns = t * ms;
        inp.push_command(&again);
        let o = b.step(t * ms, &mut inp);
        assert_eq!(o.periods, 1);
        if o.state.mode == Mode::SafeHold as u32 && entered.is_none() {
            entered = Some(o.state.trial_time_ns);
        }
        if o.state.trial_time_ns <= 100 * ms {
            assert_eq!(
                o.state.stiffness,
                [150.0, 150.0],
                "the command while covered"
            );
        } else if entered.is_none() {
            // Within the watchdog the last command stays in force.
            assert_eq!(o.state.stiffness, [150.0, 150.0], "tick {t}");
            assert_eq!(o.state.mode, Mode::Running as u32);
        }
    }
    // Safe hold entered within 2 ticks of the timeout (last cover + watchdog), after it.
    let timeout = 99 * ms + cfg.watchdog_ns;
    let entered = entered.expect("the board never entered the safe hold");
    assert!(
        entered > timeout && entered <= timeout + 2 * ms,
        "entered at {entered} ns, timeout {timeout} ns"
    );
    assert_eq!(b.counters.watchdog_trips, 1);
    // After the ramp the hold stiffness is in force.
    assert_eq!(b.stiffness(), [cfg.hold_stiffness; 2]);
    // The hand stays near the start under the stiff hold in the divergent field.
    assert!((b.state()[0] - q0[0]).abs() < 0.05);
    // Fresh valid commands covering the present resume the movement.
    let now_trial = b.trial_time_ns();
    let mut resume = hold_slice(q0, 1000, now_trial, 120.0);
    resume.header.time_ns = (t + 1) * ms;
    inp.push_command(&resume);
    let o = b.step((t + 1) * ms, &mut inp);
    assert_eq!(o.state.mode, Mode::Running as u32);
    assert_eq!(o.state.stiffness, [120.0, 120.0]);
}

#[test]
fn the_hold_ramps_the_stiffness_over_the_configured_time() {
    let (mut b, q0) = board();
    let cfg = b.config().clone();
    let mut inp = Inputs::default();
    let ms = 1_000_000;
    inp.push_control(&reset(q0, 0));
    inp.push_command(&hold_slice(q0, 1, 0, 20.0));
    b.step(0, &mut inp);
    let mut ramp = Vec::new();
    for t in 1..500u64 {
        let o = b.step(t * ms, &mut inp);
        if o.state.mode == Mode::SafeHold as u32 {
            ramp.push(o.state.stiffness[0]);
        }
    }
    // From 20 to the hold stiffness, linearly over the ramp, never above it.
    let ticks = (cfg.ramp_ns / ms) as usize;
    assert!(ramp.len() > ticks + 10, "{} hold ticks", ramp.len());
    let mid = ramp[ticks / 2];
    let expect = 20.0 + 0.5 * (cfg.hold_stiffness - 20.0);
    assert!(
        (mid - expect).abs() < 0.02 * cfg.hold_stiffness,
        "{mid} vs {expect}"
    );
    assert!(ramp.windows(2).all(|w| w[1] >= w[0]), "not monotone");
    assert_eq!(ramp[ticks + 5], cfg.hold_stiffness);
}

#[test]
fn the_plant_guard_latches_until_a_reset() {
    let s = scenario();
    let setup = vic_plan::plan::setup(&s).unwrap();
    let q0 = [setup.x0[0], setup.x0[1]];
    let cfg = BoardConfig {
        velocity_max: 0.5,
        ..vic::daemons::launch::board_config(&s, 1_000_000)
    };
    let mut b = Board::new(s.model.clone(), cfg, &q0).unwrap();
    let mut inp = Inputs::default();
    let ms = 1_000_000;
    inp.push_control(&reset(q0, 0));
    inp.push_command(&hold_slice(q0, 1, 0, 0.0));
    b.step(0, &mut inp);
    // A hard pulse with no stiffness: the shoulder speeds past 0.5 rad/s.
    inp.push_disturbance(&Disturbance {
        header: Header::new(1, 0),
        kind: DisturbanceKind::Pulse as u32,
        torque: [5.0, 0.0],
        duration_ns: 20 * ms,
        ..Default::default()
    });
    let mut tripped = None;
    for t in 1..60 {
        let o = b.step(t * ms, &mut inp);
        if o.state.mode == Mode::Fault as u32 && tripped.is_none() {
            tripped = Some(t);
            assert!(o.state.qd[0].abs() > 0.5, "tripped before the limit");
        }
    }
    assert!(tripped.is_some(), "the guard never tripped");
    assert_eq!(b.fault(), FaultReason::VelocityLimit);
    // Latched: valid commands are refused and counted, the hold stays.
    inp.push_command(&hold_slice(q0, 2, 60 * ms, 50.0));
    b.step(60 * ms, &mut inp);
    assert_eq!(b.mode(), Mode::Fault);
    assert_eq!(b.counters.rejected_by[Rejection::Faulted as usize], 1);
    // The hold settles the arm: 300 ms later it is slow again, still latched.
    for t in 61..400 {
        b.step(t * ms, &mut inp);
    }
    assert!(b.state()[2].abs() < 0.1, "not held: {:?}", b.state());
    assert_eq!(b.mode(), Mode::Fault);
    assert_eq!(b.stiffness(), [b.config().hold_stiffness; 2]);
    // Stop does not clear it either; only a reset does.
    let mut stop = reset(q0, 0);
    stop.kind = ControlKind::Stop as u32;
    stop.header.seq = 2;
    stop.header.time_ns = 400 * ms;
    inp.push_control(&stop);
    b.step(400 * ms, &mut inp);
    assert_eq!(b.mode(), Mode::Fault);
    let mut again = reset(q0, 401 * ms);
    again.header.seq = 3;
    again.header.time_ns = 401 * ms;
    inp.push_control(&again);
    b.step(401 * ms, &mut inp);
    assert_eq!(b.mode(), Mode::Running);
    assert_eq!(b.fault(), FaultReason::None);
}

#[test]
fn rejections_are_counted_by_reason_and_the_last_valid_command_stays() {
    let (mut b, q0) = board();
    let mut inp = Inputs::default();
    let ms = 1_000_000;
    inp.push_control(&reset(q0, 0));
    inp.push_command(&hold_slice(q0, 5, 0, 60.0));
    b.step(0, &mut inp);
    let mut future = hold_slice(q0, 6, 0, 90.0);
    future.header.time_ns = 1_000 * ms;
    inp.push_command(&future);
    let mut nan = hold_slice(q0, 7, 0, 90.0);
    nan.knots[0].q_d[0] = f64::INFINITY;
    inp.push_command(&nan);
    inp.push_command(&hold_slice(q0, 5, 0, 90.0)); // a replay
    inp.push_command(&hold_slice(q0, 8, 0, 500.0)); // above stiffness_max = 200
    inp.push_command(&hold_slice(q0, 9, 0, 90.0)); // one too many this tick
    let o = b.step(ms, &mut inp);
    assert_eq!(
        o.state.stiffness,
        [60.0, 60.0],
        "an invalid command reached the plant"
    );
    let by = b.counters.rejected_by;
    assert_eq!(by[Rejection::FutureTimestamp as usize], 1);
    assert_eq!(by[Rejection::NotFinite as usize], 1);
    assert_eq!(by[Rejection::OutOfOrder as usize], 1);
    assert_eq!(by[Rejection::StiffnessOutOfBounds as usize], 1);
    assert_eq!(by[Rejection::Overflow as usize], 1);
    assert_eq!(b.counters.rejected, 5);
    // Disturbances beyond the limits, repeated or from the future are refused.
    let pulse = |seq: u64, torque: f64, time_ns: u64| Disturbance {
        header: Header::new(seq, time_ns),
        kind: DisturbanceKind::Pulse as u32,
        torque: [torque, 0.0],
        duration_ns: 5 * ms,
        ..Default::default()
    };
    inp.push_disturbance(&pulse(10, 1e3, 0));
    inp.push_disturbance(&pulse(11, 1.0, 10_000 * ms));
    inp.push_disturbance(&pulse(12, 1.0, 0));
    inp.push_disturbance(&pulse(12, 1.0, 0));
    let o = b.step(2 * ms, &mut inp);
    let by = b.counters.rejected_by;
    assert_eq!(by[Rejection::DisturbanceOutOfBounds as usize], 1);
    assert_eq!(by[Rejection::FutureTimestamp as usize], 2);
    assert_eq!(by[Rejection::OutOfOrder as usize], 2);
    assert_eq!(o.state.disturbance_seq, 12);
    assert_eq!(o.state.tau_ext, [1.0, 0.0]);
    // A repeated reset (same sequence number) is refused too.
    inp.push_control(&reset(q0, 0));
    b.step(3 * ms, &mut inp);
    assert_eq!(b.counters.rejected_by[Rejection::OutOfOrder as usize], 3);
    assert_eq!(b.counters.resets, 1);
}

#[test]
fn rejects_invalid_commands() {
    let (mut b, q0) = board();
    let mut inp = Inputs::default();
    inp.push_control(&reset(q0, 0));
    b.step(0, &mut inp);
    let mut bad = hold_slice(q0, 1, 0, 50.0);
    bad.knots[3].tau_ff[1] = f64::NAN;
    assert_eq!(b.validate(&bad), Err(Rejection::NotFinite));
    let mut bad = hold_slice(q0, 1, 0, 50.0);
    bad.knots[0].stiffness[0] = -1.0;
    assert_eq!(b.validate(&bad), Err(Rejection::StiffnessOutOfBounds));
    let mut bad = hold_slice(q0, 1, 0, 50.0);
    bad.trial = 9;
    assert_eq!(b.validate(&bad), Err(Rejection::WrongTrial));
    let mut bad = hold_slice(q0, 1, 0, 50.0);
    bad.count = 0;
    assert_eq!(b.validate(&bad), Err(Rejection::Shape));
    let mut bad = hold_slice(q0, 1, 0, 50.0);
    bad.header.version = 99;
    assert_eq!(b.validate(&bad), Err(Rejection::Version));
    inp.push_command(&hold_slice(q0, 2, 0, 50.0));
    inp.push_command(&hold_slice(q0, 2, 0, 50.0));
    b.step(1_000_000, &mut inp);
    assert_eq!(b.counters.rejected, 1, "the repeated sequence number");
    // The iCub's affine damping law (K_D = 0.075 K_P − 0.0015) is unstable below
    // K_P = 0.02: such a stiffness is refused.
    let mut icub = b.model().clone();
    icub.actuator = vic_core::model::Actuator::Impedance {
        damping: vic_core::model::Damping::Affine {
            slope: 0.075,
            offset: -0.0015,
        },
    };
    let cfg = vic::daemons::launch::board_config(&scenario(), 1_000_000);
    let mut c = Board::new(icub, cfg, &q0).unwrap();
    let mut ci = Inputs::default();
    ci.push_control(&reset(q0, 0));
    c.step(0, &mut ci);
    assert_eq!(
        c.validate(&hold_slice(q0, 3, 0, 0.01)),
        Err(Rejection::DampingUnstable)
    );
    assert_eq!(c.validate(&hold_slice(q0, 3, 0, 0.03)), Ok(()));
}

#[test]
fn missed_ticks_integrate_the_elapsed_periods() {
    let (mut b, q0) = board();
    let mut inp = Inputs::default();
    inp.push_control(&reset(q0, 0));
    inp.push_command(&hold_slice(q0, 1, 0, 100.0));
    b.step(0, &mut inp);
    let o = b.step(7_000_000, &mut inp);
    assert_eq!(o.periods, 7);
    assert_eq!(o.state.trial_time_ns, 7_000_000);
}

#[test]
fn pulse_shows_in_the_state_at_the_tick_it_is_applied() {
    let (mut b, q0) = board();
    let mut inp = Inputs::default();
    inp.push_control(&reset(q0, 0));
    inp.push_command(&hold_slice(q0, 1, 0, 100.0));
    b.step(0, &mut inp);
    inp.push_disturbance(&Disturbance {
        header: Header::new(42, 0),
        kind: DisturbanceKind::Pulse as u32,
        torque: [1.0, 0.0],
        duration_ns: 3_000_000,
        ..Default::default()
    });
    let o = b.step(1_000_000, &mut inp);
    assert_eq!(o.state.disturbance_seq, 42);
    assert_eq!(o.state.disturbance_tick, o.state.tick);
    assert_eq!(o.state.tau_ext, [1.0, 0.0]);
    let o = b.step(5_000_000, &mut inp);
    assert_eq!(o.state.tau_ext, [0.0, 0.0]);
}

#[test]
fn an_idle_board_holds_its_posture_and_a_push_springs_back() {
    // No trial (no central process, or after a stop): the plant runs under the hold law, the
    // hold stiffness at its posture with gravity compensated, so a push moves the arm and it
    // springs back; a pending reset freezes it at the reset state.
    let (mut b, q0) = board();
    let cfg = b.config().clone();
    let mut inp = Inputs::default();
    let ms = 1_000_000;
    let mut now = 1_000 * ms;
    let dist = |s: &StateMsg| ((s.q[0] - q0[0]).powi(2) + (s.q[1] - q0[1]).powi(2)).sqrt();
    let run = |b: &mut Board, inp: &mut Inputs, now: &mut u64, ticks: u64| {
        let mut peak: f64 = 0.0;
        let mut last = StateMsg::default();
        for _ in 0..ticks {
            *now += ms;
            last = b.step(*now, inp).state;
            assert_eq!(last.mode, Mode::Idle as u32);
            peak = peak.max(dist(&last));
        }
        (peak, last)
    };
    let (quiet, s) = run(&mut b, &mut inp, &mut now, 300);
    assert_eq!(s.stiffness[..2], [cfg.hold_stiffness; 2]);
    inp.push_disturbance(&Disturbance {
        header: Header::new(7, now),
        kind: DisturbanceKind::Pulse as u32,
        torque: [2.0, -1.0],
        duration_ns: 50 * ms,
        ..Default::default()
    });
    let (pushed, _) = run(&mut b, &mut inp, &mut now, 100);
    let (_, end) = run(&mut b, &mut inp, &mut now, 1500);
    eprintln!(
        "idle: quiet {quiet:.2e} rad, pushed {pushed:.2e} rad, after 1.5 s {:.2e} rad",
        dist(&end)
    );
    assert!(pushed > 10.0 * quiet.max(1e-6), "the push moved nothing");
    assert!(dist(&end) < 0.1 * pushed, "it did not spring back");
    assert_eq!(b.counters.watchdog_trips, 0, "idle is no watchdog trip");
    // A reset pending: frozen at the reset state until the trial starts.
    now += ms;
    let mut c = reset(q0, now + 50 * ms);
    c.header = Header::new(1, now);
    inp.push_control(&c);
    let first = b.step(now, &mut inp).state;
    for _ in 0..20 {
        now += ms;
        let s = b.step(now, &mut inp).state;
        assert_eq!(s.mode, Mode::Idle as u32);
        assert_eq!((s.q, s.qd), (first.q, first.qd));
    }
    assert_eq!(first.q[..2], q0);
}
