//! The predictor strategy executed by the central controller (`rt::central`, here in lockstep with
//! a board on a simulated clock) against the offline Monte Carlo of the same policy: one law,
//! two executions, the same result.
//!
//! They cannot agree to the last digit with noise: the board draws its noise every 1 ms tick
//! (√1 ms scaling) while the Monte Carlo draws it once per 10 ms plan step (Eq. 10), so the same
//! seed gives different, equally distributed, realisations. Without noise nothing random is left
//! and the trajectories must match; with noise the means must agree within their spread.

use std::path::Path;
use vic_core::policy::{Feedback, Strategy};
use vic_plan::montecarlo::run_trials;
use vic_plan::plan::{Method, PlanFile, Setup, plan, setup};
use vic_plan::scenario::Scenario;
use vic_rt::board::Board;
use vic_rt::central::{Central, Controller, Latency, Timing, Track, TrialRecord, lockstep};

const PLANNER_PERIOD_NS: u64 = 20_000_000;

/// The single joint of Fig. 2 without stiffness, planned by ILQG for no delay, at noise `sigma`.
fn joint(sigma: f64) -> (Scenario, Setup, PlanFile) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/single_joint_delay.toml");
    let overrides = [
        "task.delay_ms=0".to_string(),
        "actuator.stiffness_max=0".into(),
        "actuator.initial_stiffness=0".into(),
        format!("noise.sigma={sigma}"),
    ];
    let s = Scenario::load(&path, &overrides).expect("scenario");
    let p = plan(&s, Method::Ilqg, None).expect("plan");
    let set = setup(&s).expect("setup");
    (s, set, p)
}

/// Lockstep trials of `strategy` at `latency_ms` from `x0`, the delay lines split as
/// `vic-planner` splits them by default.
#[allow(clippy::too_many_arguments)]
fn run_lockstep(
    s: &Scenario,
    set: &Setup,
    p: &PlanFile,
    strategy: Strategy,
    latency_ms: f64,
    x0: &[f64],
    trials: usize,
    seed: u64,
) -> Vec<TrialRecord> {
    let track = Track::new(
        p.policy(set).expect("policy"),
        set.dynamics.clone(),
        set.cost.clone(),
        x0,
    )
    .unwrap();
    let latency = Latency::from_ms(latency_ms, s.task.dt).expect("whole steps");
    let timing = Timing::split(latency, PLANNER_PERIOD_NS);
    let mut central = Central::new(track, strategy, timing);
    let cfg = vic::daemons::launch::board_config(s, 1_000_000);
    let mut board = Board::new(s.model.clone(), cfg, x0).expect("board");
    lockstep(
        &mut board,
        &mut central,
        1_000_000,
        PLANNER_PERIOD_NS,
        trials,
        seed,
    )
}

#[test]
fn without_noise_lockstep_and_monte_carlo_predictor_trajectories_agree() {
    // The joint starts 3° off the plan's start, so the feedback has something to correct and
    // a wrong prediction (or a wrong gain) shows in the trajectory.
    let (s, mut set, p) = joint(0.0);
    set.x0[0] += 3f64.to_radians();
    let x0 = set.x0.clone();
    for latency_ms in [100.0, 200.0] {
        let steps = (latency_ms / 10.0) as usize;
        let policy = p.policy(&set).unwrap();
        let mc = &run_trials(
            &set,
            &policy,
            Feedback::Predicted {
                latency_steps: steps,
            },
            1,
            5,
        )[0];
        let open = &run_trials(&set, &policy, Feedback::OpenLoop, 1, 5)[0];
        let rec = &run_lockstep(&s, &set, &p, Strategy::Predictor, latency_ms, &x0, 1, 5)[0];
        assert_eq!(
            rec.stale_feedback, 0,
            "{latency_ms} ms: states arrived late"
        );
        assert_eq!(rec.missing_states, 0);
        let mut worst: f64 = 0.0;
        for (a, b) in rec.x.iter().zip(&mc.x) {
            worst = worst.max((a[0] - b[0]).abs().to_degrees());
        }
        let n = mc.x.len() - 1;
        let target = set.reference[n].q_d[0];
        let miss_open = (open.x[n][0] - target).abs().to_degrees();
        let miss_mc = (mc.x[n][0] - target).abs().to_degrees();
        eprintln!(
            "{latency_ms} ms: largest lockstep − Monte Carlo angle {worst:.2e}°; final miss \
             predictor {miss_mc:.4}°, open loop {miss_open:.4}°"
        );
        // Open loop ends degrees off: the feedback acted, and lockstep acted identically.
        assert!(miss_open > 1.0, "open loop {miss_open}°");
        assert!(
            miss_mc < 0.1,
            "the predictor corrects the offset: {miss_mc}°"
        );
        assert!(
            worst < 1e-3,
            "{latency_ms} ms: trajectories differ by {worst}°"
        );
        // The commands sent are the commands the Monte Carlo applied.
        for (a, b) in rec.u.iter().zip(&mc.u) {
            assert!((a - b).amax() < 1e-6 * (1.0 + b.amax()), "{a} vs {b}");
        }
    }
}

#[test]
fn with_noise_lockstep_and_monte_carlo_predictor_agree_within_their_spread() {
    let (s, set, p) = joint(0.03);
    let (trials, seed) = (40, 21);
    let latency_ms = 200.0;
    let policy = p.policy(&set).unwrap();
    let mc = run_trials(
        &set,
        &policy,
        Feedback::Predicted { latency_steps: 20 },
        trials,
        seed,
    );
    let naive = run_trials(
        &set,
        &policy,
        Feedback::Delayed { latency_steps: 20 },
        trials,
        seed,
    );
    let recs = run_lockstep(
        &s,
        &set,
        &p,
        Strategy::Predictor,
        latency_ms,
        &set.x0,
        trials,
        seed,
    );
    let n = set.reference.len() - 1;
    let target = set.reference[n].q_d[0];
    let miss = |x: &nalgebra::DVector<f64>| (x[0] - target).to_degrees();
    let stats = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        let var = v.iter().map(|e| (e - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64;
        (m, (var / v.len() as f64).sqrt())
    };
    // Mean squared final miss: both estimate E[(q_N − q*)²] of the same policy on the same plant.
    let sq_mc: Vec<f64> = mc.iter().map(|t| miss(&t.x[n]).powi(2)).collect();
    let sq_ls: Vec<f64> = recs.iter().map(|r| miss(&r.x[n]).powi(2)).collect();
    let sq_naive: Vec<f64> = naive.iter().map(|t| miss(&t.x[n]).powi(2)).collect();
    let (m_mc, se_mc) = stats(&sq_mc);
    let (m_ls, se_ls) = stats(&sq_ls);
    let (m_nv, _) = stats(&sq_naive);
    eprintln!(
        "mean squared final miss [deg²]: Monte Carlo {m_mc:.3e} ± {se_mc:.1e}, lockstep \
         {m_ls:.3e} ± {se_ls:.1e}, naive delayed {m_nv:.3e}"
    );
    assert!(recs.iter().all(|r| r.stale_feedback == 0 && !r.safe_hold));
    let se = (se_mc * se_mc + se_ls * se_ls).sqrt();
    assert!(
        (m_mc - m_ls).abs() < 3.0 * se,
        "Monte Carlo {m_mc} vs lockstep {m_ls} (3 σ = {})",
        3.0 * se
    );
    assert!(
        m_nv > 10.0 * m_ls,
        "the naive law at 200 ms should be far worse"
    );
}

/// One trial like [`lockstep`], of the pure [`Controller`] (no clock: no period overruns),
/// except that the board misses its tick at trial time `skip_ms`, if given (it wakes a period
/// late) and integrates both periods at the next one, as the live loop does.
fn lockstep_missing_a_tick(
    s: &Scenario,
    set: &Setup,
    p: &PlanFile,
    strategy: Strategy,
    skip_ms: Option<u64>,
) -> TrialRecord {
    let track = Track::new(
        p.policy(set).expect("policy"),
        set.dynamics.clone(),
        set.cost.clone(),
        set.x0.as_slice(),
    )
    .unwrap();
    let timing = Timing::split(
        Latency::from_ms(100.0, set.dynamics.dt).unwrap(),
        PLANNER_PERIOD_NS,
    );
    let mut central = Controller::new(track, strategy, timing);
    let period = 1_000_000;
    let mut board = Board::new(
        s.model.clone(),
        vic::daemons::launch::board_config(s, period),
        set.x0.as_slice(),
    )
    .expect("board");
    let mut now: u64 = 1_000_000_000;
    let start = (now + central.lead_time_ns(PLANNER_PERIOD_NS)).div_ceil(period) * period;
    let mut inputs = vic_rt::board::Inputs::default();
    inputs.push_control(&central.begin_trial(0, 1, start, now));
    let mut out = Vec::new();
    while !central.trial_done() && now < start + 5_000_000_000 {
        if now.is_multiple_of(PLANNER_PERIOD_NS) {
            out.clear();
            central.poll(now, &mut out);
            for c in &out {
                inputs.push_command(c);
            }
        }
        if Some(now) != skip_ms.map(|ms| start + ms * 1_000_000) {
            let o = board.step(now, &mut inputs);
            central.on_state(&o.state, now);
        }
        now += period;
    }
    central.record()
}

#[test]
fn a_late_board_tick_is_counted_and_leaves_the_open_loop_plant_where_it_was() {
    // The live sweep compares its daemons with lockstep and skips the points whose counts say the
    // schedule slipped; this is what those counts and that comparison rest on. A board that
    // wakes a period late integrates both periods, the law evaluated in each: the open-loop plan
    // reads no state, so its plant must end exactly where it ends on time, while the state
    // recorded (and fed back) for the knot of the missed tick is a period off, and counted.
    let (s, mut set, p) = joint(0.0);
    set.x0[0] += 3f64.to_radians();
    let on_time = lockstep_missing_a_tick(&s, &set, &p, Strategy::Stiffness, None);
    let late = lockstep_missing_a_tick(&s, &set, &p, Strategy::Stiffness, Some(200));
    assert_eq!(on_time.off_knot_states, 0);
    assert_eq!(late.off_knot_states, 1);
    assert_eq!((late.missing_states, late.stale_feedback), (0, 0));
    let n = on_time.x.len() - 1;
    assert_eq!(on_time.x[n], late.x[n], "the open-loop plant moved");
    assert_ne!(
        on_time.x[20], late.x[20],
        "knot 20 recorded from the late tick"
    );
    for k in (0..=n).filter(|&k| k != 20) {
        assert_eq!(on_time.x[k], late.x[k], "knot {k}");
    }
    // The predictor feeds that state back (10 knots later): its commands change.
    let on_time = lockstep_missing_a_tick(&s, &set, &p, Strategy::Predictor, None);
    let late = lockstep_missing_a_tick(&s, &set, &p, Strategy::Predictor, Some(200));
    assert_eq!(late.off_knot_states, 1);
    assert_eq!(on_time.u[..30], late.u[..30]);
    assert_ne!(on_time.u[30..], late.u[30..]);
}

#[test]
fn at_its_own_rate_the_planner_feeds_back_the_state_of_k_minus_d_at_every_latency() {
    // The planner's default rate (`Timing::planner_rate_hz`) leaves every knot's feedback on the
    // state of k − D (at 0 ms the knot before: the freshest that exists), so no knot counts as
    // stale; at 50 Hz below 60 ms the states are older, and counted.
    let (s, set, p) = joint(0.0);
    let stale = |strategy, latency_ms: f64, rate_hz: u64| -> usize {
        let track = Track::new(
            p.policy(&set).expect("policy"),
            set.dynamics.clone(),
            set.cost.clone(),
            &set.x0,
        )
        .unwrap();
        let latency = Latency::from_ms(latency_ms, s.task.dt).expect("whole steps");
        let period_ns = 1_000_000_000 / rate_hz;
        let mut central = Central::new(track, strategy, Timing::split(latency, period_ns));
        let cfg = vic::daemons::launch::board_config(&s, 1_000_000);
        let mut board = Board::new(s.model.clone(), cfg, &set.x0).expect("board");
        let recs = lockstep(&mut board, &mut central, 1_000_000, period_ns, 1, 3);
        recs[0].stale_feedback
    };
    for strategy in [Strategy::NaiveDelayed, Strategy::Predictor] {
        for ms in [0.0, 10.0, 20.0, 30.0, 50.0, 60.0, 100.0] {
            let latency = Latency::from_ms(ms, s.task.dt).unwrap();
            let hz = Timing::planner_rate_hz(strategy, latency);
            assert_eq!(
                stale(strategy, ms, hz),
                0,
                "{strategy:?} at {ms} ms, {hz} Hz"
            );
        }
        for ms in [0.0, 30.0] {
            assert!(
                stale(strategy, ms, 50) > 10,
                "{strategy:?} at {ms} ms, 50 Hz"
            );
        }
    }
}
