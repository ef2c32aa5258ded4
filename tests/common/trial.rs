//! A real `vic-board` running a valid trial, for the tests that throw junk at it beside (or after)
//! a valid sender: the board, the central process's ports, the reset and the valid hold slices.

use super::daemons::{CONFIG, Daemons, unique_namespace};
use std::time::{Duration, Instant};
use vic::bench::loop_bench::hold_slice;
use vic_plan::plan::setup;
use vic_plan::scenario::Scenario;
use vic_rt::transport::{
    CentralPorts, CommandSlice, Control, ControlKind, Header, Rejection, Telemetry, monotonic_ns,
};

/// The valid sender's session.
pub const VALID_SESSION: u32 = 0x5AFE;
/// Period of the valid sender's slices (the planner's).
pub const VALID_PERIOD: Duration = Duration::from_millis(20);

/// A board in its own namespace, reset into trial 1 by [`VALID_SESSION`]. The ports are
/// dropped before the board is stopped and the namespace removed (field order).
pub struct LiveTrial {
    pub ep: CentralPorts,
    pub ns: String,
    /// The reset state's joint angles.
    pub q0: Vec<f64>,
    /// Monotonic time of the trial start [ns].
    pub start_ns: u64,
    /// Sequence number of the last valid slice sent.
    pub seq: u64,
    next_valid: Instant,
    pub daemons: Daemons,
}

impl LiveTrial {
    /// Starts a board (namespace `tag…`), waits for its telemetry and resets it into trial 1,
    /// starting 20 ms from now.
    pub fn start(tag: &str) -> LiveTrial {
        let scenario = Scenario::load(std::path::Path::new(CONFIG), &[]).unwrap();
        let q0 = setup(&scenario).unwrap().x0[..2].to_vec();
        let ns = unique_namespace(tag);
        let mut daemons = Daemons::default();
        daemons.board(&ns, &[]);
        let ep = CentralPorts::open(&ns).unwrap();
        assert!(ep.wait_for_telemetry(Duration::from_secs(20)).is_some());
        let start_ns = (monotonic_ns() + 20_000_000) / 1_000_000 * 1_000_000;
        let mut reset = Control {
            header: Header::in_session(VALID_SESSION, 1, monotonic_ns()),
            kind: ControlKind::Reset as u32,
            trial: 1,
            seed: 1,
            start_ns,
            ..Default::default()
        };
        reset.q0[..2].copy_from_slice(&q0);
        ep.publish_control(&reset).unwrap();
        LiveTrial {
            ep,
            ns,
            q0,
            start_ns,
            seq: 0,
            next_valid: Instant::now(),
            daemons,
        }
    }

    /// Publishes the next valid slice: a 100 N m/rad hold at the reset state from the present
    /// trial time (rounded down to 10 ms).
    pub fn send_hold(&mut self) -> CommandSlice {
        self.seq += 1;
        let t = monotonic_ns().saturating_sub(self.start_ns);
        let mut c = hold_slice(2, &self.q0, self.seq, 1, t / 10_000_000 * 10_000_000, 100.0);
        c.header = Header::in_session(VALID_SESSION, self.seq, monotonic_ns());
        self.ep.publish_command(&c).unwrap();
        c
    }

    /// Publishes a valid slice when one is due (every [`VALID_PERIOD`]); true when it did.
    pub fn keep_running(&mut self) -> bool {
        if Instant::now() < self.next_valid {
            return false;
        }
        self.send_hold();
        self.next_valid += VALID_PERIOD;
        true
    }

    /// When the next valid slice falls due.
    pub fn next_valid(&self) -> Instant {
        self.next_valid
    }

    /// Telemetry published after `after_ns`, the valid sender going on meanwhile when `running`
    /// (a blocking wait would let the watchdog expire).
    pub fn telemetry_after(&mut self, after_ns: u64, running: bool) -> Telemetry {
        let t0 = Instant::now();
        loop {
            if running {
                self.keep_running();
            }
            let t = if running {
                std::thread::sleep(Duration::from_millis(2));
                self.ep.latest_telemetry()
            } else {
                self.ep.wait_for_telemetry(Duration::from_millis(200))
            };
            if let Some(t) = t
                && t.header.time_ns > after_ns
            {
                return t;
            }
            assert!(t0.elapsed() < Duration::from_secs(5), "no telemetry");
        }
    }
}

/// Rejections between two telemetries, by reason name (the reasons with none left out).
pub fn rejected_by_reason(before: &Telemetry, after: &Telemetry) -> Vec<(&'static str, u64)> {
    Rejection::ALL
        .iter()
        .map(|r| {
            let i = *r as usize;
            (
                r.name(),
                after.rejected_by_reason[i] - before.rejected_by_reason[i],
            )
        })
        .filter(|(_, v)| *v > 0)
        .collect()
}
