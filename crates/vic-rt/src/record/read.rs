//! Reading a board's MCAP recording back: the ticks as [`Sample`]s, the gaps and the metadata,
//! and writing them as the CSV log that `vic identify` reads (`vic convert`).

use super::Sample;
use super::csv::{format_row, gap_line, header};
use super::error::RecordError;
use super::mcap_file::{GAP_TOPIC, METADATA_NAME, TICK_TOPIC, TickMsg};
use crate::transport::MAX_JOINTS;
use mcap::records::Record;
use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;

/// Largest MCAP file read (the whole file is read into memory): 10 minutes at 1 kHz are about
/// 100 MB uncompressed.
const MAX_FILE_BYTES: u64 = 2 << 30;

/// What a board's MCAP recording holds.
#[derive(Debug, Clone, Default)]
pub struct BoardRecording {
    /// One sample per tick written, in file order.
    pub samples: Vec<Sample>,
    /// Gaps: (first tick missing, ticks missing), in file order.
    pub gaps: Vec<(u64, u64)>,
    /// Joints of the plant (the length of the per-joint arrays).
    pub joints: usize,
    /// The `vic` metadata record.
    pub metadata: BTreeMap<String, String>,
    /// Messages on other channels (not read).
    pub(crate) other_messages: u64,
}

/// A per-joint array of a tick message whose length is not the recording's number of joints.
#[derive(Debug, thiserror::Error)]
#[error("`{field}` has {entries} entries, not {joints}")]
struct JointCount {
    field: &'static str,
    entries: usize,
    joints: usize,
}

fn array(
    v: &[Option<f64>],
    field: &'static str,
    joints: usize,
) -> Result<[f64; MAX_JOINTS], JointCount> {
    if v.len() != joints {
        return Err(JointCount {
            field,
            entries: v.len(),
            joints,
        });
    }
    let mut a = [0.0; MAX_JOINTS];
    for (x, y) in a.iter_mut().zip(v) {
        *x = y.unwrap_or(f64::NAN);
    }
    Ok(a)
}

fn sample_of(m: &TickMsg<Vec<Option<f64>>>, joints: usize) -> Result<Sample, JointCount> {
    Ok(Sample {
        tick: m.tick,
        dropped_before: m.dropped_before,
        deadline_ns: m.deadline_ns,
        trial: m.trial,
        mode: m.mode,
        trial_time_ns: (m.trial_time * 1e9).round() as u64,
        periods: m.periods,
        command_seq: m.command_seq,
        disturbance_seq: m.disturbance_seq,
        q: array(&m.q, "q", joints)?,
        qd: array(&m.qd, "qd", joints)?,
        qdd: array(&m.qdd, "qdd", joints)?,
        tau: array(&m.tau, "tau", joints)?,
        tau_ext: array(&m.tau_ext, "tau_ext", joints)?,
        tau_ff: array(&m.tau_ff, "tau_ff", joints)?,
        stiffness: array(&m.stiffness, "stiffness", joints)?,
        damping: array(&m.damping, "damping", joints)?,
        q_d: array(&m.q_d, "q_d", joints)?,
        qd_d: array(&m.qd_d, "qd_d", joints)?,
    })
}

#[derive(serde::Deserialize)]
struct GapMsg {
    first_tick: u64,
    ticks: u64,
}

/// Reads the board recording `path` (written by `vic-board --record FILE.mcap`). Every tick
/// message must decode with its schema's fields and carry as many joints as the first.
pub fn read_board_mcap(path: &Path) -> Result<BoardRecording, RecordError> {
    let len = std::fs::metadata(path)
        .map_err(|e| RecordError::io(path, e))?
        .len();
    if len > MAX_FILE_BYTES {
        return Err(RecordError::format(
            path,
            format!("{len} bytes: larger than the {MAX_FILE_BYTES} bytes read at once"),
        ));
    }
    let bytes = std::fs::read(path).map_err(|e| RecordError::io(path, e))?;
    let mut rec = BoardRecording::default();
    for record in mcap::read::LinearReader::new(&bytes).map_err(|e| RecordError::mcap(path, e))? {
        if let Record::Metadata(m) = record.map_err(|e| RecordError::mcap(path, e))?
            && m.name == METADATA_NAME
        {
            rec.metadata = m.metadata;
        }
    }
    let stream = mcap::MessageStream::new(&bytes).map_err(|e| RecordError::mcap(path, e))?;
    for (index, message) in stream.enumerate() {
        let message = message.map_err(|e| RecordError::mcap(path, e))?;
        let bad = |what: String| {
            RecordError::format(
                path,
                format!("message {} on {}: {what}", index + 1, message.channel.topic),
            )
        };
        match message.channel.topic.as_str() {
            TICK_TOPIC => {
                let m: TickMsg<Vec<Option<f64>>> =
                    serde_json::from_slice(&message.data).map_err(|e| bad(e.to_string()))?;
                if rec.joints == 0 {
                    rec.joints = m.q.len();
                    if !(1..=MAX_JOINTS).contains(&rec.joints) {
                        return Err(bad(format!("{} joints", rec.joints)));
                    }
                }
                rec.samples
                    .push(sample_of(&m, rec.joints).map_err(|e| bad(e.to_string()))?);
            }
            GAP_TOPIC => {
                let g: GapMsg =
                    serde_json::from_slice(&message.data).map_err(|e| bad(e.to_string()))?;
                rec.gaps.push((g.first_tick, g.ticks));
            }
            _ => rec.other_messages += 1,
        }
    }
    if rec.samples.is_empty() && rec.gaps.is_empty() {
        return Err(RecordError::format(
            path,
            format!("no message on {TICK_TOPIC}: not a board recording (vic-board --record)"),
        ));
    }
    Ok(rec)
}

/// Writes `rec` as the CSV log of a board recording (the format of `vic-board --record
/// FILE.csv`), gaps marked as comments before the row that follows them.
pub fn write_csv(rec: &BoardRecording, out: &mut impl Write) -> std::io::Result<()> {
    let joints = rec.joints.max(1);
    writeln!(
        out,
        "# vic-board recording v1: {joints} joint(s), converted from MCAP; {}",
        rec.metadata
            .iter()
            .map(|(k, v)| format!("{k}={}", v.replace('\n', " ")))
            .collect::<Vec<_>>()
            .join("; ")
    )?;
    writeln!(out, "{}", header(joints))?;
    let t0 = rec.samples.first().map_or(0, |s| s.deadline_ns);
    let mut gaps = rec.gaps.iter().peekable();
    let mut line = String::with_capacity(1024);
    for s in &rec.samples {
        while let Some(&&(first, n)) = gaps.peek() {
            if first + n > s.tick {
                break;
            }
            gap_line(out, n, first)?;
            gaps.next();
        }
        line.clear();
        if !super::csv::log_columns_finite(s) {
            line.push_str("# non-finite: ");
        }
        format_row(&mut line, s, t0, joints);
        line.push('\n');
        out.write_all(line.as_bytes())?;
    }
    for &(first, n) in gaps {
        gap_line(out, n, first)?;
    }
    Ok(())
}
