//! The noise model `e = (a + b |q'|) η`: maximum-likelihood and moment estimates, and the
//! Jarque–Bera test of the normalised residuals.

use super::*;

/// The fitted noise model `e = (a + b q̇) η`, `η ~ N(0, 1)` (Eq. 16).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NoiseFit {
    /// Constant part `a` (made non-negative: `(a, b)` and `(−a, −b)` are the same model).
    pub a: f64,
    /// Velocity-dependent part `b` (per rad/s).
    pub b: f64,
    /// Standard error of `a` from the observed Fisher information (`None` if it is singular).
    pub a_std_error: Option<f64>,
    /// Standard error of `b` from the observed Fisher information (`None` if it is singular).
    pub b_std_error: Option<f64>,
    /// Negative log-likelihood at the optimum,
    /// `Σ [ln|a + b q̇_i| + e_i²/(2(a + b q̇_i)²) + ½ ln 2π]`.
    pub(crate) neg_log_likelihood: f64,
    /// Number of samples.
    pub(crate) samples: usize,
    /// Smallest modelled standard deviation, [`STD_FLOOR`]` · √(a² + (b q̇_max)²)`.
    pub(crate) std_floor: f64,
}

impl NoiseFit {
    /// Standard deviation of the error predicted at velocity `qd`: `|a + b q̇|` (at least
    /// [`NoiseFit::std_floor`]).
    pub fn std_at(&self, qd: f64) -> f64 {
        (self.a + self.b * qd).abs().max(self.std_floor)
    }

    /// The normalised residual `η = e / (a + b q̇)` (the denominator at least
    /// [`NoiseFit::std_floor`] in magnitude, with its sign).
    pub(crate) fn eta(&self, qd: f64, e: f64) -> f64 {
        e / self.std_at(qd).copysign(self.a + self.b * qd)
    }
}

/// The least-squares fit of `|e_i| ≈ √(2/π) |a + b q̇_i|` (the mean absolute value of a
/// `N(0, σ²)` variable is `√(2/π) σ`): a moment estimate of `(a, b)`, less efficient than
/// [`fit_noise_ml`] but insensitive to a small noise floor where `a + b q̇` vanishes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MomentFit {
    /// Constant part `a` (non-negative).
    pub a: f64,
    /// Velocity-dependent part `b` (per rad/s).
    pub b: f64,
}

/// Numerical safeguard: the modelled standard deviation is floored at `STD_FLOOR · r`, with
/// `r = √(a² + (b q̇_max)²)` and `q̇_max = max|q̇_i|` (that is, `|a + b q̇|` is replaced by
/// `STD_FLOOR · r` within about `STD_FLOOR · q̇_max` rad/s of its zero crossing). Without it,
/// every sample with a tiny `|e_i|` near the crossing is a narrow, deep well of the likelihood
/// (its `ln|a + b q̇_i|` term tends to −∞ as the crossing moves onto it) that can capture the
/// optimum and spoil the normalised residuals of its neighbours.
pub(crate) const STD_FLOOR: f64 = 1e-3;

/// Number of directions of the coarse grid of [`minimise_over_direction`].
pub(super) const COARSE_DIRECTIONS: usize = 4096;

/// At most this many samples (evenly strided) are used on the coarse grid of the
/// maximum-likelihood fit; the refinement uses all of them.
pub(super) const COARSE_SAMPLES: usize = 20_000;

/// Minimises `fine(θ)` over the directions `θ ∈ [0, π)`: the best of [`COARSE_DIRECTIONS`]
/// equally spaced directions for `coarse` (a cheaper approximation of `fine`, or `fine`
/// itself), then nested grids of `fine`, each 10 times finer (±4 coarse spacings first, then ±2
/// spacings of the previous level, centre included so that the value never increases), down to
/// 1e-14 rad. Returns the best direction and `fine` there.
pub(super) fn minimise_over_direction(
    coarse: impl Fn(f64) -> f64,
    fine: impl Fn(f64) -> f64,
) -> (f64, f64) {
    let mut spacing = std::f64::consts::PI / COARSE_DIRECTIONS as f64;
    let mut best_theta = 0.0;
    let mut best = f64::INFINITY;
    for k in 0..COARSE_DIRECTIONS {
        let theta = spacing * k as f64;
        let value = coarse(theta);
        if value < best {
            (best_theta, best) = (theta, value);
        }
    }
    best = fine(best_theta);
    let mut half_width = 40;
    while spacing > 1e-14 {
        spacing /= 10.0;
        let center = best_theta;
        for j in -half_width..=half_width {
            let theta = center + f64::from(j) * spacing;
            let value = fine(theta);
            if value < best {
                (best_theta, best) = (theta, value);
            }
        }
        half_width = 20;
    }
    (best_theta, best)
}

/// Mean negative log-likelihood (without the constants) profiled over the scale `r`, for the
/// direction `θ`: `(a, b̃) = r (cos θ, sin θ)`, `u_i = max(|cos θ + q̃_i sin θ|, STD_FLOOR)`,
/// `r² = mean e_i²/u_i²`, `nll = ln r + mean ln u_i`. Returns `(nll, r)`.
pub(super) fn profile_nll(theta: f64, q: &[f64], e2: &[f64]) -> (f64, f64) {
    let (sin, cos) = theta.sin_cos();
    let floor = STD_FLOOR * STD_FLOOR;
    let (mut ratio, mut log) = (0.0, 0.0);
    // Σ ln u² as the logarithm of running products (u² ∈ [1e-6, 2]), flushed before they leave
    // [1e-150, 1e150]: one logarithm per ~50 samples instead of one per sample.
    let mut product = 1.0_f64;
    for (&qi, &ei2) in q.iter().zip(e2) {
        let u = cos + sin * qi;
        let u2 = (u * u).max(floor);
        ratio += ei2 / u2;
        product *= u2;
        if !(1e-150..=1e150).contains(&product) {
            log += product.ln();
            product = 1.0;
        }
    }
    log += product.ln();
    let n = q.len() as f64;
    let r2 = ratio / n;
    (0.5 * r2.ln() + 0.5 * log / n, r2.sqrt())
}

/// Validated samples with velocities scaled to `[−1, 1]`: `(q̃, v_scale)`.
pub(super) fn scaled_velocities(qd: &[f64], e: &[f64]) -> Result<(Vec<f64>, f64), IdentifyError> {
    check_samples(qd, e)?;
    let n = qd.len();
    if n < 3 {
        return Err(IdentifyError::InsufficientData(format!(
            "the noise fit needs at least 3 samples, got {n}"
        )));
    }
    let (lo, hi) = min_max(qd);
    if lo == hi {
        return Err(IdentifyError::InsufficientData(format!(
            "the noise fit needs samples at different velocities, all are at {lo} rad/s"
        )));
    }
    if e.iter().all(|&v| v == 0.0) {
        return Err(IdentifyError::InsufficientData(
            "all torque errors are zero".into(),
        ));
    }
    let v_scale = lo.abs().max(hi.abs());
    Ok((qd.iter().map(|v| v / v_scale).collect(), v_scale))
}

/// `(a, b)` from the polar form, with the sign convention `a ≥ 0`.
pub(super) fn from_polar(r: f64, theta: f64, v_scale: f64) -> (f64, f64) {
    let (sin, cos) = theta.sin_cos();
    let (a, b) = (r * cos, r * sin / v_scale);
    if a < 0.0 || (a == 0.0 && b < 0.0) {
        (-a, -b)
    } else {
        (a, b)
    }
}

/// Maximum-likelihood estimate of `(a, b)` in `e_i ~ N(0, (a + b q̇_i)²)`, i.e. the minimum of
/// `Σ [ln|a + b q̇_i| + e_i² / (2 (a + b q̇_i)²)]`.
///
/// The likelihood is infinite wherever `a + b q̇_i = 0` for a sample (a line through the origin
/// of the `(a, b)` plane per sample), so a local optimiser (Newton, Nelder–Mead) started on the
/// wrong side of the true zero crossing `q̇ = −a/b` cannot reach the optimum. Instead the
/// problem is written in polar form `(a, b q̇_s) = r (cos θ, sin θ)` (with `q̇_s = max|q̇_i|`),
/// the scale `r` is eliminated in closed form (`r² = mean e_i²/u_i²`), and the one-dimensional
/// profile in `θ ∈ [0, π)` is minimised globally: a grid of 4096 directions (on at most 20 000
/// evenly strided samples), then nested zooming grids on all samples down to 1e-14 rad. The
/// search is global over the direction, whatever the sign changes of `a + b q̇` over the data. The modelled deviation is floored at
/// [`STD_FLOOR`] times the scale of the model (a numerical safeguard, see there).
///
/// Apart from that floor the model has no noise floor: near the zero crossing of `a + b q̇` the
/// few samples with the smallest predicted deviation weigh most, so an offset left in `e` there
/// (e.g. an imperfectly subtracted mean) biases the estimate; compare with
/// [`fit_noise_moments`]. On 20 000 samples the fit takes a fraction of a second.
pub fn fit_noise_ml(qd: &[f64], e: &[f64]) -> Result<NoiseFit, IdentifyError> {
    let (q, v_scale) = scaled_velocities(qd, e)?;
    let n = q.len();
    let e2: Vec<f64> = e.iter().map(|v| v * v).collect();
    let stride = n.div_ceil(COARSE_SAMPLES);
    let q_coarse: Vec<f64> = q.iter().step_by(stride).copied().collect();
    let e2_coarse: Vec<f64> = e2.iter().step_by(stride).copied().collect();
    let (theta, value) = minimise_over_direction(
        |theta| profile_nll(theta, &q_coarse, &e2_coarse).0,
        |theta| profile_nll(theta, &q, &e2).0,
    );
    if !value.is_finite() {
        return Err(IdentifyError::Numerical(
            "the likelihood is not finite anywhere".into(),
        ));
    }
    let r = profile_nll(theta, &q, &e2).1;
    let (a, b) = from_polar(r, theta, v_scale);
    let std_floor = STD_FLOOR * r;

    // Negative log-likelihood and observed information in (a, b).
    let mut nll = 0.0;
    let mut info = Matrix2::zeros();
    for (&v, &err) in qd.iter().zip(e) {
        let s2 = ((a + b * v) * (a + b * v)).max(std_floor * std_floor);
        nll += 0.5 * s2.ln() + err * err / (2.0 * s2);
        let curvature = -1.0 / s2 + 3.0 * err * err / (s2 * s2);
        info += curvature * Matrix2::new(1.0, v, v, v * v);
    }
    nll += 0.5 * n as f64 * (2.0 * std::f64::consts::PI).ln();
    let (a_std_error, b_std_error) = match info.try_inverse() {
        Some(cov) if cov[(0, 0)] > 0.0 && cov[(1, 1)] > 0.0 => {
            (Some(cov[(0, 0)].sqrt()), Some(cov[(1, 1)].sqrt()))
        }
        _ => (None, None),
    };
    Ok(NoiseFit {
        a,
        b,
        a_std_error,
        b_std_error,
        neg_log_likelihood: nll,
        samples: n,
        std_floor,
    })
}

/// Least-squares fit of `|e_i| ≈ √(2/π) |a + b q̇_i|` ([`MomentFit`]). The absolute value makes
/// it non-linear when `a + b q̇` changes sign over the data; it is solved like
/// [`fit_noise_ml`], in polar form with the scale in closed form and a global search over the
/// direction (the objective is continuous, so the search is straightforward).
pub fn fit_noise_moments(qd: &[f64], e: &[f64]) -> Result<MomentFit, IdentifyError> {
    let (q, v_scale) = scaled_velocities(qd, e)?;
    let k = (2.0 / std::f64::consts::PI).sqrt();
    // For a direction, Σ (|e| − k r |u|)² is minimal at r = Σ|e||u| / (k Σu²), where it equals
    // Σe² − (Σ|e||u|)²/Σu²: maximise the last ratio.
    let sums = |theta: f64| {
        let (sin, cos) = theta.sin_cos();
        q.iter().zip(e).fold((0.0, 0.0), |(eu, uu), (&qi, &ei)| {
            let u = cos + sin * qi;
            (eu + ei.abs() * u.abs(), uu + u * u)
        })
    };
    let objective = |theta: f64| {
        let (eu, uu) = sums(theta);
        -eu * eu / uu
    };
    let (theta, _) = minimise_over_direction(objective, objective);
    let (eu, uu) = sums(theta);
    let (a, b) = from_polar(eu / (k * uu), theta, v_scale);
    Ok(MomentFit { a, b })
}

// ---------------------------------------------------------------------------------------------
// Jarque–Bera
// ---------------------------------------------------------------------------------------------

/// The Jarque–Bera normality test of a sample.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct JarqueBera {
    /// Sample size.
    pub(crate) n: usize,
    /// Sample skewness `S = m₃ / m₂^{3/2}` (biased central moments).
    pub skewness: f64,
    /// Sample kurtosis `K = m₄ / m₂²` (3 for a normal distribution; not the excess).
    pub kurtosis: f64,
    /// `JB = n/6 (S² + (K − 3)²/4)`.
    pub statistic: f64,
    /// Asymptotic p-value: the χ²(2) survival function at `JB`, `exp(−JB/2)`.
    pub p_value: f64,
}

impl JarqueBera {
    /// Whether normality is rejected at significance level `alpha` (`p < alpha`).
    pub fn rejects_normality(&self, alpha: f64) -> bool {
        self.p_value < alpha
    }
}

/// Survival function of the χ² distribution with 2 degrees of freedom: `P(X > x) = exp(−x/2)`.
pub fn chi2_2dof_sf(x: f64) -> f64 {
    if x <= 0.0 { 1.0 } else { (-0.5 * x).exp() }
}

/// Jarque–Bera test with the asymptotic χ²(2) p-value (Matlab's `jbtest` uses tabulated
/// small-sample critical values instead; the two agree for the thousands of samples of a log).
pub fn jarque_bera(x: &[f64]) -> Result<JarqueBera, IdentifyError> {
    let n = x.len();
    if n < 3 {
        return Err(IdentifyError::InsufficientData(format!(
            "the Jarque-Bera test needs at least 3 samples, got {n}"
        )));
    }
    if x.iter().any(|v| !v.is_finite()) {
        return Err(IdentifyError::InvalidInput(
            "Jarque-Bera: non-finite sample".into(),
        ));
    }
    let nf = n as f64;
    let mean = x.iter().sum::<f64>() / nf;
    let (mut m2, mut m3, mut m4) = (0.0, 0.0, 0.0);
    for &v in x {
        let d = v - mean;
        let d2 = d * d;
        m2 += d2;
        m3 += d2 * d;
        m4 += d2 * d2;
    }
    let (m2, m3, m4) = (m2 / nf, m3 / nf, m4 / nf);
    if m2 <= 0.0 {
        return Err(IdentifyError::InsufficientData(
            "the Jarque-Bera test needs a sample with non-zero variance".into(),
        ));
    }
    let skewness = m3 / m2.powf(1.5);
    let kurtosis = m4 / (m2 * m2);
    let statistic = nf / 6.0 * (skewness * skewness + 0.25 * (kurtosis - 3.0).powi(2));
    Ok(JarqueBera {
        n,
        skewness,
        kurtosis,
        statistic,
        p_value: chi2_2dof_sf(statistic),
    })
}
