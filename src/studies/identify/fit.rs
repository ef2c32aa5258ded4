//! The torque error of a logged sample, velocity bins and (weighted) polynomial fits.

use super::*;

/// Rigid-body parameters of the single joint of Eq. 15.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct JointParams {
    /// Moment of inertia `J` (kg·m²).
    pub inertia: f64,
    /// Mass `m` (kg).
    pub mass: f64,
    /// Distance from the joint to the centre of mass `l_c` (m).
    pub com: f64,
    /// Gravity acceleration `g` (m/s²).
    pub gravity: f64,
}

impl JointParams {
    /// The iCub forearm of the paper (§III-B): `J = 5.08e-3 kg·m²`, `m = 0.812 kg`,
    /// `l_c = 0.103 m`, `g = 9.81 m/s²`.
    pub const ICUB_FOREARM: JointParams = JointParams {
        inertia: 5.08e-3,
        mass: 0.812,
        com: 0.103,
        gravity: 9.81,
    };
}

impl Default for JointParams {
    fn default() -> Self {
        Self::ICUB_FOREARM
    }
}

/// The torque error of one sample (paper §III-B):
/// `e = −J q̈ − m g l_c cos q + τ_ff − K_P (q − q_d) − K_D (q̇ − q̇_d)`.
pub fn torque_error(row: &LogRow, joint: &JointParams) -> f64 {
    -joint.inertia * row.qdd - joint.mass * joint.gravity * joint.com * row.q.cos() + row.tau_ff
        - row.stiffness * (row.q - row.q_d)
        - row.damping * (row.qd - row.qd_d)
}

// ---------------------------------------------------------------------------------------------
// Binning and polynomial fits
// ---------------------------------------------------------------------------------------------

/// Statistics of the torque error over one velocity bin.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct VelocityBin {
    /// Lower edge of the bin (rad/s).
    pub lo: f64,
    /// Upper edge of the bin (rad/s).
    pub hi: f64,
    /// Mean velocity of the samples in the bin (rad/s), the abscissa of the fits.
    pub velocity: f64,
    /// Number of samples.
    pub count: usize,
    /// Mean torque error `ē`.
    pub mean: f64,
    /// Sample standard deviation of the torque error `σ_e` (with `count − 1`).
    pub std: f64,
}

/// Splits `[min q̇, max q̇]` into `n_bins` equal-width bins and returns the error statistics of
/// every bin holding at least `max(min_count, 2)` samples (sparser bins are dropped).
pub fn bin_by_velocity(
    qd: &[f64],
    e: &[f64],
    n_bins: usize,
    min_count: usize,
) -> Result<Vec<VelocityBin>, IdentifyError> {
    check_samples(qd, e)?;
    if n_bins == 0 {
        return Err(IdentifyError::InvalidInput(
            "the number of bins must be positive".into(),
        ));
    }
    let (lo, hi) = min_max(qd);
    let width = (hi - lo) / n_bins as f64;
    // Welford accumulators: count, mean velocity, mean error, M2 of the error.
    let mut acc = vec![(0usize, 0.0, 0.0, 0.0); n_bins];
    for (&v, &err) in qd.iter().zip(e) {
        let k = if width > 0.0 {
            (((v - lo) / width) as usize).min(n_bins - 1)
        } else {
            0
        };
        let (count, mean_v, mean_e, m2) = &mut acc[k];
        *count += 1;
        let c = *count as f64;
        *mean_v += (v - *mean_v) / c;
        let delta = err - *mean_e;
        *mean_e += delta / c;
        *m2 += delta * (err - *mean_e);
    }
    let min_count = min_count.max(2);
    Ok(acc
        .iter()
        .enumerate()
        .filter(|(_, a)| a.0 >= min_count)
        .map(|(k, &(count, velocity, mean, m2))| VelocityBin {
            lo: lo + k as f64 * width,
            hi: if k + 1 == n_bins {
                hi
            } else {
                lo + (k + 1) as f64 * width
            },
            velocity,
            count,
            mean,
            std: (m2 / (count - 1) as f64).sqrt(),
        })
        .collect())
}

/// A polynomial `c₀ + c₁ x + c₂ x² + …`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Polynomial {
    /// Coefficients in increasing powers: `coefficients[k]` multiplies `x^k`.
    pub coefficients: Vec<f64>,
}

impl Polynomial {
    /// Value at `x` (Horner).
    pub fn eval(&self, x: f64) -> f64 {
        self.coefficients
            .iter()
            .rev()
            .fold(0.0, |acc, c| acc * x + c)
    }

    /// Degree (number of coefficients − 1; 0 for an empty polynomial).
    pub fn degree(&self) -> usize {
        self.coefficients.len().saturating_sub(1)
    }
}

impl fmt::Display for Polynomial {
    /// Decreasing powers of `q̇`, as in the caption of Fig. 3: `1.254 q̇² − 0.351 q̇ + 0.057`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let precision = f.precision().unwrap_or(4);
        let mut first = true;
        for (k, &c) in self.coefficients.iter().enumerate().rev() {
            if first {
                write!(f, "{c:.precision$}")?;
                first = false;
            } else if c < 0.0 {
                write!(f, " - {:.precision$}", -c)?;
            } else {
                write!(f, " + {c:.precision$}")?;
            }
            match k {
                0 => {}
                1 => write!(f, " q'")?,
                _ => write!(f, " q'^{k}")?,
            }
        }
        if first {
            write!(f, "0")?;
        }
        Ok(())
    }
}

/// A least-squares polynomial fit and its quality.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PolyFit {
    /// The fitted polynomial.
    pub polynomial: Polynomial,
    /// Number of points fitted.
    pub(crate) points: usize,
    /// Root mean square of the residuals.
    pub rms_residual: f64,
    /// Coefficient of determination (1 for an exact fit; 1 if `y` is constant and fitted exactly).
    pub r_squared: f64,
}

/// Least-squares fit of a polynomial of degree `degree` to the points `(x_i, y_i)`.
///
/// The abscissae are centred and scaled to `[−1, 1]` before the Vandermonde system is solved by
/// SVD (nalgebra), and the coefficients are converted back to powers of `x`. Needs at least
/// `degree + 1` distinct abscissae.
pub fn polyfit(x: &[f64], y: &[f64], degree: usize) -> Result<PolyFit, IdentifyError> {
    polyfit_weighted(x, y, None, degree)
}

/// [`polyfit`] minimising `Σ w_i (y_i − p(x_i))²` (all weights 1 if `weights` is `None`); the
/// reported residuals are unweighted.
pub(super) fn polyfit_weighted(
    x: &[f64],
    y: &[f64],
    weights: Option<&[f64]>,
    degree: usize,
) -> Result<PolyFit, IdentifyError> {
    if x.len() != y.len() || weights.is_some_and(|w| w.len() != x.len()) {
        return Err(IdentifyError::InvalidInput(format!(
            "polyfit: {} abscissae but {} ordinates",
            x.len(),
            y.len()
        )));
    }
    if x.iter().chain(y).any(|v| !v.is_finite()) {
        return Err(IdentifyError::InvalidInput(
            "polyfit: non-finite point".into(),
        ));
    }
    let n = x.len();
    let m = degree + 1;
    if n < m {
        return Err(IdentifyError::InsufficientData(format!(
            "a degree-{degree} fit needs at least {m} points, got {n}"
        )));
    }
    let center = x.iter().sum::<f64>() / n as f64;
    let scale = x.iter().fold(0.0_f64, |s, v| s.max((v - center).abs()));
    if scale == 0.0 && degree > 0 {
        return Err(IdentifyError::InsufficientData(format!(
            "a degree-{degree} fit needs distinct abscissae, all are {center}"
        )));
    }
    let scale = if scale == 0.0 { 1.0 } else { scale };
    let sqrt_w = |i: usize| weights.map_or(1.0, |w| w[i].sqrt());
    let vandermonde = DMatrix::from_fn(n, m, |i, j| {
        sqrt_w(i) * ((x[i] - center) / scale).powi(j as i32)
    });
    let rhs = DVector::from_fn(n, |i, _| sqrt_w(i) * y[i]);
    let svd = vandermonde.svd(true, true);
    let s_max = svd.singular_values.max();
    let s_min = svd.singular_values.min();
    if s_min <= s_max * 1e-12 {
        return Err(IdentifyError::InsufficientData(format!(
            "a degree-{degree} fit needs at least {m} distinct abscissae"
        )));
    }
    let scaled = svd
        .solve(&rhs, 0.0)
        .map_err(|msg| IdentifyError::Numerical(msg.into()))?;
    // p(x) = Σ_k c_k ((x − center)/scale)^k, expanded by the binomial theorem.
    let mut coefficients = vec![0.0; m];
    for k in 0..m {
        let ck = scaled[k] / scale.powi(k as i32);
        let mut binomial = 1.0; // C(k, j)
        for (j, coefficient) in coefficients.iter_mut().enumerate().take(k + 1) {
            *coefficient += ck * binomial * (-center).powi((k - j) as i32);
            binomial = binomial * (k - j) as f64 / (j + 1) as f64;
        }
    }
    let polynomial = Polynomial { coefficients };
    let mean_y = y.iter().sum::<f64>() / n as f64;
    let (ss_res, ss_tot) = x.iter().zip(y).fold((0.0, 0.0), |(r, t), (&xi, &yi)| {
        let res = yi - polynomial.eval(xi);
        (r + res * res, t + (yi - mean_y) * (yi - mean_y))
    });
    let r_squared = if ss_tot > 0.0 {
        1.0 - ss_res / ss_tot
    } else if ss_res == 0.0 {
        1.0
    } else {
        0.0
    };
    Ok(PolyFit {
        polynomial,
        points: n,
        rms_residual: (ss_res / n as f64).sqrt(),
        r_squared,
    })
}
