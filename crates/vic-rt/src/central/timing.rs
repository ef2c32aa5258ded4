//! When the central controller sees and sends: the feedback latency in plan steps, the delay
//! lines on the state and command paths, and how far each slice reaches.

use vic_core::latency::Latency;

/// Timing of the central controller.
#[derive(Debug, Clone, Copy)]
pub struct Timing {
    /// Feedback latency `D` in plan steps: knot `k` feeds back the state of knot `k − D`.
    pub latency_steps: usize,
    /// Delay lines on the state and command paths [ns].
    pub sensor_latency_ns: u64,
    pub command_latency_ns: u64,
    /// How far past the command's arrival each slice reaches [ns] (default: two planner periods).
    pub(crate) lookahead_ns: u64,
}

impl Timing {
    /// The timing of a controller whose feedback sees the state `latency` late, ticking every
    /// `planner_period_ns`, with `lines` on the state and command paths; each slice reaches two
    /// planner periods past its arrival ([`Timing::lookahead_ms`]).
    pub fn new(latency: Latency, planner_period_ns: u64, lines: DelayLines) -> Self {
        let ns = |ms: f64| (ms * 1e6) as u64;
        Timing {
            latency_steps: latency.knots(),
            sensor_latency_ns: ns(lines.sensor_ms),
            command_latency_ns: ns(lines.command_ms),
            lookahead_ns: ns(Self::lookahead_ms(planner_period_ns)),
        }
    }

    /// [`Timing::new`] with the default delay lines ([`DelayLines::split`]).
    pub fn split(latency: Latency, planner_period_ns: u64) -> Self {
        Self::new(
            latency,
            planner_period_ns,
            DelayLines::split(latency, planner_period_ns),
        )
    }

    /// How far past its arrival a slice reaches [ms]: two planner periods.
    pub fn lookahead_ms(planner_period_ns: u64) -> f64 {
        2.0 * planner_period_ns as f64 * 1e-6
    }
}

/// The delay lines on the state and command paths [ms].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DelayLines {
    pub sensor_ms: f64,
    pub command_ms: f64,
}

impl DelayLines {
    /// The default split of a feedback latency for a planner ticking every `planner_period_ns`:
    /// what remains after the slice lookahead and one more planner period (the planner computes
    /// a knot at its first tick inside the lookahead), shared equally.
    pub fn split(latency: Latency, planner_period_ns: u64) -> DelayLines {
        let rest = (latency.ms() - 1.5 * Timing::lookahead_ms(planner_period_ns)).max(0.0);
        DelayLines {
            sensor_ms: rest / 2.0,
            command_ms: rest / 2.0,
        }
    }
}
