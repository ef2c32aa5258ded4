//! The CSV rows of a recording: the nine columns `vic identify` reads, then the board's extra
//! columns (prefixed `x_`, which the log reader ignores), one row per tick.

use super::Sample;
use std::fmt::Write as _;
use std::io::{self, Write};

/// The nine columns a log must contain (in any order), as `vic identify` reads them.
pub const LOG_COLUMNS: [&str; 9] = [
    "t",
    "q",
    "qd",
    "qdd",
    "tau_ff",
    "stiffness",
    "damping",
    "q_d",
    "qd_d",
];

/// The header line of a joint log (without the newline).
pub const LOG_HEADER: &str = "t,q,qd,qdd,tau_ff,stiffness,damping,q_d,qd_d";

/// Columns whose name starts with this prefix are accepted and ignored by `vic identify`.
pub const EXTRA_COLUMN_PREFIX: &str = "x_";

/// The header line for `joints` joints (without the newline).
pub fn header(joints: usize) -> String {
    let x = EXTRA_COLUMN_PREFIX;
    let mut h = LOG_COLUMNS.join(",");
    for name in [
        "tick",
        "dropped",
        "trial",
        "mode",
        "trial_time",
        "periods",
        "command_seq",
        "disturbance_seq",
        "tau_0",
        "tau_ext_0",
    ] {
        let _ = write!(h, ",{x}{name}");
    }
    for j in 1..joints {
        for name in LOG_COLUMNS.iter().skip(1).chain(&["tau", "tau_ext"]) {
            let _ = write!(h, ",{x}{name}_{j}");
        }
    }
    h
}

/// Appends the fields of `s` in the order of [`header`].
pub(super) fn format_row(line: &mut String, s: &Sample, t0_ns: u64, joints: usize) {
    let t = s.deadline_ns.saturating_sub(t0_ns) as f64 * 1e-9;
    let _ = write!(
        line,
        "{t},{},{},{},{},{},{},{},{}",
        s.q[0], s.qd[0], s.qdd[0], s.tau_ff[0], s.stiffness[0], s.damping[0], s.q_d[0], s.qd_d[0]
    );
    let _ = write!(
        line,
        ",{},{},{},{},{},{},{},{},{},{}",
        s.tick,
        s.dropped_before,
        s.trial,
        s.mode,
        s.trial_time_ns as f64 * 1e-9,
        s.periods,
        s.command_seq,
        s.disturbance_seq,
        s.tau[0],
        s.tau_ext[0]
    );
    for j in 1..joints {
        let _ = write!(
            line,
            ",{},{},{},{},{},{},{},{},{},{}",
            s.q[j],
            s.qd[j],
            s.qdd[j],
            s.tau_ff[j],
            s.stiffness[j],
            s.damping[j],
            s.q_d[j],
            s.qd_d[j],
            s.tau[j],
            s.tau_ext[j]
        );
    }
}

/// Whether the nine log columns of `s` are finite (a plant fault makes them NaN).
pub(super) fn log_columns_finite(s: &Sample) -> bool {
    [
        s.q[0],
        s.qd[0],
        s.qdd[0],
        s.tau_ff[0],
        s.stiffness[0],
        s.damping[0],
        s.q_d[0],
        s.qd_d[0],
    ]
    .iter()
    .all(|v| v.is_finite())
}

/// The comment line that marks `n` ticks lost from tick `first` on.
pub(super) fn gap_line(out: &mut impl Write, n: u64, first: u64) -> io::Result<()> {
    writeln!(
        out,
        "# gap: {n} ticks dropped (ticks {first} to {}): recording queue full",
        first + n - 1
    )
}
