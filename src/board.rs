//! The board: a pure state machine that runs the impedance law of paper Eq. 4 on the freshest
//! local state and integrates the plant, one [`Board::step`] per tick (DESIGN §8).
//!
//! It knows no clock and no transport: the caller passes the tick's time and the messages that
//! arrived, and publishes what comes out. The same code runs in the 1 kHz loop of `vic-board`, in
//! the lockstep mode (a simulated clock) and in tests. A step allocates nothing.
//!
//! Time: `step(now)` takes the tick's *deadline* (a whole number of periods). The plant follows
//! the clock: when ticks were missed, the step integrates every elapsed period (up to
//! [`BoardConfig::max_catch_up`]) with the law evaluated each period, as the plant would have
//! moved; the loop itself never catches up in a burst.

use crate::dynamics::{Integrator, flow};
use crate::model::{ArmModel, Exogenous, Field, Noise};
use crate::scalar::{MAX_NW, MAX_NX};
use crate::transport::{
    CommandSlice, Control, ControlKind, Disturbance, DisturbanceKind, Interpolation, Knot,
    MAX_JOINTS, MAX_KNOTS, Mode, PROTOCOL_VERSION, StateMsg,
};
use rand::rngs::Xoshiro256PlusPlus;
use rand_distr::{Distribution, StandardNormal};

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
    pub safe_hold_ticks: u64,
    /// Periods not integrated because a step would have exceeded `max_catch_up`.
    pub lost_periods: u64,
    pub resets: u64,
}

/// Why a command slice was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rejection {
    Version,
    Joints,
    Shape,
    NotFinite,
    StiffnessOutOfBounds,
    TorqueOutOfBounds,
    WrongTrial,
    OutOfOrder,
}

const SLICES: usize = 4;

/// The board state machine.
pub struct Board {
    model: ArmModel,
    base_noise: Noise,
    base_field: Field,
    cfg: BoardConfig,
    dof: usize,
    nx: usize,
    x: [f64; MAX_NX],
    tau: [f64; MAX_JOINTS],
    stiffness: [f64; MAX_JOINTS],
    mode: Mode,
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
    used_command_seq: u64,
    hold: Knot,
    rng: Xoshiro256PlusPlus,
    pulse: [f64; MAX_JOINTS],
    pulse_until_ns: u64,
    load: [f64; MAX_JOINTS],
    noise_factor: f64,
    disturbance_seq: u64,
    disturbance_tick: u64,
    tick: u64,
    pub counters: Counters,
}

/// The random stream of one trial: the Monte Carlo's, so that live and offline trials with the
/// same seed draw the same noise.
pub use crate::simulation::trial_rng;

impl Board {
    /// A board for `model` (impedance actuator, type 2), at rest at `q0`.
    pub fn new(model: ArmModel, cfg: BoardConfig, q0: &[f64]) -> Result<Board, String> {
        if !matches!(model.actuator, crate::model::Actuator::Impedance { .. }) {
            return Err(format!(
                "the board runs the impedance law (actuator type 2); this scenario has a {} actuator",
                model.actuator.name()
            ));
        }
        if cfg.period_ns == 0 || cfg.substeps == 0 {
            return Err("the board period and sub-steps must be positive".into());
        }
        let dof = model.dof();
        let nx = model.nx();
        let mut x = [0.0; MAX_NX];
        x[..dof].copy_from_slice(&q0[..dof]);
        let mut hold = Knot::default();
        hold.q_d[..dof].copy_from_slice(&q0[..dof]);
        hold.stiffness = [cfg.hold_stiffness; MAX_JOINTS];
        Ok(Board {
            base_noise: model.noise,
            base_field: model.field,
            model,
            cfg,
            dof,
            nx,
            x,
            tau: [0.0; MAX_JOINTS],
            stiffness: [0.0; MAX_JOINTS],
            mode: Mode::Idle,
            trial: 0,
            start_ns: None,
            plant_ns: 0,
            trial_time_ns: 0,
            slices: [CommandSlice::default(); SLICES],
            slice_valid: [false; SLICES],
            next_slot: 0,
            last_command_seq: 0,
            used_command_seq: 0,
            hold,
            rng: trial_rng(0, 0),
            pulse: [0.0; MAX_JOINTS],
            pulse_until_ns: 0,
            load: [0.0; MAX_JOINTS],
            noise_factor: 1.0,
            disturbance_seq: 0,
            disturbance_tick: 0,
            tick: 0,
            counters: Counters::default(),
        })
    }

    pub fn mode(&self) -> Mode {
        self.mode
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
        if let crate::model::Actuator::Impedance { damping } = &self.model.actuator {
            for i in 0..self.dof {
                d[i] = damping.gain(k[i]);
            }
        }
        d
    }

    /// Checks a command slice; `Ok` when it may be used.
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
        {
            return Err(Rejection::Shape);
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
                if k.tau_ff[i].abs() > self.cfg.torque_max {
                    return Err(Rejection::TorqueOutOfBounds);
                }
            }
        }
        Ok(())
    }

    fn apply_control(&mut self, c: &Control) {
        if c.version != PROTOCOL_VERSION
            || c.q0[..self.dof]
                .iter()
                .chain(&c.qd0[..self.dof])
                .any(|v| !v.is_finite())
        {
            self.counters.rejected += 1;
            return;
        }
        match c.kind {
            k if k == ControlKind::Reset as u32 => {
                self.x = [0.0; MAX_NX];
                self.x[..self.dof].copy_from_slice(&c.q0[..self.dof]);
                self.x[self.dof..2 * self.dof].copy_from_slice(&c.qd0[..self.dof]);
                self.trial = c.trial;
                self.start_ns = Some(c.start_ns);
                self.mode = Mode::Idle;
                self.trial_time_ns = 0;
                self.slice_valid = [false; SLICES];
                self.last_command_seq = 0;
                self.used_command_seq = 0;
                self.rng = trial_rng(c.seed, c.trial as u64);
                self.tau = [0.0; MAX_JOINTS];
                self.stiffness = [0.0; MAX_JOINTS];
                self.counters.resets += 1;
            }
            k if k == ControlKind::Stop as u32 => {
                self.mode = Mode::Idle;
                self.start_ns = None;
                self.slice_valid = [false; SLICES];
            }
            _ => self.counters.rejected += 1,
        }
    }

    fn apply_disturbance(&mut self, d: &Disturbance, now_ns: u64) {
        let finite = d.torque.iter().all(|v| v.is_finite()) && d.value.is_finite();
        let Some(kind) = DisturbanceKind::from_u32(d.kind).filter(|_| finite) else {
            self.counters.rejected += 1;
            return;
        };
        if d.version != PROTOCOL_VERSION {
            self.counters.rejected += 1;
            return;
        }
        match kind {
            DisturbanceKind::Pulse => {
                self.pulse = d.torque;
                self.pulse_until_ns = now_ns + d.duration_ns;
            }
            DisturbanceKind::Load => self.load = d.torque,
            DisturbanceKind::Field => {
                self.model.field = if d.value == 0.0 {
                    Field::None
                } else if self.dof == 2 {
                    Field::Divergent { beta: d.value }
                } else {
                    self.counters.rejected += 1;
                    return;
                };
            }
            DisturbanceKind::Noise => {
                if d.value < 0.0 {
                    self.counters.rejected += 1;
                    return;
                }
                self.noise_factor = d.value;
                self.model.noise = self.base_noise.scaled(d.value);
            }
        }
        self.disturbance_seq = d.seq;
        self.disturbance_tick = self.tick;
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
            let n = &c.knots[i + 1];
            for j in 0..MAX_JOINTS {
                k.tau_ff[j] += a * (n.tau_ff[j] - k.tau_ff[j]);
                k.stiffness[j] += a * (n.stiffness[j] - k.stiffness[j]);
                k.q_d[j] += a * (n.q_d[j] - k.q_d[j]);
                k.qd_d[j] += a * (n.qd_d[j] - k.qd_d[j]);
            }
        }
        Some((k, c.time_ns, c.seq))
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
            let mut f = [0.0; MAX_NX * MAX_NW];
            self.model.diffusion(&self.x[..nx], &u[..2 * dof], &mut f);
            let s = dt.sqrt();
            for ch in 0..nw {
                let e: f64 = StandardNormal.sample(&mut self.rng);
                for r in 0..nx {
                    next[r] += s * f[ch * nx + r] * e;
                }
            }
        }
        self.x = next;
    }

    /// One tick at the deadline `now_ns`: take the messages in `inputs` (emptied), then integrate
    /// the plant over the periods elapsed since the last step.
    pub fn step(&mut self, now_ns: u64, inputs: &mut Inputs) -> Outputs {
        self.tick += 1;
        self.counters.ticks += 1;
        self.counters.rejected += inputs.overflow;
        inputs.overflow = 0;
        for i in 0..inputs.n_controls {
            let c = inputs.controls[i];
            self.apply_control(&c);
        }
        inputs.n_controls = 0;
        for i in 0..inputs.n_disturbances {
            let d = inputs.disturbances[i];
            self.apply_disturbance(&d, now_ns);
        }
        inputs.n_disturbances = 0;
        for i in 0..inputs.n_commands {
            match self.validate(&inputs.commands[i]) {
                Ok(()) => {
                    self.slices[self.next_slot] = inputs.commands[i];
                    self.slice_valid[self.next_slot] = true;
                    self.next_slot = (self.next_slot + 1) % SLICES;
                    self.last_command_seq = inputs.commands[i].seq;
                }
                Err(_) => self.counters.rejected += 1,
            }
        }
        inputs.n_commands = 0;

        let mut out = Outputs::default();
        match (self.mode, self.start_ns) {
            (Mode::Idle, Some(start)) if now_ns >= start => {
                // The trial starts at this tick: trial time 0 is the reset state.
                self.mode = Mode::Running;
                self.plant_ns = now_ns;
                self.trial_time_ns = 0;
            }
            (Mode::Running | Mode::SafeHold, _) => {
                let elapsed = now_ns.saturating_sub(self.plant_ns) / self.cfg.period_ns;
                let periods = elapsed.min(self.cfg.max_catch_up);
                self.counters.lost_periods += elapsed - periods;
                for p in 0..periods {
                    let t = self.trial_time_ns;
                    let now_p = now_ns - (periods - 1 - p) * self.cfg.period_ns;
                    let knot = match self.command_at(t) {
                        Some((k, sent, seq)) => {
                            self.mode = Mode::Running;
                            self.used_command_seq = seq;
                            out.command_age_ns = Some(now_p.saturating_sub(sent));
                            k
                        }
                        None => {
                            if self.mode != Mode::SafeHold {
                                self.mode = Mode::SafeHold;
                                self.hold.q_d[..self.dof].copy_from_slice(&self.x[..self.dof]);
                                self.hold.qd_d = [0.0; MAX_JOINTS];
                                self.hold.tau_ff = [0.0; MAX_JOINTS];
                                self.hold.stiffness = [self.cfg.hold_stiffness; MAX_JOINTS];
                            }
                            self.counters.safe_hold_ticks += 1;
                            self.hold
                        }
                    };
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
                    if !self.x[..self.nx].iter().all(|v| v.is_finite()) {
                        self.mode = Mode::Fault;
                        self.start_ns = None;
                        break;
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
            ..Default::default()
        };
        s.q[..dof].copy_from_slice(&self.x[..dof]);
        s.qd[..dof].copy_from_slice(&self.x[dof..2 * dof]);
        out.state = s;
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Scenario;
    use std::path::Path;

    fn scenario() -> Scenario {
        Scenario::load(
            Path::new(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/config/two_link_divergent.toml"
            )),
            &[],
        )
        .unwrap()
    }

    fn board() -> (Board, [f64; 2]) {
        let s = scenario();
        let setup = crate::plan::setup(&s).unwrap();
        let q0 = [setup.x0[0], setup.x0[1]];
        let b = Board::new(s.model.clone(), BoardConfig::default(), &q0).unwrap();
        (b, q0)
    }

    fn reset(q0: [f64; 2], start: u64) -> Control {
        Control {
            version: PROTOCOL_VERSION,
            kind: ControlKind::Reset as u32,
            seq: 1,
            trial: 1,
            seed: 5,
            start_ns: start,
            q0,
            ..Default::default()
        }
    }

    fn hold_slice(q0: [f64; 2], seq: u64, start: u64, k: f64) -> CommandSlice {
        let mut c = CommandSlice {
            joints: 2,
            seq,
            trial: 1,
            start_ns: start,
            knot_dt_ns: 10_000_000,
            count: 10,
            ..Default::default()
        };
        for knot in &mut c.knots[..10] {
            knot.q_d = q0;
            knot.stiffness = [k, k];
        }
        c
    }

    #[test]
    fn runs_commands_then_falls_back_to_safe_hold() {
        let (mut b, q0) = board();
        let mut inp = Inputs::default();
        let ms = 1_000_000;
        inp.push_control(&reset(q0, 5 * ms));
        let o = b.step(ms, &mut inp);
        assert_eq!(o.state.mode, Mode::Idle as u32);
        inp.push_command(&hold_slice(q0, 1, 0, 150.0));
        let o = b.step(5 * ms, &mut inp);
        assert_eq!(o.state.mode, Mode::Running as u32);
        assert_eq!(o.state.trial_time_ns, 0);
        for t in 6..=105 {
            let o = b.step(t * ms, &mut inp);
            assert_eq!(o.state.mode, Mode::Running as u32, "tick {t}");
            assert_eq!(o.periods, 1);
        }
        // The slice covered 100 ms of trial time: now the board holds.
        let o = b.step(106 * ms, &mut inp);
        assert_eq!(o.state.mode, Mode::SafeHold as u32);
        assert_eq!(b.counters.safe_hold_ticks, 1);
        // The hand stays near the start under the stiff hold in the divergent field.
        assert!((o.state.q[0] - q0[0]).abs() < 0.05);
    }

    #[test]
    fn rejects_invalid_commands() {
        let (mut b, q0) = board();
        let mut inp = Inputs::default();
        inp.push_control(&reset(q0, 0));
        b.step(0, &mut inp);
        let mut bad = hold_slice(q0, 1, 0, 50.0);
        bad.knots[3].tau_ff[1] = f64::NAN;
        assert_eq!(b.validate(&bad), Err(Rejection::NotFinite));
        let mut bad = hold_slice(q0, 1, 0, 50.0);
        bad.knots[0].stiffness[0] = -1.0;
        assert_eq!(b.validate(&bad), Err(Rejection::StiffnessOutOfBounds));
        let mut bad = hold_slice(q0, 1, 0, 50.0);
        bad.trial = 9;
        assert_eq!(b.validate(&bad), Err(Rejection::WrongTrial));
        let mut bad = hold_slice(q0, 1, 0, 50.0);
        bad.count = 0;
        assert_eq!(b.validate(&bad), Err(Rejection::Shape));
        let mut bad = hold_slice(q0, 1, 0, 50.0);
        bad.version = 99;
        assert_eq!(b.validate(&bad), Err(Rejection::Version));
        inp.push_command(&hold_slice(q0, 2, 0, 50.0));
        inp.push_command(&hold_slice(q0, 2, 0, 50.0));
        b.step(1_000_000, &mut inp);
        assert_eq!(b.counters.rejected, 1, "the repeated sequence number");
    }

    #[test]
    fn missed_ticks_integrate_the_elapsed_periods() {
        let (mut b, q0) = board();
        let mut inp = Inputs::default();
        inp.push_control(&reset(q0, 0));
        inp.push_command(&hold_slice(q0, 1, 0, 100.0));
        b.step(0, &mut inp);
        let o = b.step(7_000_000, &mut inp);
        assert_eq!(o.periods, 7);
        assert_eq!(o.state.trial_time_ns, 7_000_000);
    }

    #[test]
    fn pulse_shows_in_the_state_at_the_tick_it_is_applied() {
        let (mut b, q0) = board();
        let mut inp = Inputs::default();
        inp.push_control(&reset(q0, 0));
        inp.push_command(&hold_slice(q0, 1, 0, 100.0));
        b.step(0, &mut inp);
        inp.push_disturbance(&Disturbance {
            version: PROTOCOL_VERSION,
            kind: DisturbanceKind::Pulse as u32,
            seq: 42,
            torque: [1.0, 0.0],
            duration_ns: 3_000_000,
            ..Default::default()
        });
        let o = b.step(1_000_000, &mut inp);
        assert_eq!(o.state.disturbance_seq, 42);
        assert_eq!(o.state.disturbance_tick, o.state.tick);
        assert_eq!(o.state.tau_ext, [1.0, 0.0]);
        let o = b.step(5_000_000, &mut inp);
        assert_eq!(o.state.tau_ext, [0.0, 0.0]);
    }
}
