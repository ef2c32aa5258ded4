//! The board's tick work and message validation: `cargo bench --bench board`.
//!
//! - `board_step_hold`: [`Board::step`] on the two-link arm in the divergent field (impedance
//!   law, one plant period, the noise draw), following a full hold slice: the pure tick work.
//! - `board_step_new_slice`: the same with a fresh 32-knot slice to validate and store every
//!   tick (the planner sends one every 20 ticks; this is the worst tick).
//! - `board_validate_full_slice`: [`Board::validate`] on a valid 32-knot slice.
//! - `board_tick_transport`: [`vic_rt::realtime::board_tick`]: drain the three subscriptions,
//!   step, publish the state over iceoryx2 to one subscriber (a namespace of its own).
//!
//! Target (issue 7): tick work p99 under 5 µs; `vic bench loop` measures its distribution live.

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::path::Path;
use vic::bench::loop_bench::{PERIOD_NS, board_config, hold_slice};
use vic_plan::scenario::Scenario;
use vic_rt::board::live::{BoardHistograms, board_tick};
use vic_rt::board::{Board, Inputs};
use vic_rt::realtime::Wake;
use vic_rt::transport::{BoardPorts, CentralPorts, Control, ControlKind, Header};

fn running_board() -> (Board, Vec<f64>, usize) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/two_link_divergent.toml");
    let s = Scenario::load(&path, &[]).expect("scenario loads");
    let setup = vic_plan::plan::setup(&s).expect("scenario sets up");
    let dof = s.model.dof();
    let q0 = setup.x0[..dof].to_vec();
    let mut b = Board::new(s.model.clone(), board_config(&s, PERIOD_NS), &q0).expect("a board");
    let mut inputs = Inputs::default();
    let mut reset = Control {
        header: Header::new(1, 0),
        kind: ControlKind::Reset as u32,
        trial: 1,
        seed: 1,
        start_ns: 0,
        ..Default::default()
    };
    reset.q0[..dof].copy_from_slice(&q0);
    inputs.push_control(&reset);
    b.step(0, &mut inputs);
    (b, q0, dof)
}

fn board(c: &mut Criterion) {
    // Pure step under a slice long enough for every iteration criterion runs: the slice is
    // re-sent (with a new sequence number) whenever the trial time nears its end.
    let (mut b, q0, dof) = running_board();
    let mut inputs = Inputs::default();
    let mut seq = 1;
    let mut now = 0;
    let mut covered = 0;
    c.bench_function("board_step_hold", |bench| {
        bench.iter(|| {
            now += PERIOD_NS;
            if now + 2 * PERIOD_NS >= covered {
                seq += 1;
                let start = now / 10_000_000 * 10_000_000;
                inputs.push_command(&hold_slice(dof, &q0, seq, 1, start, 100.0));
                covered = start + 320_000_000;
            }
            black_box(b.step(black_box(now), &mut inputs))
        })
    });

    let (mut b, q0, dof) = running_board();
    let mut now = 0;
    let mut seq = 1;
    c.bench_function("board_step_new_slice", |bench| {
        bench.iter(|| {
            now += PERIOD_NS;
            seq += 1;
            inputs.push_command(&hold_slice(
                dof,
                &q0,
                seq,
                1,
                now / 10_000_000 * 10_000_000,
                100.0,
            ));
            black_box(b.step(black_box(now), &mut inputs))
        })
    });

    let (b, q0, dof) = running_board();
    let slice = hold_slice(dof, &q0, 2, 1, 0, 100.0);
    assert_eq!(b.validate(&slice), Ok(()));
    c.bench_function("board_validate_full_slice", |bench| {
        bench.iter(|| black_box(b.validate(black_box(&slice))))
    });

    let ns = vic::bench::unique_namespace("bc");
    {
        let ep = BoardPorts::open(&ns).expect("board endpoint");
        let reader = CentralPorts::open(&ns).expect("planner endpoint");
        let (mut b, _, _) = running_board();
        let mut inputs = Inputs::default();
        let mut hist = BoardHistograms::default();
        let mut tick = 0u64;
        c.bench_function("board_tick_transport", |bench| {
            bench.iter(|| {
                tick += 1;
                let wake = Wake {
                    deadline_ns: tick * PERIOD_NS,
                    woke_ns: vic_rt::transport::monotonic_ns(),
                    ..Default::default()
                };
                let out = board_tick(&ep, &mut b, &mut inputs, &wake, tick, &mut hist);
                if tick.is_multiple_of(64) {
                    reader.drain_states(|_| {});
                }
                black_box(out)
            })
        });
    }
    vic_rt::transport::remove_namespace(&ns);
}

criterion_group!(benches, board);
criterion_main!(benches);
