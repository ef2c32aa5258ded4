//! The board's supervision: which knot acts at each period, and what happens when none should.
//!
//! The watchdog ([`BoardConfig::watchdog_ns`]) is fed by the *arrival* of fresh valid commands,
//! never by how far a command claims to reach: when none has arrived for the watchdog time, or
//! none has covered the present for that long (the last one stays in force meanwhile), the board
//! ramps to a *safe hold* (the current position, the hold stiffness, gravity and field
//! compensated) and resumes when fresh valid commands cover the present again. Leaving the joint or speed limits latches a fault (ramp to the hold, commands
//! refused) that only a reset clears.

use super::commands::CommandBuffer;
use super::plant::SimulatedPlant;
use super::{BoardConfig, Counters};
use crate::transport::wire_enum::wire_enum;
use crate::transport::{Knot, Mode};

wire_enum! {
    /// Why the plant guard latched a fault.
    pub enum FaultReason: u32 else NotFinite {
        None = 0 => "none",
        JointLimit = 1 => "joint-limit",
        VelocityLimit = 2 => "velocity-limit",
        /// The state stopped being finite: the plant is frozen rather than held.
        NotFinite = 3 => "not-finite",
    }
}

/// The plant guard: `Some(reason)` when the state `x` has left the configured limits.
pub(super) fn guard(cfg: &BoardConfig, x: &[f64], dof: usize) -> Option<FaultReason> {
    if !x.iter().all(|v| v.is_finite()) {
        return Some(FaultReason::NotFinite);
    }
    if (0..dof).any(|i| x[i] < cfg.joint_min[i] || x[i] > cfg.joint_max[i]) {
        return Some(FaultReason::JointLimit);
    }
    if x[dof..2 * dof].iter().any(|v| v.abs() > cfg.velocity_max) {
        return Some(FaultReason::VelocityLimit);
    }
    None
}

/// The mode, the watchdog and the safe-hold ramp.
#[derive(Debug, Clone)]
pub(super) struct Supervisor {
    pub mode: Mode,
    pub fault: FaultReason,
    /// Sequence number of the command slice last used.
    pub(crate) used_command_seq: u64,
    /// The knot last taken from a valid command, and the trial time it covered last.
    pub(crate) last_knot: Knot,
    pub(crate) last_cover_ns: u64,
    /// Board clock at the arrival of the last fresh valid command (or at the trial start) [ns,
    /// monotonic]; `None`: none since the reset.
    pub(crate) fresh_ns: Option<u64>,
    /// The safe hold: ramp from `hold_from` to `hold_to` starting at trial time `hold_start_ns`.
    hold_from: Knot,
    hold_to: Knot,
    hold_start_ns: u64,
}

impl Supervisor {
    /// Idle, with the last knot the hold at the plant's present position (and the idle plant
    /// held there).
    pub fn new(last_knot: Knot) -> Self {
        Supervisor {
            mode: Mode::Idle,
            fault: FaultReason::None,
            used_command_seq: 0,
            last_knot,
            last_cover_ns: 0,
            fresh_ns: None,
            hold_from: last_knot,
            hold_to: last_knot,
            hold_start_ns: 0,
        }
    }

    /// No trial (a stop): idle, ramping from the knot `from` into the hold at the plant's
    /// position from trial time `t` on, as the safe hold does.
    pub fn idle(&mut self, from: Knot, t: u64, plant: &SimulatedPlant, cfg: &BoardConfig) {
        self.mode = Mode::Idle;
        self.begin_hold(from, t, plant, cfg);
    }

    /// Starts the ramp from the knot `from` to the safe hold at the plant's position, at trial
    /// time `t`.
    pub(crate) fn begin_hold(
        &mut self,
        from: Knot,
        t: u64,
        plant: &SimulatedPlant,
        cfg: &BoardConfig,
    ) {
        self.hold_from = from;
        self.hold_to = plant.hold_target(cfg);
        self.hold_start_ns = t;
    }

    /// The knot of the safe-hold ramp at trial time `t` (linear in every input, so the joint
    /// torque stays continuous).
    fn hold_knot(&self, t: u64, cfg: &BoardConfig) -> Knot {
        let a = if cfg.ramp_ns == 0 {
            1.0
        } else {
            (t.saturating_sub(self.hold_start_ns) as f64 / cfg.ramp_ns as f64).min(1.0)
        };
        self.hold_from.lerp(&self.hold_to, a)
    }

    /// A fresh valid command arrived at board time `now_ns`.
    pub fn fed(&mut self, now_ns: u64) {
        self.fresh_ns = Some(self.fresh_ns.map_or(now_ns, |f| f.max(now_ns)));
    }

    /// Whether the watchdog still runs for the period that starts at board time `start_ns`
    /// and trial time `t`: a fresh command arrived less than the timeout before, and the last
    /// covered period is less than the timeout before.
    fn alive(&self, start_ns: u64, t: u64, cfg: &BoardConfig) -> bool {
        self.fresh_ns
            .is_some_and(|f| start_ns < f.saturating_add(cfg.watchdog_ns))
            && t < self.last_cover_ns.saturating_add(cfg.watchdog_ns)
    }

    /// The knot for the plant period at trial time `t` (the period ends at `now_ns`): the valid
    /// command covering it while the watchdog runs (the last one while none covers it); else the
    /// safe-hold ramp. `command_age_ns` gets the age of the command used, if one was.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn knot_for(
        &mut self,
        t: u64,
        now_ns: u64,
        commands: &CommandBuffer,
        plant: &SimulatedPlant,
        cfg: &BoardConfig,
        counters: &mut Counters,
        command_age_ns: &mut Option<u64>,
    ) -> Knot {
        if matches!(self.mode, Mode::Fault | Mode::Idle) {
            // Idle (no trial) holds as the fault does; neither is a watchdog trip.
            return self.hold_knot(t, cfg);
        }
        let start_ns = now_ns.saturating_sub(cfg.period_ns);
        let fresh = self
            .fresh_ns
            .is_some_and(|f| start_ns < f.saturating_add(cfg.watchdog_ns));
        if fresh && let Some(c) = commands.covering(t) {
            self.mode = Mode::Running;
            self.used_command_seq = c.seq;
            self.last_knot = c.knot;
            self.last_cover_ns = t;
            *command_age_ns = Some(now_ns.saturating_sub(c.sent_ns));
            return c.knot;
        }
        if self.mode != Mode::SafeHold {
            if self.alive(start_ns, t, cfg) {
                return self.last_knot;
            }
            self.mode = Mode::SafeHold;
            counters.watchdog_trips += 1;
            self.begin_hold(self.last_knot, t, plant, cfg);
        }
        counters.safe_hold_ticks += 1;
        self.hold_knot(t, cfg)
    }

    /// Latches a fault: the guard tripped for `reason`.
    pub(crate) fn latch(&mut self, reason: FaultReason, counters: &mut Counters) {
        self.mode = Mode::Fault;
        self.fault = reason;
        counters.faults += 1;
    }

    /// Trial time at which the watchdog expires unless a fresh valid command arrives (and
    /// covers the present), for a board at trial time `t` and board time `now_ns`: the earlier
    /// of the two timeouts, the arrival one mapped from board time to trial time.
    pub fn watchdog_deadline_ns(&self, t: u64, now_ns: u64, cfg: &BoardConfig) -> u64 {
        let cover = self.last_cover_ns.saturating_add(cfg.watchdog_ns);
        let Some(f) = self.fresh_ns else {
            return t.min(cover);
        };
        let arrival = (t as i128 + f as i128 + cfg.watchdog_ns as i128 - now_ns as i128)
            .clamp(0, u64::MAX as i128) as u64;
        arrival.min(cover)
    }
}
