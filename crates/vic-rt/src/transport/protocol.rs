//! The wire protocol between the board, the planner and the command-line tools.
//!
//! Every payload is a fixed-size `#[repr(C)]` struct with a stable type name that starts with the
//! same [`Header`]: the protocol [`PROTOCOL_VERSION`], the sender's session, a sequence number
//! and a publish time stamp on the monotonic clock that all processes of the machine share
//! ([`super::clock::monotonic_ns`]). Enumerations travel as `u32` so that an unknown value from a
//! newer or broken sender is a rejection, not undefined behaviour. `docs/PROTOCOL.md` describes
//! the wire format for clients in other languages (a test keeps it in step with these types).

use crate::transport::wire_enum::wire_enum;
use iceoryx2::prelude::*;

/// Version of the message layout; a message with another version is rejected.
/// 3: one [`Header`] leads every payload; rejection counts sized by [`Rejection::COUNT`].
/// 4: a sender session in the header (sequence numbers count per session); bounds on the knot
/// interval, the slice duration, how far ahead a slice reaches and the age of a message; the
/// rejections [`Rejection::Stale`] and [`Rejection::TooFarAhead`].
pub const PROTOCOL_VERSION: u32 = 4;
/// Largest number of joints a message carries.
pub const MAX_JOINTS: usize = 2;
/// Knots per command slice. At 10 ms per knot a slice covers up to 320 ms.
pub const MAX_KNOTS: usize = 32;
/// Shortest and longest time between knots [ns] (0.1 ms and 100 ms).
pub const MIN_KNOT_DT_NS: u64 = 100_000;
pub const MAX_KNOT_DT_NS: u64 = 100_000_000;
/// Longest slice, `count · knot_dt` [ns] (1 s).
pub const MAX_SLICE_NS: u64 = 1_000_000_000;
/// How far past the board's present trial time a slice may end, and how far past the board's
/// clock a reset may schedule its trial start [ns] (2 s). A command cannot buy time from the
/// watchdog anyway (only the arrival of fresh commands feeds it); this keeps what a board holds
/// close to the present.
pub const MAX_REACH_NS: u64 = 2_000_000_000;
/// Oldest message accepted: its time stamp at most this long before the board's clock [ns]
/// (100 ms). An old message is not a fresh command, whatever its sequence number.
pub const MAX_MESSAGE_AGE_NS: u64 = 100_000_000;

/// What every message starts with: who may read it (the version), which sender session it
/// belongs to, its order among that session's messages and when it was published.
///
/// Sequence rules (the board's, per kind of message): within a session the sequence number must
/// increase; a message of another session is accepted when its time stamp is not earlier than
/// that of the last message accepted, and then starts the order anew. So a restarted sender (a
/// new session) is recognised at once, and a `seq` of `u64::MAX` blocks nothing but its own
/// session. A reset forgets the last command and disturbance seen.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("vic::Header/4")]
#[repr(C)]
pub struct Header {
    /// [`PROTOCOL_VERSION`] of the sender.
    pub version: u32,
    /// Sender session: a number the sender draws at random when it starts
    /// ([`super::clock::process_session`]).
    pub session: u32,
    /// Sequence number, increasing within the session.
    pub seq: u64,
    /// Publish time [ns, monotonic].
    pub time_ns: u64,
}

impl Header {
    /// A header of this protocol version in this process's session.
    pub fn new(seq: u64, time_ns: u64) -> Header {
        Header::in_session(super::clock::process_session(), seq, time_ns)
    }
    /// A header of this protocol version in `session`.
    pub fn in_session(session: u32, seq: u64, time_ns: u64) -> Header {
        Header {
            version: PROTOCOL_VERSION,
            session,
            seq,
            time_ns,
        }
    }
}

wire_enum! {
    /// What the board is doing.
    pub enum Mode: u32 else Fault {
        /// No trial: the plant holds its posture under the hold law (a push moves it, it springs
        /// back); after a reset, frozen at the reset state until the trial start.
        Idle = 0 => "idle",
        /// Following a valid command.
        Running = 1 => "running",
        /// No valid command covers the present: holding the position with the safe stiffness.
        SafeHold = 2 => "safe-hold",
        /// The plant guard tripped (a joint or speed limit, or a state that is not finite):
        /// latched in a safe hold (or frozen) until an explicit reset.
        Fault = 3 => "fault",
    }
}

/// The board's plant state, published every tick.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("vic::State/4")]
#[repr(C)]
pub struct StateMsg {
    pub header: Header,
    pub joints: u32,
    /// Trial the state belongs to (from the last reset).
    pub trial: u32,
    /// Board tick counter.
    pub tick: u64,
    /// [`Mode`] as `u32`.
    pub mode: u32,
    pub _pad: u32,
    /// Plant time since the trial start [ns] (0 while idle before the start).
    pub trial_time_ns: u64,
    /// Joint angles [rad], velocities [rad/s] and the joint torque applied [N m].
    pub q: [f64; MAX_JOINTS],
    pub qd: [f64; MAX_JOINTS],
    pub tau: [f64; MAX_JOINTS],
    /// External torque from disturbances in force [N m].
    pub tau_ext: [f64; MAX_JOINTS],
    /// Stiffness in use [N m/rad].
    pub stiffness: [f64; MAX_JOINTS],
    /// Sequence number of the command slice used (0: none).
    pub command_seq: u64,
    /// Sequence number of the last disturbance applied and the tick it was applied at.
    pub disturbance_seq: u64,
    pub disturbance_tick: u64,
    /// Trial time at which the watchdog expires unless a fresh valid command arrives before
    /// [ns] (the arrival of the last one + the watchdog timeout, in trial time).
    pub watchdog_deadline_ns: u64,
    /// Sequence number of the reset that started this trial: a restarted planner numbers its
    /// trials from 0 again, and this tells its trial from the one before the restart.
    pub reset_seq: u64,
}

/// One knot of a command: the inputs of the impedance law (Eq. 4) at one time.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("vic::Knot/1")]
#[repr(C)]
pub struct Knot {
    /// Feedforward torque `τ_ff` [N m].
    pub tau_ff: [f64; MAX_JOINTS],
    /// Stiffness `K_P` [N m/rad] (the damping follows from the actuator's law).
    pub stiffness: [f64; MAX_JOINTS],
    /// Equilibrium `q_d` [rad] and `q_d'` [rad/s].
    pub q_d: [f64; MAX_JOINTS],
    pub qd_d: [f64; MAX_JOINTS],
}

impl Knot {
    /// `self + t (other − self)` for every input: the linear interpolation between knots, and
    /// the ramp into the safe hold (linear in every input, so the joint torque stays continuous).
    pub(crate) fn lerp(&self, other: &Knot, t: f64) -> Knot {
        let mut k = *self;
        for j in 0..MAX_JOINTS {
            k.tau_ff[j] += t * (other.tau_ff[j] - self.tau_ff[j]);
            k.stiffness[j] += t * (other.stiffness[j] - self.stiffness[j]);
            k.q_d[j] += t * (other.q_d[j] - self.q_d[j]);
            k.qd_d[j] += t * (other.qd_d[j] - self.qd_d[j]);
        }
        k
    }
}

wire_enum! {
    /// How the board reads the knots between their times.
    pub enum Interpolation: u32 {
        /// Zero-order hold: knot `i` holds over `[t_i, t_{i+1})` (the plan's discretisation).
        Hold = 0 => "hold",
        /// Linear between knots.
        Linear = 1 => "linear",
    }
}

/// A slice of commands covering `[start, start + count · knot_dt)` of a trial's plant time.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("vic::CommandSlice/4")]
#[repr(C)]
pub struct CommandSlice {
    pub header: Header,
    pub joints: u32,
    /// The trial the slice is for; slices for another trial are rejected.
    pub trial: u32,
    /// [`Interpolation`] as `u32`.
    pub interpolation: u32,
    /// Number of valid knots.
    pub count: u32,
    /// Trial time of the first knot [ns].
    pub start_ns: u64,
    /// Time between knots [ns].
    pub knot_dt_ns: u64,
    pub knots: [Knot; MAX_KNOTS],
}

impl Default for CommandSlice {
    /// An empty slice of this protocol version.
    fn default() -> Self {
        CommandSlice {
            header: Header::new(0, 0),
            joints: 0,
            trial: 0,
            interpolation: Interpolation::Hold as u32,
            count: 0,
            start_ns: 0,
            knot_dt_ns: 0,
            knots: [Knot::default(); MAX_KNOTS],
        }
    }
}

impl CommandSlice {
    /// Duration `count · knot_dt` [ns], `None` when it overflows (the board bounds both factors
    /// before it asks).
    pub fn duration_ns(&self) -> Option<u64> {
        (self.count as u64).checked_mul(self.knot_dt_ns)
    }
    /// Trial time just after the last knot's interval [ns] (saturating: only a validated slice,
    /// whose end cannot overflow, is ever asked).
    pub(crate) fn end_ns(&self) -> u64 {
        self.duration_ns()
            .and_then(|d| self.start_ns.checked_add(d))
            .unwrap_or(u64::MAX)
    }
}

wire_enum! {
    /// Kinds of disturbance.
    pub enum DisturbanceKind: u32 {
        /// `torque` for `duration_ns`.
        Pulse = 0 => "pulse",
        /// A steady `torque` until changed (zero removes it).
        Load = 1 => "load",
        /// Field on (`value` = β of a divergent field [N/m]) or off (`value` = 0).
        Field = 2 => "field",
        /// Noise level: the plant noise is multiplied by `value` (1: as configured, 0: none).
        Noise = 3 => "noise",
    }
}

/// A disturbance for the board to apply.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("vic::Disturbance/4")]
#[repr(C)]
pub struct Disturbance {
    pub header: Header,
    /// [`DisturbanceKind`] as `u32`.
    pub kind: u32,
    pub _pad: u32,
    /// Joint torque [N m] (pulse, load).
    pub torque: [f64; MAX_JOINTS],
    /// Pulse duration [ns].
    pub duration_ns: u64,
    /// Field β [N/m] or noise factor.
    pub value: f64,
}

wire_enum! {
    /// Control requests.
    pub enum ControlKind: u32 {
        /// Put the plant at `q0`, `qd0`, reseed the noise from `(seed, trial)`, wait for the trial
        /// to start at the board tick on or after `start_ns` (monotonic).
        Reset = 0 => "reset",
        /// Stop the trial: idle, the plant ramped into the hold at its posture.
        Stop = 1 => "stop",
    }
}

/// A control request to the board.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("vic::Control/4")]
#[repr(C)]
pub struct Control {
    pub header: Header,
    /// [`ControlKind`] as `u32`.
    pub kind: u32,
    pub trial: u32,
    pub seed: u64,
    /// Monotonic time at which the trial starts [ns].
    pub start_ns: u64,
    pub q0: [f64; MAX_JOINTS],
    pub qd0: [f64; MAX_JOINTS],
}

/// Percentiles of a histogram [µs] (also the form JSON reports print).
#[derive(
    Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, serde::Serialize, serde::Deserialize,
)]
#[type_name("vic::Percentiles/1")]
#[repr(C)]
pub struct Percentiles {
    pub p50: f64,
    pub p99: f64,
    pub p999: f64,
    pub max: f64,
    pub count: u64,
}

wire_enum! {
    /// Why the board rejected a message. The board counts them by reason; [`Telemetry`] carries
    /// the counts, indexed by `reason as usize` (the values run from 0 without a gap, so
    /// `ALL[r as usize] == r`; a new reason goes last).
    pub enum Rejection: usize {
        /// Another protocol version.
        Version = 0 => "version",
        /// Another number of joints.
        Joints = 1 => "joints",
        /// Knot count, knot interval, slice duration or interpolation out of range.
        Shape = 2 => "shape",
        /// A number that is NaN or infinite.
        NotFinite = 3 => "not-finite",
        /// Stiffness below 0 or above the actuator's maximum.
        StiffnessOutOfBounds = 4 => "stiffness-out-of-bounds",
        /// Feedforward torque beyond the actuator's limit.
        TorqueOutOfBounds = 5 => "torque-out-of-bounds",
        /// The damping that the actuator's law gives this stiffness is negative (unstable joint).
        DampingUnstable = 6 => "damping-unstable",
        /// A command for another trial, or with no trial reset.
        WrongTrial = 7 => "wrong-trial",
        /// A sequence number that repeats or goes backwards within its session, or a new session
        /// whose time stamp is earlier than the last message accepted.
        OutOfOrder = 8 => "out-of-order",
        /// A time stamp later than the board's clock beyond the tolerance.
        FutureTimestamp = 9 => "future-timestamp",
        /// A disturbance beyond the configured limits.
        DisturbanceOutOfBounds = 10 => "disturbance-out-of-bounds",
        /// An unknown disturbance or control kind.
        UnknownKind = 11 => "unknown-kind",
        /// More messages in one tick than the board takes.
        Overflow = 12 => "overflow",
        /// A command while the plant guard's fault is latched (only a reset clears it).
        Faulted = 13 => "faulted",
        /// An equilibrium `q_d` outside the joint range or `q_d'` beyond the speed limit.
        EquilibriumOutOfBounds = 14 => "equilibrium-out-of-bounds",
        /// A time stamp older than [`MAX_MESSAGE_AGE_NS`] by the board's clock.
        Stale = 15 => "stale",
        /// A slice that ends more than [`MAX_REACH_NS`] after the board's present trial time, or a
        /// reset whose start is more than that after the board's clock.
        TooFarAhead = 16 => "too-far-ahead",
    }
}

const _: () = {
    let mut i = 0;
    while i < Rejection::COUNT {
        assert!(
            Rejection::ALL[i] as usize == i,
            "Rejection::ALL is out of order"
        );
        i += 1;
    }
};

/// The board's telemetry, published at a lower rate than the state.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("vic::Telemetry/4")]
#[repr(C)]
pub struct Telemetry {
    pub header: Header,
    pub mode: u32,
    pub trial: u32,
    pub tick: u64,
    /// Tick rate measured over the last telemetry interval [Hz].
    pub tick_rate_hz: f64,
    /// Wake-up lateness, tick work time and age of the command used [µs].
    pub jitter_us: Percentiles,
    pub work_us: Percentiles,
    pub command_age_us: Percentiles,
    /// Ticks that woke more than one period late, and periods skipped.
    pub late_ticks: u64,
    pub missed_periods: u64,
    pub rejected_messages: u64,
    pub safe_hold_ticks: u64,
    /// Distance of the joint angles to the commanded equilibrium [rad] (Euclidean).
    pub tracking_error: f64,
    pub stiffness: [f64; MAX_JOINTS],
    pub tau_ext: [f64; MAX_JOINTS],
    pub field_beta: f64,
    pub noise_factor: f64,
    pub joints: u32,
    /// Why the board is in fault (`board::FaultReason as u32`, 0: none).
    pub fault_reason: u32,
    /// Rejected messages by reason (indexed by `Rejection as usize`).
    pub rejected_by_reason: [u64; Rejection::COUNT],
    /// Times the watchdog ramped the board to its safe hold.
    pub watchdog_trips: u64,
    /// Sequence number of the last disturbance applied and the tick it was applied at.
    pub disturbance_seq: u64,
    pub disturbance_tick: u64,
    /// Messages lost before the board saw them (overwritten in its receive buffers), counted
    /// from the gaps in each sender session's sequence numbers.
    pub dropped_messages: u64,
}

/// What a board's event wakes its listeners for (iceoryx2 event ids).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(usize)]
pub enum BoardEvent {
    /// New telemetry was published.
    Telemetry = 1,
    /// A disturbance or control request was applied (its acknowledgement is in the state).
    Applied = 2,
}
