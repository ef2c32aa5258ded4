//! Recording a namespace from outside the board (`vic record`): a separate process subscribes
//! to every service (states at 1 kHz, command slices, control requests, disturbances,
//! telemetry) and writes each message to an MCAP file as it arrives. It publishes nothing, so
//! the board does not know it is there; its subscriber buffers (128 messages per service) give
//! it 128 ms to come back to each queue, and the states it missed anyway are counted from the
//! board's sequence numbers and marked on the `/gap` channel.

use super::error::RecordError;
use super::file::Placement;
use super::mcap_file::McapOut;
use super::observe::{SPECS, STATE, StateTrack, drain};
use crate::transport::RecorderPorts;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// What `vic record` was asked for.
#[derive(Debug, Clone)]
pub struct ExternalOptions {
    /// Stop this long after the first state [ns] (0: when `stop` is set).
    pub duration_ns: u64,
    /// How long to wait for the board's first state before giving up [ms].
    pub wait_for_board_ms: u64,
    /// Key-value pairs of the file's metadata record (command line, plan hash, …).
    pub metadata: BTreeMap<String, String>,
    /// Replace an existing file at the path (once the board's first state arrived).
    pub replace: bool,
}

/// Messages written on one channel.
#[derive(Debug, Clone, Serialize, PartialEq, Eq)]
pub struct TopicCount {
    pub topic: String,
    pub messages: u64,
}

/// What an external recording wrote and what it missed.
#[derive(Debug, Clone, Serialize)]
pub struct ExternalSummary {
    pub path: PathBuf,
    pub namespace: String,
    /// States written.
    pub states: u64,
    /// States the board published that the recorder missed (sequence numbers skipped).
    pub states_lost: u64,
    /// Gaps marked on `/gap`.
    pub gaps: u64,
    /// First and last board tick written.
    pub first_tick: u64,
    pub last_tick: u64,
    /// Messages per channel.
    pub topics: Vec<TopicCount>,
    /// Seconds from the first state to the end.
    pub seconds: f64,
}

struct Channels {
    ids: [u16; 6],
    counts: [u64; 6],
}

/// Records namespace `ns` into the MCAP file `path` until `stop` is set or the duration ends.
///
/// The file is written under a temporary name in the same directory (`O_EXCL`, never through
/// a link) and takes its name once the board's first state arrived: an existing `path` is
/// refused unless [`ExternalOptions::replace`], and a recording that finds no board leaves
/// nothing behind and touches nothing. Every [`super::FLUSH_INTERVAL`] the chunk in progress is
/// handed to the kernel, so a recorder killed with SIGKILL loses at most that (and the
/// subscriber buffers not yet drained, 2 ms). A write error (a full disk) ends the recording
/// at once: the file is cut back to the last flush and closed readable, and the error names
/// it (`ENOSPC`) with the states kept.
pub fn record_namespace(
    ns: &str,
    path: &Path,
    opts: &ExternalOptions,
    stop: &AtomicBool,
) -> Result<ExternalSummary, RecordError> {
    let (mut placement, file) = Placement::create(path, opts.replace)?;
    let ports = RecorderPorts::open(ns)?;
    let mut metadata = opts.metadata.clone();
    metadata.insert("vic_version".into(), env!("CARGO_PKG_VERSION").into());
    metadata.insert("namespace".into(), ns.into());
    metadata.insert("clock".into(), "CLOCK_MONOTONIC".into());
    metadata.insert("recorder".into(), "vic record".into());
    let mut ch = Channels {
        ids: [0; 6],
        counts: [0; 6],
    };
    let mut out = McapOut::start(file, &metadata)
        .and_then(|mut out| {
            for (id, spec) in ch.ids.iter_mut().zip(SPECS) {
                *id = out.channel(spec)?;
            }
            out.flush()?;
            Ok(out)
        })
        .map_err(|e| write_error(placement.current(), e, None))?;
    let started = Instant::now();
    let mut first_state: Option<Instant> = None;
    let mut track = StateTrack::default();
    let mut last_flush = Instant::now();
    // States written before the last flush: what a salvaged file keeps.
    let mut flushed_states = 0;
    let mut flushed_tick = 0;
    loop {
        let stopping = stop.load(Ordering::Relaxed)
            || first_state.is_some_and(|t| {
                opts.duration_ns > 0 && t.elapsed() >= Duration::from_nanos(opts.duration_ns)
            });
        let mut step = drain_once(&ports, &mut out, &mut ch, &mut track);
        if step.is_ok() && last_flush.elapsed() >= super::FLUSH_INTERVAL {
            step = out.flush();
            if step.is_ok() {
                flushed_states = ch.counts[STATE];
                flushed_tick = track.last_tick;
            }
            last_flush = Instant::now();
        }
        if let Err(e) = step {
            let kept = (flushed_states, track.first_tick, flushed_tick);
            let _ = out.salvage();
            return Err(write_error(placement.current(), e, Some(kept)));
        }
        if first_state.is_none() && ch.counts[STATE] > 0 {
            first_state = Some(Instant::now());
            placement.place()?;
        }
        if stopping {
            break;
        }
        if first_state.is_none()
            && started.elapsed() >= Duration::from_millis(opts.wait_for_board_ms)
        {
            // The temporary file is removed with the placement.
            drop(out);
            return Err(RecordError::NoBoard {
                namespace: ns.into(),
                waited_ms: opts.wait_for_board_ms,
            });
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    let summary = ExternalSummary {
        path: path.to_path_buf(),
        namespace: ns.into(),
        states: ch.counts[STATE],
        states_lost: track.lost,
        gaps: track.gaps,
        first_tick: track.first_tick,
        last_tick: track.last_tick,
        topics: SPECS
            .iter()
            .zip(ch.counts)
            .map(|(s, n)| TopicCount {
                topic: s.topic.into(),
                messages: n,
            })
            .collect(),
        seconds: first_state.map_or(0.0, |t| t.elapsed().as_secs_f64()),
    };
    let mut m = BTreeMap::new();
    for t in &summary.topics {
        m.insert(
            format!("messages{}", t.topic.replace('/', "_")),
            t.messages.to_string(),
        );
    }
    m.insert("states_lost".into(), track.lost.to_string());
    m.insert("gaps".into(), track.gaps.to_string());
    if let Err(e) = out.metadata("vic.summary", m).and_then(|()| out.finish()) {
        let kept = (ch.counts[STATE], track.first_tick, track.last_tick);
        // Everything was flushed before the summary: the salvaged file keeps every state.
        let flushed = out.flush().is_ok();
        let _ = out.salvage();
        return Err(write_error(
            placement.current(),
            e,
            Some(if flushed {
                kept
            } else {
                (flushed_states, kept.1, flushed_tick)
            }),
        ));
    }
    Ok(summary)
}

/// A write error of `path`, with what the salvaged file keeps (states, first and last tick).
fn write_error(path: &Path, e: mcap::McapError, kept: Option<(u64, u64, u64)>) -> RecordError {
    let Some(io) = super::file::io_of(&e) else {
        return RecordError::mcap(path, e);
    };
    let what = super::file::describe(io);
    RecordError::Write {
        path: path.to_path_buf(),
        message: match kept {
            None => what,
            Some((0, ..)) => format!("{what}; the file holds no state (closed readable)"),
            Some((n, first, last)) => format!(
                "{what}; recording stopped, the file keeps {n} states (ticks {first} to {last}) \
                 and is closed readable"
            ),
        },
    }
}

/// Writes everything waiting on every service.
fn drain_once(
    ports: &RecorderPorts,
    out: &mut McapOut,
    ch: &mut Channels,
    track: &mut StateTrack,
) -> mcap::McapResult<()> {
    let mut result = Ok(());
    drain(ports, track, |item| {
        if result.is_ok() {
            let (k, t) = (item.channel(), item.time_ns());
            result = out.write(ch.ids[k], t, t, &item.json());
            ch.counts[k] += 1;
        }
    });
    result
}
