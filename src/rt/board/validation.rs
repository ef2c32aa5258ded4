//! What the board checks before a message may touch the plant. A message that fails a check is
//! counted by [`Rejection`] and dropped; the order of the checks decides which reason a message
//! with several faults is counted under.

use super::BoardConfig;
use crate::core::model::Damping;
use crate::rt::transport::{
    CommandSlice, Control, ControlKind, Disturbance, DisturbanceKind, Interpolation, MAX_KNOTS,
    PROTOCOL_VERSION, Rejection,
};

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
    pub last_command_seq: u64,
}

impl Checks<'_> {
    /// A time stamp later than the board's clock by more than the tolerance.
    pub fn in_future(&self, time_ns: u64, clock_ns: u64) -> bool {
        time_ns > clock_ns.saturating_add(self.cfg.future_tolerance_ns)
    }

    /// A command slice: its shape, then the trial, then every knot (finite; stiffness, damping,
    /// torque and equilibrium within the limits). Its time stamp is checked by the caller.
    pub fn command(&self, c: &CommandSlice, trial: &TrialState) -> Result<(), Rejection> {
        if c.header.version != PROTOCOL_VERSION {
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
        if trial.faulted {
            return Err(Rejection::Faulted);
        }
        if c.trial != trial.trial || !trial.reset {
            return Err(Rejection::WrongTrial);
        }
        if c.header.seq <= trial.last_command_seq {
            return Err(Rejection::OutOfOrder);
        }
        c.knots[..c.count as usize]
            .iter()
            .try_for_each(|k| (0..self.dof).try_for_each(|i| self.knot_joint(k, i)))
    }

    /// Joint `i` of a knot within the limits.
    fn knot_joint(&self, k: &crate::rt::transport::Knot, i: usize) -> Result<(), Rejection> {
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

    /// A control request: known kind, finite, in order, not from the future, and a reset state
    /// inside the plant guard's limits.
    pub fn control(&self, c: &Control, last_seq: u64, clock_ns: u64) -> Result<(), Rejection> {
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
        if c.header.seq <= last_seq {
            return Err(Rejection::OutOfOrder);
        }
        if self.in_future(c.header.time_ns, clock_ns) {
            return Err(Rejection::FutureTimestamp);
        }
        if c.kind == ControlKind::Reset as u32 {
            let q = &c.q0[..dof];
            let inside = (0..dof).all(|i| q[i] >= cfg.joint_min[i] && q[i] <= cfg.joint_max[i])
                && c.qd0[..dof].iter().all(|v| v.abs() <= cfg.velocity_max);
            if !inside {
                return Err(Rejection::DisturbanceOutOfBounds);
            }
        }
        Ok(())
    }

    /// A disturbance: known kind, finite, in order, not from the future, within the configured
    /// limits.
    pub fn disturbance(
        &self,
        d: &Disturbance,
        last_seq: u64,
        clock_ns: u64,
    ) -> Result<DisturbanceKind, Rejection> {
        let (cfg, dof) = (self.cfg, self.dof);
        if d.header.version != PROTOCOL_VERSION {
            return Err(Rejection::Version);
        }
        let kind = DisturbanceKind::from_u32(d.kind).ok_or(Rejection::UnknownKind)?;
        if !(d.torque.iter().all(|v| v.is_finite()) && d.value.is_finite()) {
            return Err(Rejection::NotFinite);
        }
        if d.header.seq <= last_seq {
            return Err(Rejection::OutOfOrder);
        }
        if self.in_future(d.header.time_ns, clock_ns) {
            return Err(Rejection::FutureTimestamp);
        }
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
