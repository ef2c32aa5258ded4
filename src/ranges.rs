//! The ranges of the numeric flags of every binary, checked while clap parses (a value outside
//! is refused with exit code 2 before anything runs, never a panic later): one parser per kind
//! of number, used as `value_parser = real(0.0, 3600.0)`.
//!
//! Each flag's help ends with `[range: MIN to MAX]`, the bounds its parser enforces (inclusive),
//! so `--help` is the manual and a test (`tests/numeric_flags.rs`) checks every flag it lists
//! against its stated range. The error names the value and the range; clap adds the flag:
//! `invalid value '1e300' for '--duration-s <DURATION_S>': 1e300 is not in the range 0 to 604800`.

use std::fmt::Display;
use std::str::FromStr;

/// The longest a run of a daemon or recorder may be asked to last [s]: a week (0, where a flag
/// allows it, means until stopped).
pub(crate) const MAX_RUN_S: f64 = 604_800.0;

/// The longest wait for a board or an answer [s]: an hour.
pub(crate) const MAX_WAIT_S: f64 = 3_600.0;

/// The longest feedback latency or delay line [ms]: 1 s, five times the paper's 200 ms and
/// longer than most movements. A plan for a latency of `d` knots has the delay-augmented state
/// `n + d m`, its memory growing as the square: the two-link arm at 1 s (100 knots of 10 ms)
/// takes 1.7 GB and 4 s to plan; 10 s did not fit in memory.
pub(crate) const MAX_LATENCY_MS: f64 = 1_000.0;

/// The most trials of one run.
pub(crate) const MAX_TRIALS: u64 = 100_000;

/// The largest disturbance torque a command may name [N m]: the largest `board.max_pulse_torque`
/// and `board.max_load_torque` a scenario may set (the board applies its own, smaller limit).
pub(crate) const MAX_TORQUE_NM: f64 = 200.0;

/// The longest pulse [ms]: the largest `board.max_pulse_duration` a scenario may set.
pub(crate) const MAX_PULSE_MS: f64 = 10_000.0;

/// The largest β of the divergent field [N/m]: the largest `board.max_field_beta`.
pub(crate) const MAX_FIELD_BETA: f64 = 5_000.0;

/// The largest noise factor: the largest `board.max_noise_factor`.
pub(crate) const MAX_NOISE_FACTOR: f64 = 100.0;

/// The largest divergence radius [mm for the arm, degrees for a joint].
pub(crate) const MAX_DIVERGENCE: f64 = 100_000.0;

/// The longest spin before a deadline [µs]: 10 ms (a period of a 100 Hz loop).
pub(crate) const MAX_SPIN_US: u64 = 10_000;

/// The parser of a flag taking a real number in `[min, max]` (NaN and infinities never are).
pub(crate) fn real(
    min: f64,
    max: f64,
) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync + 'static {
    move |s: &str| {
        let v: f64 = s
            .trim()
            .parse()
            .map_err(|_| format!("'{s}' is not a number in the range {min} to {max}"))?;
        if v.is_finite() && (min..=max).contains(&v) {
            Ok(v)
        } else {
            Err(format!("{s} is not in the range {min} to {max}"))
        }
    }
}

/// The parser of a flag taking a whole number in `[min, max]` (of the flag's integer type:
/// `u64`, `usize`, `i64`, `u16`, `i32`).
pub(crate) fn whole<T>(min: T, max: T) -> impl Fn(&str) -> Result<T, String> + Clone + Send + Sync
where
    T: FromStr + PartialOrd + Display + Copy + Send + Sync + 'static,
{
    move |s: &str| {
        let v: T = s
            .trim()
            .parse()
            .map_err(|_| format!("'{s}' is not a whole number in the range {min} to {max}"))?;
        if v >= min && v <= max {
            Ok(v)
        } else {
            Err(format!("{s} is not in the range {min} to {max}"))
        }
    }
}

/// The parser of a count of trials in `[min, MAX_TRIALS]`; below `min` the error says why fewer
/// will not do.
pub(crate) fn trials(
    min: u64,
    why: &'static str,
) -> impl Fn(&str) -> Result<u64, String> + Clone + Send + Sync + 'static {
    let count = whole(min, MAX_TRIALS);
    move |s: &str| match s.trim().parse::<u64>() {
        Ok(n) if n < min => Err(format!(
            "{n} is not in the range {min} to {MAX_TRIALS}: at least {min} trials are needed: {why}"
        )),
        _ => count(s),
    }
}

/// A flag's seconds as a `Duration`; the parser has bounded them (no overflow, no NaN).
pub(crate) fn seconds(s: f64) -> std::time::Duration {
    std::time::Duration::from_secs_f64(s.max(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reals_outside_the_range_and_non_numbers_are_refused_naming_the_range() {
        let p = real(0.0, 3600.0);
        assert_eq!(p("0").unwrap(), 0.0);
        assert_eq!(p("3600").unwrap(), 3600.0);
        for bad in [
            "nan", "NaN", "inf", "-inf", "1e300", "-1", "3600.5", "x", "",
        ] {
            let e = p(bad).unwrap_err();
            assert!(e.contains("0 to 3600"), "{bad}: {e}");
        }
    }

    #[test]
    fn whole_numbers_outside_the_range_overflows_and_fractions_are_refused() {
        let p = whole(1u64, 10_000);
        assert_eq!(p("10000").unwrap(), 10_000);
        for bad in [
            "0",
            "10001",
            "-1",
            "1.5",
            "1e3",
            "18446744073709551616",
            "nan",
        ] {
            let e = p(bad).unwrap_err();
            assert!(e.contains("1 to 10000"), "{bad}: {e}");
        }
        let seed = whole(0u64, u64::MAX);
        assert_eq!(seed("18446744073709551615").unwrap(), u64::MAX);
        assert!(seed("18446744073709551616").is_err());
    }

    #[test]
    fn the_largest_durations_convert_without_overflow() {
        assert_eq!(seconds(MAX_RUN_S).as_secs(), 604_800);
        assert_eq!(seconds(MAX_WAIT_S).as_secs(), 3_600);
        // The board's tick count at the largest duration and rate.
        assert!(MAX_RUN_S * 10_000.0 < u64::MAX as f64);
    }

    #[test]
    fn too_few_trials_say_why() {
        let p = trials(3, "the ellipse needs three");
        assert!(p("2").unwrap_err().contains("the ellipse needs three"));
        assert!(p("100001").unwrap_err().contains("3 to 100000"));
        assert_eq!(p("3").unwrap(), 3);
    }
}
