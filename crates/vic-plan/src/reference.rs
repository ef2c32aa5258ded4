//! Reference movements `q_d(t)`, `q_d'(t)`: minimum-jerk profiles in joint space, or along a
//! straight hand path mapped to the joints by inverse kinematics (a bell-shaped hand speed).

use vic_core::model::{Exogenous, Plant};

/// Minimum-jerk position and speed fractions `s(τ) = 10τ³ − 15τ⁴ + 6τ⁵` and `ds/dt` at time `t` of
/// a movement of duration `duration`.
pub(crate) fn minimum_jerk(t: f64, duration: f64) -> (f64, f64) {
    let tau = (t / duration).clamp(0.0, 1.0);
    let s = tau * tau * tau * (10.0 - 15.0 * tau + 6.0 * tau * tau);
    let ds = if (0.0..=duration).contains(&t) {
        30.0 * tau * tau * (1.0 - tau) * (1.0 - tau) / duration
    } else {
        0.0
    };
    (s, ds)
}

/// Reference at knots `k = 0..=steps` (time `k Δ`) for a minimum-jerk joint movement `q0 → q1`.
pub(crate) fn joint_minimum_jerk(
    q0: &[f64],
    q1: &[f64],
    duration: f64,
    dt: f64,
    steps: usize,
) -> Vec<Exogenous> {
    (0..=steps)
        .map(|k| {
            let (s, ds) = minimum_jerk(k as f64 * dt, duration);
            let mut e = Exogenous::default();
            for i in 0..q0.len() {
                e.q_d[i] = q0[i] + (q1[i] - q0[i]) * s;
                e.qd_d[i] = (q1[i] - q0[i]) * ds;
            }
            e
        })
        .collect()
}

/// Why a straight hand path cannot be followed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PathError {
    #[error("hand position ({x:.3}, {y:.3}) m is out of reach")]
    OutOfReach { x: f64, y: f64 },
    #[error("the path passes a singular arm posture at ({x:.3}, {y:.3}) m")]
    Singular { x: f64, y: f64 },
}

/// Reference at knots `k = 0..=steps` for a straight hand path `p0 → p1` with a minimum-jerk speed
/// profile, through inverse kinematics (`q_d' = J⁻¹ p'`). Fails if a point is out of reach or the
/// arm passes a singularity.
pub(crate) fn hand_straight_line(
    plant: &Plant,
    p0: [f64; 2],
    p1: [f64; 2],
    duration: f64,
    dt: f64,
    steps: usize,
) -> Result<Vec<Exogenous>, PathError> {
    (0..=steps)
        .map(|k| {
            let (s, ds) = minimum_jerk(k as f64 * dt, duration);
            let p = [p0[0] + (p1[0] - p0[0]) * s, p0[1] + (p1[1] - p0[1]) * s];
            let v = [(p1[0] - p0[0]) * ds, (p1[1] - p0[1]) * ds];
            let q = plant
                .inverse_kinematics(p)
                .ok_or(PathError::OutOfReach { x: p[0], y: p[1] })?;
            let j = plant.jacobian(&q);
            let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
            if det.abs() < 1e-9 {
                return Err(PathError::Singular { x: p[0], y: p[1] });
            }
            let qd = [
                (j[1][1] * v[0] - j[0][1] * v[1]) / det,
                (j[0][0] * v[1] - j[1][0] * v[0]) / det,
            ];
            Ok(Exogenous {
                q_d: q,
                qd_d: qd,
                tau_ext: [0.0; 2],
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn minimum_jerk_speed_is_derivative_of_position() {
        let t_end = 0.8;
        for i in 1..80 {
            let t = i as f64 * 0.01;
            let h = 1e-6;
            let fd = (minimum_jerk(t + h, t_end).0 - minimum_jerk(t - h, t_end).0) / (2.0 * h);
            assert!((fd - minimum_jerk(t, t_end).1).abs() < 1e-6);
        }
        assert_eq!(minimum_jerk(0.0, t_end).0, 0.0);
        assert!((minimum_jerk(t_end, t_end).0 - 1.0).abs() < 1e-15);
    }
}
