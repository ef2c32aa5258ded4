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
use std::io::{self, BufWriter};

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
pub(crate) struct McapOut {
    writer: Writer<BufWriter<std::fs::File>>,
    buf: Vec<u8>,
    sequence: BTreeMap<u16, u32>,
}

impl McapOut {
    /// Starts an MCAP file on `file` with lz4-compressed chunks and writes `metadata`.
    pub fn start(
        file: std::fs::File,
        metadata: &BTreeMap<String, String>,
    ) -> mcap::McapResult<McapOut> {
        let writer = WriteOptions::new()
            .compression(Some(Compression::Lz4))
            .profile(PROFILE)
            .library(format!("vic {} (mcap crate)", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::with_capacity(1 << 16, file))?;
        let mut out = McapOut {
            writer,
            buf: Vec::with_capacity(4096),
            sequence: BTreeMap::new(),
        };
        out.writer.write_metadata(&Metadata {
            name: METADATA_NAME.into(),
            metadata: metadata.clone(),
        })?;
        Ok(out)
    }

    /// Registers the schema and channel of `spec`; returns the channel id.
    pub fn channel(&mut self, spec: &ChannelSpec) -> mcap::McapResult<u16> {
        let schema = self
            .writer
            .add_schema(spec.schema, "jsonschema", &spec.json_schema())?;
        self.writer
            .add_channel(schema, spec.topic, "json", &BTreeMap::new())
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
        self.writer.write_to_known_channel(&header, &self.buf)
    }

    /// Writes a second metadata record (a summary at the end of a recording).
    pub fn metadata(&mut self, name: &str, m: BTreeMap<String, String>) -> mcap::McapResult<()> {
        self.writer.write_metadata(&Metadata {
            name: name.into(),
            metadata: m,
        })
    }

    /// Writes the summary and the footer, flushes and syncs the file.
    pub fn finish(mut self) -> mcap::McapResult<()> {
        self.writer.finish()?;
        let out = self.writer.into_inner();
        let file = out.into_inner().map_err(|e| e.into_error())?;
        file.sync_data()?;
        Ok(())
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

impl Sink for McapSink {
    fn sample(&mut self, s: &Sample, t0_ns: u64) -> io::Result<()> {
        let (channel, joints) = (self.tick, self.joints);
        let msg = TickMsg::of(s, t0_ns, joints);
        self.out()?
            .write(channel, s.deadline_ns, s.deadline_ns, &msg)
            .map_err(io::Error::other)
    }
    fn gap(&mut self, n: u64, first: u64, log_time_ns: u64) -> io::Result<()> {
        let channel = self.gap;
        let msg = gap_json(first, n, "recording queue full");
        self.out()?
            .write(channel, log_time_ns, log_time_ns, &msg)
            .map_err(io::Error::other)
    }
    /// Chunks close by size (the library's default, under a megabyte): closing one every
    /// 100 ms would cost compression for little.
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
    fn finish(&mut self) -> io::Result<()> {
        match self.out.take() {
            Some(out) => out.finish().map_err(io::Error::other),
            None => Ok(()),
        }
    }
}
