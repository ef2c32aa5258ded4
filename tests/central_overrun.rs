//! The central controller's compute time per period and its overrun rule: a period whose work
//! takes longer than its budget sends the previous slice again, never nothing, and the knots it
//! computed go out with the next slice. Slow periods are injected through the controller's clock
//! (a fake one advancing by a known amount per period), so the histogram has known percentiles.

use std::cell::Cell;
use std::path::Path;
use vic_core::policy::Strategy;
use vic_plan::plan::{Method, PlanFile, Setup, plan, setup};
use vic_plan::scenario::Scenario;
use vic_rt::board::Board;
use vic_rt::central::{Central, Latency, Timing, Track, lockstep};
use vic_rt::transport::CommandSlice;

const PERIOD_NS: u64 = 20_000_000;
const FAST_NS: u64 = 1_000_000;
const SLOW_NS: u64 = 30_000_000;

thread_local! {
    static CALLS: Cell<u64> = const { Cell::new(0) };
    static NOW: Cell<u64> = const { Cell::new(0) };
    /// Which periods are slow: period `i` is when `SLOW(i)`.
    static SLOW: Cell<fn(u64) -> bool> = const { Cell::new(|_| false) };
}

/// The controller reads the clock twice per period (start and end of its work): the second
/// read of period `i` is `SLOW_NS` after the first when `SLOW(i)`, else `FAST_NS`.
fn fake_clock() -> u64 {
    let n = CALLS.with(|c| {
        let n = c.get();
        c.set(n + 1);
        n
    });
    if n % 2 == 1 {
        let slow = SLOW.with(|s| s.get())(n / 2);
        NOW.with(|t| t.set(t.get() + if slow { SLOW_NS } else { FAST_NS }));
    }
    NOW.with(|t| t.get())
}

fn use_fake_clock(slow: fn(u64) -> bool) {
    CALLS.with(|c| c.set(0));
    NOW.with(|t| t.set(0));
    SLOW.with(|s| s.set(slow));
}

fn joint() -> (Scenario, Setup, PlanFile) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/single_joint_delay.toml");
    let overrides = [
        "task.delay_ms=0".to_string(),
        "actuator.stiffness_max=0".into(),
        "actuator.initial_stiffness=0".into(),
        "noise.sigma=0".into(),
    ];
    let s = Scenario::load(&path, &overrides).expect("scenario");
    let p = plan(&s, Method::Ilqg, None).expect("plan");
    let set = setup(&s).expect("setup");
    (s, set, p)
}

fn central(set: &Setup, p: &PlanFile, latency_ms: f64, x0: &[f64]) -> Central {
    let track = Track::new(
        p.policy(set).expect("policy"),
        set.dynamics.clone(),
        set.cost.clone(),
        x0,
    )
    .unwrap();
    let timing = Timing::split(
        Latency::from_ms(latency_ms, set.dynamics.dt).unwrap(),
        PERIOD_NS,
    );
    Central::new(track, Strategy::Predictor, timing)
}

#[test]
fn an_overrunning_period_sends_the_previous_slice_again() {
    let (_, set, p) = joint();
    // No latency, no delay lines: what poll returns is what leaves now.
    let mut c = central(&set, &p, 0.0, &set.x0.clone());
    use_fake_clock(|i| i == 5 || i == 6);
    c.set_clock(fake_clock);
    let start = 1_000_000_000;
    c.begin_trial(0, 1, start, start - 2 * PERIOD_NS);
    let mut sent: Vec<CommandSlice> = Vec::new();
    for i in 0..12u64 {
        let mut out = Vec::new();
        c.poll(start + i * PERIOD_NS, &mut out);
        assert_eq!(out.len(), 1, "period {i} sent {} slices", out.len());
        sent.push(out[0]);
    }
    let same = |a: &CommandSlice, b: &CommandSlice| {
        a.start_ns == b.start_ns && a.count == b.count && a.knots == b.knots
    };
    for i in [5, 6] {
        assert!(
            same(&sent[i], &sent[4]),
            "period {i} must resend period 4's slice"
        );
        assert!(
            sent[i].header.seq > sent[i - 1].header.seq,
            "a resend is a new message"
        );
    }
    for i in [4, 7, 8] {
        assert!(!same(&sent[i], &sent[i - 1]), "period {i} sent a new slice");
    }
    // Period 7 covers its own present (two periods ahead of period 4's start).
    assert_eq!(sent[7].start_ns, sent[4].start_ns + 3 * PERIOD_NS);
    let t = c.compute_timing();
    assert_eq!(t.overruns, 2);
    assert_eq!(t.compute_us.count, 12);
    assert!((t.budget_us - 20_000.0).abs() < 1e-9);
    // 10 periods of 1 ms and 2 of 30 ms (3 significant digits in the histogram).
    assert!(
        (t.compute_us.p50 - 1000.0).abs() < 2.0,
        "{:?}",
        t.compute_us
    );
    assert!(
        (t.compute_us.max - 30_000.0).abs() < 40.0,
        "{:?}",
        t.compute_us
    );
}

#[test]
fn overruns_leave_the_noiseless_trajectory_unchanged() {
    // The joint starts 3° off the plan so the predictor's feedback acts; every fourth period
    // overruns. Resending the previous slice keeps the board supplied (no safe hold) and the
    // knots are the same, so the trajectory is the one without overruns.
    let (s, mut set, p) = joint();
    set.x0[0] += 3f64.to_radians();
    let x0 = set.x0.clone();
    let run = |slow: Option<fn(u64) -> bool>| {
        let mut c = central(&set, &p, 100.0, &x0);
        if let Some(slow) = slow {
            use_fake_clock(slow);
            c.set_clock(fake_clock);
        }
        let cfg = vic::daemons::launch::board_config(&s, 1_000_000);
        let mut board = Board::new(s.model.clone(), cfg, &x0).expect("board");
        let recs = lockstep(&mut board, &mut c, 1_000_000, PERIOD_NS, 1, 3);
        (recs, c.compute_timing())
    };
    let (plain, _) = run(None);
    let (slow, timing) = run(Some(|i| i % 4 == 3));
    assert!(timing.overruns >= 10, "{timing:?}");
    assert!(!slow[0].safe_hold && !slow[0].stalled && slow[0].missing_states == 0);
    let worst = plain[0]
        .x
        .iter()
        .zip(&slow[0].x)
        .map(|(a, b)| (a - b).amax())
        .fold(0.0, f64::max);
    assert!(worst < 1e-9, "trajectories differ by {worst}");
}

#[test]
fn lockstep_on_the_real_clock_decides_no_overrun() {
    // A budget of 1 ns: every period's real work exceeds it. Live, each would be an overrun;
    // in lockstep the real clock only measures (a simulation must give the same trajectory
    // however loaded the machine running it is), while an injected clock still decides (above).
    let (s, mut set, p) = joint();
    set.x0[0] += 3f64.to_radians();
    let x0 = set.x0.clone();
    let run = |budget_ns: u64| {
        let mut c = central(&set, &p, 200.0, &x0);
        c.set_compute_budget_ns(budget_ns);
        let cfg = vic::daemons::launch::board_config(&s, 1_000_000);
        let mut board = Board::new(s.model.clone(), cfg, &x0).expect("board");
        let recs = lockstep(&mut board, &mut c, 1_000_000, PERIOD_NS, 1, 3);
        (recs, c.compute_timing())
    };
    let (tight, timing) = run(1);
    let (loose, _) = run(u64::MAX / 4);
    assert_eq!(timing.overruns, 0, "{timing:?}");
    assert!(
        timing.compute_us.max > 0.0,
        "the work is still measured: {timing:?}"
    );
    assert_eq!(tight[0].x, loose[0].x);
}
