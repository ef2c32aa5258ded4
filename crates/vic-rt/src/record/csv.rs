//! The CSV rows of a recording: the nine columns `vic identify` reads, then the board's extra
//! columns (prefixed `x_`, which the log reader ignores), one row per tick.

use super::{RecordOptions, Sample, Sink};
use std::fmt::Write as _;
use std::io::{self, Seek, Write};

/// The CSV file of a recording: a banner, the header, one row per tick, comments for gaps.
pub(super) struct CsvSink {
    out: Option<io::BufWriter<std::fs::File>>,
    /// A duplicate of the file's descriptor (same offset), to cut the file after an error.
    file: std::fs::File,
    /// The file's length after the last flush (whole lines only).
    safe_end: u64,
    line: String,
    joints: usize,
}

impl CsvSink {
    /// Writes the banner and the header to `file`.
    pub(super) fn start(file: std::fs::File, opts: &RecordOptions) -> io::Result<CsvSink> {
        let dup = file.try_clone()?;
        let mut out = io::BufWriter::with_capacity(1 << 16, file);
        writeln!(
            out,
            "# vic-board recording v1: {} joint(s), queue {} ticks{}{}",
            opts.joints,
            opts.capacity,
            if opts.banner.is_empty() { "" } else { "; " },
            opts.banner.replace('\n', " ")
        )?;
        out.write_all(header(opts.joints).as_bytes())?;
        out.write_all(b"\n")?;
        out.flush()?;
        let safe_end = out.get_ref().stream_position()?;
        Ok(CsvSink {
            out: Some(out),
            file: dup,
            safe_end,
            line: String::with_capacity(1024),
            joints: opts.joints,
        })
    }
}

impl CsvSink {
    fn out(&mut self) -> io::Result<&mut io::BufWriter<std::fs::File>> {
        self.out
            .as_mut()
            .ok_or_else(|| io::Error::other("the CSV file is already closed"))
    }
}

impl Sink for CsvSink {
    fn sample(&mut self, s: &Sample, t0_ns: u64) -> io::Result<()> {
        self.line.clear();
        if !log_columns_finite(s) {
            self.line.push_str("# non-finite: ");
        }
        format_row(&mut self.line, s, t0_ns, self.joints);
        self.line.push('\n');
        let out = self
            .out
            .as_mut()
            .ok_or_else(|| io::Error::other("the CSV file is already closed"))?;
        out.write_all(self.line.as_bytes())
    }
    fn gap(&mut self, n: u64, first: u64, _log_time_ns: u64) -> io::Result<()> {
        gap_line(self.out()?, n, first)
    }
    fn flush(&mut self) -> io::Result<()> {
        let out = self.out()?;
        out.flush()?;
        self.safe_end = out.get_ref().stream_position()?;
        Ok(())
    }
    fn finish(&mut self) -> io::Result<()> {
        self.flush()?;
        self.out()?.get_ref().sync_data()
    }
    /// Cuts the file back to the last flush: whole lines only.
    fn salvage(&mut self) -> io::Result<u64> {
        if let Some(out) = self.out.take() {
            let (file, _buffered) = out.into_parts();
            drop(file);
        }
        self.file.set_len(self.safe_end)?;
        let _ = self.file.sync_data();
        Ok(self.safe_end)
    }
}

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
pub(crate) fn format_row(line: &mut String, s: &Sample, t0_ns: u64, joints: usize) {
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
pub(crate) fn log_columns_finite(s: &Sample) -> bool {
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
pub(crate) fn gap_line(out: &mut impl Write, n: u64, first: u64) -> io::Result<()> {
    writeln!(
        out,
        "# gap: {n} ticks dropped (ticks {first} to {}): recording queue full",
        first + n - 1
    )
}
