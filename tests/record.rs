//! `vic-board --record`: the real board with a planner trial and an injected disturbance, stopped
//! by SIGTERM; every tick it ran is in the file exactly once, in order, and the log reader of
//! `vic identify` reads it. And the loop's side of a recording (building the sample, pushing it,
//! dropping it when the queue is full) allocates nothing.

use crate::common;

use common::alloc::allocations;
use common::daemons::{CONFIG, Daemons, SIGMA, sooc_plan};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;
use vic_plan::scenario::Scenario;
use vic_rt::board::{Board, Inputs};
use vic_rt::record::{RecordOptions, Recorder, Sample};
use vic_rt::transport::{
    CommandSlice, Control, ControlKind, Disturbance, DisturbanceKind, Header, ToolPorts,
};

#[test]
fn building_and_pushing_a_sample_does_not_allocate_even_when_the_queue_is_full() {
    let scenario = Scenario::load(Path::new(CONFIG), &[]).unwrap();
    let setup = vic_plan::plan::setup(&scenario).unwrap();
    let q0 = [setup.x0[0], setup.x0[1]];
    let cfg = vic::daemons::launch::board_config(&scenario, 1_000_000);
    let mut board = Board::new(scenario.model.clone(), cfg, &q0).unwrap();
    let path = Path::new(env!("CARGO_TARGET_TMPDIR")).join("record_alloc.csv");
    let mut rec = Recorder::start(
        &path,
        &RecordOptions {
            capacity: 256,
            joints: 2,
            start_paused: true,
            // A file left by an interrupted earlier run is replaced.
            replace: true,
            ..Default::default()
        },
    )
    .unwrap();
    let ms = 1_000_000u64;
    let mut inputs = Inputs::default();
    inputs.push_control(&Control {
        header: Header::new(0, 0),
        kind: ControlKind::Reset as u32,
        seed: 3,
        q0,
        ..Default::default()
    });
    let mut slice = CommandSlice {
        joints: 2,
        knot_dt_ns: 10 * ms,
        count: 20,
        ..Default::default()
    };
    for k in &mut slice.knots[..20] {
        k.q_d = q0;
        k.stiffness = [80.0, 80.0];
    }
    let before = allocations();
    let mut accepted = 0;
    for tick in 1..=1000u64 {
        if tick % 20 == 1 {
            slice.header.seq = tick;
            slice.start_ns = (tick - 1) * ms;
            inputs.push_command(&slice);
        }
        if tick == 100 {
            inputs.push_disturbance(&Disturbance {
                header: Header::new(1, 0),
                kind: DisturbanceKind::Pulse as u32,
                torque: [0.5, 0.0],
                duration_ns: 5 * ms,
                ..Default::default()
            });
        }
        let out = board.step(tick * ms, &mut inputs);
        let sample = Sample::from_step(tick, tick * ms, &board, &out);
        accepted += rec.producer().push(&sample) as u64;
        if tick == 600 {
            // The writer drains the queue from here on (its allocations are its thread's).
            rec.set_paused(false);
        }
    }
    let after = allocations();
    assert_eq!(
        after - before,
        0,
        "the loop side of the recording allocated"
    );
    assert!((256..1000).contains(&accepted), "{accepted}");
    assert_eq!(rec.producer().dropped(), 1000 - accepted);
    let summary = rec.finish().unwrap();
    assert_eq!(summary.written, accepted);
    assert_eq!(summary.dropped, 1000 - accepted);
    assert!(summary.gaps >= 1);
    std::fs::remove_file(&path).unwrap();
}

/// The columns of a recording by name, one vector of fields per row, and its comment lines.
fn parse(text: &str) -> (Vec<String>, Vec<Vec<String>>, Vec<String>) {
    let comments = text
        .lines()
        .filter(|l| l.starts_with('#'))
        .map(String::from)
        .collect();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let head: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    let rows = lines
        .map(|l| l.split(',').map(String::from).collect::<Vec<_>>())
        .collect();
    (head, rows, comments)
}

#[test]
fn the_board_records_every_tick_it_runs_exactly_once() {
    let plan = sooc_plan();
    let ns = format!("rec{}", std::process::id());
    let file = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("{ns}.csv"));
    let mut guard = Daemons::default();
    guard.namespaces.push(ns.clone());
    let board = Command::new(env!("CARGO_BIN_EXE_vic-board"))
        .args([
            "--config",
            CONFIG,
            "--set",
            SIGMA,
            "--namespace",
            &ns,
            "--json",
        ])
        .arg("--record")
        .arg(&file)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let board_pid = board.id();
    guard.children.push(board);
    let planner = Command::new(env!("CARGO_BIN_EXE_vic-planner"))
        .args([
            "--config",
            CONFIG,
            "--set",
            SIGMA,
            "--namespace",
            &ns,
            "--json",
            "--strategy",
            "stiffness",
            "--latency-ms",
            "200",
            "--seed",
            "11",
            "--trials",
            "2",
        ])
        .arg("--plan")
        .arg(&plan)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    guard.children.push(planner);

    // A pulse while the trial runs: the file must show it.
    let tool = ToolPorts::open(&ns).unwrap();
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    loop {
        let running = tool
            .latest_state()
            .is_some_and(|s| s.mode == vic_rt::transport::Mode::Running as u32);
        if running {
            break;
        }
        assert!(std::time::Instant::now() < deadline, "no trial started");
        std::thread::sleep(Duration::from_millis(5));
    }
    std::thread::sleep(Duration::from_millis(100));
    tool.publish_disturbance(&Disturbance {
        header: Header::new(77, vic_rt::transport::monotonic_ns()),
        kind: DisturbanceKind::Pulse as u32,
        torque: [0.25, -0.125],
        duration_ns: 20_000_000,
        value: 0.0,
        ..Default::default()
    })
    .unwrap();
    drop(tool);

    let planner = guard.children.pop().unwrap();
    let out = planner.wait_with_output().unwrap();
    assert!(out.status.success(), "vic-planner failed");

    // SIGTERM: the board stops at the end of the tick, the writer flushes, the board exits 0.
    unsafe { libc::kill(board_pid as libc::pid_t, libc::SIGTERM) };
    let board = guard.children.pop().unwrap();
    let out = board.wait_with_output().unwrap();
    assert!(out.status.success(), "the board exited with {}", out.status);
    drop(guard);
    let stats: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    eprintln!("board: {stats}");
    let ticks = stats["ticks"].as_u64().unwrap();
    assert!(ticks > 1000, "{ticks} ticks");
    assert_eq!(stats["recorded"].as_u64(), Some(ticks), "ticks recorded");
    assert_eq!(stats["dropped"].as_u64(), Some(0), "ticks dropped");

    let text = std::fs::read_to_string(&file).unwrap();
    let (head, rows, comments) = parse(&text);
    let col = |n: &str| {
        head.iter()
            .position(|h| h == n)
            .unwrap_or_else(|| panic!("no column {n}"))
    };
    assert!(comments.iter().all(|c| !c.starts_with("# gap")));
    assert!(comments.iter().all(|c| !c.starts_with("# non-finite")));
    // Every tick from the first to the last, exactly once, in order.
    let tick: Vec<u64> = rows
        .iter()
        .map(|r| r[col("x_tick")].parse().unwrap())
        .collect();
    assert_eq!(tick.len() as u64, ticks);
    assert!(
        tick.iter().zip(1..).all(|(a, b)| *a == b),
        "ticks out of sequence"
    );
    assert!(rows.iter().all(|r| r.len() == head.len()));
    let num = |r: &Vec<String>, n: &str| r[col(n)].parse::<f64>().unwrap();
    // Both trials ran with the plan's stiffness and the law's damping (K_D = 0.1 K_P).
    let running: Vec<&Vec<String>> = rows
        .iter()
        .filter(|r| num(r, "x_mode") == vic_rt::transport::Mode::Running as u32 as f64)
        .collect();
    assert!(running.len() > 1000, "{} running ticks", running.len());
    assert!(running.iter().any(|r| num(r, "x_trial") == 1.0));
    for r in &running {
        for (k, d) in [("stiffness", "damping"), ("x_stiffness_1", "x_damping_1")] {
            assert!(num(r, k) >= 0.0 && num(r, k) <= 200.0);
            assert!((num(r, d) - 0.1 * num(r, k)).abs() < 1e-9);
        }
        // Running after the start tick means following a command.
        assert!(num(r, "x_periods") == 0.0 || num(r, "x_command_seq") > 0.0);
    }
    assert!(running.iter().any(|r| num(r, "stiffness") > 10.0));
    // The pulse: 20 ms of ticks in a row with its torque, tagged with its sequence number
    // (fewer than 20 ticks when wake-ups came late: the deadlines are what counts).
    let pulsed: Vec<usize> = (0..rows.len())
        .filter(|&i| num(&rows[i], "x_tau_ext_0") == 0.25 && num(&rows[i], "x_tau_ext_1") == -0.125)
        .collect();
    assert!(!pulsed.is_empty(), "the pulse is not in the file");
    let (first, last) = (pulsed[0], pulsed[pulsed.len() - 1]);
    assert_eq!(
        last - first + 1,
        pulsed.len(),
        "the pulse rows are not contiguous"
    );
    assert!(
        pulsed
            .iter()
            .all(|&i| num(&rows[i], "x_disturbance_seq") == 77.0)
    );
    let t_of = |i: usize| num(&rows[i], "t");
    assert!(t_of(last) - t_of(first) < 0.020 - 1e-6);
    assert!(t_of(last + 1) - t_of(first) >= 0.020 - 1e-6);
    // Time advances by one period per row; the accelerations match the velocities.
    let t: Vec<f64> = rows.iter().map(|r| num(r, "t")).collect();
    assert_eq!(t[0], 0.0);
    let late = stats["missed_periods"].as_u64().unwrap();
    let span = ((t[t.len() - 1] - t[0]) * 1000.0).round() as u64;
    // Each row is at least one period after the previous; missed periods account for the rest
    // (those skipped before the first tick, when the very first wake-up was late, are not in
    // the file's span).
    assert!(
        span >= ticks - 1 && span <= ticks - 1 + late,
        "time span of the file {span} ms, {ticks} ticks, {late} periods missed"
    );
    for w in running.windows(2) {
        let (a, b) = (w[0], w[1]);
        if num(b, "x_tick") == num(a, "x_tick") + 1.0 && num(b, "x_periods") == 1.0 {
            let qdd = (num(b, "qd") - num(a, "qd")) / 1e-3;
            assert!((qdd - num(b, "qdd")).abs() < 1e-6 * (1.0 + qdd.abs()));
        }
    }

    // The log reader of `vic identify` reads the whole recording.
    let log = vic::studies::identify::read_log_file(&file).unwrap();
    assert_eq!(log.len() as u64, ticks);
    assert_eq!(log[5].q, num(&rows[5], "q"));
    std::fs::remove_file(&file).unwrap();
    assert!(
        vic_rt::transport::namespace_files(&ns).is_empty(),
        "shared memory left behind"
    );
}
