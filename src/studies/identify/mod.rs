//! Noise identification from joint logs (paper §III-B, "Experimental results on the iCub", and
//! Fig. 3(a)): `vic identify --log FILE.csv`.
//!
//! The procedure of the paper, step by step:
//!
//! 1. A log of a single joint is recorded while the feedforward torque `τ_ff` and the stiffness
//!    `K_P` are varied (see [the log format](#log-format)).
//! 2. For every sample the torque error of the model of Eq. 15 is computed ([`torque_error`]):
//!
//!    `e = −J q̈ − m g l_c cos q + τ_ff − K_P (q − q_d) − K_D (q̇ − q̇_d)`
//!
//!    (the paper writes `K_D = α K_P`; the log stores the damping gain actually applied).
//! 3. The samples are binned by velocity ([`bin_by_velocity`]) and the per-bin mean `ē` and
//!    standard deviation `σ_e` are fitted by least-squares polynomials of the velocity
//!    ([`polyfit`]); in Fig. 3(a) `σ_e` is quadratic and `ē` linear.
//! 4. The parameters `(a, b)` of the state-dependent noise of Eq. 16, `e = (a + b q̇) η` with
//!    `η ~ N(0, 1)`, are estimated by maximum likelihood ([`fit_noise_ml`]), and cross-checked by
//!    a least-squares fit of `|e|` ([`fit_noise_moments`]). The model has zero mean: if the
//!    errors have a systematic part, [`IdentifyOptions::subtract_mean`] removes a fitted mean
//!    polynomial first.
//! 5. The normalised residuals `η_i = e_i / (a + b q̇_i)` are tested for normality with the
//!    Jarque–Bera test ([`jarque_bera`]). (The paper prints `η = (a + b q̇)/e`, a typo: `η` is the
//!    error divided by its standard deviation.) The paper found `(a, b) = (0.15, 0.37)`.
//!
//! [`identify`] runs steps 2–5 on log rows and returns an [`IdentifyReport`] (serialisable to
//! JSON, and printable as text through its `Display` implementation); [`identify_samples`] does
//! steps 3–5 on velocities and errors computed elsewhere.
//!
//! # Log format
//!
//! A plain comma-separated text file, written by [`write_header`]/[`write_row`] (also by the
//! board daemon) and read by [`read_log`]:
//!
//! * The first line that is neither blank nor a comment is the header. It must name each of the
//!   nine columns of [`LOG_COLUMNS`] exactly once, in any order:
//!
//!   | column      | meaning                                  | unit      |
//!   |-------------|------------------------------------------|-----------|
//!   | `t`         | time                                     | s         |
//!   | `q`         | joint angle (from the horizontal, as in Eq. 15) | rad |
//!   | `qd`        | joint velocity                           | rad/s     |
//!   | `qdd`       | joint acceleration                       | rad/s²    |
//!   | `tau_ff`    | feedforward torque                       | N·m       |
//!   | `stiffness` | stiffness gain `K_P`                     | N·m/rad   |
//!   | `damping`   | damping gain `K_D`                       | N·m·s/rad |
//!   | `q_d`       | desired angle                            | rad       |
//!   | `qd_d`      | desired velocity                         | rad/s     |
//!
//! * Extra columns are allowed only if their name starts with [`EXTRA_COLUMN_PREFIX`] (`x_`, e.g.
//!   `x_motor_current`); they are ignored. Any other unknown column is an error.
//! * Every following line is one sample: as many fields as the header, separated by commas, no
//!   quoting. Spaces around fields are ignored. The nine known fields must parse as finite
//!   `f64` (`NaN` and infinities are rejected).
//! * Blank lines and lines whose first non-blank character is `#` are ignored anywhere (e.g. a
//!   `# vic joint log v1` banner or recording metadata).
//!
//! [`write_row`] prints each number with Rust's shortest round-trip representation, so a log
//! written and read back gives bit-identical rows.
//!
//! Errors name the 1-based line number and the column ([`IdentifyError`]).

use nalgebra::{DMatrix, DVector, Matrix2};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::io::{self, BufRead, Write};
use std::path::{Path, PathBuf};

pub use vic_rt::record::{EXTRA_COLUMN_PREFIX, LOG_COLUMNS, LOG_HEADER};

mod fit;
mod log;
mod noise;

pub use fit::*;
pub use log::*;
pub use noise::*;

/// One sample of a joint log. See [the log format](self#log-format) for units.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct LogRow {
    /// Time (s).
    pub t: f64,
    /// Joint angle (rad).
    pub q: f64,
    /// Joint velocity (rad/s).
    pub qd: f64,
    /// Joint acceleration (rad/s²).
    pub qdd: f64,
    /// Feedforward torque (N·m).
    pub tau_ff: f64,
    /// Stiffness gain `K_P` (N·m/rad).
    pub stiffness: f64,
    /// Damping gain `K_D` (N·m·s/rad).
    pub damping: f64,
    /// Desired angle (rad).
    pub q_d: f64,
    /// Desired velocity (rad/s).
    pub qd_d: f64,
}

impl LogRow {
    /// The field for column `index` of [`LOG_COLUMNS`].
    fn field_mut(&mut self, index: usize) -> &mut f64 {
        match index {
            0 => &mut self.t,
            1 => &mut self.q,
            2 => &mut self.qd,
            3 => &mut self.qdd,
            4 => &mut self.tau_ff,
            5 => &mut self.stiffness,
            6 => &mut self.damping,
            7 => &mut self.q_d,
            _ => &mut self.qd_d,
        }
    }
}

/// What can go wrong while reading a log or identifying the noise. Log errors carry the 1-based
/// line number and the column name.
#[derive(Debug, thiserror::Error)]
pub enum IdentifyError {
    /// A board's MCAP recording that cannot be read.
    #[error(transparent)]
    Recording(#[from] vic_rt::record::RecordError),
    #[error("{path}: cannot open: {source}")]
    Open { path: PathBuf, source: io::Error },
    #[error("line {line}: cannot read: {source}")]
    Read { line: usize, source: io::Error },
    #[error("empty log: expected a header line `{LOG_HEADER}`")]
    MissingHeader,
    #[error(
        "line {line}: unknown column `{column}` (expected {LOG_HEADER}, extra columns must start with `{EXTRA_COLUMN_PREFIX}`)"
    )]
    UnknownColumn { line: usize, column: String },
    #[error("line {line}: column `{column}` is missing from the header")]
    MissingColumn { line: usize, column: &'static str },
    #[error("line {line}: bad header: {message}")]
    BadHeader { line: usize, message: String },
    #[error(
        "line {line}, column `{column}`: missing field ({found} fields, header has {expected})"
    )]
    MissingField {
        line: usize,
        column: String,
        found: usize,
        expected: usize,
    },
    #[error("line {line}: too many fields ({found}, header has {expected})")]
    ExtraField {
        line: usize,
        found: usize,
        expected: usize,
    },
    #[error("line {line}, column `{column}`: `{value}` is not a number")]
    BadNumber {
        line: usize,
        column: String,
        value: String,
    },
    #[error("line {line}, column `{column}`: `{value}` is not finite")]
    NonFinite {
        line: usize,
        column: String,
        value: String,
    },
    #[error("not enough data: {0}")]
    InsufficientData(String),
    #[error("invalid input: {0}")]
    InvalidInput(String),
    #[error("numerical failure: {0}")]
    Numerical(String),
}

/// Options of [`identify`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IdentifyOptions {
    /// Number of equal-width velocity bins between the smallest and largest velocity (20).
    pub bins: usize,
    /// Bins with fewer samples are dropped from the fits (30).
    pub min_bin_count: usize,
    /// Degree of the polynomial fitted to the bin means `ē(q̇)` (1, linear as in Fig. 3).
    pub mean_degree: usize,
    /// Degree of the polynomial fitted to the bin standard deviations `σ_e(q̇)` (2, quadratic as
    /// in Fig. 3).
    pub std_degree: usize,
    /// Subtract a fitted mean polynomial `ē(q̇_i)` (degree `mean_degree`) from every error
    /// before the noise fits and the normality test (false). The noise model of Eq. 16 has zero
    /// mean; switch this on when the mean fit shows a systematic error, as in Fig. 3 where
    /// `ē = 0.213 q̇ − 0.049`. The subtracted polynomial is refitted on all samples by weighted
    /// least squares (see [`IdentifyReport::subtracted_mean`]), not the bin fit itself.
    pub subtract_mean: bool,
}

impl Default for IdentifyOptions {
    fn default() -> Self {
        Self {
            bins: 20,
            min_bin_count: 30,
            mean_degree: 1,
            std_degree: 2,
            subtract_mean: false,
        }
    }
}

/// Everything `vic identify` reports.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct IdentifyReport {
    /// Number of samples.
    pub n: usize,
    /// Joint parameters used for the torque error (`None` from [`identify_samples`]).
    pub(crate) joint: Option<JointParams>,
    /// Options used.
    pub(crate) options: IdentifyOptions,
    /// Smallest and largest velocity (rad/s).
    pub(crate) velocity_range: [f64; 2],
    /// Mean of the torque error over all samples.
    pub(crate) error_mean: f64,
    /// Standard deviation of the torque error over all samples.
    pub(crate) error_std: f64,
    /// Per-bin statistics (bins with too few samples dropped).
    pub bins: Vec<VelocityBin>,
    /// Fit of the bin means `ē(q̇)`.
    pub mean_fit: PolyFit,
    /// Fit of the bin standard deviations `σ_e(q̇)`.
    pub std_fit: PolyFit,
    /// The mean polynomial subtracted from the errors before the noise fits, if
    /// [`IdentifyOptions::subtract_mean`]: a weighted least-squares fit on all samples with
    /// weights `1/σ_i²` (`σ_i` from the moment estimate, floored at 1 % of its root mean square).
    /// Close to `mean_fit`, but accurate where the noise is small, which the maximum-likelihood
    /// fit needs.
    pub subtracted_mean: Option<Polynomial>,
    /// Maximum-likelihood `(a, b)` of `e = (a + b q̇) η`.
    pub noise: NoiseFit,
    /// Least-squares fit of `|e| ≈ √(2/π) |a + b q̇|`: a cross-check of `noise` (a large
    /// difference points at a noise floor or an unmodelled mean).
    pub noise_moments: MomentFit,
    /// Jarque–Bera test of `η_i = e_i / (a + b q̇_i)`.
    pub(crate) jarque_bera: JarqueBera,
    /// Whether the Jarque–Bera test accepts normality of `η` at the 5 % level (`p ≥ 0.05`).
    pub normal_at_5_percent: bool,
}

/// Computes the torque error of every row with [`torque_error`] and runs [`identify_samples`].
pub fn identify(
    rows: &[LogRow],
    joint: &JointParams,
    options: &IdentifyOptions,
) -> Result<IdentifyReport, IdentifyError> {
    let qd: Vec<f64> = rows.iter().map(|r| r.qd).collect();
    let e: Vec<f64> = rows.iter().map(|r| torque_error(r, joint)).collect();
    let mut report = identify_samples(&qd, &e, options)?;
    report.joint = Some(*joint);
    Ok(report)
}

/// The identification on velocities `qd` and torque errors `e`: binning, polynomial fits of
/// `ē(q̇)` and `σ_e(q̇)`, maximum-likelihood `(a, b)` and Jarque–Bera test of the normalised
/// residuals.
pub fn identify_samples(
    qd: &[f64],
    e: &[f64],
    options: &IdentifyOptions,
) -> Result<IdentifyReport, IdentifyError> {
    check_samples(qd, e)?;
    let n = qd.len();
    if n < 3 {
        return Err(IdentifyError::InsufficientData(format!(
            "need at least 3 samples, got {n}"
        )));
    }
    let bins = bin_by_velocity(qd, e, options.bins, options.min_bin_count)?;
    let fit_bins = |degree: usize, what: &str, y: fn(&VelocityBin) -> f64| {
        let x: Vec<f64> = bins.iter().map(|b| b.velocity).collect();
        let y: Vec<f64> = bins.iter().map(y).collect();
        polyfit(&x, &y, degree).map_err(|err| match err {
            IdentifyError::InsufficientData(msg) => IdentifyError::InsufficientData(format!(
                "{what} fit: {msg}; {} of {} bins hold at least {} samples \
                 (change the number of bins or the minimum count per bin)",
                bins.len(),
                options.bins,
                options.min_bin_count.max(2)
            )),
            other => other,
        })
    };
    let mean_fit = fit_bins(options.mean_degree, "mean", |b| b.mean)?;
    let std_fit = fit_bins(options.std_degree, "standard deviation", |b| b.std)?;

    let subtracted_mean = if options.subtract_mean {
        Some(refine_mean(
            qd,
            e,
            &mean_fit.polynomial,
            options.mean_degree,
        )?)
    } else {
        None
    };
    let residual: Vec<f64> = match &subtracted_mean {
        Some(mean) => qd
            .iter()
            .zip(e)
            .map(|(&v, &err)| err - mean.eval(v))
            .collect(),
        None => e.to_vec(),
    };
    let noise = fit_noise_ml(qd, &residual)?;
    let noise_moments = fit_noise_moments(qd, &residual)?;
    let eta: Vec<f64> = qd
        .iter()
        .zip(&residual)
        .map(|(&v, &err)| noise.eta(v, err))
        .collect();
    let jarque_bera = jarque_bera(&eta)?;

    let nf = n as f64;
    let error_mean = e.iter().sum::<f64>() / nf;
    let error_std = (e.iter().map(|v| (v - error_mean).powi(2)).sum::<f64>() / (nf - 1.0)).sqrt();
    let (lo, hi) = min_max(qd);
    Ok(IdentifyReport {
        n,
        joint: None,
        options: *options,
        velocity_range: [lo, hi],
        error_mean,
        error_std,
        bins,
        mean_fit,
        std_fit,
        subtracted_mean,
        noise,
        noise_moments,
        normal_at_5_percent: !jarque_bera.rejects_normality(0.05),
        jarque_bera,
    })
}

impl fmt::Display for IdentifyReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "samples: {}, velocity range [{:.3}, {:.3}] rad/s",
            self.n, self.velocity_range[0], self.velocity_range[1]
        )?;
        writeln!(
            f,
            "torque error: mean {:.4}, std {:.4}",
            self.error_mean, self.error_std
        )?;
        writeln!(
            f,
            "velocity bins: {} of {} used (at least {} samples)",
            self.bins.len(),
            self.options.bins,
            self.options.min_bin_count.max(2)
        )?;
        writeln!(f, "  {:>9} {:>7} {:>10} {:>10}", "q'", "n", "mean", "std")?;
        for bin in &self.bins {
            writeln!(
                f,
                "  {:>9.3} {:>7} {:>10.4} {:>10.4}",
                bin.velocity, bin.count, bin.mean, bin.std
            )?;
        }
        writeln!(
            f,
            "mean fit:  e_mean  = {}   (R² {:.3})",
            self.mean_fit.polynomial, self.mean_fit.r_squared
        )?;
        writeln!(
            f,
            "std fit:   sigma_e = {}   (R² {:.3})",
            self.std_fit.polynomial, self.std_fit.r_squared
        )?;
        if let Some(mean) = &self.subtracted_mean {
            writeln!(f, "subtracted mean (weighted fit on all samples): {mean}")?;
        }
        let se = |s: Option<f64>| s.map_or_else(|| "?".to_owned(), |s| format!("{s:.4}"));
        writeln!(
            f,
            "noise e = (a + b q') eta, maximum likelihood: a = {:.4} ± {}, b = {:.4} ± {}",
            self.noise.a,
            se(self.noise.a_std_error),
            self.noise.b,
            se(self.noise.b_std_error)
        )?;
        writeln!(
            f,
            "  cross-check, |e| ~ sqrt(2/pi) |a + b q'|: a = {:.4}, b = {:.4}",
            self.noise_moments.a, self.noise_moments.b
        )?;
        write!(
            f,
            "Jarque-Bera on eta: JB = {:.3}, p = {:.4} (skewness {:.3}, kurtosis {:.3}): {}",
            self.jarque_bera.statistic,
            self.jarque_bera.p_value,
            self.jarque_bera.skewness,
            self.jarque_bera.kurtosis,
            if self.normal_at_5_percent {
                "normal at the 5 % level"
            } else {
                "normality rejected at the 5 % level"
            }
        )
    }
}

/// Weights of the generalised least-squares mean fit are `1/max(σ_i², (MEAN_WEIGHT_FLOOR σ_rms)²)`.
const MEAN_WEIGHT_FLOOR: f64 = 0.01;

/// The mean polynomial subtracted by [`IdentifyOptions::subtract_mean`]: refitted on all samples
/// by weighted least squares with weights `1/σ_i²`, `σ_i` from the moment estimate
/// ([`fit_noise_moments`]) of the noise of the errors minus the bin fit, floored at 1 % of its
/// root mean square (feasible generalised least squares).
///
/// Subtracting the bin fit itself is not accurate enough: its error (a few thousandths of the
/// error scale) is of the order of the noise near the zero crossing of `a + b q̇`, where the
/// maximum-likelihood fit is most sensitive, and biases `(a, b)` by tens of percent. The weighted
/// fit is most accurate precisely there.
fn refine_mean(
    qd: &[f64],
    e: &[f64],
    bin_fit: &Polynomial,
    degree: usize,
) -> Result<Polynomial, IdentifyError> {
    let centred: Vec<f64> = qd
        .iter()
        .zip(e)
        .map(|(&v, &err)| err - bin_fit.eval(v))
        .collect();
    let moments = fit_noise_moments(qd, &centred)?;
    let s2: Vec<f64> = qd
        .iter()
        .map(|&v| (moments.a + moments.b * v).powi(2))
        .collect();
    let floor2 = MEAN_WEIGHT_FLOOR * MEAN_WEIGHT_FLOOR * s2.iter().sum::<f64>() / s2.len() as f64;
    let weights: Vec<f64> = s2.iter().map(|s2| 1.0 / s2.max(floor2)).collect();
    Ok(polyfit_weighted(qd, e, Some(&weights), degree)?.polynomial)
}

fn check_samples(qd: &[f64], e: &[f64]) -> Result<(), IdentifyError> {
    if qd.len() != e.len() {
        return Err(IdentifyError::InvalidInput(format!(
            "{} velocities but {} errors",
            qd.len(),
            e.len()
        )));
    }
    if qd.is_empty() {
        return Err(IdentifyError::InsufficientData("no samples".into()));
    }
    if let Some(i) = qd
        .iter()
        .zip(e)
        .position(|(v, err)| !v.is_finite() || !err.is_finite())
    {
        return Err(IdentifyError::InvalidInput(format!(
            "sample {i} is not finite (velocity {}, error {})",
            qd[i], e[i]
        )));
    }
    Ok(())
}

fn min_max(values: &[f64]) -> (f64, f64) {
    values
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        })
}
