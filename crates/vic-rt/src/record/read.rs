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
    /// Why reading stopped early in a file its board never closed ([`Recording::truncated`]).
    pub truncated: Option<String>,
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

/// Every message of a recording, in file order.
#[derive(Debug, Clone, Default)]
pub struct Recording {
    /// (topic, log time [ns], JSON payload) per message.
    pub messages: Vec<(String, u64, Vec<u8>)>,
    /// The metadata records by name.
    pub metadata: BTreeMap<String, BTreeMap<String, String>>,
    /// Why reading stopped before the end of a file that was not closed (a recorder killed, a
    /// disk that filled up): every whole chunk before that point was read. `None` for a closed
    /// file.
    pub truncated: Option<String>,
}

/// Reads the file whole (bounded by [`MAX_FILE_BYTES`]).
fn read_bytes(path: &Path) -> Result<Vec<u8>, RecordError> {
    let len = std::fs::metadata(path)
        .map_err(|e| RecordError::io(path, e))?
        .len();
    if len > MAX_FILE_BYTES {
        return Err(RecordError::format(
            path,
            format!("{len} bytes: larger than the {MAX_FILE_BYTES} bytes read at once"),
        ));
    }
    std::fs::read(path).map_err(|e| RecordError::io(path, e))
}

/// Reads every message and metadata record of the MCAP file `path`, also a file its recorder
/// never closed (killed with SIGKILL, a full disk): such a file has no summary or footer and
/// may end inside a chunk or a record; everything before its last whole chunk is read and
/// [`Recording::truncated`] says where reading stopped. A file that ends with the MCAP end
/// magic was closed, and any error in it is an error.
pub fn read_recording(path: &Path) -> Result<Recording, RecordError> {
    let bytes = read_bytes(path)?;
    if !bytes.starts_with(mcap::MAGIC) {
        return Err(RecordError::format(
            path,
            format!(
                "not an MCAP file ({} bytes, without the MCAP magic at the start)",
                bytes.len()
            ),
        ));
    }
    let closed = bytes.len() >= 2 * mcap::MAGIC.len() && bytes.ends_with(mcap::MAGIC);
    let mut rec = Recording::default();
    let mut stop = |e: mcap::McapError, what: &str| -> Result<(), RecordError> {
        if closed {
            return Err(RecordError::mcap(path, e));
        }
        if rec.truncated.is_none() {
            rec.truncated = Some(format!(
                "the file was not closed (no summary, no end magic; its recorder was killed or \
                 its disk filled up): {what} stopped at its unfinished end ({e})"
            ));
        }
        Ok(())
    };
    let mut metadata = BTreeMap::new();
    let options = mcap::read::Options::IgnoreEndMagic;
    for record in mcap::read::LinearReader::new_with_options(&bytes, options.into())
        .map_err(|e| RecordError::mcap(path, e))?
    {
        match record {
            Ok(Record::Metadata(m)) => {
                metadata.insert(m.name, m.metadata);
            }
            Ok(_) => {}
            Err(e) => {
                stop(e, "reading its records")?;
                break;
            }
        }
    }
    let mut messages = Vec::new();
    for message in mcap::MessageStream::new_with_options(&bytes, options.into())
        .map_err(|e| RecordError::mcap(path, e))?
    {
        match message {
            Ok(m) => messages.push((m.channel.topic.clone(), m.log_time, m.data.into_owned())),
            Err(e) => {
                stop(e, "reading its messages")?;
                break;
            }
        }
    }
    if !closed && rec.truncated.is_none() {
        rec.truncated = Some(
            "the file was not closed (no summary, no end magic; its recorder was killed or its \
             disk filled up): every record in it was read"
                .into(),
        );
    }
    rec.metadata = metadata;
    rec.messages = messages;
    Ok(rec)
}

/// Reads the board recording `path` (written by `vic-board --record FILE.mcap`), also one its
/// board never closed ([`read_recording`]). Every tick message must decode with its schema's
/// fields and carry as many joints as the first.
pub fn read_board_mcap(path: &Path) -> Result<BoardRecording, RecordError> {
    board_recording(read_recording(path)?, path)
}

/// The board recording in the messages of `file` (read from `path`, named in errors).
pub fn board_recording(file: Recording, path: &Path) -> Result<BoardRecording, RecordError> {
    let mut rec = BoardRecording {
        truncated: file.truncated,
        ..BoardRecording::default()
    };
    if let Some(m) = file.metadata.get(METADATA_NAME) {
        rec.metadata = m.clone();
    }
    for (index, (topic, _, data)) in file.messages.iter().enumerate() {
        let bad = |what: String| {
            RecordError::format(path, format!("message {} on {topic}: {what}", index + 1))
        };
        match topic.as_str() {
            TICK_TOPIC => {
                let m: TickMsg<Vec<Option<f64>>> =
                    serde_json::from_slice(data).map_err(|e| bad(e.to_string()))?;
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
                let g: GapMsg = serde_json::from_slice(data).map_err(|e| bad(e.to_string()))?;
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

/// What [`write_states_csv`] wrote.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StatesCsv {
    pub rows: usize,
    pub gaps: usize,
    pub joints: usize,
}

/// The per-joint columns of a states CSV, in the order written.
const STATE_JOINT_FIELDS: [&str; 5] = ["q", "qd", "tau", "tau_ext", "stiffness"];

#[derive(serde::Deserialize)]
struct StateRow {
    tick: u64,
    trial: u64,
    mode: u64,
    trial_time: Option<f64>,
    q: Vec<Option<f64>>,
    qd: Vec<Option<f64>>,
    tau: Vec<Option<f64>>,
    tau_ext: Vec<Option<f64>>,
    stiffness: Vec<Option<f64>>,
    command_seq: u64,
    disturbance_seq: u64,
}

/// Writes the board states of a namespace recording (`vic record`, channel `/state`) as CSV:
/// `t` (log time since the first state [s]), `tick`, `trial`, `mode`, `trial_time`, then
/// `q_<j>`, `qd_<j>`, `tau_<j>`, `tau_ext_<j>`, `stiffness_<j>` per joint, `command_seq`,
/// `disturbance_seq`; each gap on `/gap` (states the recorder missed) is a
/// `# gap: N states missed (ticks A to B)` comment. Every state must have the first one's
/// number of joints (1 to [`MAX_JOINTS`]). `path` names the recording in errors.
pub fn write_states_csv(
    rec: &Recording,
    path: &Path,
    out: &mut impl Write,
) -> Result<StatesCsv, RecordError> {
    let mut summary = StatesCsv::default();
    let mut t0 = None;
    let io = |e: std::io::Error| RecordError::io(path, e);
    let mut line = String::with_capacity(512);
    for (index, (topic, log_time, data)) in rec.messages.iter().enumerate() {
        let bad = |what: String| {
            RecordError::format(path, format!("message {} on {topic}: {what}", index + 1))
        };
        match topic.as_str() {
            "/state" => {
                let s: StateRow = serde_json::from_slice(data).map_err(|e| bad(e.to_string()))?;
                let arrays = [&s.q, &s.qd, &s.tau, &s.tau_ext, &s.stiffness];
                if summary.joints == 0 {
                    summary.joints = s.q.len();
                    if !(1..=MAX_JOINTS).contains(&summary.joints) {
                        return Err(bad(format!("{} joints", summary.joints)));
                    }
                    let mut header = String::from("t,tick,trial,mode,trial_time");
                    for f in STATE_JOINT_FIELDS {
                        for j in 0..summary.joints {
                            header.push_str(&format!(",{f}_{j}"));
                        }
                    }
                    header.push_str(",command_seq,disturbance_seq");
                    writeln!(
                        out,
                        "# vic record states v1: {} joint(s), converted from MCAP; {}",
                        summary.joints,
                        rec.metadata
                            .get(METADATA_NAME)
                            .into_iter()
                            .flatten()
                            .map(|(k, v)| format!("{k}={}", v.replace('\n', " ")))
                            .collect::<Vec<_>>()
                            .join("; ")
                    )
                    .map_err(io)?;
                    writeln!(out, "{header}").map_err(io)?;
                }
                for (f, a) in STATE_JOINT_FIELDS.iter().zip(arrays) {
                    if a.len() != summary.joints {
                        return Err(bad(format!(
                            "`{f}` has {} entries, not {}",
                            a.len(),
                            summary.joints
                        )));
                    }
                }
                let t0 = *t0.get_or_insert(*log_time);
                let num = |x: Option<f64>| x.map_or("nan".to_string(), |x| format!("{x:e}"));
                line.clear();
                line.push_str(&format!(
                    "{},{},{},{},{}",
                    log_time.saturating_sub(t0) as f64 * 1e-9,
                    s.tick,
                    s.trial,
                    s.mode,
                    num(s.trial_time)
                ));
                for a in arrays {
                    for x in a {
                        line.push(',');
                        line.push_str(&num(*x));
                    }
                }
                line.push_str(&format!(",{},{}\n", s.command_seq, s.disturbance_seq));
                out.write_all(line.as_bytes()).map_err(io)?;
                summary.rows += 1;
            }
            "/gap" => {
                let g: GapMsg = serde_json::from_slice(data).map_err(|e| bad(e.to_string()))?;
                if g.ticks > 0 {
                    writeln!(
                        out,
                        "# gap: {} states missed (ticks {} to {})",
                        g.ticks,
                        g.first_tick,
                        g.first_tick.saturating_add(g.ticks - 1)
                    )
                    .map_err(io)?;
                }
                summary.gaps += 1;
            }
            _ => {}
        }
    }
    if summary.rows == 0 {
        return Err(RecordError::format(
            path,
            "no message on /board/tick or /state: neither a board recording (vic-board --record) \
             nor a namespace recording (vic record)",
        ));
    }
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::mcap_file::McapOut;
    use crate::record::schema;

    fn temp(tag: &str) -> std::path::PathBuf {
        std::env::temp_dir().join(format!("vic-read-{tag}-{}.mcap", std::process::id()))
    }

    /// Writes 5 flushes of 40 gap messages each (numbered 0..200), then 17 more unflushed;
    /// returns the file's length after each flush.
    fn write_flushed(path: &Path) -> (McapOut, Vec<u64>) {
        let _ = std::fs::remove_file(path);
        let file = std::fs::File::create(path).unwrap();
        let mut out = McapOut::start(file, &BTreeMap::new()).unwrap();
        let ch = out.channel(&schema::GAP).unwrap();
        out.flush().unwrap();
        let mut ends = vec![out.flushed_bytes()];
        for i in 0..217u64 {
            out.write(ch, i, i, &schema::gap_json(i, 1, "test"))
                .unwrap();
            if i % 40 == 39 && i < 200 {
                out.flush().unwrap();
                ends.push(out.flushed_bytes());
            }
        }
        (out, ends)
    }

    fn numbers(rec: &Recording) -> Vec<u64> {
        rec.messages
            .iter()
            .map(|(_, _, d)| serde_json::from_slice::<GapMsg>(d).unwrap().first_tick)
            .collect()
    }

    /// A file cut at any byte after its header (what SIGKILL leaves between two flushes, or in
    /// the middle of one) reads back with every message of the chunks that were complete before
    /// the cut, in order, and says it was not closed.
    #[test]
    fn a_file_cut_anywhere_reads_back_up_to_its_last_whole_chunk() {
        let path = temp("cut");
        let (out, ends) = write_flushed(&path);
        // The unflushed tail may or may not have reached the file; the flushes did.
        std::mem::forget(out);
        let bytes = std::fs::read(&path).unwrap();
        assert!(bytes.len() as u64 >= *ends.last().unwrap());
        let cut = temp("cut-part");
        let mut last = 0;
        for k in (ends[0] as usize..=bytes.len()).step_by(29) {
            std::fs::write(&cut, &bytes[..k]).unwrap();
            let rec = read_recording(&cut).unwrap_or_else(|e| panic!("cut at {k}: {e}"));
            let n = numbers(&rec);
            let whole = ends.iter().filter(|&&e| e as usize <= k).count() - 1;
            assert!(
                n.len() >= 40 * whole,
                "cut at {k}: {} messages, {whole} whole chunks",
                n.len()
            );
            assert!(
                n.len() >= last,
                "cut at {k}: fewer messages than a shorter cut"
            );
            assert_eq!(n, (0..n.len() as u64).collect::<Vec<_>>(), "cut at {k}");
            assert!(
                rec.truncated.is_some(),
                "cut at {k}: not reported as unfinished"
            );
            last = n.len();
        }
        std::fs::remove_file(&path).unwrap();
        std::fs::remove_file(&cut).unwrap();
    }

    /// After a write error the file is cut back to the last flush and closed: the strict reader
    /// of the mcap crate (which requires the end magic) reads exactly the flushed messages.
    #[test]
    fn a_salvaged_file_is_a_closed_mcap_with_every_flushed_message() {
        let path = temp("salvage");
        let (mut out, ends) = write_flushed(&path);
        let len = out.salvage().unwrap();
        assert_eq!(len, ends.last().unwrap() + 50);
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(bytes.len() as u64, len);
        let strict: Vec<u64> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(|m| {
                serde_json::from_slice::<GapMsg>(&m.unwrap().data)
                    .unwrap()
                    .first_tick
            })
            .collect();
        assert_eq!(strict, (0..200).collect::<Vec<_>>());
        let rec = read_recording(&path).unwrap();
        assert_eq!(numbers(&rec), strict);
        assert!(rec.truncated.is_none());
        drop(out);
        // Dropping the salvaged writer writes nothing more.
        assert_eq!(std::fs::read(&path).unwrap().len() as u64, len);
        std::fs::remove_file(&path).unwrap();
    }

    /// A closed file with a damaged middle is an error, not a silent truncation.
    #[test]
    fn damage_inside_a_closed_file_is_an_error() {
        let path = temp("damage");
        let (mut out, ends) = write_flushed(&path);
        out.flush().unwrap();
        out.finish().unwrap();
        drop(out);
        let mut bytes = std::fs::read(&path).unwrap();
        assert!(read_recording(&path).unwrap().truncated.is_none());
        // The opcode of the second chunk's first record.
        bytes[ends[1] as usize] = 0xEE;
        bytes[ends[1] as usize + 1..ends[1] as usize + 9].copy_from_slice(&u64::MAX.to_le_bytes());
        std::fs::write(&path, &bytes).unwrap();
        assert!(read_recording(&path).is_err());
        std::fs::remove_file(&path).unwrap();
    }
}
