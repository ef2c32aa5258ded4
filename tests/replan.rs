//! The `replan` strategy (receding-horizon stiffness planning, `core::replan`): the central
//! controller in lockstep executes exactly what the Monte Carlo executes, and at 200 ms of latency
//! in the divergent field it ends no farther from the target than the `stiffness` playback after
//! a torque pulse it could not know of, and closer than the best delayed feedback (`predictor`).
//! Re-solving on a worker thread one period ahead (as live) executes the Monte Carlo's law with
//! the same lead.

use std::path::Path;
use vic::core::policy::{Feedback, Strategy};
use vic::core::replan::{Executor, ReplanOptions, Replanner};
use vic::planning::evaluation::summarize;
use vic::planning::montecarlo::{
    Pulse, Trial, position, run_trial_on, run_trials, run_trials_disturbed,
};
use vic::planning::plan::{Method, PlanFile, Setup, plan, setup};
use vic::planning::scenario::Scenario;
use vic::rt::board::Board;
use vic::rt::central::{Central, Timing, Track, lockstep, split_latency_ms};

const PLANNER_PERIOD_NS: u64 = 20_000_000;

fn config(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config")
        .join(name)
}

fn planned(file: &str, method: Method, extra: &[&str]) -> (Scenario, Setup, PlanFile) {
    let mut overrides = vec!["task.delay_ms=0".to_string()];
    overrides.extend(extra.iter().map(|s| s.to_string()));
    let s = Scenario::load(&config(file), &overrides).expect("scenario");
    let p = plan(&s, method, None).expect("plan");
    let set = setup(&s).expect("setup");
    (s, set, p)
}

#[test]
fn lockstep_replans_exactly_like_the_monte_carlo() {
    // No noise: nothing random is left, so the central controller in lockstep and the Monte
    // Carlo must produce the same trajectory (as for the predictor, tests/central_predictor.rs).
    // The joint starts 3° off the plan's start: the re-solves have something to correct.
    let (s, mut set, p) = planned("single_joint_delay.toml", Method::Sooc, &["noise.sigma=0"]);
    set.x0[0] += 3f64.to_radians();
    let x0 = set.x0.clone();
    let latency_ms = 100.0;
    let steps = 10;
    let policy = p.policy(&set).unwrap();
    let mc = &run_trials(
        &set,
        &policy,
        Feedback::Replan {
            latency_steps: steps,
        },
        1,
        5,
    )[0];
    let open = &run_trials(&set, &policy, Feedback::OpenLoop, 1, 5)[0];
    let track = Track::new(policy, set.dynamics.clone(), set.cost.clone(), &x0).unwrap();
    let lookahead_ms = 2.0 * PLANNER_PERIOD_NS as f64 * 1e-6;
    let (sensor, command) = split_latency_ms(latency_ms, lookahead_ms);
    let timing = Timing {
        latency_steps: steps,
        sensor_latency_ns: (sensor * 1e6) as u64,
        command_latency_ns: (command * 1e6) as u64,
        lookahead_ns: (lookahead_ms * 1e6) as u64,
    };
    let mut central = Central::new(track, Strategy::Replan, timing);
    // On the simulated clock the law is executed whatever a re-solve takes on the real one (a
    // re-solve takes longer than the 20 ms period on a loaded machine: live, such periods
    // overrun and resend the previous slice, which this test is not about).
    central.set_compute_budget_ns(u64::MAX);
    let cfg = vic::tools::launch::board_config(&s, 1_000_000);
    let mut board = Board::new(s.model.clone(), cfg, &x0).expect("board");
    let rec = &lockstep(&mut board, &mut central, 1_000_000, PLANNER_PERIOD_NS, 1, 5)[0];
    assert!(!rec.safe_hold && !rec.fault && rec.missing_states == 0);
    assert_eq!(rec.stale_feedback, 0, "states arrived late");
    let n = mc.x.len() - 1;
    let target = set.reference[n].q_d[0];
    let miss = |t: &Trial| (t.x[n][0] - target).abs().to_degrees();
    let worst = rec
        .x
        .iter()
        .zip(&mc.x)
        .map(|(a, b)| (a[0] - b[0]).abs().to_degrees())
        .fold(0.0, f64::max);
    let timing = central.compute_timing();
    let replan = timing
        .replan
        .expect("the replan strategy reports its re-solves");
    eprintln!(
        "lockstep − Monte Carlo {worst:.2e}°; final miss replan {:.4}°, open loop {:.4}°; \
         {replan:?}",
        miss(mc),
        miss(open)
    );
    // One re-solve per 20 ms period from the first state seen (knot 10) to the last but one.
    let expected = (steps..n - 1).filter(|k| k % 2 == 0 && *k > 0).count();
    assert_eq!(replan.stats.solves, expected);
    assert!(replan.stats.accepted > 0);
    assert!(replan.solve_us.p50 > 0.0 && replan.solve_us.p99 >= replan.solve_us.p50);
    // The re-solves corrected the offset that the playback keeps part of.
    assert!(
        miss(mc) < 0.5 * miss(open),
        "{} vs {}",
        miss(mc),
        miss(open)
    );
    assert!(worst < 1e-3, "trajectories differ by {worst}°");
    for (a, b) in rec.u.iter().zip(&mc.u) {
        assert!((a - b).amax() < 1e-6 * (1.0 + b.amax()), "{a} vs {b}");
    }
}

#[test]
fn replanning_in_the_background_executes_the_monte_carlo_law_one_period_ahead() {
    // As above (no noise, 3° off the start), but the central controller re-solves on a worker
    // thread from the state predicted one period (2 knots) ahead and adopts the result at that
    // knot; `wait` makes lockstep wait for each re-solve at the next period. The Monte Carlo
    // with the same lead must then produce the same commands and trajectory.
    let (s, mut set, p) = planned("single_joint_delay.toml", Method::Sooc, &["noise.sigma=0"]);
    set.x0[0] += 3f64.to_radians();
    let x0 = set.x0.clone();
    let steps = 10;
    let feedback = Feedback::Replan {
        latency_steps: steps,
    };
    let policy = p.policy(&set).unwrap();
    let mc_with_lead = |lead_steps: usize| {
        let options = ReplanOptions {
            lead_steps,
            ..ReplanOptions::at_50_hz(set.dynamics.dt)
        };
        let replanner = Replanner::new(&policy, &set.dynamics, &set.cost, options);
        let mut exec = Executor::Replan(Box::new(replanner));
        let d = &set.dynamics;
        run_trial_on(d, d, &set.cost, &x0, &mut exec, feedback, 5, 0)
    };
    let (mc, mc_at_once) = (mc_with_lead(2), mc_with_lead(0));
    let track = Track::new(policy.clone(), set.dynamics.clone(), set.cost.clone(), &x0).unwrap();
    let lookahead_ms = 2.0 * PLANNER_PERIOD_NS as f64 * 1e-6;
    let (sensor, command) = split_latency_ms(100.0, lookahead_ms);
    let timing = Timing {
        latency_steps: steps,
        sensor_latency_ns: (sensor * 1e6) as u64,
        command_latency_ns: (command * 1e6) as u64,
        lookahead_ns: (lookahead_ms * 1e6) as u64,
    };
    let mut central = Central::new(track, Strategy::Replan, timing);
    central.set_compute_budget_ns(u64::MAX);
    central.replan_in_background(true);
    let cfg = vic::tools::launch::board_config(&s, 1_000_000);
    let mut board = Board::new(s.model.clone(), cfg, &x0).expect("board");
    let rec = &lockstep(&mut board, &mut central, 1_000_000, PLANNER_PERIOD_NS, 1, 5)[0];
    assert!(!rec.safe_hold && !rec.fault && rec.missing_states == 0);
    let replan = central.compute_timing().replan.expect("re-solves reported");
    let n = mc.x.len() - 1;
    eprintln!("{replan:?}");
    // One re-solve per period from the first state seen, while its knot (2 ahead) is not the last.
    let expected = (steps..n - 3).filter(|k| k % 2 == 0).count();
    assert_eq!(replan.stats.solves, expected);
    assert!(replan.stats.accepted > 0);
    assert_eq!((replan.late, replan.skipped), (0, 0));
    let worst = rec
        .x
        .iter()
        .zip(&mc.x)
        .map(|(a, b)| (a[0] - b[0]).abs().to_degrees())
        .fold(0.0, f64::max);
    assert!(worst < 1e-3, "trajectories differ by {worst}°");
    for (a, b) in rec.u.iter().zip(&mc.u) {
        assert!((a - b).amax() < 1e-6 * (1.0 + b.amax()), "{a} vs {b}");
    }
    // The lead matters: re-solving at once executes other commands.
    let moved =
        mc.u.iter()
            .zip(&mc_at_once.u)
            .map(|(a, b)| (a - b).amax())
            .fold(0.0, f64::max);
    assert!(moved > 1e-6, "the lead changed nothing ({moved})");
}

/// Largest distance of the mean hand path from the reference [mm].
fn peak_mean_deviation(set: &Setup, trials: &[Trial]) -> f64 {
    let model = &set.dynamics.model;
    (0..trials[0].x.len())
        .map(|k| {
            let mut ref_x = nalgebra::DVector::zeros(model.nx());
            ref_x[0] = set.reference[k].q_d[0];
            ref_x[1] = set.reference[k].q_d[1];
            let r = position(model, &ref_x);
            let mut mean = [0.0; 2];
            for t in trials {
                let p = position(model, &t.x[k]);
                mean[0] += p[0] / trials.len() as f64;
                mean[1] += p[1] / trials.len() as f64;
            }
            ((mean[0] - r[0]).powi(2) + (mean[1] - r[1]).powi(2)).sqrt() * 1e3
        })
        .fold(0.0, f64::max)
}

#[test]
fn after_a_pulse_replan_ends_no_farther_than_the_stiffness_playback() {
    // The arm in the divergent field (σ = 0.05), 200 ms of latency, a 10 N m shoulder pulse of
    // 50 ms at 0.4 s: the same pulse and the same noise seeds for both strategies.
    let (_, set, p) = planned("two_link_divergent.toml", Method::Sooc, &[]);
    let policy = p.policy(&set).unwrap();
    let pulse = Pulse {
        torque: [10.0, 0.0],
        start: 0.4,
        duration: 0.05,
    };
    let latency = 20;
    let run =
        |s: Strategy| run_trials_disturbed(&set, &policy, s.feedback(latency), Some(&pulse), 4, 7);
    let (stiff, replan) = (run(Strategy::Stiffness), run(Strategy::Replan));
    let (rs, rr) = (
        summarize(&set, &stiff, 50.0),
        summarize(&set, &replan, 50.0),
    );
    let moved = peak_mean_deviation(&set, &stiff);
    eprintln!(
        "pulse 10 N m at 200 ms: stiffness final {:?} mm (RMS {:?}, path pushed {moved:.1} mm \
         off), replan final {:?} mm (RMS {:?}); costs {:?} vs {:?}",
        rs.final_error_mean,
        rs.rms_error,
        rr.final_error_mean,
        rr.rms_error,
        rs.expected_cost_mc,
        rr.expected_cost_mc
    );
    // The pulse moves the hand by centimetres under the playback.
    assert!(moved > 20.0, "the pulse moved the hand only {moved} mm");
    assert_eq!(rr.diverged, 0);
    let (fs, fr) = (rs.final_error_mean.unwrap(), rr.final_error_mean.unwrap());
    assert!(fr <= fs, "replan ends {fr} mm off, the playback {fs} mm");
}

#[test]
fn in_the_divergent_field_at_200_ms_replan_beats_the_predictor() {
    let (_, set, p) = planned("two_link_divergent.toml", Method::Sooc, &[]);
    let (_, fb_set, fb) = planned(
        "two_link_divergent.toml",
        Method::Ilqg,
        &[
            "actuator.stiffness_min=0",
            "actuator.stiffness_max=0",
            "actuator.initial_stiffness=0",
        ],
    );
    let latency = 20;
    let replan = run_trials(
        &set,
        &p.policy(&set).unwrap(),
        Strategy::Replan.feedback(latency),
        4,
        9,
    );
    let pred = run_trials(
        &fb_set,
        &fb.policy(&fb_set).unwrap(),
        Strategy::Predictor.feedback(latency),
        4,
        9,
    );
    // Final errors of every trial (a diverged one is far, or not finite: it sorts last), median.
    let median = |set: &Setup, trials: &[Trial]| {
        let n = trials[0].x.len() - 1;
        let model = &set.dynamics.model;
        let mut goal = nalgebra::DVector::zeros(model.nx());
        goal[0] = set.reference[n].q_d[0];
        goal[1] = set.reference[n].q_d[1];
        let g = position(model, &goal);
        let mut e: Vec<f64> = trials
            .iter()
            .map(|t| {
                let p = position(model, &t.x[n]);
                let d = ((p[0] - g[0]).powi(2) + (p[1] - g[1]).powi(2)).sqrt() * 1e3;
                if d.is_finite() { d } else { f64::INFINITY }
            })
            .collect();
        e.sort_by(f64::total_cmp);
        (e[e.len() / 2 - 1] + e[e.len() / 2]) / 2.0
    };
    let (mr, mp) = (median(&set, &replan), median(&fb_set, &pred));
    let (rr, rp) = (
        summarize(&set, &replan, 50.0),
        summarize(&fb_set, &pred, 50.0),
    );
    eprintln!(
        "200 ms, σ = 0.05: replan median final {mr:.2} mm ({} diverged), predictor {mp:.2} mm \
         ({} diverged)",
        rr.diverged, rp.diverged
    );
    assert_eq!(rr.diverged, 0);
    assert!(rr.diverged <= rp.diverged);
    assert!(mr < mp, "replan {mr} mm, predictor {mp} mm");
}
