//! A board tick allocates nothing: a counting global allocator watches `Board::step`, and the
//! I/O of the real-time loop (`vic_rt::board::live`) around it, with a planner and a tool connected.

use crate::common;

use common::alloc::allocations;
use common::daemons::unique_namespace;
use std::path::Path;
use vic_plan::scenario::Scenario;
use vic_rt::board::{Board, Inputs};
use vic_rt::transport::{
    BoardEvent, BoardPorts, CentralPorts, CommandSlice, Control, ControlKind, Disturbance,
    DisturbanceKind, Header, StateMsg, Telemetry, ToolPorts,
};

#[test]
fn a_board_step_does_not_allocate() {
    let path = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/config/two_link_divergent.toml"
    ));
    let scenario = Scenario::load(path, &[]).unwrap();
    let setup = vic_plan::plan::setup(&scenario).unwrap();
    let q0 = [setup.x0[0], setup.x0[1]];
    let mut board = Board::new(
        scenario.model.clone(),
        vic::daemons::launch::board_config(&scenario, 1_000_000),
        &q0,
    )
    .unwrap();
    let mut inputs = Inputs::default();
    let ms = 1_000_000u64;
    let reset = Control {
        header: Header::new(1, 0),
        kind: ControlKind::Reset as u32,
        trial: 0,
        seed: 3,
        start_ns: 0,
        q0,
        ..Default::default()
    };
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
    let pulse = Disturbance {
        header: Header::new(1, 0),
        kind: DisturbanceKind::Pulse as u32,
        torque: [0.5, 0.0],
        duration_ns: 5 * ms,
        ..Default::default()
    };
    let before = allocations();
    let mut now = 0;
    for tick in 0..1000u64 {
        if tick == 0 {
            inputs.push_control(&reset);
        }
        // A gap in the commands: the watchdog ramps the board into its safe hold and back.
        if tick % 20 == 0 && !(500..700).contains(&tick) {
            slice.header.seq = tick + 1;
            slice.header.time_ns = now;
            slice.start_ns = tick * ms;
            inputs.push_command(&slice);
        }
        if tick == 100 {
            let mut pulse = pulse;
            pulse.header.time_ns = now;
            inputs.push_disturbance(&pulse);
        }
        // Every fifth tick is late by three periods.
        now += if tick % 5 == 4 { 3 * ms } else { ms };
        let out = board.step(now, &mut inputs);
        std::hint::black_box(out);
    }
    let after = allocations();
    assert_eq!(after - before, 0, "Board::step allocated");
    assert_eq!(board.counters.rejected, 0);
    assert_eq!(
        board.counters.watchdog_trips, 1,
        "the hold path was not exercised"
    );
    assert!(board.state().iter().all(|v| v.is_finite()));
}

/// What the real-time loop does with its ports each tick (`vic_rt::board::live`): drain the controls,
/// disturbances and command slices, publish the state, notify, and every 100th tick publish the
/// telemetry and notify, with a `CentralPorts` subscribed to the states and telemetry and sending
/// commands and controls, and a `ToolPorts` sending disturbances. Only the board's calls are
/// counted. iceoryx2 0.10 allocates the shared state of every loaned sample
/// (`ChunkMutSharedState::new` through the service's `ArcThreadSafetyPolicy`), so this fails
/// unless that policy recycles its blocks (`rt::transport::recycled`); the first ticks are a
/// warm-up (the first loan fills the recycling pool, the first notifications connect).
#[test]
fn the_board_ports_do_not_allocate_in_a_tick() {
    let ns = unique_namespace("bal");
    {
        let board = BoardPorts::open(&ns).unwrap();
        let central = CentralPorts::open(&ns).unwrap();
        let tool = ToolPorts::open(&ns).unwrap();
        let mut received = [0usize; 3];
        // Allocations of the board's calls in one tick: drains, publishes, notifications.
        let mut tick = |seq: u64| {
            let mut n = [0u64; 2];
            let before = allocations();
            received[0] += board.drain_controls(|c| {
                std::hint::black_box(c);
            });
            received[1] += board.drain_disturbances(|d| {
                std::hint::black_box(d);
            });
            received[2] += board.drain_commands(|c| {
                std::hint::black_box(c);
            });
            let mid = allocations();
            n[0] = mid - before;
            let s = StateMsg {
                header: Header::new(seq, 0),
                ..Default::default()
            };
            board.publish_state(&s).unwrap();
            board.notify(BoardEvent::Applied);
            if seq.is_multiple_of(100) {
                board.publish_telemetry(&Telemetry::default()).unwrap();
                board.notify(BoardEvent::Telemetry);
            }
            n[1] = allocations() - mid;
            n
        };
        // The other side, not counted: a command every 20 ticks, a control and a disturbance now
        // and then, the states and telemetry read.
        let other = |seq: u64| {
            if seq.is_multiple_of(20) {
                let c = CommandSlice {
                    header: Header::new(seq, 0),
                    ..Default::default()
                };
                central.publish_command(&c).unwrap();
            }
            if seq.is_multiple_of(250) {
                let c = Control {
                    header: Header::new(seq, 0),
                    kind: ControlKind::Reset as u32,
                    ..Default::default()
                };
                central.publish_control(&c).unwrap();
                let d = Disturbance {
                    header: Header::new(seq, 0),
                    kind: DisturbanceKind::Pulse as u32,
                    ..Default::default()
                };
                tool.publish_disturbance(&d).unwrap();
            }
            central.drain_states(|s| {
                std::hint::black_box(s);
            });
            std::hint::black_box(central.latest_telemetry());
        };
        // Warm-up: up to the first telemetry publish, which connects to the subscriber.
        let mut warm_up = 0;
        for seq in 1..=100 {
            other(seq);
            warm_up += tick(seq)[1];
        }
        let mut drains = 0;
        let mut publishes = 0;
        let mut first_allocating = 0;
        for seq in 101..=1100 {
            other(seq);
            let [d, p] = tick(seq);
            drains += d;
            publishes += p;
            if p > 0 && publishes == p {
                first_allocating = seq;
            }
        }
        assert_eq!(drains, 0, "allocations of the drains in 1000 ticks");
        assert_eq!(
            publishes, 0,
            "allocations of the publishes and notifications in 1000 ticks after {warm_up} in \
             the warm-up (the first at tick {})",
            first_allocating
        );
        // The drains saw what was sent: the counted path is the one that carries messages.
        assert_eq!(received, [4, 4, 55], "controls, disturbances, commands");
    }
    vic_rt::transport::remove_namespace(&ns);
}
