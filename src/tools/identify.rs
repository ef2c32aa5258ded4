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

pub use crate::rt::record::{EXTRA_COLUMN_PREFIX, LOG_COLUMNS, LOG_HEADER};

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

// ---------------------------------------------------------------------------------------------
// Log reading and writing
// ---------------------------------------------------------------------------------------------

/// The parsed header: the name of every field and, for known columns, its index in
/// [`LOG_COLUMNS`].
struct Header {
    names: Vec<String>,
    slots: Vec<Option<usize>>,
}

fn parse_header(text: &str, line: usize) -> Result<Header, IdentifyError> {
    let mut names = Vec::new();
    let mut slots = Vec::new();
    let mut seen = [false; LOG_COLUMNS.len()];
    for (position, raw) in text.split(',').enumerate() {
        let name = raw.trim();
        if name.is_empty() {
            return Err(IdentifyError::BadHeader {
                line,
                message: format!("column {} has an empty name", position + 1),
            });
        }
        if names.iter().any(|n| n == name) {
            return Err(IdentifyError::BadHeader {
                line,
                message: format!("column `{name}` appears twice"),
            });
        }
        let slot = LOG_COLUMNS.iter().position(|c| *c == name);
        match slot {
            Some(index) => seen[index] = true,
            None if name.starts_with(EXTRA_COLUMN_PREFIX) => {}
            None => {
                return Err(IdentifyError::UnknownColumn {
                    line,
                    column: name.to_owned(),
                });
            }
        }
        names.push(name.to_owned());
        slots.push(slot);
    }
    if let Some(missing) = seen.iter().position(|s| !s) {
        return Err(IdentifyError::MissingColumn {
            line,
            column: LOG_COLUMNS[missing],
        });
    }
    Ok(Header { names, slots })
}

fn parse_row(text: &str, line: usize, header: &Header) -> Result<LogRow, IdentifyError> {
    let expected = header.names.len();
    let mut row = LogRow::default();
    let mut found = 0;
    for (index, raw) in text.split(',').enumerate() {
        found = index + 1;
        if index >= expected {
            return Err(IdentifyError::ExtraField {
                line,
                found: text.split(',').count(),
                expected,
            });
        }
        let Some(slot) = header.slots[index] else {
            continue;
        };
        let value = raw.trim();
        let parsed: f64 = value.parse().map_err(|_| IdentifyError::BadNumber {
            line,
            column: header.names[index].clone(),
            value: value.to_owned(),
        })?;
        if !parsed.is_finite() {
            return Err(IdentifyError::NonFinite {
                line,
                column: header.names[index].clone(),
                value: value.to_owned(),
            });
        }
        *row.field_mut(slot) = parsed;
    }
    if found < expected {
        return Err(IdentifyError::MissingField {
            line,
            column: header.names[found].clone(),
            found,
            expected,
        });
    }
    Ok(row)
}

/// Reads a log in [the log format](self#log-format). A log with a header and no sample is valid
/// (and gives no row).
pub fn read_log<R: BufRead>(mut reader: R) -> Result<Vec<LogRow>, IdentifyError> {
    let mut buffer = String::new();
    let mut line = 0;
    let mut header: Option<Header> = None;
    let mut rows = Vec::new();
    loop {
        buffer.clear();
        let read = reader
            .read_line(&mut buffer)
            .map_err(|source| IdentifyError::Read {
                line: line + 1,
                source,
            })?;
        if read == 0 {
            break;
        }
        line += 1;
        let text = buffer.trim();
        if text.is_empty() || text.starts_with('#') {
            continue;
        }
        match &header {
            None => header = Some(parse_header(text, line)?),
            Some(h) => rows.push(parse_row(text, line, h)?),
        }
    }
    if header.is_none() {
        return Err(IdentifyError::MissingHeader);
    }
    Ok(rows)
}

/// Opens and reads a log file (see [`read_log`]).
pub fn read_log_file(path: impl AsRef<Path>) -> Result<Vec<LogRow>, IdentifyError> {
    let path = path.as_ref();
    let file = std::fs::File::open(path).map_err(|source| IdentifyError::Open {
        path: path.to_owned(),
        source,
    })?;
    read_log(io::BufReader::new(file))
}

/// Writes the header line [`LOG_HEADER`].
pub fn write_header<W: Write + ?Sized>(writer: &mut W) -> io::Result<()> {
    writer.write_all(LOG_HEADER.as_bytes())?;
    writer.write_all(b"\n")
}

/// Writes one sample, in the column order of [`LOG_HEADER`], with the shortest representation
/// that reads back bit-identically. Does not allocate (the formatting goes straight to
/// `writer`; wrap it in a `BufWriter` on a recording thread). Non-finite values are written as
/// `NaN`/`inf` but [`read_log`] rejects them.
pub fn write_row<W: Write + ?Sized>(writer: &mut W, row: &LogRow) -> io::Result<()> {
    writeln!(
        writer,
        "{},{},{},{},{},{},{},{},{}",
        row.t, row.q, row.qd, row.qdd, row.tau_ff, row.stiffness, row.damping, row.q_d, row.qd_d
    )
}

/// Writes a header and all rows.
pub fn write_log<W: Write + ?Sized>(writer: &mut W, rows: &[LogRow]) -> io::Result<()> {
    write_header(writer)?;
    for row in rows {
        write_row(writer, row)?;
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Torque error
// ---------------------------------------------------------------------------------------------

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
    pub points: usize,
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
fn polyfit_weighted(
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

// ---------------------------------------------------------------------------------------------
// Maximum-likelihood noise model
// ---------------------------------------------------------------------------------------------

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
    pub neg_log_likelihood: f64,
    /// Number of samples.
    pub samples: usize,
    /// Smallest modelled standard deviation, [`STD_FLOOR`]` · √(a² + (b q̇_max)²)`.
    pub std_floor: f64,
}

impl NoiseFit {
    /// Standard deviation of the error predicted at velocity `qd`: `|a + b q̇|` (at least
    /// [`NoiseFit::std_floor`]).
    pub fn std_at(&self, qd: f64) -> f64 {
        (self.a + self.b * qd).abs().max(self.std_floor)
    }

    /// The normalised residual `η = e / (a + b q̇)` (the denominator at least
    /// [`NoiseFit::std_floor`] in magnitude, with its sign).
    pub fn eta(&self, qd: f64, e: f64) -> f64 {
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
pub const STD_FLOOR: f64 = 1e-3;

/// Number of directions of the coarse grid of [`minimise_over_direction`].
const COARSE_DIRECTIONS: usize = 4096;

/// At most this many samples (evenly strided) are used on the coarse grid of the
/// maximum-likelihood fit; the refinement uses all of them.
const COARSE_SAMPLES: usize = 20_000;

/// Minimises `fine(θ)` over the directions `θ ∈ [0, π)`: the best of [`COARSE_DIRECTIONS`]
/// equally spaced directions for `coarse` (a cheaper approximation of `fine`, or `fine`
/// itself), then nested grids of `fine`, each 10 times finer (±4 coarse spacings first, then ±2
/// spacings of the previous level, centre included so that the value never increases), down to
/// 1e-14 rad. Returns the best direction and `fine` there.
fn minimise_over_direction(coarse: impl Fn(f64) -> f64, fine: impl Fn(f64) -> f64) -> (f64, f64) {
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
fn profile_nll(theta: f64, q: &[f64], e2: &[f64]) -> (f64, f64) {
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
fn scaled_velocities(qd: &[f64], e: &[f64]) -> Result<(Vec<f64>, f64), IdentifyError> {
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
fn from_polar(r: f64, theta: f64, v_scale: f64) -> (f64, f64) {
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
    pub n: usize,
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

// ---------------------------------------------------------------------------------------------
// The whole procedure
// ---------------------------------------------------------------------------------------------

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
    pub joint: Option<JointParams>,
    /// Options used.
    pub options: IdentifyOptions,
    /// Smallest and largest velocity (rad/s).
    pub velocity_range: [f64; 2],
    /// Mean of the torque error over all samples.
    pub error_mean: f64,
    /// Standard deviation of the torque error over all samples.
    pub error_std: f64,
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
    pub jarque_bera: JarqueBera,
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
