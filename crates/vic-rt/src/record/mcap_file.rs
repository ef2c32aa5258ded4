//! MCAP recordings: JSON messages described by JSON Schemas, in lz4-compressed chunks.
//!
//! A board recording (`vic-board --record run.mcap`) has the channels
//!
//! | topic | one message per | content |
//! |---|---|---|
//! | [`TICK_TOPIC`] (`/board/tick`) | tick written | the fields of the CSV log ([`TickMsg`]) |
//! | [`GAP_TOPIC`] (`/board/gap`) | gap | `first_tick`, `ticks`, `reason`: ticks the queue dropped |
//!
//! and a metadata record named [`METADATA_NAME`] (vic version, command line, scenario, rate,
//! namespace, joints). Log and publish times are the tick's deadline on the board's
//! `CLOCK_MONOTONIC` (the clock every process of the machine shares), so the board's file and
//! an external recording of the same run (`vic record`) share one time axis.

use super::schema::{ChannelSpec, Field, Kind, fields, gap_json};
use super::{RecordOptions, Sample, Sink};
use crate::transport::MAX_JOINTS;
use mcap::records::{MessageHeader, Metadata};
use mcap::{Compression, WriteOptions, Writer};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{self, BufWriter, Seek, SeekFrom, Write};

/// Topic of the board's per-tick messages.
pub const TICK_TOPIC: &str = "/board/tick";
/// Topic of the board recording's gap messages.
pub const GAP_TOPIC: &str = "/board/gap";
/// Name of the metadata record of every `vic` recording.
pub(crate) const METADATA_NAME: &str = "vic";
/// The MCAP profile field: none of the standard profiles (ros1, ros2) applies.
const PROFILE: &str = "";

/// The board's tick channel.
pub(crate) const TICK: ChannelSpec = ChannelSpec {
    topic: TICK_TOPIC,
    schema: "vic.BoardTick",
    doc: "One tick of the board's 1 kHz loop: state, the impedance-law inputs in use (Eq. 4), disturbances",
    fields: fields![
        tick: Int "loop tick, 1 for the first; consecutive unless a gap is marked",
        dropped_before: Int "ticks dropped just before this one (queue full)",
        deadline_ns: Int "tick deadline [ns, CLOCK_MONOTONIC]",
        t: Num "deadline since the first recorded tick [s]",
        trial: Int "trial",
        mode: Int "0 idle, 1 running, 2 safe-hold, 3 fault",
        trial_time: Num "plant time of the trial [s]",
        periods: Int "plant periods integrated by the tick",
        command_seq: Int "sequence number of the command slice in use",
        disturbance_seq: Int "last disturbance in use",
        q: Nums "joint angles [rad]",
        qd: Nums "joint velocities [rad/s]",
        qdd: Nums "joint accelerations over the period [rad/s^2]",
        tau: Nums "joint torque applied [N m]",
        tau_ext: Nums "external (disturbance) torque [N m]",
        tau_ff: Nums "feedforward torque of the law [N m]",
        stiffness: Nums "stiffness K_P of the law [N m/rad]",
        damping: Nums "damping K_D of the law [N m s/rad]",
        q_d: Nums "equilibrium of the law [rad]",
        qd_d: Nums "equilibrium velocity of the law [rad/s]",
    ],
};

/// The board recording's gap channel.
pub(crate) const GAP: ChannelSpec = ChannelSpec {
    topic: GAP_TOPIC,
    ..super::schema::GAP
};

/// One tick as an MCAP message. `A` is `&[f64]` when writing (one entry per joint) and
/// `Vec<Option<f64>>` when reading (`null`: a number that was not finite).
#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct TickMsg<A> {
    pub tick: u64,
    pub dropped_before: u64,
    pub deadline_ns: u64,
    pub t: f64,
    pub trial: u32,
    pub mode: u32,
    pub(crate) trial_time: f64,
    pub periods: u64,
    pub command_seq: u64,
    pub disturbance_seq: u64,
    pub q: A,
    pub qd: A,
    pub qdd: A,
    pub tau: A,
    pub tau_ext: A,
    pub tau_ff: A,
    pub stiffness: A,
    pub damping: A,
    pub q_d: A,
    pub qd_d: A,
}

impl<'a> TickMsg<&'a [f64]> {
    /// The message of `s`, `t0_ns` being the first tick's deadline.
    pub fn of(s: &'a Sample, t0_ns: u64, joints: usize) -> Self {
        let n = joints.clamp(1, MAX_JOINTS);
        TickMsg {
            tick: s.tick,
            dropped_before: s.dropped_before,
            deadline_ns: s.deadline_ns,
            t: s.deadline_ns.saturating_sub(t0_ns) as f64 * 1e-9,
            trial: s.trial,
            mode: s.mode,
            trial_time: s.trial_time_ns as f64 * 1e-9,
            periods: s.periods,
            command_seq: s.command_seq,
            disturbance_seq: s.disturbance_seq,
            q: &s.q[..n],
            qd: &s.qd[..n],
            qdd: &s.qdd[..n],
            tau: &s.tau[..n],
            tau_ext: &s.tau_ext[..n],
            tau_ff: &s.tau_ff[..n],
            stiffness: &s.stiffness[..n],
            damping: &s.damping[..n],
            q_d: &s.q_d[..n],
            qd_d: &s.qd_d[..n],
        }
    }
}

/// An MCAP file being written: registered channels and a reused message buffer.
///
/// Crash safety: [`McapOut::flush`] (every [`FLUSH_INTERVAL`]) closes the chunk in progress and
/// hands it to the kernel, so a process killed with SIGKILL leaves every chunk up to the last
/// flush whole; readers recover them from a file without summary or footer
/// ([`super::read_recording`]). On a write error (a full disk) [`McapOut::salvage`] cuts the
/// file back to the last flush and closes it with a data-end record, a footer without summary
/// and the end magic: a valid MCAP that every reader opens.
pub(crate) struct McapOut {
    writer: Option<Writer<BufWriter<File>>>,
    /// A duplicate of the file's descriptor (the same offset): the end of the last flush, and
    /// the file to cut and close after a write error.
    file: File,
    /// The file's length after the last successful flush.
    safe_end: u64,
    buf: Vec<u8>,
    sequence: BTreeMap<u16, u32>,
}

/// How often a recording hands what it wrote to the kernel (a chunk of the MCAP file, the lines
/// of the CSV): the data a SIGKILL can lose is what was written since (plus what was still
/// queued, a few milliseconds while the writer keeps up).
pub const FLUSH_INTERVAL: std::time::Duration = std::time::Duration::from_millis(50);

/// The records that close a data section without a summary: a data-end record (no CRC), a
/// footer whose summary offsets are 0 (none) and the end magic.
fn closing_records() -> Vec<u8> {
    let mut v = Vec::with_capacity(13 + 29 + 8);
    v.push(0x0F); // data end
    v.extend_from_slice(&4u64.to_le_bytes());
    v.extend_from_slice(&0u32.to_le_bytes());
    v.push(0x02); // footer
    v.extend_from_slice(&20u64.to_le_bytes());
    v.extend_from_slice(&0u64.to_le_bytes());
    v.extend_from_slice(&0u64.to_le_bytes());
    v.extend_from_slice(&0u32.to_le_bytes());
    v.extend_from_slice(mcap::MAGIC);
    v
}

impl McapOut {
    /// Starts an MCAP file on `file` with lz4-compressed chunks, writes `metadata` and flushes.
    pub fn start(file: File, metadata: &BTreeMap<String, String>) -> mcap::McapResult<McapOut> {
        let dup = file.try_clone()?;
        let writer = WriteOptions::new()
            .compression(Some(Compression::Lz4))
            .profile(PROFILE)
            .library(format!("vic {} (mcap crate)", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::with_capacity(1 << 16, file))?;
        let mut out = McapOut {
            writer: Some(writer),
            file: dup,
            safe_end: 0,
            buf: Vec::with_capacity(4096),
            sequence: BTreeMap::new(),
        };
        out.writer()?.write_metadata(&Metadata {
            name: METADATA_NAME.into(),
            metadata: metadata.clone(),
        })?;
        out.flush()?;
        Ok(out)
    }

    fn writer(&mut self) -> mcap::McapResult<&mut Writer<BufWriter<File>>> {
        self.writer
            .as_mut()
            .ok_or_else(|| mcap::McapError::Io(io::Error::other("the MCAP file is already closed")))
    }

    /// Closes the chunk in progress and writes everything to the file (not synced to disk:
    /// what a killed process leaves, not what a power cut leaves).
    pub fn flush(&mut self) -> mcap::McapResult<()> {
        self.writer()?.flush()?;
        self.safe_end = self.file.stream_position()?;
        Ok(())
    }

    /// After a write error: drops what was written since the last flush, closes the file as a
    /// valid MCAP without summary (see [`McapOut`]) and syncs it. Returns the bytes kept. If
    /// even the closing records do not fit, the file ends at the last flush, which the readers
    /// of [`super::read_recording`] still read.
    pub fn salvage(&mut self) -> io::Result<u64> {
        if let Some(w) = self.writer.take() {
            // Discards the buffered bytes; nothing more is written through the writer.
            let (file, _buffered) = w.into_inner().into_parts();
            drop(file);
        }
        self.file.set_len(self.safe_end)?;
        self.file.seek(SeekFrom::Start(self.safe_end))?;
        let closing = closing_records();
        if let Err(e) = self.file.write_all(&closing) {
            let _ = self.file.set_len(self.safe_end);
            return Err(e);
        }
        let _ = self.file.sync_data();
        Ok(self.safe_end + closing.len() as u64)
    }

    /// Registers the schema and channel of `spec`; returns the channel id.
    pub fn channel(&mut self, spec: &ChannelSpec) -> mcap::McapResult<u16> {
        let writer = self.writer()?;
        let schema = writer.add_schema(spec.schema, "jsonschema", &spec.json_schema())?;
        writer.add_channel(schema, spec.topic, "json", &BTreeMap::new())
    }

    /// Writes `value` as JSON on `channel` at `log_time_ns` (published at `publish_time_ns`).
    pub fn write<T: Serialize>(
        &mut self,
        channel: u16,
        log_time_ns: u64,
        publish_time_ns: u64,
        value: &T,
    ) -> mcap::McapResult<()> {
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, value)
            .map_err(|e| mcap::McapError::Io(io::Error::other(e)))?;
        let seq = self.sequence.entry(channel).or_insert(0);
        *seq = seq.wrapping_add(1);
        let header = MessageHeader {
            channel_id: channel,
            sequence: *seq,
            log_time: log_time_ns,
            publish_time: publish_time_ns,
        };
        let writer = self.writer.as_mut().ok_or_else(|| {
            mcap::McapError::Io(io::Error::other("the MCAP file is already closed"))
        })?;
        writer.write_to_known_channel(&header, &self.buf)
    }

    /// Writes a second metadata record (a summary at the end of a recording).
    pub fn metadata(&mut self, name: &str, m: BTreeMap<String, String>) -> mcap::McapResult<()> {
        self.writer()?.write_metadata(&Metadata {
            name: name.into(),
            metadata: m,
        })
    }

    /// Writes the summary and the footer, flushes and syncs the file.
    pub fn finish(&mut self) -> mcap::McapResult<()> {
        self.writer()?.finish()?;
        if let Some(w) = self.writer.take() {
            let file = w.into_inner().into_inner().map_err(|e| e.into_error())?;
            file.sync_data()?;
        }
        Ok(())
    }

    /// The file's length after the last flush.
    #[cfg(test)]
    pub fn flushed_bytes(&self) -> u64 {
        self.safe_end
    }
}

/// The MCAP file of a board recording.
pub(super) struct McapSink {
    out: Option<McapOut>,
    tick: u16,
    gap: u16,
    joints: usize,
}

impl McapSink {
    pub(super) fn start(file: std::fs::File, opts: &RecordOptions) -> mcap::McapResult<McapSink> {
        let mut metadata = opts.metadata.clone();
        metadata.insert("vic_version".into(), env!("CARGO_PKG_VERSION").into());
        metadata.insert("joints".into(), opts.joints.to_string());
        metadata.insert("period_ns".into(), opts.period_ns.to_string());
        metadata.insert("queue_ticks".into(), opts.capacity.to_string());
        metadata.insert("clock".into(), "CLOCK_MONOTONIC".into());
        metadata.insert("recorder".into(), "vic-board".into());
        let mut out = McapOut::start(file, &metadata)?;
        let tick = out.channel(&TICK)?;
        let gap = out.channel(&GAP)?;
        out.flush()?;
        Ok(McapSink {
            out: Some(out),
            tick,
            gap,
            joints: opts.joints,
        })
    }
    fn out(&mut self) -> io::Result<&mut McapOut> {
        self.out
            .as_mut()
            .ok_or_else(|| io::Error::other("the MCAP file is already finished"))
    }
}

/// An MCAP error as an I/O error, the OS error (ENOSPC, …) kept when there is one.
pub(crate) fn to_io(e: mcap::McapError) -> io::Error {
    match e {
        mcap::McapError::Io(e) => e,
        e => io::Error::other(e),
    }
}

impl Sink for McapSink {
    fn sample(&mut self, s: &Sample, t0_ns: u64) -> io::Result<()> {
        let (channel, joints) = (self.tick, self.joints);
        let msg = TickMsg::of(s, t0_ns, joints);
        self.out()?
            .write(channel, s.deadline_ns, s.deadline_ns, &msg)
            .map_err(to_io)
    }
    fn gap(&mut self, n: u64, first: u64, log_time_ns: u64) -> io::Result<()> {
        let channel = self.gap;
        let msg = gap_json(first, n, "recording queue full");
        self.out()?
            .write(channel, log_time_ns, log_time_ns, &msg)
            .map_err(to_io)
    }
    /// Closes the chunk in progress: one small chunk per flush interval (about 50 ticks at
    /// 1 kHz), so that a killed board leaves all but the last interval readable.
    fn flush(&mut self) -> io::Result<()> {
        self.out()?.flush().map_err(to_io)
    }
    fn finish(&mut self) -> io::Result<()> {
        match self.out.as_mut() {
            Some(out) => out.finish().map_err(to_io),
            None => Ok(()),
        }
    }
    fn salvage(&mut self) -> io::Result<u64> {
        self.out()?.salvage()
    }
}
