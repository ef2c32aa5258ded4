//! A feedback latency on a plan's grid: the `D` of paper Eq. 13, the number of steps by which
//! the central controller sees the state late. Given in milliseconds by the user, it must be a
//! whole number of plan steps Δ; [`Latency::from_ms`] is the one place that checks it and
//! converts, and the rest of the code reads [`Latency::knots`] (the policy's delay) and
//! [`Latency::ms`] (what is printed and recorded, exactly as given).

/// A feedback latency that is a whole number of plan steps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Latency {
    ms: f64,
    knots: usize,
}

/// A latency that is not a whole number of plan steps (or is negative or not a number).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("latency {ms} ms: not a whole number of {step_ms} ms plan steps")]
pub struct LatencyError {
    /// The latency asked for [ms].
    pub ms: f64,
    /// The plan step Δ [ms].
    pub step_ms: f64,
}

/// How far from a whole number of steps a latency may be and still count as one (the rounding
/// of a decimal number of ms divided by a decimal step).
const WHOLE_TOLERANCE: f64 = 1e-6;

impl Latency {
    /// No latency: the controller sees the present state.
    pub const ZERO: Latency = Latency { ms: 0.0, knots: 0 };

    /// `ms` milliseconds on a grid of steps of `dt` seconds, if it is a whole number ≥ 0 of them.
    pub fn from_ms(ms: f64, dt: f64) -> Result<Latency, LatencyError> {
        let knots = ms / 1000.0 / dt;
        if !(knots >= 0.0 && (knots - knots.round()).abs() <= WHOLE_TOLERANCE) {
            return Err(LatencyError {
                ms,
                step_ms: dt * 1000.0,
            });
        }
        Ok(Latency {
            // −0 ms is 0 ms.
            ms: ms + 0.0,
            knots: knots.round() as usize,
        })
    }

    /// `knots` steps of `dt` seconds.
    pub fn from_knots(knots: usize, dt: f64) -> Latency {
        Latency {
            ms: knots as f64 * dt * 1000.0,
            knots,
        }
    }

    /// The latency in milliseconds, as given.
    pub fn ms(self) -> f64 {
        self.ms
    }

    /// The latency in plan steps: knot `k` feeds back the state of knot `k − D`.
    pub fn knots(self) -> usize {
        self.knots
    }

    /// Whether there is no latency at all.
    pub fn is_zero(self) -> bool {
        self.knots == 0
    }
}

impl std::fmt::Display for Latency {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} ms", self.ms)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whole_steps_convert_and_the_rest_is_refused_with_the_value_and_the_step() {
        let l = Latency::from_ms(200.0, 0.01).unwrap();
        assert_eq!((l.ms(), l.knots()), (200.0, 20));
        // 0.1 ms steps: 30 ms is 300 steps although 30 / 1000 / 0.0001 is not exactly 300.
        assert_eq!(Latency::from_ms(30.0, 0.0001).unwrap().knots(), 300);
        assert_eq!(Latency::from_ms(-0.0, 0.01).unwrap(), Latency::ZERO);
        let e = Latency::from_ms(205.0, 0.01).unwrap_err();
        assert_eq!(
            e.to_string(),
            "latency 205 ms: not a whole number of 10 ms plan steps"
        );
        for bad in [-10.0, f64::NAN, f64::INFINITY] {
            assert!(Latency::from_ms(bad, 0.01).is_err(), "{bad} accepted");
        }
    }

    #[test]
    fn knots_give_back_the_ms_of_the_plan_file() {
        let l = Latency::from_knots(20, 0.01);
        assert_eq!(l.knots(), 20);
        assert_eq!(l.ms(), 20.0 * 0.01 * 1000.0);
        assert_eq!(Latency::from_ms(l.ms(), 0.01).unwrap().knots(), 20);
    }
}
