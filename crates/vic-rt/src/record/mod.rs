//! Recording every board tick to a CSV log or an MCAP file, from a thread outside the 1 kHz loop,
//! and recording a whole namespace from another process ([`record_namespace`]).
//!
//! The loop holds a [`RecordProducer`]: [`RecordProducer::push`] copies one [`Sample`] into a
//! bounded single-producer single-consumer ring buffer (`rtrb`, allocated once at start) and never
//! allocates, locks or blocks. A writer thread owned by the [`Recorder`] pops the samples and
//! writes them to the file (CSV or MCAP, chosen by the file's extension: [`RecordFormat`]). When the queue is full the sample is dropped and
//! counted, never silently: the file marks the gap (see below), and [`Recorder::finish`] returns
//! the ticks written and dropped.
//!
//! The writer hands what it wrote to the kernel every [`FLUSH_INTERVAL`] (50 ms: the MCAP chunk
//! in progress is closed, the CSV lines written out), so a process killed with SIGKILL leaves a
//! file that [`read_recording`] (and `vic convert`) reads, less the last interval. A write error
//! (a full disk) cuts the file back to the last flush and closes it readable, is reported at
//! once ([`RecordOptions::report`]) and leaves the loop undisturbed. The file is created new
//! ([`file::create_new`]: never over an existing file unless asked to, never through a link).
//!
//! # File format
//!
//! The log format that `vic identify`'s reader reads (so `vic identify --log FILE.csv`
//! reads a recording of a single joint). The nine columns of [`LOG_COLUMNS`] hold joint 0; every
//! other column starts with [`EXTRA_COLUMN_PREFIX`] so that the reader ignores it:
//!
//! | column | meaning |
//! |---|---|
//! | `t` | tick deadline since the first recorded tick [s] |
//! | `q`, `qd`, `qdd` | joint 0 angle, velocity, acceleration (change of `q'` over the period) |
//! | `tau_ff`, `stiffness`, `damping`, `q_d`, `qd_d` | the knot the law used at joint 0 (`damping` from the actuator's law) |
//! | `x_tick` | loop tick, 1 for the first tick of the run; consecutive unless a gap is marked |
//! | `x_dropped` | ticks dropped just before this row because the queue was full (0 normally) |
//! | `x_trial`, `x_mode`, `x_trial_time` | trial, [`crate::transport::Mode`] as a number, plant time of the trial [s] |
//! | `x_periods` | plant periods integrated by the tick (more than 1 after a late wake-up) |
//! | `x_command_seq`, `x_disturbance_seq` | sequence numbers of the command slice and of the last disturbance in use |
//! | `x_tau_0`, `x_tau_ext_0` | joint torque applied and external (disturbance) torque at joint 0 [N m] |
//! | `x_<name>_1` | the same per-joint columns for joint 1 (two-joint plants only) |
//!
//! Lines starting with `#` are comments that the reader skips: a banner, and one
//! `# gap: N ticks dropped (ticks A to B): recording queue full` line before the row that
//! follows each gap (or at the end of the file when the run ended during a gap). A row whose
//! nine log columns are not all finite (a plant fault) is written as a comment
//! `# non-finite: <row>` so that the file stays readable.
//!
//! An MCAP recording (`.mcap`) holds the same fields per tick as JSON messages on the channel
//! [`TICK_TOPIC`] and one message per gap on [`GAP_TOPIC`]; see [`mcap_file`].

mod csv;
mod error;
mod external;
pub mod file;
pub(crate) mod mcap_file;
mod observe;
mod read;
mod schema;
#[cfg(feature = "foxglove")]
mod view;

pub use csv::{EXTRA_COLUMN_PREFIX, LOG_COLUMNS, LOG_HEADER, header};
pub use error::RecordError;
pub use external::{ExternalOptions, ExternalSummary, TopicCount, record_namespace};
pub use mcap_file::{FLUSH_INTERVAL, GAP_TOPIC, TICK_TOPIC};
pub use read::{
    BoardRecording, Recording, StatesCsv, board_recording, read_board_mcap, read_recording,
    write_csv, write_states_csv,
};
#[cfg(feature = "foxglove")]
pub use view::{
    HAND_TOPIC, Kinematics, REFERENCE_TOPIC, ViewOptions, ViewSummary, serve_namespace,
};

use crate::transport::MAX_JOINTS;
use csv::CsvSink;
use mcap_file::McapSink;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

/// Default queue capacity: 8192 ticks, 8 s at 1 kHz (about 3 MB).
pub const DEFAULT_CAPACITY: usize = 8192;

/// Largest queue capacity: 131072 ticks, 131 s at 1 kHz (about 48 MB, locked in memory with the
/// rest of the board). A longer stall of the writer loses ticks (marked as gaps) rather than
/// memory.
pub const MAX_CAPACITY: usize = 131_072;

/// One tick as recorded: plain data, copied into the queue (the board's live runner makes it
/// from a step: [`Sample::from_step`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Sample {
    /// Loop tick (1, 2, … over a run).
    pub tick: u64,
    /// Ticks dropped just before this one (filled in by [`RecordProducer::push`]).
    pub dropped_before: u64,
    /// The tick's deadline [ns, monotonic].
    pub deadline_ns: u64,
    pub trial: u32,
    /// [`crate::transport::Mode`] as `u32`.
    pub mode: u32,
    pub trial_time_ns: u64,
    pub periods: u64,
    pub command_seq: u64,
    pub disturbance_seq: u64,
    pub q: [f64; MAX_JOINTS],
    pub qd: [f64; MAX_JOINTS],
    pub qdd: [f64; MAX_JOINTS],
    pub tau: [f64; MAX_JOINTS],
    pub tau_ext: [f64; MAX_JOINTS],
    pub tau_ff: [f64; MAX_JOINTS],
    pub stiffness: [f64; MAX_JOINTS],
    pub damping: [f64; MAX_JOINTS],
    pub q_d: [f64; MAX_JOINTS],
    pub qd_d: [f64; MAX_JOINTS],
}

/// The loop's half of a recording: pushes samples into the bounded queue.
pub struct RecordProducer {
    queue: rtrb::Producer<Sample>,
    pending_drops: u64,
    pushed: u64,
    dropped: u64,
}

impl RecordProducer {
    /// Queues one sample; `false` when the queue was full and the sample was dropped (counted,
    /// and marked in the file before the next sample that gets through). Never allocates,
    /// locks or blocks.
    #[inline]
    pub fn push(&mut self, sample: &Sample) -> bool {
        let mut s = *sample;
        s.dropped_before = self.pending_drops;
        match self.queue.push(s) {
            Ok(()) => {
                self.pending_drops = 0;
                self.pushed += 1;
                true
            }
            Err(_) => {
                self.pending_drops += 1;
                self.dropped += 1;
                false
            }
        }
    }
    /// Samples queued so far.
    pub fn pushed(&self) -> u64 {
        self.pushed
    }
    /// Samples dropped so far because the queue was full.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }
    /// Free slots in the queue (the writer has caught up when it equals the capacity).
    pub fn free_slots(&self) -> usize {
        self.queue.slots()
    }
}

/// The file format of a recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordFormat {
    /// The CSV log of `vic identify` (`.csv`).
    Csv,
    /// MCAP with JSON-schema channels, lz4-compressed chunks (`.mcap`): what Foxglove,
    /// PlotJuggler and rosbag2 open.
    Mcap,
}

impl RecordFormat {
    /// The format named by the extension of `path` (`.csv` or `.mcap`, any case).
    pub fn from_path(path: &Path) -> Result<RecordFormat, RecordError> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("csv") => Ok(RecordFormat::Csv),
            Some("mcap") => Ok(RecordFormat::Mcap),
            _ => Err(RecordError::Format {
                path: path.to_path_buf(),
                message: "the file name must end in .csv or .mcap (the format is chosen by \
                          the extension)"
                    .into(),
            }),
        }
    }
}

/// Options of a recording.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    /// Queue capacity in ticks (default [`DEFAULT_CAPACITY`]).
    pub capacity: usize,
    /// Joints of the plant (1 or 2): the per-joint columns written.
    pub joints: usize,
    /// Free text for the banner comment (scenario, rate, …); one line.
    pub banner: String,
    /// Start with the writer paused (tests of the overflow marking).
    pub start_paused: bool,
    /// Key-value pairs of the MCAP file's metadata record (scenario, command line, …); the CSV
    /// has its banner instead.
    pub metadata: std::collections::BTreeMap<String, String>,
    /// The tick period [ns] (the MCAP file's metadata, and the log time of a trailing gap).
    pub period_ns: u64,
    /// Replace an existing file (the entry: a symbolic link is replaced, never followed);
    /// without it an existing file is an error and stays untouched.
    pub replace: bool,
    /// Called once from the writer thread when writing fails (a full disk), with the message
    /// that names the file, the error and what the file keeps; the loop is not disturbed.
    pub report: Option<fn(&str)>,
}

impl Default for RecordOptions {
    fn default() -> Self {
        RecordOptions {
            capacity: DEFAULT_CAPACITY,
            joints: 2,
            banner: String::new(),
            start_paused: false,
            metadata: Default::default(),
            period_ns: 1_000_000,
            replace: false,
            report: None,
        }
    }
}

/// What a recording wrote.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct RecordSummary {
    /// Rows written (one per tick that got through the queue).
    pub written: u64,
    /// Ticks dropped because the queue was full (each gap is marked in the file).
    pub dropped: u64,
    /// Gaps marked in the file.
    pub gaps: u64,
    /// First and last tick written (0 when none).
    pub first_tick: u64,
    pub last_tick: u64,
}

struct Shared {
    done: AtomicBool,
    paused: AtomicBool,
    /// Set by the writer while it is parked by `paused`.
    parked: AtomicBool,
    /// Drops after the last sample that got through, set by `finish` before `done`.
    trailing_drops: AtomicU64,
}

/// A recording: the producer for the loop and the writer thread that owns the file.
pub struct Recorder {
    producer: RecordProducer,
    shared: Arc<Shared>,
    writer: Option<JoinHandle<io::Result<RecordSummary>>>,
    path: PathBuf,
}

impl Recorder {
    /// Creates `path` (a new file: an existing one is refused unless [`RecordOptions::replace`]; a
    /// symbolic link is never followed) in the format of its extension ([`RecordFormat`]), writes
    /// the file's header (the CSV's banner and column names, the MCAP's schemas, channels and
    /// metadata), and starts the writer thread. The queue is allocated here, once.
    pub fn start(path: &Path, opts: &RecordOptions) -> io::Result<Recorder> {
        if !(1..=MAX_CAPACITY).contains(&opts.capacity) || !(1..=MAX_JOINTS).contains(&opts.joints)
        {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!(
                    "recording: capacity must be 1 to {MAX_CAPACITY} and joints 1 to {MAX_JOINTS} (got {} and {})",
                    opts.capacity, opts.joints
                ),
            ));
        }
        let format = RecordFormat::from_path(path)
            .map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, e.to_string()))?;
        let file = file::create_new(path, opts.replace).map_err(|e| {
            let kind = match &e {
                RecordError::Io { source, .. } => source.kind(),
                RecordError::Exists { .. } => io::ErrorKind::AlreadyExists,
                _ => io::ErrorKind::Other,
            };
            io::Error::new(kind, e.to_string())
        })?;
        let sink: Box<dyn Sink> = match format {
            RecordFormat::Csv => Box::new(CsvSink::start(file, opts)?),
            RecordFormat::Mcap => Box::new(McapSink::start(file, opts).map_err(io::Error::other)?),
        };
        let (tx, rx) = rtrb::RingBuffer::new(opts.capacity);
        let shared = Arc::new(Shared {
            done: AtomicBool::new(false),
            paused: AtomicBool::new(opts.start_paused),
            parked: AtomicBool::new(false),
            trailing_drops: AtomicU64::new(0),
        });
        let writer = {
            let shared = shared.clone();
            let (path, report) = (path.to_path_buf(), opts.report);
            std::thread::Builder::new()
                .name("vic-record".into())
                .spawn(move || write_loop(rx, sink, &shared, &path, report))?
        };
        Ok(Recorder {
            producer: RecordProducer {
                queue: tx,
                pending_drops: 0,
                pushed: 0,
                dropped: 0,
            },
            shared,
            writer: Some(writer),
            path: path.to_path_buf(),
        })
    }

    /// The loop's half.
    pub fn producer(&mut self) -> &mut RecordProducer {
        &mut self.producer
    }

    /// Pauses or resumes the writer thread (samples pile up in the queue while paused). A pause
    /// returns once the writer is parked: nothing pushed after it is written until resumed.
    pub fn set_paused(&self, paused: bool) {
        self.shared.paused.store(paused, Ordering::Release);
        while paused && !self.shared.parked.load(Ordering::Acquire) {
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Stops the writer once it has written everything queued, marks a trailing gap, flushes and
    /// closes the file. Returns what was written and dropped.
    pub fn finish(mut self) -> io::Result<RecordSummary> {
        self.shared
            .trailing_drops
            .store(self.producer.pending_drops, Ordering::Relaxed);
        self.shared.paused.store(false, Ordering::Release);
        self.shared.done.store(true, Ordering::Release);
        let summary = self
            .writer
            .take()
            .expect("the writer runs until finish")
            .join()
            .map_err(|_| io::Error::other("the recording thread panicked"))??;
        debug_assert_eq!(summary.dropped, self.producer.dropped);
        debug_assert_eq!(summary.written, self.producer.pushed);
        Ok(summary)
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        if let Some(w) = self.writer.take() {
            self.shared.paused.store(false, Ordering::Release);
            self.shared.done.store(true, Ordering::Release);
            let _ = w.join();
        }
    }
}

/// Where the writer thread puts what it pops: one file format.
trait Sink: Send {
    /// Writes one tick; `t0_ns` is the deadline of the first tick written.
    fn sample(&mut self, s: &Sample, t0_ns: u64) -> io::Result<()>;
    /// Marks `n` ticks lost from tick `first` on, noticed at `log_time_ns`.
    fn gap(&mut self, n: u64, first: u64, log_time_ns: u64) -> io::Result<()>;
    /// Hands what was written so far to the kernel, readable as it is (every
    /// [`FLUSH_INTERVAL`]).
    fn flush(&mut self) -> io::Result<()>;
    /// Completes the file and syncs it to disk.
    fn finish(&mut self) -> io::Result<()>;
    /// After a write error: cuts the file back to the last flush and closes it readable;
    /// returns its length.
    fn salvage(&mut self) -> io::Result<u64>;
}

/// The writer thread's progress, kept across an error.
#[derive(Default)]
struct Progress {
    summary: RecordSummary,
    /// The last tick written before the last successful flush (what a salvaged file keeps).
    flushed_tick: u64,
}

/// The writer thread: pops samples, writes them, marks gaps, flushes every [`FLUSH_INTERVAL`].
/// A write error (a full disk) stops the writing, not the loop: the file is cut back to the
/// last flush and closed readable, the error is reported at once through `report`, and the
/// queue is emptied (the samples discarded) until [`Recorder::finish`], which returns the error.
fn write_loop(
    mut rx: rtrb::Consumer<Sample>,
    mut sink: Box<dyn Sink>,
    shared: &Shared,
    path: &Path,
    report: Option<fn(&str)>,
) -> io::Result<RecordSummary> {
    let mut p = Progress::default();
    let Err(e) = write_all(&mut rx, sink.as_mut(), shared, &mut p) else {
        return Ok(p.summary);
    };
    let kept = sink.salvage();
    let (first, last) = (p.summary.first_tick, p.flushed_tick);
    let detail = format!(
        "{}: recording stopped at tick {}; {}",
        file::describe(&e),
        p.summary.last_tick + 1,
        match kept {
            Ok(_) if last >= first && last > 0 => format!(
                "the file keeps ticks {first} to {last} and is closed readable (vic convert reads it)"
            ),
            Ok(_) => "the file holds no tick and is closed readable".into(),
            Err(e2) => format!(
                "closing the file failed too ({}): it keeps the ticks up to {last}, which vic convert recovers",
                file::describe(&e2)
            ),
        }
    );
    if let Some(report) = report {
        report(&format!("{}: {detail}", path.display()));
    }
    // Keep the queue empty so that the loop's pushes stay cheap; nothing more is written.
    let mut discarded = 0u64;
    loop {
        let done = shared.done.load(Ordering::Acquire);
        while rx.pop().is_ok() {
            discarded += 1;
        }
        if done {
            break;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    Err(io::Error::new(
        e.kind(),
        format!("{detail}; {discarded} later tick(s) were not recorded"),
    ))
}

fn write_all(
    rx: &mut rtrb::Consumer<Sample>,
    sink: &mut dyn Sink,
    shared: &Shared,
    p: &mut Progress,
) -> io::Result<()> {
    let summary = &mut p.summary;
    let mut t0_ns = None;
    let mut last_deadline_ns = 0;
    let mut last_flush = std::time::Instant::now();
    loop {
        // Read `done` before draining: everything pushed before it was set is then visible.
        let done = shared.done.load(Ordering::Acquire);
        if !done && shared.paused.load(Ordering::Acquire) {
            shared.parked.store(true, Ordering::Release);
            std::thread::sleep(Duration::from_millis(1));
            continue;
        }
        shared.parked.store(false, Ordering::Release);
        let mut popped = 0;
        while let Ok(s) = rx.pop() {
            popped += 1;
            let t0 = *t0_ns.get_or_insert(s.deadline_ns);
            // The producer counts its drops; the tick numbers must agree with it.
            let expected = if summary.written == 0 {
                s.tick.saturating_sub(s.dropped_before)
            } else {
                summary.last_tick + 1
            };
            let missing = s.tick.saturating_sub(expected).max(s.dropped_before);
            if missing > 0 {
                sink.gap(missing, s.tick - missing, s.deadline_ns)?;
                summary.dropped += missing;
                summary.gaps += 1;
            }
            sink.sample(&s, t0)?;
            if summary.written == 0 {
                summary.first_tick = s.tick;
            }
            summary.written += 1;
            summary.last_tick = s.tick;
            last_deadline_ns = s.deadline_ns;
            if last_flush.elapsed() >= FLUSH_INTERVAL {
                break;
            }
        }
        if done && rx.is_empty() {
            let trailing = shared.trailing_drops.load(Ordering::Relaxed);
            if trailing > 0 {
                sink.gap(trailing, summary.last_tick + 1, last_deadline_ns)?;
                summary.dropped += trailing;
                summary.gaps += 1;
            }
            sink.finish()?;
            p.flushed_tick = summary.last_tick;
            return Ok(());
        }
        if last_flush.elapsed() >= FLUSH_INTERVAL {
            sink.flush()?;
            p.flushed_tick = summary.last_tick;
            last_flush = std::time::Instant::now();
        }
        if popped == 0 {
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}
