//! The board: a pure state machine that runs the impedance law of paper Eq. 4 on the freshest
//! local state and integrates the plant, one [`Board::step`] per tick.
//!
//! It knows no clock and no transport: the caller passes the tick's time and the messages that
//! arrived, and publishes what comes out. The same code runs in the 1 kHz loop of `vic-board`, in
//! the lockstep mode (a simulated clock) and in tests; [`live`] is the loop of `vic-board`
//! around it. A step allocates nothing.
//!
//! It is composed of: [`validation`] (every message is checked before use; a rejected one is
//! counted by [`Rejection`] and never reaches the plant), the command buffer (the newest valid
//! slices and the knot covering a time), [`supervisor`] (watchdog, ramp into the safe hold, plant
//! guard, fault latch) and the simulated plant (Eq. 4, the shared integrator, the noise of Eq. 10).
//!
//! Time: `step(now)` takes the tick's *deadline* (a whole number of periods). The plant follows
//! the clock: when ticks were missed, the step integrates every elapsed period (up to
//! [`BoardConfig::max_catch_up`]) with the law evaluated each period, as the plant would have
//! moved; the loop itself never catches up in a burst.

mod commands;
pub mod gaps;
pub mod live;
mod plant;
pub(crate) mod supervisor;
pub(crate) mod validation;

use crate::transport::{
    CommandSlice, Control, ControlKind, Disturbance, Header, Knot, MAX_JOINTS, Mode, StateMsg,
};
use commands::CommandBuffer;
use gaps::GapCounter;
use plant::SimulatedPlant;
pub use supervisor::FaultReason;
use supervisor::{Supervisor, guard};
use validation::{Checks, LastSeen, TrialState};
use vic_core::dynamics::Integrator;
use vic_core::model::{Actuator, ArmModel, Damping, Field};

pub use crate::transport::Rejection;

/// Fixed parameters of a board. The defaults live in the scenario's `[board]` section; a board
/// is built from a scenario (or a literal in tests), never from defaults of its own.
#[derive(Debug, Clone)]
pub struct BoardConfig {
    /// Tick period [ns].
    pub period_ns: u64,
    /// Integration sub-steps per period (at 1 ms the semi-implicit step is stable with one).
    pub substeps: usize,
    pub integrator: Integrator,
    /// Stiffness of the safe hold [N m/rad].
    pub hold_stiffness: f64,
    /// How long the last command stays in force once none covers the present [ns].
    pub watchdog_ns: u64,
    /// Duration of the ramp into the safe hold [ns].
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
    /// Most periods integrated in one step after missed ticks; the rest are lost.
    pub max_catch_up: u64,
}

/// Why a board cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BoardError {
    #[error("the board runs the impedance law (actuator type 2); this scenario has a {0} actuator")]
    NotImpedance(&'static str),
    #[error("the board period and sub-steps must be positive")]
    ZeroPeriod,
    #[error(
        "the board's limits must be finite: stiffness_max {stiffness_max}, torque_max \
         {torque_max}, velocity_max {velocity_max}"
    )]
    Limits {
        stiffness_max: f64,
        torque_max: f64,
        velocity_max: f64,
    },
    #[error("hold stiffness {0}: its damping under the actuator's law must be ≥ 0")]
    HoldStiffness(f64),
    #[error("initial state: {got} joint angles for a {dof}-joint arm")]
    InitialState { got: usize, dof: usize },
    #[error("a {0}-joint arm: the messages carry at most {MAX_JOINTS} joints")]
    TooManyJoints(usize),
}

/// Most messages of each kind a step takes; more are counted as rejected ([`Rejection::Overflow`]).
const INPUT_CAPACITY: usize = 4;

/// A fixed-capacity queue of one kind of message (a step allocates nothing).
#[derive(Debug, Clone, Default)]
struct Queue<T: Copy + Default> {
    items: [T; INPUT_CAPACITY],
    len: usize,
}

impl<T: Copy + Default> Queue<T> {
    /// Adds `item`; false when full.
    fn push(&mut self, item: &T) -> bool {
        if self.len == INPUT_CAPACITY {
            return false;
        }
        self.items[self.len] = *item;
        self.len += 1;
        true
    }
    fn take(&mut self) -> impl Iterator<Item = T> + '_ {
        let n = std::mem::take(&mut self.len);
        self.items[..n].iter().copied()
    }
}

/// Messages that arrived since the last step (fixed capacity: a step allocates nothing). Extra
/// messages beyond the capacity are counted as rejected; messages a sender numbered but that
/// never arrived (overwritten in the receive buffers) are counted from the sequence gaps of
/// each sender session ([`gaps`]; it lives here, across steps, because it sees every message
/// received, valid or not).
#[derive(Debug, Clone, Default)]
pub struct Inputs {
    commands: Queue<CommandSlice>,
    controls: Queue<Control>,
    disturbances: Queue<Disturbance>,
    overflow: u64,
    gaps: [GapCounter; 3],
    dropped: u64,
    /// When the messages were taken [ns, monotonic] (0: the step's deadline). Time stamps later
    /// than this by more than the tolerance are rejected.
    pub(crate) received_ns: u64,
}

impl Inputs {
    pub fn push_command(&mut self, c: &CommandSlice) {
        self.dropped += self.gaps[0].missing_before(&c.header);
        self.overflow += !self.commands.push(c) as u64;
    }
    pub fn push_control(&mut self, c: &Control) {
        self.dropped += self.gaps[1].missing_before(&c.header);
        self.overflow += !self.controls.push(c) as u64;
    }
    pub fn push_disturbance(&mut self, d: &Disturbance) {
        self.dropped += self.gaps[2].missing_before(&d.header);
        self.overflow += !self.disturbances.push(d) as u64;
    }
}

/// What one step produced.
#[derive(Debug, Clone, Copy, Default)]
pub struct Outputs {
    /// The state to publish (time stamp left to the caller).
    pub state: StateMsg,
    /// Age of the command used at this tick [ns] (its publish time to `now`), if one was used.
    pub(crate) command_age_ns: Option<u64>,
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
    pub rejected_by: [u64; Rejection::COUNT],
    /// Messages lost before the board saw them (sequence gaps within each sender session).
    pub dropped: u64,
    pub safe_hold_ticks: u64,
    /// Times the watchdog expired and the board ramped to its safe hold.
    pub watchdog_trips: u64,
    /// Times the plant guard latched a fault.
    pub faults: u64,
    /// Periods not integrated because a step would have exceeded `max_catch_up`.
    pub lost_periods: u64,
    pub resets: u64,
}

impl Counters {
    fn reject(&mut self, r: Rejection) {
        self.rejected += 1;
        self.rejected_by[r as usize] += 1;
    }
}

/// The board state machine: validation, command buffer, supervisor and plant, composed.
pub struct Board {
    cfg: BoardConfig,
    damping: Damping,
    plant: SimulatedPlant,
    commands: CommandBuffer,
    supervisor: Supervisor,
    trial: u32,
    /// Monotonic time at which the pending trial starts (None: no trial pending or running).
    start_ns: Option<u64>,
    /// Deadline up to which the plant is integrated.
    plant_ns: u64,
    trial_time_ns: u64,
    /// The last command, control and disturbance accepted (the sequence rules of `Header`).
    last_command: LastSeen,
    last_control: LastSeen,
    last_disturbance: LastSeen,
    /// Sequence number of the reset that started the present trial.
    reset_seq: u64,
    disturbance_seq: u64,
    disturbance_tick: u64,
    /// A disturbance or control was applied at the last step (the loop wakes listeners).
    applied: bool,
    tick: u64,
    pub counters: Counters,
}

impl Board {
    /// A board for `model` (impedance actuator, type 2), at rest at `q0`.
    pub fn new(model: ArmModel, cfg: BoardConfig, q0: &[f64]) -> Result<Board, BoardError> {
        let Actuator::Impedance { damping } = model.actuator else {
            return Err(BoardError::NotImpedance(model.actuator.name()));
        };
        if cfg.period_ns == 0 || cfg.substeps == 0 {
            return Err(BoardError::ZeroPeriod);
        }
        if ![cfg.stiffness_max, cfg.torque_max, cfg.velocity_max]
            .iter()
            .all(|v| v.is_finite() && *v >= 0.0)
        {
            return Err(BoardError::Limits {
                stiffness_max: cfg.stiffness_max,
                torque_max: cfg.torque_max,
                velocity_max: cfg.velocity_max,
            });
        }
        if !(cfg.hold_stiffness.is_finite() && damping.gain(cfg.hold_stiffness) >= 0.0) {
            return Err(BoardError::HoldStiffness(cfg.hold_stiffness));
        }
        if model.dof() > MAX_JOINTS {
            return Err(BoardError::TooManyJoints(model.dof()));
        }
        if q0.len() < model.dof() {
            return Err(BoardError::InitialState {
                got: q0.len(),
                dof: model.dof(),
            });
        }
        let plant = SimulatedPlant::new(model, q0);
        let supervisor = Supervisor::new(plant.hold_target(&cfg));
        Ok(Board {
            cfg,
            damping,
            plant,
            commands: CommandBuffer::new(),
            supervisor,
            trial: 0,
            start_ns: None,
            plant_ns: 0,
            trial_time_ns: 0,
            last_command: LastSeen::default(),
            last_control: LastSeen::default(),
            last_disturbance: LastSeen::default(),
            reset_seq: 0,
            disturbance_seq: 0,
            disturbance_tick: 0,
            applied: false,
            tick: 0,
            counters: Counters::default(),
        })
    }

    pub fn mode(&self) -> Mode {
        self.supervisor.mode
    }
    /// Why the fault is latched ([`FaultReason::None`] outside [`Mode::Fault`]).
    pub fn fault(&self) -> FaultReason {
        self.supervisor.fault
    }
    pub fn config(&self) -> &BoardConfig {
        &self.cfg
    }
    /// The plant it simulates.
    pub fn model(&self) -> &ArmModel {
        &self.plant.model
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
        &self.plant.x[..self.plant.nx]
    }
    pub fn stiffness(&self) -> [f64; MAX_JOINTS] {
        self.plant.stiffness
    }
    /// Whether the last step applied a disturbance or control request.
    pub fn applied(&self) -> bool {
        self.applied
    }
    /// Sequence number and tick of the last disturbance applied.
    pub(crate) fn last_disturbance(&self) -> (u64, u64) {
        (self.disturbance_seq, self.disturbance_tick)
    }
    /// External torque now in force [N m].
    pub fn tau_ext(&self, now_ns: u64) -> [f64; MAX_JOINTS] {
        self.plant.tau_ext(now_ns)
    }
    /// β of the divergent field in force [N/m] (0 without one).
    pub fn field_beta(&self) -> f64 {
        match self.plant.model.field {
            Field::Divergent { beta } => beta,
            _ => 0.0,
        }
    }
    pub fn noise_factor(&self) -> f64 {
        self.plant.noise_factor
    }
    /// Damping gain `K_D` of the impedance law (Eq. 4) for the stiffness `k` [N m s/rad].
    pub fn damping(&self, k: &[f64; MAX_JOINTS]) -> [f64; MAX_JOINTS] {
        let mut d = [0.0; MAX_JOINTS];
        for i in 0..self.plant.dof {
            d[i] = self.damping.gain(k[i]);
        }
        d
    }

    fn checks(&self) -> Checks<'_> {
        Checks {
            cfg: &self.cfg,
            damping: &self.damping,
            dof: self.plant.dof,
        }
    }

    /// Checks a command slice; `Ok` when it may be used. (Its time stamp is checked in
    /// [`Board::step`], against the clock.)
    pub fn validate(&self, c: &CommandSlice) -> Result<(), Rejection> {
        let trial = TrialState {
            faulted: self.supervisor.mode == Mode::Fault,
            trial: self.trial,
            reset: self.start_ns.is_some(),
            last: self.last_command,
            now_ns: self.trial_time_ns,
        };
        self.checks().command(c, &trial)
    }

    fn apply_control(&mut self, c: &Control, clock_ns: u64) {
        if let Err(r) = self.checks().control(c, &self.last_control, clock_ns) {
            self.counters.reject(r);
            return;
        }
        self.last_control.record(&c.header);
        self.applied = true;
        self.commands.clear();
        if c.kind == ControlKind::Reset as u32 {
            // The explicit reset: the only way out of a latched fault.
            self.plant.reset(&c.q0, &c.qd0, c.seed, c.trial);
            self.trial = c.trial;
            self.reset_seq = c.header.seq;
            self.start_ns = Some(c.start_ns);
            self.trial_time_ns = 0;
            // A new trial starts every order afresh: whatever a sender (or a forger) numbered
            // before cannot block the commands and disturbances after the reset.
            self.last_command = LastSeen::default();
            self.last_disturbance = LastSeen::default();
            self.supervisor = Supervisor::new(self.plant.hold_target(&self.cfg));
            self.counters.resets += 1;
        } else if self.supervisor.mode != Mode::Fault {
            // Stop: no trial; the plant ramps into the hold at its present posture and holds it
            // (idle). A latched fault stays latched (and held).
            let (from, t) = (self.supervisor.last_knot, self.trial_time_ns);
            self.supervisor.idle(from, t, &self.plant, &self.cfg);
            self.start_ns = None;
        }
    }

    fn apply_disturbance(&mut self, d: &Disturbance, now_ns: u64, clock_ns: u64) {
        match self
            .checks()
            .disturbance(d, &self.last_disturbance, clock_ns)
        {
            Ok(kind) => {
                self.plant.apply(kind, d, now_ns);
                self.last_disturbance.record(&d.header);
                self.disturbance_seq = d.header.seq;
                self.disturbance_tick = self.tick;
                self.applied = true;
            }
            Err(r) => self.counters.reject(r),
        }
    }

    /// A command slice arrived at the step of board time `now_ns` (the clock of its arrival
    /// `clock_ns`): kept when valid; it feeds the watchdog when it reaches past the present.
    fn accept_command(&mut self, c: &CommandSlice, now_ns: u64, clock_ns: u64) {
        let verdict = self
            .validate(c)
            .and_then(|()| self.checks().time(c.header.time_ns, clock_ns));
        match verdict {
            Ok(()) => {
                self.commands.insert(c);
                self.last_command.record(&c.header);
                // A slice that ends before the present holds nothing: it is no sign of a live
                // sender (and a replay of old ones cannot keep the watchdog quiet).
                if c.end_ns() > self.trial_time_ns {
                    self.supervisor.fed(now_ns);
                }
            }
            Err(r) => self.counters.reject(r),
        }
    }

    /// Takes the messages in `inputs` (emptied): controls first, then disturbances, then
    /// commands, each checked against the clock of their arrival.
    fn take_inputs(&mut self, now_ns: u64, inputs: &mut Inputs) {
        for _ in 0..std::mem::take(&mut inputs.overflow) {
            self.counters.reject(Rejection::Overflow);
        }
        self.counters.dropped += std::mem::take(&mut inputs.dropped);
        let received = std::mem::take(&mut inputs.received_ns);
        let clock = if received == 0 {
            now_ns
        } else {
            received.max(now_ns)
        };
        for c in inputs.controls.take() {
            self.apply_control(&c, clock);
        }
        for d in inputs.disturbances.take() {
            self.apply_disturbance(&d, now_ns, clock);
        }
        for c in inputs.commands.take() {
            self.accept_command(&c, now_ns, clock);
        }
    }

    /// One tick at the deadline `now_ns`: take the messages in `inputs` (emptied), then integrate
    /// the plant over the periods elapsed since the last step.
    pub fn step(&mut self, now_ns: u64, inputs: &mut Inputs) -> Outputs {
        self.tick += 1;
        self.counters.ticks += 1;
        self.applied = false;
        self.take_inputs(now_ns, inputs);
        let mut out = Outputs::default();
        match (self.supervisor.mode, self.start_ns) {
            (Mode::Idle, Some(start)) if now_ns >= start => {
                // The trial starts at this tick: trial time 0 is the reset state.
                self.supervisor.mode = Mode::Running;
                self.plant_ns = now_ns;
                self.trial_time_ns = 0;
                // The watchdog's window opens at the start (the reset state's hold is in force
                // until the first command covers the present).
                self.supervisor.fed(now_ns);
            }
            (Mode::Fault, _) if self.supervisor.fault == FaultReason::NotFinite => {
                // Nothing to hold: the state is lost. Frozen until a reset.
                self.plant_ns = now_ns;
            }
            (Mode::Running | Mode::SafeHold | Mode::Fault, _) => self.advance(now_ns, &mut out),
            (Mode::Idle, None) => {
                // No trial: the plant holds its posture under the hold law (the supervisor's
                // idle knot), so a push moves the arm and it springs back. The first tick only
                // starts the plant's clock.
                if self.plant_ns == 0 {
                    self.plant_ns = now_ns;
                }
                self.advance(now_ns, &mut out);
            }
            // A reset is pending: frozen at the reset state, which the trial starts from.
            (Mode::Idle, Some(_)) => {}
        }
        out.state = self.state_msg(now_ns);
        out
    }

    /// Integrates every period elapsed up to `now_ns` (at most `max_catch_up`), the law
    /// evaluated each period; the plant guard checked after each.
    fn advance(&mut self, now_ns: u64, out: &mut Outputs) {
        let period = self.cfg.period_ns;
        let elapsed = now_ns.saturating_sub(self.plant_ns) / period;
        let periods = elapsed.min(self.cfg.max_catch_up);
        self.counters.lost_periods += elapsed - periods;
        for p in 0..periods {
            let now_p = now_ns - (periods - 1 - p) * period;
            if !self.integrate_period(now_p, out) {
                break;
            }
        }
        self.plant_ns = now_ns;
        out.periods = periods;
    }

    /// One period ending at `now_p`; false when the state stopped being finite (the plant is
    /// frozen at its last finite state).
    fn integrate_period(&mut self, now_p: u64, out: &mut Outputs) -> bool {
        let (dof, t) = (self.plant.dof, self.trial_time_ns);
        let knot = self.supervisor.knot_for(
            t,
            now_p,
            &self.commands,
            &self.plant,
            &self.cfg,
            &mut self.counters,
            &mut out.command_age_ns,
        );
        out.knot = knot;
        let before = self.plant.x;
        self.plant.step(&knot, now_p, &self.cfg);
        let x = &self.plant.x;
        let dt = self.cfg.period_ns as f64 * 1e-9;
        for i in dof..2 * dof {
            out.qdd[i - dof] = (x[i] - before[i]) / dt;
        }
        out.tracking_error = (0..dof)
            .map(|i| (x[i] - knot.q_d[i]).powi(2))
            .sum::<f64>()
            .sqrt();
        self.trial_time_ns += self.cfg.period_ns;
        if self.supervisor.mode == Mode::Fault {
            return true;
        }
        let Some(reason) = guard(&self.cfg, &x[..self.plant.nx], dof) else {
            return true;
        };
        self.supervisor.latch(reason, &mut self.counters);
        self.commands.clear();
        if reason == FaultReason::NotFinite {
            // Keep the last finite state for the record.
            self.plant.x = before;
            return false;
        }
        let t = self.trial_time_ns;
        self.supervisor.begin_hold(knot, t, &self.plant, &self.cfg);
        true
    }

    /// The state message of this tick (its time stamp and sequence number left to the caller).
    fn state_msg(&self, now_ns: u64) -> StateMsg {
        let dof = self.plant.dof;
        let mut s = StateMsg {
            header: Header::in_session(0, 0, 0),
            joints: dof as u32,
            tick: self.tick,
            trial: self.trial,
            mode: self.supervisor.mode as u32,
            trial_time_ns: self.trial_time_ns,
            tau: self.plant.tau,
            tau_ext: self.plant.tau_ext(now_ns),
            stiffness: self.plant.stiffness,
            command_seq: self.supervisor.used_command_seq,
            disturbance_seq: self.disturbance_seq,
            disturbance_tick: self.disturbance_tick,
            watchdog_deadline_ns: self.supervisor.watchdog_deadline_ns(
                self.trial_time_ns,
                now_ns,
                &self.cfg,
            ),
            reset_seq: self.reset_seq,
            ..Default::default()
        };
        s.q[..dof].copy_from_slice(&self.plant.x[..dof]);
        s.qd[..dof].copy_from_slice(&self.plant.x[dof..2 * dof]);
        s
    }
}
