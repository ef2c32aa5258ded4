//! The board: a pure state machine that runs the impedance law of paper Eq. 4 on the freshest
//! local state and integrates the plant, one [`Board::step`] per tick (DESIGN §8).
//!
//! It knows no clock and no transport: the caller passes the tick's time and the messages that
//! arrived, and publishes what comes out. The same code runs in the 1 kHz loop of `vic-board`, in
//! the lockstep mode (a simulated clock) and in tests. A step allocates nothing.
//!
//! Safety (what the board promises whatever arrives): every message is validated before use and
//! a rejected one is counted by [`Rejection`] and never reaches the plant; when no valid command
//! covers the present, the last one stays in force for [`BoardConfig::watchdog_ns`], then the
//! board ramps to a *safe hold* (the current position, the hold stiffness, gravity and field
//! compensated) and resumes when valid commands cover the present again; leaving the joint or
//! speed limits latches a [`Mode::Fault`] (ramp to the hold, commands refused) that only a reset
//! clears.
//!
//! Time: `step(now)` takes the tick's *deadline* (a whole number of periods). The plant follows
//! the clock: when ticks were missed, the step integrates every elapsed period (up to
//! [`BoardConfig::max_catch_up`]) with the law evaluated each period, as the plant would have
//! moved; the loop itself never catches up in a burst.

use crate::core::dynamics::{Integrator, flow};
use crate::core::model::{ArmModel, Exogenous, Field, Noise};
use crate::core::scalar::{MAX_NW, MAX_NX};
use crate::rt::transport::{
    CommandSlice, Control, ControlKind, Disturbance, DisturbanceKind, Interpolation, Knot,
    MAX_JOINTS, MAX_KNOTS, Mode, PROTOCOL_VERSION, REJECTION_REASONS, StateMsg,
};
use rand::rngs::Xoshiro256PlusPlus;

/// Fixed parameters of a board.
#[derive(Debug, Clone)]
pub struct BoardConfig {
    /// Tick period [ns] (default 1 ms).
    pub period_ns: u64,
    /// Integration sub-steps per period (default 1: at 1 ms the semi-implicit step is stable).
    pub substeps: usize,
    pub integrator: Integrator,
    /// Stiffness of the safe hold [N m/rad] (default 100).
    pub hold_stiffness: f64,
    /// How long the last command stays in force once none covers the present [ns] (default 50 ms).
    pub watchdog_ns: u64,
    /// Duration of the ramp into the safe hold [ns] (default 100 ms).
    pub ramp_ns: u64,
    /// Plant guard: joint range [rad] and speed limit [rad/s].
    pub joint_min: [f64; MAX_JOINTS],
    pub joint_max: [f64; MAX_JOINTS],
    pub velocity_max: f64,
    /// Messages stamped later than the board's clock by more than this are rejected [ns].
    pub future_tolerance_ns: u64,
    /// Largest disturbances accepted.
    pub max_pulse_torque: f64,
    pub max_load_torque: f64,
    pub max_pulse_ns: u64,
    pub max_field_beta: f64,
    pub max_noise_factor: f64,
    /// Largest stiffness a command may ask for [N m/rad] (from the scenario's bounds).
    pub stiffness_max: f64,
    /// Largest feedforward torque magnitude a command may ask for [N m].
    pub torque_max: f64,
    /// Most periods integrated in one step after missed ticks (default 50); the rest are lost.
    pub max_catch_up: u64,
}

impl Default for BoardConfig {
    fn default() -> Self {
        BoardConfig {
            period_ns: 1_000_000,
            substeps: 1,
            integrator: Integrator::SemiImplicit,
            hold_stiffness: 100.0,
            watchdog_ns: 50_000_000,
            ramp_ns: 100_000_000,
            joint_min: [-std::f64::consts::PI; MAX_JOINTS],
            joint_max: [std::f64::consts::PI; MAX_JOINTS],
            velocity_max: 20.0,
            future_tolerance_ns: 5_000_000,
            max_pulse_torque: 20.0,
            max_load_torque: 10.0,
            max_pulse_ns: 2_000_000_000,
            max_field_beta: 500.0,
            max_noise_factor: 10.0,
            stiffness_max: 1e4,
            torque_max: 1e4,
            max_catch_up: 50,
        }
    }
}

/// Messages that arrived since the last step (fixed capacity: a step allocates nothing). Extra
/// messages beyond the capacity are counted as rejected.
#[derive(Debug, Clone, Default)]
pub struct Inputs {
    commands: [CommandSlice; 4],
    n_commands: usize,
    controls: [Control; 4],
    n_controls: usize,
    disturbances: [Disturbance; 4],
    n_disturbances: usize,
    overflow: u64,
    /// When the messages were taken [ns, monotonic] (0: the step's deadline). Time stamps later
    /// than this by more than the tolerance are rejected.
    pub received_ns: u64,
}

impl Inputs {
    pub fn push_command(&mut self, c: &CommandSlice) {
        if self.n_commands < self.commands.len() {
            self.commands[self.n_commands] = *c;
            self.n_commands += 1;
        } else {
            self.overflow += 1;
        }
    }
    pub fn push_control(&mut self, c: &Control) {
        if self.n_controls < self.controls.len() {
            self.controls[self.n_controls] = *c;
            self.n_controls += 1;
        } else {
            self.overflow += 1;
        }
    }
    pub fn push_disturbance(&mut self, d: &Disturbance) {
        if self.n_disturbances < self.disturbances.len() {
            self.disturbances[self.n_disturbances] = *d;
            self.n_disturbances += 1;
        } else {
            self.overflow += 1;
        }
    }
}

/// What one step produced.
#[derive(Debug, Clone, Copy, Default)]
pub struct Outputs {
    /// The state to publish (time stamp left to the caller).
    pub state: StateMsg,
    /// Age of the command used at this tick [ns] (its publish time to `now`), if one was used.
    pub command_age_ns: Option<u64>,
    /// Plant periods integrated by this step.
    pub periods: u64,
    /// Distance of the joint angles to the equilibrium in use [rad].
    pub tracking_error: f64,
    /// The knot the law used over the last period integrated (the safe hold's while holding;
    /// zero when no period was integrated).
    pub knot: Knot,
    /// Joint acceleration over the last period integrated: the change of `q'` over the period
    /// divided by the period [rad/s²] (noise included; zero when no period was integrated).
    pub qdd: [f64; MAX_JOINTS],
}

/// Running counts of a board.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    pub ticks: u64,
    pub rejected: u64,
    /// Rejected messages by [`Rejection`] (index `reason as usize`).
    pub rejected_by: [u64; REJECTION_REASONS],
    pub safe_hold_ticks: u64,
    /// Times the watchdog expired and the board ramped to its safe hold.
    pub watchdog_trips: u64,
    /// Times the plant guard latched a fault.
    pub faults: u64,
    /// Periods not integrated because a step would have exceeded `max_catch_up`.
    pub lost_periods: u64,
    pub resets: u64,
}

/// Why a message was rejected.
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
    pub const ALL: [Rejection; 15] = [
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

/// Why the plant guard latched a fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum FaultReason {
    None = 0,
    JointLimit = 1,
    VelocityLimit = 2,
    /// The state stopped being finite: the plant is frozen rather than held.
    NotFinite = 3,
}

impl FaultReason {
    pub fn from_u32(v: u32) -> FaultReason {
        match v {
            0 => FaultReason::None,
            1 => FaultReason::JointLimit,
            2 => FaultReason::VelocityLimit,
            _ => FaultReason::NotFinite,
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            FaultReason::None => "none",
            FaultReason::JointLimit => "joint-limit",
            FaultReason::VelocityLimit => "velocity-limit",
            FaultReason::NotFinite => "not-finite",
        }
    }
}

const SLICES: usize = 4;

/// The board state machine.
pub struct Board {
    model: ArmModel,
    base_noise: Noise,
    base_field: Field,
    damping: crate::core::model::Damping,
    cfg: BoardConfig,
    dof: usize,
    nx: usize,
    x: [f64; MAX_NX],
    tau: [f64; MAX_JOINTS],
    stiffness: [f64; MAX_JOINTS],
    mode: Mode,
    fault: FaultReason,
    trial: u32,
    /// Monotonic time at which the pending trial starts (None: no trial pending or running).
    start_ns: Option<u64>,
    /// Deadline up to which the plant is integrated.
    plant_ns: u64,
    trial_time_ns: u64,
    slices: [CommandSlice; SLICES],
    slice_valid: [bool; SLICES],
    next_slot: usize,
    last_command_seq: u64,
    last_control_seq: u64,
    /// Sequence number of the reset that started the present trial.
    reset_seq: u64,
    used_command_seq: u64,
    /// The knot last taken from a valid command, and the trial time it covered last.
    last_knot: Knot,
    last_cover_ns: u64,
    /// The safe hold: ramp from `hold_from` to `hold_to` starting at trial time `hold_start_ns`.
    hold_from: Knot,
    hold_to: Knot,
    hold_start_ns: u64,
    rng: Xoshiro256PlusPlus,
    pulse: [f64; MAX_JOINTS],
    pulse_until_ns: u64,
    load: [f64; MAX_JOINTS],
    noise_factor: f64,
    disturbance_seq: u64,
    disturbance_tick: u64,
    /// A disturbance or control was applied at the last step (the loop wakes listeners).
    applied: bool,
    tick: u64,
    pub counters: Counters,
}

// The random stream of a trial is the Monte Carlo's, so that live and offline trials with the
// same seed draw the same noise.
use crate::core::rng::{add_diffusion, trial_rng};

impl Board {
    /// A board for `model` (impedance actuator, type 2), at rest at `q0`.
    pub fn new(model: ArmModel, cfg: BoardConfig, q0: &[f64]) -> Result<Board, String> {
        let damping = match model.actuator {
            crate::core::model::Actuator::Impedance { damping } => damping,
            _ => {
                return Err(format!(
                    "the board runs the impedance law (actuator type 2); this scenario has a {} \
                     actuator",
                    model.actuator.name()
                ));
            }
        };
        if cfg.period_ns == 0 || cfg.substeps == 0 {
            return Err("the board period and sub-steps must be positive".into());
        }
        if ![cfg.stiffness_max, cfg.torque_max, cfg.velocity_max]
            .iter()
            .all(|v| v.is_finite() && *v >= 0.0)
        {
            return Err(format!(
                "the board's limits must be finite: stiffness_max {}, torque_max {}, \
                 velocity_max {}",
                cfg.stiffness_max, cfg.torque_max, cfg.velocity_max
            ));
        }
        if !(cfg.hold_stiffness.is_finite() && damping.gain(cfg.hold_stiffness) >= 0.0) {
            return Err(format!(
                "hold stiffness {}: its damping under the actuator's law must be ≥ 0",
                cfg.hold_stiffness
            ));
        }
        let dof = model.dof();
        let nx = model.nx();
        let mut x = [0.0; MAX_NX];
        x[..dof].copy_from_slice(&q0[..dof]);
        let mut b = Board {
            base_noise: model.noise,
            base_field: model.field,
            damping,
            model,
            cfg,
            dof,
            nx,
            x,
            tau: [0.0; MAX_JOINTS],
            stiffness: [0.0; MAX_JOINTS],
            mode: Mode::Idle,
            fault: FaultReason::None,
            trial: 0,
            start_ns: None,
            plant_ns: 0,
            trial_time_ns: 0,
            slices: [CommandSlice::default(); SLICES],
            slice_valid: [false; SLICES],
            next_slot: 0,
            last_command_seq: 0,
            last_control_seq: 0,
            reset_seq: 0,
            used_command_seq: 0,
            last_knot: Knot::default(),
            last_cover_ns: 0,
            hold_from: Knot::default(),
            hold_to: Knot::default(),
            hold_start_ns: 0,
            rng: trial_rng(0, 0),
            pulse: [0.0; MAX_JOINTS],
            pulse_until_ns: 0,
            load: [0.0; MAX_JOINTS],
            noise_factor: 1.0,
            disturbance_seq: 0,
            disturbance_tick: 0,
            applied: false,
            tick: 0,
            counters: Counters::default(),
        };
        b.last_knot = b.hold_target();
        Ok(b)
    }

    pub fn mode(&self) -> Mode {
        self.mode
    }
    /// Why the fault is latched ([`FaultReason::None`] outside [`Mode::Fault`]).
    pub fn fault(&self) -> FaultReason {
        self.fault
    }
    pub fn config(&self) -> &BoardConfig {
        &self.cfg
    }
    /// The plant it simulates.
    pub fn model(&self) -> &ArmModel {
        &self.model
    }
    /// Time into the present trial [ns].
    pub fn trial_time_ns(&self) -> u64 {
        self.trial_time_ns
    }
    pub fn trial(&self) -> u32 {
        self.trial
    }
    /// The plant state `(q, q')`.
    pub fn state(&self) -> &[f64] {
        &self.x[..self.nx]
    }
    pub fn stiffness(&self) -> [f64; MAX_JOINTS] {
        self.stiffness
    }
    /// Whether the last step applied a disturbance or control request.
    pub fn applied(&self) -> bool {
        self.applied
    }
    /// Sequence number and tick of the last disturbance applied.
    pub fn last_disturbance(&self) -> (u64, u64) {
        (self.disturbance_seq, self.disturbance_tick)
    }
    /// External torque now in force [N m].
    pub fn tau_ext(&self, now_ns: u64) -> [f64; MAX_JOINTS] {
        let mut t = self.load;
        if now_ns < self.pulse_until_ns {
            for i in 0..MAX_JOINTS {
                t[i] += self.pulse[i];
            }
        }
        t
    }
    /// β of the divergent field in force [N/m] (0 without one).
    pub fn field_beta(&self) -> f64 {
        match self.model.field {
            Field::Divergent { beta } => beta,
            _ => 0.0,
        }
    }
    pub fn noise_factor(&self) -> f64 {
        self.noise_factor
    }
    /// Damping gain `K_D` of the impedance law (Eq. 4) for the stiffness `k` [N m s/rad].
    pub fn damping(&self, k: &[f64; MAX_JOINTS]) -> [f64; MAX_JOINTS] {
        let mut d = [0.0; MAX_JOINTS];
        if let crate::core::model::Actuator::Impedance { damping } = &self.model.actuator {
            for i in 0..self.dof {
                d[i] = damping.gain(k[i]);
            }
        }
        d
    }

    fn reject(&mut self, r: Rejection) {
        self.counters.rejected += 1;
        self.counters.rejected_by[r as usize] += 1;
    }

    /// Checks a command slice; `Ok` when it may be used. (Its time stamp is checked in
    /// [`Board::step`], against the clock.)
    pub fn validate(&self, c: &CommandSlice) -> Result<(), Rejection> {
        if c.version != PROTOCOL_VERSION {
            return Err(Rejection::Version);
        }
        if c.joints as usize != self.dof {
            return Err(Rejection::Joints);
        }
        if c.count == 0
            || c.count as usize > MAX_KNOTS
            || c.knot_dt_ns == 0
            || c.interpolation > Interpolation::Linear as u32
            || c.start_ns
                .checked_add(c.count as u64 * c.knot_dt_ns)
                .is_none()
        {
            return Err(Rejection::Shape);
        }
        if self.mode == Mode::Fault {
            return Err(Rejection::Faulted);
        }
        if c.trial != self.trial || self.start_ns.is_none() {
            return Err(Rejection::WrongTrial);
        }
        if c.seq <= self.last_command_seq {
            return Err(Rejection::OutOfOrder);
        }
        for k in &c.knots[..c.count as usize] {
            for i in 0..self.dof {
                let v = [k.tau_ff[i], k.stiffness[i], k.q_d[i], k.qd_d[i]];
                if v.iter().any(|x| !x.is_finite()) {
                    return Err(Rejection::NotFinite);
                }
                if k.stiffness[i] < 0.0 || k.stiffness[i] > self.cfg.stiffness_max * (1.0 + 1e-9) {
                    return Err(Rejection::StiffnessOutOfBounds);
                }
                // The damping follows the stiffness by the actuator's law; an affine law can
                // make it negative for small stiffness (the iCub's), an unstable joint.
                if self.damping.gain(k.stiffness[i]) < 0.0 {
                    return Err(Rejection::DampingUnstable);
                }
                if k.tau_ff[i].abs() > self.cfg.torque_max {
                    return Err(Rejection::TorqueOutOfBounds);
                }
                // A spring pulled towards a point outside the joint range (or a huge one) is a
                // torque command in disguise.
                if k.q_d[i] < self.cfg.joint_min[i]
                    || k.q_d[i] > self.cfg.joint_max[i]
                    || k.qd_d[i].abs() > self.cfg.velocity_max
                {
                    return Err(Rejection::EquilibriumOutOfBounds);
                }
            }
        }
        Ok(())
    }

    fn in_future(&self, time_ns: u64, clock_ns: u64) -> bool {
        time_ns > clock_ns.saturating_add(self.cfg.future_tolerance_ns)
    }

    fn check_control(&self, c: &Control, clock_ns: u64) -> Result<(), Rejection> {
        if c.version != PROTOCOL_VERSION {
            return Err(Rejection::Version);
        }
        if c.kind != ControlKind::Reset as u32 && c.kind != ControlKind::Stop as u32 {
            return Err(Rejection::UnknownKind);
        }
        if c.q0[..self.dof]
            .iter()
            .chain(&c.qd0[..self.dof])
            .any(|v| !v.is_finite())
        {
            return Err(Rejection::NotFinite);
        }
        if c.seq <= self.last_control_seq {
            return Err(Rejection::OutOfOrder);
        }
        if self.in_future(c.time_ns, clock_ns) {
            return Err(Rejection::FutureTimestamp);
        }
        if c.kind == ControlKind::Reset as u32 {
            let q = &c.q0[..self.dof];
            let inside = (0..self.dof)
                .all(|i| q[i] >= self.cfg.joint_min[i] && q[i] <= self.cfg.joint_max[i])
                && c.qd0[..self.dof]
                    .iter()
                    .all(|v| v.abs() <= self.cfg.velocity_max);
            if !inside {
                return Err(Rejection::DisturbanceOutOfBounds);
            }
        }
        Ok(())
    }

    fn apply_control(&mut self, c: &Control, clock_ns: u64) {
        if let Err(r) = self.check_control(c, clock_ns) {
            self.reject(r);
            return;
        }
        self.last_control_seq = c.seq;
        self.applied = true;
        if c.kind == ControlKind::Reset as u32 {
            // The explicit reset: the only way out of a latched fault.
            self.x = [0.0; MAX_NX];
            self.x[..self.dof].copy_from_slice(&c.q0[..self.dof]);
            self.x[self.dof..2 * self.dof].copy_from_slice(&c.qd0[..self.dof]);
            self.trial = c.trial;
            self.reset_seq = c.seq;
            self.start_ns = Some(c.start_ns);
            self.mode = Mode::Idle;
            self.fault = FaultReason::None;
            self.trial_time_ns = 0;
            self.slice_valid = [false; SLICES];
            self.last_command_seq = 0;
            self.used_command_seq = 0;
            self.last_knot = self.hold_target();
            self.last_cover_ns = 0;
            self.rng = trial_rng(c.seed, c.trial as u64);
            self.tau = [0.0; MAX_JOINTS];
            self.stiffness = [0.0; MAX_JOINTS];
            self.counters.resets += 1;
        } else {
            // Stop freezes the plant; a latched fault stays latched (and held).
            self.slice_valid = [false; SLICES];
            if self.mode != Mode::Fault {
                self.mode = Mode::Idle;
                self.start_ns = None;
            }
        }
    }

    fn check_disturbance(
        &self,
        d: &Disturbance,
        clock_ns: u64,
    ) -> Result<DisturbanceKind, Rejection> {
        if d.version != PROTOCOL_VERSION {
            return Err(Rejection::Version);
        }
        let kind = DisturbanceKind::from_u32(d.kind).ok_or(Rejection::UnknownKind)?;
        if !(d.torque.iter().all(|v| v.is_finite()) && d.value.is_finite()) {
            return Err(Rejection::NotFinite);
        }
        if d.seq <= self.disturbance_seq {
            return Err(Rejection::OutOfOrder);
        }
        if self.in_future(d.time_ns, clock_ns) {
            return Err(Rejection::FutureTimestamp);
        }
        let torque = d.torque[..self.dof]
            .iter()
            .fold(0.0_f64, |m, v| m.max(v.abs()));
        let ok = match kind {
            DisturbanceKind::Pulse => {
                torque <= self.cfg.max_pulse_torque && d.duration_ns <= self.cfg.max_pulse_ns
            }
            DisturbanceKind::Load => torque <= self.cfg.max_load_torque,
            // The divergent field is a hand-space field: a two-link arm only.
            DisturbanceKind::Field => {
                d.value.abs() <= self.cfg.max_field_beta && (d.value == 0.0 || self.dof == 2)
            }
            DisturbanceKind::Noise => d.value >= 0.0 && d.value <= self.cfg.max_noise_factor,
        };
        if ok {
            Ok(kind)
        } else {
            Err(Rejection::DisturbanceOutOfBounds)
        }
    }

    fn apply_disturbance(&mut self, d: &Disturbance, now_ns: u64, clock_ns: u64) {
        let kind = match self.check_disturbance(d, clock_ns) {
            Ok(k) => k,
            Err(r) => {
                self.reject(r);
                return;
            }
        };
        let mut torque = [0.0; MAX_JOINTS];
        torque[..self.dof].copy_from_slice(&d.torque[..self.dof]);
        match kind {
            DisturbanceKind::Pulse => {
                self.pulse = torque;
                self.pulse_until_ns = now_ns + d.duration_ns;
            }
            DisturbanceKind::Load => self.load = torque,
            DisturbanceKind::Field => {
                self.model.field = if d.value == 0.0 {
                    Field::None
                } else {
                    Field::Divergent { beta: d.value }
                };
            }
            DisturbanceKind::Noise => {
                self.noise_factor = d.value;
                self.model.noise = self.base_noise.scaled(d.value);
            }
        }
        self.disturbance_seq = d.seq;
        self.disturbance_tick = self.tick;
        self.applied = true;
    }

    /// Restores the configured field and noise and removes loads and pulses.
    pub fn clear_disturbances(&mut self) {
        self.model.field = self.base_field;
        self.model.noise = self.base_noise;
        self.noise_factor = 1.0;
        self.load = [0.0; MAX_JOINTS];
        self.pulse_until_ns = 0;
    }

    /// The knot in force at trial time `t` from the newest valid slice that covers it, with the
    /// slice's publish time.
    fn command_at(&self, t: u64) -> Option<(Knot, u64, u64)> {
        let mut best: Option<usize> = None;
        for s in 0..SLICES {
            let c = &self.slices[s];
            if self.slice_valid[s]
                && c.start_ns <= t
                && t < c.end_ns()
                && best.is_none_or(|b| self.slices[b].seq < c.seq)
            {
                best = Some(s);
            }
        }
        let c = &self.slices[best?];
        let offset = t - c.start_ns;
        let i = (offset / c.knot_dt_ns) as usize;
        let mut k = c.knots[i];
        if c.interpolation == Interpolation::Linear as u32 && i + 1 < c.count as usize {
            let a = (offset - i as u64 * c.knot_dt_ns) as f64 / c.knot_dt_ns as f64;
            k = lerp(&k, &c.knots[i + 1], a);
        }
        Some((k, c.time_ns, c.seq))
    }

    /// The safe hold at the present position: the hold stiffness, no velocity, the torque that
    /// balances gravity and the field there.
    fn hold_target(&self) -> Knot {
        let dof = self.dof;
        let mut k = Knot::default();
        k.q_d[..dof].copy_from_slice(&self.x[..dof]);
        k.stiffness[..dof]
            .iter_mut()
            .for_each(|v| *v = self.cfg.hold_stiffness);
        let g = self.model.inverse_dynamics(
            &self.x[..dof],
            &[0.0; MAX_JOINTS][..dof],
            &[0.0; MAX_JOINTS][..dof],
        );
        for i in 0..dof {
            // Clamped to the actuator's torque range, like any command.
            k.tau_ff[i] = g[i].clamp(-self.cfg.torque_max, self.cfg.torque_max);
        }
        k
    }

    /// Starts the ramp from the knot in use to the safe hold at trial time `t`.
    fn begin_hold(&mut self, from: Knot, t: u64) {
        self.hold_from = from;
        self.hold_to = self.hold_target();
        self.hold_start_ns = t;
    }

    /// The knot of the safe-hold ramp at trial time `t` (linear in every input, so the joint
    /// torque stays continuous).
    fn hold_knot(&self, t: u64) -> Knot {
        let a = if self.cfg.ramp_ns == 0 {
            1.0
        } else {
            (t.saturating_sub(self.hold_start_ns) as f64 / self.cfg.ramp_ns as f64).min(1.0)
        };
        lerp(&self.hold_from, &self.hold_to, a)
    }

    /// The plant guard: `Some(reason)` when the state has left the configured limits.
    fn guard(&self) -> Option<FaultReason> {
        let dof = self.dof;
        if !self.x[..self.nx].iter().all(|v| v.is_finite()) {
            return Some(FaultReason::NotFinite);
        }
        if (0..dof).any(|i| self.x[i] < self.cfg.joint_min[i] || self.x[i] > self.cfg.joint_max[i])
        {
            return Some(FaultReason::JointLimit);
        }
        if self.x[dof..2 * dof]
            .iter()
            .any(|v| v.abs() > self.cfg.velocity_max)
        {
            return Some(FaultReason::VelocityLimit);
        }
        None
    }

    /// One plant period under knot `k`: Eq. 4 through [`ArmModel::f`], [`flow`], then the noise
    /// `√Δ F(x) ε` (Euler–Maruyama at the board period).
    fn integrate(&mut self, k: &Knot, now_ns: u64) {
        let dof = self.dof;
        let nx = self.nx;
        let mut u = [0.0; 2 * MAX_JOINTS];
        u[..dof].copy_from_slice(&k.tau_ff[..dof]);
        u[dof..2 * dof].copy_from_slice(&k.stiffness[..dof]);
        let ex = Exogenous {
            q_d: k.q_d,
            qd_d: k.qd_d,
            tau_ext: self.tau_ext(now_ns),
        };
        let mut tau = [0.0; MAX_JOINTS];
        self.model
            .joint_torque(&self.x[..nx], &u[..2 * dof], &ex, &mut tau);
        self.tau = tau;
        self.stiffness = k.stiffness;
        let dt = self.cfg.period_ns as f64 * 1e-9;
        let mut next = [0.0; MAX_NX];
        flow(
            &self.model,
            &ex,
            dt,
            self.cfg.substeps,
            self.cfg.integrator,
            &self.x[..nx],
            &u[..2 * dof],
            &mut next[..nx],
        );
        let nw = self.model.nw();
        if nw > 0 {
            // Euler–Maruyama (Eq. 10) once per period, as the Monte Carlo does per plan step.
            let mut f = [0.0; MAX_NX * MAX_NW];
            self.model.diffusion(&self.x[..nx], &u[..2 * dof], &mut f);
            let s = dt.sqrt();
            f[..nx * nw].iter_mut().for_each(|v| *v *= s);
            add_diffusion(&mut next[..nx], &f[..nx * nw], nx, nw, &mut self.rng);
        }
        self.x = next;
    }

    /// The knot for plant period at trial time `t`: the valid command covering it; else the last
    /// one while the watchdog runs; else the safe-hold ramp.
    fn knot_for(&mut self, t: u64, now_p: u64, out: &mut Outputs) -> Knot {
        if self.mode == Mode::Fault {
            return self.hold_knot(t);
        }
        if let Some((k, sent, seq)) = self.command_at(t) {
            self.mode = Mode::Running;
            self.used_command_seq = seq;
            self.last_knot = k;
            self.last_cover_ns = t;
            out.command_age_ns = Some(now_p.saturating_sub(sent));
            return k;
        }
        if self.mode != Mode::SafeHold {
            if t < self.last_cover_ns + self.cfg.watchdog_ns {
                return self.last_knot;
            }
            self.mode = Mode::SafeHold;
            self.counters.watchdog_trips += 1;
            let from = self.last_knot;
            self.begin_hold(from, t);
        }
        self.counters.safe_hold_ticks += 1;
        self.hold_knot(t)
    }

    /// One tick at the deadline `now_ns`: take the messages in `inputs` (emptied), then integrate
    /// the plant over the periods elapsed since the last step.
    pub fn step(&mut self, now_ns: u64, inputs: &mut Inputs) -> Outputs {
        self.tick += 1;
        self.counters.ticks += 1;
        self.applied = false;
        for _ in 0..inputs.overflow {
            self.reject(Rejection::Overflow);
        }
        inputs.overflow = 0;
        let clock = if inputs.received_ns == 0 {
            now_ns
        } else {
            inputs.received_ns.max(now_ns)
        };
        for i in 0..inputs.n_controls {
            let c = inputs.controls[i];
            self.apply_control(&c, clock);
        }
        inputs.n_controls = 0;
        for i in 0..inputs.n_disturbances {
            let d = inputs.disturbances[i];
            self.apply_disturbance(&d, now_ns, clock);
        }
        inputs.n_disturbances = 0;
        for i in 0..inputs.n_commands {
            let c = inputs.commands[i];
            let verdict = if self.in_future(c.time_ns, clock) {
                Err(Rejection::FutureTimestamp)
            } else {
                self.validate(&c)
            };
            match verdict {
                Ok(()) => {
                    self.slices[self.next_slot] = c;
                    self.slice_valid[self.next_slot] = true;
                    self.next_slot = (self.next_slot + 1) % SLICES;
                    self.last_command_seq = c.seq;
                }
                Err(r) => self.reject(r),
            }
        }
        inputs.n_commands = 0;
        inputs.received_ns = 0;

        let mut out = Outputs::default();
        match (self.mode, self.start_ns) {
            (Mode::Idle, Some(start)) if now_ns >= start => {
                // The trial starts at this tick: trial time 0 is the reset state.
                self.mode = Mode::Running;
                self.plant_ns = now_ns;
                self.trial_time_ns = 0;
            }
            (Mode::Fault, _) if self.fault == FaultReason::NotFinite => {
                // Nothing to hold: the state is lost. Frozen until a reset.
                self.plant_ns = now_ns;
            }
            (Mode::Running | Mode::SafeHold | Mode::Fault, _) => {
                let elapsed = now_ns.saturating_sub(self.plant_ns) / self.cfg.period_ns;
                let periods = elapsed.min(self.cfg.max_catch_up);
                self.counters.lost_periods += elapsed - periods;
                for p in 0..periods {
                    let t = self.trial_time_ns;
                    let now_p = now_ns - (periods - 1 - p) * self.cfg.period_ns;
                    let knot = self.knot_for(t, now_p, &mut out);
                    out.knot = knot;
                    let before = self.x;
                    self.integrate(&knot, now_p);
                    let dt = self.cfg.period_ns as f64 * 1e-9;
                    for i in self.dof..2 * self.dof {
                        out.qdd[i - self.dof] = (self.x[i] - before[i]) / dt;
                    }
                    out.tracking_error = (0..self.dof)
                        .map(|i| (self.x[i] - knot.q_d[i]).powi(2))
                        .sum::<f64>()
                        .sqrt();
                    self.trial_time_ns += self.cfg.period_ns;
                    if self.mode != Mode::Fault
                        && let Some(reason) = self.guard()
                    {
                        self.mode = Mode::Fault;
                        self.fault = reason;
                        self.counters.faults += 1;
                        self.slice_valid = [false; SLICES];
                        if reason == FaultReason::NotFinite {
                            // Keep the last finite state for the record.
                            self.x = before;
                            break;
                        }
                        self.begin_hold(knot, self.trial_time_ns);
                    }
                }
                self.plant_ns = now_ns;
                out.periods = periods;
            }
            _ => {}
        }
        let dof = self.dof;
        let mut s = StateMsg {
            version: PROTOCOL_VERSION,
            joints: dof as u32,
            tick: self.tick,
            trial: self.trial,
            mode: self.mode as u32,
            trial_time_ns: self.trial_time_ns,
            tau: self.tau,
            tau_ext: self.tau_ext(now_ns),
            stiffness: self.stiffness,
            command_seq: self.used_command_seq,
            disturbance_seq: self.disturbance_seq,
            disturbance_tick: self.disturbance_tick,
            watchdog_deadline_ns: self.last_cover_ns + self.cfg.watchdog_ns,
            reset_seq: self.reset_seq,
            ..Default::default()
        };
        s.q[..dof].copy_from_slice(&self.x[..dof]);
        s.qd[..dof].copy_from_slice(&self.x[dof..2 * dof]);
        out.state = s;
        out
    }
}

/// `a + t (b − a)` for every input of a knot.
fn lerp(a: &Knot, b: &Knot, t: f64) -> Knot {
    let mut k = *a;
    for j in 0..MAX_JOINTS {
        k.tau_ff[j] += t * (b.tau_ff[j] - a.tau_ff[j]);
        k.stiffness[j] += t * (b.stiffness[j] - a.stiffness[j]);
        k.q_d[j] += t * (b.q_d[j] - a.q_d[j]);
        k.qd_d[j] += t * (b.qd_d[j] - a.qd_d[j]);
    }
    k
}
