//! What the board checks before a message may touch the plant. A message that fails a check is
//! counted by [`Rejection`] and dropped; the order of the checks decides which reason a message
//! with several faults is counted under (`docs/PROTOCOL.md` lists the order).

use super::BoardConfig;
use crate::transport::{
    CommandSlice, Control, ControlKind, Disturbance, DisturbanceKind, Header, Interpolation,
    MAX_KNOT_DT_NS, MAX_KNOTS, MAX_MESSAGE_AGE_NS, MAX_REACH_NS, MAX_SLICE_NS, MIN_KNOT_DT_NS,
    PROTOCOL_VERSION, Rejection,
};
use vic_core::model::Damping;

/// What a message is checked against besides its own content: the board's limits and the state
/// of the trial.
pub(super) struct Checks<'a> {
    pub cfg: &'a BoardConfig,
    /// The actuator's law from stiffness to damping.
    pub damping: &'a Damping,
    pub dof: usize,
}

/// Where the board's trial stands, for command slices.
pub(super) struct TrialState {
    pub faulted: bool,
    pub trial: u32,
    /// A reset announced the trial.
    pub reset: bool,
    /// The last command slice accepted in this trial.
    pub last: LastSeen,
    /// The board's present trial time [ns] (0 before the start).
    pub(crate) now_ns: u64,
}

/// The last message of one kind that the board accepted: the sequence rules of [`Header`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct LastSeen {
    /// Nothing accepted yet (or forgotten by a reset).
    pub any: bool,
    pub session: u32,
    pub seq: u64,
    pub time_ns: u64,
}

impl LastSeen {
    /// Whether `h` may follow: a higher sequence number in the same session, or another session
    /// whose time stamp is not earlier than the last message's (a restarted sender). A poisoned
    /// `u64::MAX` thus blocks its own session only, and the time stamps it could poison are
    /// bounded by the future tolerance.
    pub(crate) fn admits(&self, h: &Header) -> bool {
        !self.any
            || if h.session == self.session {
                h.seq > self.seq
            } else {
                h.time_ns >= self.time_ns
            }
    }
    /// Remembers `h` as the last accepted.
    pub fn record(&mut self, h: &Header) {
        *self = LastSeen {
            any: true,
            session: h.session,
            seq: h.seq,
            time_ns: h.time_ns,
        };
    }
}

impl Checks<'_> {
    /// A time stamp later than the board's clock by more than the tolerance, or older than
    /// [`MAX_MESSAGE_AGE_NS`].
    pub fn time(&self, time_ns: u64, clock_ns: u64) -> Result<(), Rejection> {
        if time_ns > clock_ns.saturating_add(self.cfg.future_tolerance_ns) {
            return Err(Rejection::FutureTimestamp);
        }
        if clock_ns.saturating_sub(time_ns) > MAX_MESSAGE_AGE_NS {
            return Err(Rejection::Stale);
        }
        Ok(())
    }

    /// A command slice: its shape (the duration bounded before it is computed, so nothing can
    /// overflow), then the trial, the order, how far ahead it reaches and every knot (finite;
    /// stiffness, damping, torque and equilibrium within the limits). Its time stamp is checked
    /// by the caller, against the clock.
    pub fn command(&self, c: &CommandSlice, trial: &TrialState) -> Result<(), Rejection> {
        if c.header.version != PROTOCOL_VERSION {
            return Err(Rejection::Version);
        }
        if c.joints as usize != self.dof {
            return Err(Rejection::Joints);
        }
        if c.count == 0
            || c.count as usize > MAX_KNOTS
            || !(MIN_KNOT_DT_NS..=MAX_KNOT_DT_NS).contains(&c.knot_dt_ns)
            || c.interpolation > Interpolation::Linear as u32
            || c.duration_ns().is_none_or(|d| d > MAX_SLICE_NS)
        {
            return Err(Rejection::Shape);
        }
        if trial.faulted {
            return Err(Rejection::Faulted);
        }
        if c.trial != trial.trial || !trial.reset {
            return Err(Rejection::WrongTrial);
        }
        if !trial.last.admits(&c.header) {
            return Err(Rejection::OutOfOrder);
        }
        // The duration is at most MAX_SLICE_NS: the end overflows only with a start near
        // u64::MAX, which is too far ahead anyway.
        let reach = trial.now_ns.saturating_add(MAX_REACH_NS);
        if c.start_ns.checked_add(MAX_SLICE_NS).is_none() || c.end_ns() > reach {
            return Err(Rejection::TooFarAhead);
        }
        c.knots[..c.count as usize]
            .iter()
            .try_for_each(|k| (0..self.dof).try_for_each(|i| self.knot_joint(k, i)))
    }

    /// Joint `i` of a knot within the limits.
    fn knot_joint(&self, k: &crate::transport::Knot, i: usize) -> Result<(), Rejection> {
        let cfg = self.cfg;
        let v = [k.tau_ff[i], k.stiffness[i], k.q_d[i], k.qd_d[i]];
        if v.iter().any(|x| !x.is_finite()) {
            return Err(Rejection::NotFinite);
        }
        if k.stiffness[i] < 0.0 || k.stiffness[i] > cfg.stiffness_max * (1.0 + 1e-9) {
            return Err(Rejection::StiffnessOutOfBounds);
        }
        // The damping follows the stiffness by the actuator's law; an affine law can make it
        // negative for small stiffness (the iCub's), an unstable joint.
        if self.damping.gain(k.stiffness[i]) < 0.0 {
            return Err(Rejection::DampingUnstable);
        }
        if k.tau_ff[i].abs() > cfg.torque_max {
            return Err(Rejection::TorqueOutOfBounds);
        }
        // A spring pulled towards a point outside the joint range (or a huge one) is a torque
        // command in disguise.
        if k.q_d[i] < cfg.joint_min[i]
            || k.q_d[i] > cfg.joint_max[i]
            || k.qd_d[i].abs() > cfg.velocity_max
        {
            return Err(Rejection::EquilibriumOutOfBounds);
        }
        Ok(())
    }

    /// A control request: known kind, finite, in order, fresh, and a reset state inside the
    /// plant guard's limits whose start is not too far ahead.
    pub fn control(&self, c: &Control, last: &LastSeen, clock_ns: u64) -> Result<(), Rejection> {
        let (cfg, dof) = (self.cfg, self.dof);
        if c.header.version != PROTOCOL_VERSION {
            return Err(Rejection::Version);
        }
        if c.kind != ControlKind::Reset as u32 && c.kind != ControlKind::Stop as u32 {
            return Err(Rejection::UnknownKind);
        }
        if c.q0[..dof]
            .iter()
            .chain(&c.qd0[..dof])
            .any(|v| !v.is_finite())
        {
            return Err(Rejection::NotFinite);
        }
        if !last.admits(&c.header) {
            return Err(Rejection::OutOfOrder);
        }
        self.time(c.header.time_ns, clock_ns)?;
        if c.kind == ControlKind::Reset as u32 {
            let q = &c.q0[..dof];
            let inside = (0..dof).all(|i| q[i] >= cfg.joint_min[i] && q[i] <= cfg.joint_max[i])
                && c.qd0[..dof].iter().all(|v| v.abs() <= cfg.velocity_max);
            if !inside {
                return Err(Rejection::DisturbanceOutOfBounds);
            }
            if c.start_ns > clock_ns.saturating_add(MAX_REACH_NS) {
                return Err(Rejection::TooFarAhead);
            }
        }
        Ok(())
    }

    /// A disturbance: known kind, finite, in order, fresh, within the configured limits.
    pub fn disturbance(
        &self,
        d: &Disturbance,
        last: &LastSeen,
        clock_ns: u64,
    ) -> Result<DisturbanceKind, Rejection> {
        let (cfg, dof) = (self.cfg, self.dof);
        if d.header.version != PROTOCOL_VERSION {
            return Err(Rejection::Version);
        }
        let kind = DisturbanceKind::from_wire(d.kind).ok_or(Rejection::UnknownKind)?;
        if !(d.torque.iter().all(|v| v.is_finite()) && d.value.is_finite()) {
            return Err(Rejection::NotFinite);
        }
        if !last.admits(&d.header) {
            return Err(Rejection::OutOfOrder);
        }
        self.time(d.header.time_ns, clock_ns)?;
        let torque = d.torque[..dof].iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let ok = match kind {
            DisturbanceKind::Pulse => {
                torque <= cfg.max_pulse_torque && d.duration_ns <= cfg.max_pulse_ns
            }
            DisturbanceKind::Load => torque <= cfg.max_load_torque,
            // The divergent field is a hand-space field: a two-link arm only.
            DisturbanceKind::Field => {
                d.value.abs() <= cfg.max_field_beta && (d.value == 0.0 || dof == 2)
            }
            DisturbanceKind::Noise => d.value >= 0.0 && d.value <= cfg.max_noise_factor,
        };
        if ok {
            Ok(kind)
        } else {
            Err(Rejection::DisturbanceOutOfBounds)
        }
    }
}
