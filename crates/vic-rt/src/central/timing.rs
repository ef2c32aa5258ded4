//! When the central controller sees and sends: the feedback latency in plan steps, the delay
//! lines on the state and command paths, and how far each slice reaches.

use vic_core::latency::Latency;
use vic_core::policy::Strategy;

/// The rates the central controller may tick at [Hz], slowest first: each period a whole number
/// of the board's 1 ms ticks. 50 Hz is the paper's iCub central layer.
pub const PLANNER_RATES_HZ: [u64; 3] = [50, 100, 250];

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

    /// The rate at which the central controller runs `strategy` at `latency` so that the
    /// strategy means what it means in the offline Monte Carlo: the slowest of
    /// [`PLANNER_RATES_HZ`] whose own delay fits in the latency. A knot is computed up to one
    /// and a half lookaheads (three periods) before it acts ([`DelayLines::split`]), so at
    /// 50 Hz a latency below 60 ms would feed back states older than the `k − D` the plan
    /// assumes: at 0 ms the gains of an undelayed plan on states 40–60 ms old, which diverge.
    /// Below the fastest rate's 12 ms the fastest is taken: there knot `k` feeds back the state
    /// of `k − 1` (the state of knot `k` does not exist before the knot acts; counted as stale).
    /// The open-loop plan reads no state and the replanner re-solves once a 20 ms central period
    /// by definition, as offline: both at 50 Hz.
    pub fn planner_rate_hz(strategy: Strategy, latency: Latency) -> u64 {
        match strategy {
            Strategy::Stiffness | Strategy::Replan => PLANNER_RATES_HZ[0],
            Strategy::NaiveDelayed | Strategy::Predictor | Strategy::StiffnessPredictor => {
                PLANNER_RATES_HZ
                    .into_iter()
                    .find(|&hz| Self::own_delay_ms(1_000_000_000 / hz) <= latency.ms() + 1e-9)
                    .unwrap_or(PLANNER_RATES_HZ[PLANNER_RATES_HZ.len() - 1])
            }
        }
    }

    /// The planner's own delay [ms]: a knot is computed at the planner's first tick inside the
    /// lookahead, up to one and a half lookaheads (three periods) before it acts.
    pub fn own_delay_ms(planner_period_ns: u64) -> f64 {
        1.5 * Self::lookahead_ms(planner_period_ns)
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
        let rest = (latency.ms() - Timing::own_delay_ms(planner_period_ns)).max(0.0);
        DelayLines {
            sensor_ms: rest / 2.0,
            command_ms: rest / 2.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_planner_ticks_fast_enough_for_its_own_delay_to_fit_in_the_latency() {
        let at = |ms: f64| Latency::from_ms(ms, 0.01).expect("on the grid");
        let rate = |s, ms| Timing::planner_rate_hz(s, at(ms));
        for s in [
            Strategy::NaiveDelayed,
            Strategy::Predictor,
            Strategy::StiffnessPredictor,
        ] {
            for ms in [0.0, 10.0, 20.0, 30.0, 50.0, 60.0, 100.0, 200.0] {
                let hz = rate(s, ms);
                let period_ns = 1_000_000_000 / hz;
                let own = Timing::own_delay_ms(period_ns);
                // Its own delay fits (or it is the fastest rate) ...
                assert!(own <= ms || hz == 250, "{s:?} {ms} ms: {hz} Hz");
                // ... and no slower rate would fit: the slowest that does.
                let slower = PLANNER_RATES_HZ.iter().filter(|&&r| r < hz);
                for &r in slower {
                    assert!(Timing::own_delay_ms(1_000_000_000 / r) > ms);
                }
                // The delay lines then take the rest of the latency: states of k − D exactly.
                let lines = DelayLines::split(at(ms), period_ns);
                if own <= ms {
                    let total = lines.sensor_ms + lines.command_ms + own;
                    assert!((total - ms).abs() < 1e-9, "{s:?} {ms} ms: {lines:?}");
                }
            }
            assert_eq!(rate(s, 0.0), 250);
            assert_eq!(rate(s, 30.0), 100);
            assert_eq!(rate(s, 60.0), 50);
        }
        // The open-loop plan and the replanner keep the paper's 20 ms central period.
        for s in [Strategy::Stiffness, Strategy::Replan] {
            assert_eq!(rate(s, 0.0), 50);
        }
    }
}
