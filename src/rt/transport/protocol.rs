//! The wire protocol between the board, the planner and the command-line tools.
//!
//! Every payload is a fixed-size `#[repr(C)]` struct with a stable type name that starts with the
//! same [`Header`]: the protocol [`PROTOCOL_VERSION`], a sequence number and a publish time stamp
//! on the monotonic clock that all processes of the machine share
//! ([`super::clock::monotonic_ns`]). Enumerations travel as `u32` so that an unknown value from a
//! newer or broken sender is a rejection, not undefined behaviour.

use iceoryx2::prelude::*;

/// Version of the message layout; a message with another version is rejected.
/// 3: one [`Header`] leads every payload; rejection counts sized by [`Rejection::COUNT`].
pub const PROTOCOL_VERSION: u32 = 3;
/// Largest number of joints a message carries.
pub const MAX_JOINTS: usize = 2;
/// Knots per command slice. At 10 ms per knot a slice covers up to 320 ms.
pub const MAX_KNOTS: usize = 32;

/// What every message starts with: who may read it (the version), its order among the sender's
/// messages (receivers refuse sequence numbers that repeat or go backwards) and when it was
/// published.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("vic::Header/3")]
#[repr(C)]
pub struct Header {
    /// [`PROTOCOL_VERSION`] of the sender.
    pub version: u32,
    pub _pad: u32,
    /// Sequence number, increasing per sender.
    pub seq: u64,
    /// Publish time [ns, monotonic].
    pub time_ns: u64,
}

impl Header {
    /// A header of this protocol version.
    pub fn new(seq: u64, time_ns: u64) -> Header {
        Header {
            version: PROTOCOL_VERSION,
            _pad: 0,
            seq,
            time_ns,
        }
    }
}

/// What the board is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Mode {
    /// Plant frozen at its reset state, waiting for the trial start or a command.
    Idle = 0,
    /// Following a valid command.
    Running = 1,
    /// No valid command covers the present: holding the position with the safe stiffness.
    SafeHold = 2,
    /// The plant guard tripped (a joint or speed limit, or a state that is not finite): latched
    /// in a safe hold (or frozen) until an explicit reset.
    Fault = 3,
}

impl Mode {
    /// From the wire value (unknown values read as `Fault`).
    pub fn from_u32(v: u32) -> Mode {
        match v {
            0 => Mode::Idle,
            1 => Mode::Running,
            2 => Mode::SafeHold,
            _ => Mode::Fault,
        }
    }
    /// Lower-case name for reports.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Idle => "idle",
            Mode::Running => "running",
            Mode::SafeHold => "safe-hold",
            Mode::Fault => "fault",
        }
    }
}

/// The board's plant state, published every tick.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("vic::State/3")]
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
    /// Trial time at which the watchdog expires unless a valid command covers the present
    /// [ns] (the last covered period + the watchdog timeout).
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
    pub fn lerp(&self, other: &Knot, t: f64) -> Knot {
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

/// How the board reads the knots between their times.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Interpolation {
    /// Zero-order hold: knot `i` holds over `[t_i, t_{i+1})` (the plan's discretisation).
    Hold = 0,
    /// Linear between knots.
    Linear = 1,
}

/// A slice of commands covering `[start, start + count · knot_dt)` of a trial's plant time.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("vic::CommandSlice/3")]
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
    /// Trial time just after the last knot's interval [ns].
    pub fn end_ns(&self) -> u64 {
        self.start_ns + self.count as u64 * self.knot_dt_ns
    }
}

/// Kinds of disturbance.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum DisturbanceKind {
    /// `torque` for `duration_ns`.
    Pulse = 0,
    /// A steady `torque` until changed (zero removes it).
    Load = 1,
    /// Field on (`value` = β of a divergent field [N/m]) or off (`value` = 0).
    Field = 2,
    /// Noise level: the plant noise is multiplied by `value` (1: as configured, 0: none).
    Noise = 3,
}

impl DisturbanceKind {
    pub fn from_u32(v: u32) -> Option<Self> {
        Some(match v {
            0 => DisturbanceKind::Pulse,
            1 => DisturbanceKind::Load,
            2 => DisturbanceKind::Field,
            3 => DisturbanceKind::Noise,
            _ => return None,
        })
    }
}

/// A disturbance for the board to apply.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("vic::Disturbance/3")]
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

/// Control requests.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum ControlKind {
    /// Put the plant at `q0`, `qd0`, reseed the noise from `(seed, trial)`, wait for the trial to
    /// start at the board tick on or after `start_ns` (monotonic).
    Reset = 0,
    /// Stop the trial: freeze the plant (idle).
    Stop = 1,
}

/// A control request to the board.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("vic::Control/3")]
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

/// Why the board rejected a message. The board counts them by reason; [`Telemetry`] carries the
/// counts, indexed by `reason as usize`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(usize)]
pub enum Rejection {
    /// Another protocol version.
    Version = 0,
    /// Another number of joints.
    Joints = 1,
    /// Knot count, knot interval or interpolation out of range.
    Shape = 2,
    /// A number that is NaN or infinite.
    NotFinite = 3,
    /// Stiffness below 0 or above the actuator's maximum.
    StiffnessOutOfBounds = 4,
    /// Feedforward torque beyond the actuator's limit.
    TorqueOutOfBounds = 5,
    /// The damping that the actuator's law gives this stiffness is negative (unstable joint).
    DampingUnstable = 6,
    /// A command for another trial, or with no trial reset.
    WrongTrial = 7,
    /// A sequence number that repeats or goes backwards.
    OutOfOrder = 8,
    /// A time stamp later than the board's clock beyond the tolerance.
    FutureTimestamp = 9,
    /// A disturbance beyond the configured limits.
    DisturbanceOutOfBounds = 10,
    /// An unknown disturbance or control kind.
    UnknownKind = 11,
    /// More messages in one tick than the board takes.
    Overflow = 12,
    /// A command while the plant guard's fault is latched (only a reset clears it).
    Faulted = 13,
    /// An equilibrium `q_d` outside the joint range or `q_d'` beyond the speed limit.
    EquilibriumOutOfBounds = 14,
}

impl Rejection {
    /// Number of reasons: one past the last variant (a new reason goes last, and [`Self::ALL`]
    /// fails to compile until it lists it).
    pub const COUNT: usize = Rejection::EquilibriumOutOfBounds as usize + 1;
    /// Every reason, in wire order (`ALL[r as usize] == r`).
    pub const ALL: [Rejection; Rejection::COUNT] = [
        Rejection::Version,
        Rejection::Joints,
        Rejection::Shape,
        Rejection::NotFinite,
        Rejection::StiffnessOutOfBounds,
        Rejection::TorqueOutOfBounds,
        Rejection::DampingUnstable,
        Rejection::WrongTrial,
        Rejection::OutOfOrder,
        Rejection::FutureTimestamp,
        Rejection::DisturbanceOutOfBounds,
        Rejection::UnknownKind,
        Rejection::Overflow,
        Rejection::Faulted,
        Rejection::EquilibriumOutOfBounds,
    ];
    /// Name for reports and JSON.
    pub fn name(self) -> &'static str {
        match self {
            Rejection::Version => "version",
            Rejection::Joints => "joints",
            Rejection::Shape => "shape",
            Rejection::NotFinite => "not-finite",
            Rejection::StiffnessOutOfBounds => "stiffness-out-of-bounds",
            Rejection::TorqueOutOfBounds => "torque-out-of-bounds",
            Rejection::DampingUnstable => "damping-unstable",
            Rejection::WrongTrial => "wrong-trial",
            Rejection::OutOfOrder => "out-of-order",
            Rejection::FutureTimestamp => "future-timestamp",
            Rejection::DisturbanceOutOfBounds => "disturbance-out-of-bounds",
            Rejection::UnknownKind => "unknown-kind",
            Rejection::Overflow => "overflow",
            Rejection::Faulted => "faulted",
            Rejection::EquilibriumOutOfBounds => "equilibrium-out-of-bounds",
        }
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
#[type_name("vic::Telemetry/3")]
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
