//! A board tick allocates nothing: a counting global allocator watches `Board::step`.

mod common;

use common::alloc::{Counting, allocations};
use std::path::Path;
use vic::planning::scenario::Scenario;
use vic::rt::board::{Board, Inputs};
use vic::rt::transport::{
    CommandSlice, Control, ControlKind, Disturbance, DisturbanceKind, Header,
};

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn a_board_step_does_not_allocate() {
    let path = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/config/two_link_divergent.toml"
    ));
    let scenario = Scenario::load(path, &[]).unwrap();
    let setup = vic::planning::plan::setup(&scenario).unwrap();
    let q0 = [setup.x0[0], setup.x0[1]];
    let mut board = Board::new(
        scenario.model.clone(),
        vic::tools::launch::board_config(&scenario, 1_000_000),
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
