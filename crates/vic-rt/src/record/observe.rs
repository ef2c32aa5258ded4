//! What an observer of a namespace sees: every message of every service as an [`Item`], in
//! the order [`drain`] takes them, with the states it missed counted from the board's sequence
//! numbers and given as a gap first. `vic record` writes the items to an MCAP file, `vic view`
//! serves them to Foxglove: the same channels, schemas and gap accounting in both.

use super::schema::{self, ChannelSpec};
use crate::transport::{CommandSlice, Control, Disturbance, RecorderPorts, StateMsg, Telemetry};
use serde_json::Value;

/// The channels of an observed namespace, in [`Item::channel`]'s order.
pub(crate) const SPECS: [&ChannelSpec; 6] = [
    &schema::STATE,
    &schema::COMMAND,
    &schema::CONTROL,
    &schema::DISTURBANCE,
    &schema::TELEMETRY,
    &schema::GAP,
];
pub(crate) const STATE: usize = 0;
pub(crate) const GAP: usize = 5;

/// One message as it arrived, or states that never did.
pub(crate) enum Item<'a> {
    State(&'a StateMsg),
    Command(&'a CommandSlice),
    Control(&'a Control),
    Disturbance(&'a Disturbance),
    Telemetry(&'a Telemetry),
    /// `missing` states before the one stamped `time_ns`, from tick `first_tick` on.
    Gap {
        time_ns: u64,
        first_tick: u64,
        missing: u64,
    },
}

impl Item<'_> {
    /// Its index in [`SPECS`].
    pub(crate) fn channel(&self) -> usize {
        match self {
            Item::State(_) => 0,
            Item::Command(_) => 1,
            Item::Control(_) => 2,
            Item::Disturbance(_) => 3,
            Item::Telemetry(_) => 4,
            Item::Gap { .. } => GAP,
        }
    }

    /// The sender's stamp [ns, CLOCK_MONOTONIC].
    pub(crate) fn time_ns(&self) -> u64 {
        match self {
            Item::State(m) => m.header.time_ns,
            Item::Command(m) => m.header.time_ns,
            Item::Control(m) => m.header.time_ns,
            Item::Disturbance(m) => m.header.time_ns,
            Item::Telemetry(m) => m.header.time_ns,
            Item::Gap { time_ns, .. } => *time_ns,
        }
    }

    /// The message as its channel's schema describes it.
    pub(crate) fn json(&self) -> Value {
        match self {
            Item::State(m) => schema::state_json(m),
            Item::Command(m) => schema::command_json(m),
            Item::Control(m) => schema::control_json(m),
            Item::Disturbance(m) => schema::disturbance_json(m),
            Item::Telemetry(m) => schema::telemetry_json(m),
            Item::Gap {
                first_tick,
                missing,
                ..
            } => schema::gap_json(*first_tick, *missing, "observer missed states"),
        }
    }
}

/// Loss accounting of the state stream.
#[derive(Default)]
pub(crate) struct StateTrack {
    last_seq: u64,
    /// First and last tick seen (0: none yet).
    pub first_tick: u64,
    pub last_tick: u64,
    /// States missed, and the gaps they came in.
    pub lost: u64,
    pub gaps: u64,
}

/// Hands everything waiting on every service to `f`: the states first (each preceded by a
/// [`Item::Gap`] when states were missed before it), then command slices, control requests,
/// disturbances and telemetry.
pub(crate) fn drain(ports: &RecorderPorts, track: &mut StateTrack, mut f: impl FnMut(Item)) {
    ports.drain_states(|s| {
        // A board numbers its states 1, 2, …; a jump is states this observer missed. A restart
        // of the board (numbers going back) starts a new count.
        if track.last_seq > 0 && s.header.seq > track.last_seq + 1 {
            let missing = s.header.seq - track.last_seq - 1;
            track.lost += missing;
            track.gaps += 1;
            f(Item::Gap {
                time_ns: s.header.time_ns,
                first_tick: s.tick.saturating_sub(missing),
                missing,
            });
        }
        if track.first_tick == 0 {
            track.first_tick = s.tick;
        }
        track.last_seq = s.header.seq;
        track.last_tick = s.tick;
        f(Item::State(s));
    });
    ports.drain_commands(|c| f(Item::Command(c)));
    ports.drain_controls(|c| f(Item::Control(c)));
    ports.drain_disturbances(|d| f(Item::Disturbance(d)));
    ports.drain_telemetry(|t| f(Item::Telemetry(t)));
}
