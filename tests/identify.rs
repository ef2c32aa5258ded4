//! Noise identification (paper §III-B, Fig. 3a): the CSV log format, the polynomial fits, the
//! maximum-likelihood `(a, b)` of `e = (a + b q̇) η` and the Jarque–Bera test.

use vic::studies::identify;

use identify::*;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Exp1, StandardNormal};

const A: f64 = 0.15;
const B: f64 = 0.37;

/// Velocities uniform over ±2 rad/s and errors `(A + B q̇) η`, `η ~ N(0, 1)`.
fn synthetic_errors(n: usize, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let mut rng = StdRng::seed_from_u64(seed);
    let qd: Vec<f64> = (0..n).map(|_| rng.random_range(-2.0..2.0)).collect();
    let e = qd
        .iter()
        .map(|&v| {
            let eta: f64 = rng.sample(StandardNormal);
            (A + B * v) * eta
        })
        .collect();
    (qd, e)
}

/// Log rows whose torque error (for `joint`) is `e`: random states, gains and targets, with the
/// feedforward torque chosen so that Eq. 15 plus `e` holds.
fn synthetic_rows(qd: &[f64], e: &[f64], joint: &JointParams, seed: u64) -> Vec<LogRow> {
    let mut rng = StdRng::seed_from_u64(seed);
    qd.iter()
        .zip(e)
        .enumerate()
        .map(|(i, (&qd, &e))| {
            let q: f64 = rng.random_range(-1.5..0.5);
            let qdd = rng.random_range(-20.0..20.0);
            let stiffness = rng.random_range(0.0..5.0);
            let damping = 0.2 * stiffness;
            let q_d = q + rng.random_range(-0.2..0.2);
            let qd_d = qd + rng.random_range(-0.5..0.5);
            let tau_ff = joint.inertia * qdd
                + joint.mass * joint.gravity * joint.com * q.cos()
                + stiffness * (q - q_d)
                + damping * (qd - qd_d)
                + e;
            LogRow {
                t: i as f64 * 0.01,
                q,
                qd,
                qdd,
                tau_ff,
                stiffness,
                damping,
                q_d,
                qd_d,
            }
        })
        .collect()
}

fn assert_within(estimate: f64, truth: f64, relative: f64, what: &str) {
    let error = (estimate - truth).abs() / truth.abs();
    assert!(
        error <= relative,
        "{what}: estimate {estimate} vs truth {truth} (relative error {error:.4})"
    );
}

#[test]
fn ml_recovers_known_a_b_within_5_percent() {
    for seed in [1, 2, 3] {
        let (qd, e) = synthetic_errors(20_000, seed);
        let fit = fit_noise_ml(&qd, &e).unwrap();
        assert_within(fit.a, A, 0.05, "a");
        assert_within(fit.b, B, 0.05, "b");
        // The standard errors are consistent with the actual errors.
        assert!((fit.a - A).abs() < 5.0 * fit.a_std_error.unwrap());
        assert!((fit.b - B).abs() < 5.0 * fit.b_std_error.unwrap());
    }
}

#[test]
fn moment_fit_recovers_known_a_b() {
    let (qd, e) = synthetic_errors(20_000, 4);
    let fit = fit_noise_moments(&qd, &e).unwrap();
    assert_within(fit.a, A, 0.1, "a");
    assert_within(fit.b, B, 0.1, "b");
}

#[test]
fn ml_sign_convention_and_pure_additive_noise() {
    // (a, b) and (−a, −b) are the same model: the fit reports a ≥ 0.
    let (qd, e) = synthetic_errors(5_000, 7);
    let negated: Vec<f64> = e.iter().map(|v| -v).collect();
    let fit = fit_noise_ml(&qd, &negated).unwrap();
    assert!(fit.a > 0.0 && fit.b > 0.0, "{fit:?}");

    // b = 0: purely additive noise.
    let mut rng = StdRng::seed_from_u64(8);
    let e: Vec<f64> = qd
        .iter()
        .map(|_| 0.2 * rng.sample::<f64, _>(StandardNormal))
        .collect();
    let fit = fit_noise_ml(&qd, &e).unwrap();
    assert_within(fit.a, 0.2, 0.05, "a");
    assert!(fit.b.abs() < 0.01, "b = {}", fit.b);
}

#[test]
fn identify_on_a_synthetic_log_recovers_a_b_and_accepts_normality() {
    let joint = JointParams::ICUB_FOREARM;
    let (qd, e) = synthetic_errors(20_000, 11);
    let rows = synthetic_rows(&qd, &e, &joint, 12);

    // Through the CSV format, as `vic identify --log` does.
    let mut csv = Vec::new();
    write_log(&mut csv, &rows).unwrap();
    let read = read_log(csv.as_slice()).unwrap();
    let report = identify(&read, &joint, &IdentifyOptions::default()).unwrap();

    assert_eq!(report.n, 20_000);
    assert_within(report.noise.a, A, 0.05, "a");
    assert_within(report.noise.b, B, 0.05, "b");
    assert!(report.normal_at_5_percent, "{report}");
    assert_eq!(report.bins.len(), 20);
    // Zero-mean noise: the mean fit is flat.
    for c in &report.mean_fit.polynomial.coefficients {
        assert!(c.abs() < 0.02, "mean fit {}", report.mean_fit.polynomial);
    }
    // σ_e = |a + b q̇| is V-shaped: the quadratic fit opens upwards.
    assert_eq!(report.std_fit.polynomial.degree(), 2);
    assert!(report.std_fit.polynomial.coefficients[2] > 0.0);
    // The per-bin standard deviation follows |a + b q̇| (bins are 0.2 rad/s wide).
    for bin in &report.bins {
        let predicted = report.noise.std_at(bin.velocity);
        assert!(
            (bin.std - predicted).abs() < 0.1 * predicted + 0.05,
            "bin at {}: std {} vs |a + b q'| {}",
            bin.velocity,
            bin.std,
            predicted
        );
    }
    // The report serialises, and prints.
    let json = serde_json::to_value(&report).unwrap();
    assert_eq!(json["normal_at_5_percent"], true);
    assert!(json["noise"]["a"].is_f64());
    assert!(json["jarque_bera"]["p_value"].is_f64());
    assert!(report.to_string().contains("Jarque-Bera"));
}

#[test]
fn a_wrong_noise_model_is_rejected_by_jarque_bera() {
    // Errors whose η is uniform (not normal): the fit still runs, the test rejects.
    let mut rng = StdRng::seed_from_u64(21);
    let qd: Vec<f64> = (0..5_000).map(|_| rng.random_range(-2.0..2.0)).collect();
    let e: Vec<f64> = qd
        .iter()
        .map(|&v| (A + B * v) * rng.random_range(-1.7..1.7))
        .collect();
    let report = identify_samples(&qd, &e, &IdentifyOptions::default()).unwrap();
    assert!(!report.normal_at_5_percent, "{report}");
}

#[test]
fn subtracting_the_mean_fit_handles_a_biased_error() {
    // The mean of Fig. 3, ē = 0.213 q̇ − 0.049, added to the noise.
    let biased = |seed| {
        let (qd, mut e) = synthetic_errors(20_000, seed);
        for (err, &v) in e.iter_mut().zip(&qd) {
            *err += 0.213 * v - 0.049;
        }
        (qd, e)
    };
    let options = IdentifyOptions {
        subtract_mean: true,
        ..IdentifyOptions::default()
    };
    for seed in [31, 32, 33] {
        let (qd, e) = biased(seed);
        let report = identify_samples(&qd, &e, &options).unwrap();
        let mean = &report.mean_fit.polynomial.coefficients;
        assert!(
            (mean[0] + 0.049).abs() < 0.02 && (mean[1] - 0.213).abs() < 0.02,
            "{report}"
        );
        let subtracted = &report.subtracted_mean.as_ref().unwrap().coefficients;
        assert!(
            (subtracted[0] + 0.049).abs() < 0.005 && (subtracted[1] - 0.213).abs() < 0.005,
            "{report}"
        );
        assert_within(report.noise.a, A, 0.05, "a");
        assert_within(report.noise.b, B, 0.05, "b");
        assert_within(report.noise_moments.a, A, 0.1, "moment a");
        assert_within(report.noise_moments.b, B, 0.1, "moment b");
    }
    // Without the subtraction the zero-mean model does not fit: normality is rejected.
    let (qd, e) = biased(34);
    let report = identify_samples(&qd, &e, &IdentifyOptions::default()).unwrap();
    assert!(report.subtracted_mean.is_none());
    assert!(!report.normal_at_5_percent, "{report}");
}

#[test]
fn jarque_bera_accepts_a_normal_sample() {
    let mut rng = StdRng::seed_from_u64(41);
    let x: Vec<f64> = (0..2_000)
        .map(|_| 3.0 + 0.5 * rng.sample::<f64, _>(StandardNormal))
        .collect();
    let jb = jarque_bera(&x).unwrap();
    assert!(!jb.rejects_normality(0.05), "{jb:?}");
    assert!((jb.kurtosis - 3.0).abs() < 0.3 && jb.skewness.abs() < 0.2);
}

#[test]
fn jarque_bera_rejects_uniform_and_exponential_samples() {
    let mut rng = StdRng::seed_from_u64(42);
    let uniform: Vec<f64> = (0..2_000).map(|_| rng.random_range(0.0..1.0)).collect();
    let jb = jarque_bera(&uniform).unwrap();
    assert!(jb.rejects_normality(0.05), "{jb:?}");
    assert!((jb.kurtosis - 1.8).abs() < 0.1, "{jb:?}");

    let exponential: Vec<f64> = (0..2_000).map(|_| rng.sample(Exp1)).collect();
    let jb = jarque_bera(&exponential).unwrap();
    assert!(jb.rejects_normality(0.05), "{jb:?}");
    assert!(jb.p_value < 1e-10 && jb.skewness > 1.5, "{jb:?}");
}

#[test]
fn jarque_bera_has_about_the_nominal_size() {
    // Under normality, p < 0.05 about 5 % of the time (asymptotic χ²(2) with n = 2000).
    let mut rng = StdRng::seed_from_u64(43);
    let trials = 400;
    let rejections = (0..trials)
        .filter(|_| {
            let x: Vec<f64> = (0..2_000).map(|_| rng.sample(StandardNormal)).collect();
            jarque_bera(&x).unwrap().rejects_normality(0.05)
        })
        .count();
    assert!((6..=36).contains(&rejections), "{rejections} of {trials}");
}

#[test]
fn jarque_bera_statistic_and_p_value_by_hand() {
    // x = (0, 0, 0, 1): mean 1/4, m2 = 3/16, m3 = 3/32, m4 = 21/256.
    let jb = jarque_bera(&[0.0, 0.0, 0.0, 1.0]).unwrap();
    let s: f64 = (3.0 / 32.0) / (3.0_f64 / 16.0).powf(1.5);
    let k: f64 = (21.0 / 256.0) / (3.0_f64 / 16.0).powi(2);
    let statistic = 4.0 / 6.0 * (s * s + (k - 3.0).powi(2) / 4.0);
    assert!((jb.skewness - s).abs() < 1e-12 && (jb.kurtosis - k).abs() < 1e-12);
    assert!((jb.statistic - statistic).abs() < 1e-12);
    assert!((jb.p_value - (-statistic / 2.0).exp()).abs() < 1e-15);
    assert_eq!(chi2_2dof_sf(0.0), 1.0);
    assert!((chi2_2dof_sf(5.991464547107979) - 0.05).abs() < 1e-12);
    assert!(jarque_bera(&[1.0, 1.0, 1.0]).is_err());
}

#[test]
fn polyfit_recovers_exact_polynomials() {
    // The σ_e fit of Fig. 3, at 15 velocities, and an offset cubic.
    let x: Vec<f64> = (0..15).map(|i| -1.0 + 0.21 * i as f64).collect();
    let sigma = |v: f64| 1.254 * v * v - 0.351 * v + 0.057;
    let y: Vec<f64> = x.iter().map(|&v| sigma(v)).collect();
    let fit = polyfit(&x, &y, 2).unwrap();
    for (c, truth) in fit
        .polynomial
        .coefficients
        .iter()
        .zip([0.057, -0.351, 1.254])
    {
        assert!((c - truth).abs() < 1e-10, "{}", fit.polynomial);
    }
    assert!(fit.rms_residual < 1e-10 && (fit.r_squared - 1.0).abs() < 1e-12);
    assert_eq!(
        fit.polynomial.to_string(),
        "1.2540 q'^2 - 0.3510 q' + 0.0570"
    );
    assert_eq!(
        format!("{:.3}", fit.polynomial),
        "1.254 q'^2 - 0.351 q' + 0.057"
    );

    let cubic = [2.0, -0.5, 0.25, -0.125];
    let x: Vec<f64> = (0..30).map(|i| 10.0 + 0.1 * i as f64).collect();
    let p = Polynomial {
        coefficients: cubic.to_vec(),
    };
    let y: Vec<f64> = x.iter().map(|&v| p.eval(v)).collect();
    let fit = polyfit(&x, &y, 3).unwrap();
    for (c, truth) in fit.polynomial.coefficients.iter().zip(cubic) {
        assert!((c - truth).abs() < 1e-6 * truth.abs().max(1.0), "{fit:?}");
    }

    // A degree-1 fit of noisy-free linear data through a higher degree: extra terms vanish.
    let x: Vec<f64> = (0..10).map(f64::from).collect();
    let y: Vec<f64> = x.iter().map(|v| 0.213 * v - 0.049).collect();
    let fit = polyfit(&x, &y, 3).unwrap();
    assert!(fit.polynomial.coefficients[2].abs() < 1e-10);
    assert!(fit.polynomial.coefficients[3].abs() < 1e-10);

    // Too few (distinct) points.
    assert!(polyfit(&[1.0, 2.0], &[1.0, 2.0], 2).is_err());
    assert!(polyfit(&[1.0, 1.0, 1.0], &[1.0, 2.0, 3.0], 1).is_err());
}

#[test]
fn binning_computes_per_bin_mean_and_std() {
    // Two bins: velocities in [0, 1) and [1, 2].
    let qd = [0.0, 0.5, 0.9, 1.1, 1.5, 2.0];
    let e = [1.0, 2.0, 3.0, -1.0, 1.0, 3.0];
    let bins = bin_by_velocity(&qd, &e, 2, 2).unwrap();
    assert_eq!(bins.len(), 2);
    assert_eq!((bins[0].lo, bins[0].hi, bins[0].count), (0.0, 1.0, 3));
    assert_eq!((bins[1].lo, bins[1].hi, bins[1].count), (1.0, 2.0, 3));
    assert!((bins[0].mean - 2.0).abs() < 1e-15 && (bins[0].std - 1.0).abs() < 1e-15);
    assert!((bins[1].mean - 1.0).abs() < 1e-15 && (bins[1].std - 2.0).abs() < 1e-15);
    assert!((bins[1].velocity - 1.5333333333333334).abs() < 1e-12);
    // Sparse bins are dropped.
    assert_eq!(bin_by_velocity(&qd, &e, 2, 4).unwrap().len(), 0);
}

#[test]
fn torque_error_follows_the_paper() {
    let joint = JointParams::ICUB_FOREARM;
    let row = LogRow {
        t: 0.0,
        q: 0.3,
        qd: 1.0,
        qdd: 2.0,
        tau_ff: 1.5,
        stiffness: 4.0,
        damping: 0.8,
        q_d: 0.1,
        qd_d: 0.5,
    };
    let expected = -5.08e-3 * 2.0 - 0.812 * 9.81 * 0.103 * 0.3_f64.cos() + 1.5
        - 4.0 * (0.3 - 0.1)
        - 0.8 * (1.0 - 0.5);
    assert!((torque_error(&row, &joint) - expected).abs() < 1e-15);
}

#[test]
fn csv_round_trips_bit_for_bit() {
    let mut rng = StdRng::seed_from_u64(51);
    let mut rows: Vec<LogRow> = (0..500)
        .map(|i| LogRow {
            t: i as f64 * 0.001,
            q: rng.random_range(-3.0..3.0),
            qd: rng.sample(StandardNormal),
            qdd: 100.0 * rng.sample::<f64, _>(StandardNormal),
            tau_ff: rng.random_range(-1.0..1.0),
            stiffness: rng.random_range(0.0..10.0),
            damping: 1e-300 * rng.random_range(0.0..1.0),
            q_d: -0.0,
            qd_d: 1e20 * rng.random_range(-1.0..1.0),
        })
        .collect();
    rows.push(LogRow::default());
    let mut csv = Vec::new();
    write_log(&mut csv, &rows).unwrap();
    let text = String::from_utf8(csv).unwrap();
    assert!(text.starts_with(&format!("{LOG_HEADER}\n")));
    assert_eq!(LOG_HEADER, LOG_COLUMNS.join(","));
    let read = read_log(text.as_bytes()).unwrap();
    assert_eq!(read.len(), rows.len());
    for (a, b) in read.iter().zip(&rows) {
        assert_eq!(a, b);
        assert_eq!(a.qd.to_bits(), b.qd.to_bits());
        assert_eq!(a.q_d.to_bits(), b.q_d.to_bits());
    }
}

#[test]
fn csv_accepts_reordered_and_extra_columns_comments_and_blank_lines() {
    let text = "# vic joint log v1\n\
                \n\
                qd_d, q_d ,damping,stiffness,tau_ff,qdd,qd,q,t,x_current\n\
                9,8,7,6,5,4,3,2,1,0.5\r\n\
                # a comment between samples\n\
                \n\
                -9,-8,-7,-6,-5,-4,-3,-2,-1,abc\n";
    let rows = read_log(text.as_bytes()).unwrap();
    assert_eq!(rows.len(), 2);
    assert_eq!(
        rows[0],
        LogRow {
            t: 1.0,
            q: 2.0,
            qd: 3.0,
            qdd: 4.0,
            tau_ff: 5.0,
            stiffness: 6.0,
            damping: 7.0,
            q_d: 8.0,
            qd_d: 9.0,
        }
    );
    assert_eq!(rows[1].t, -1.0);
    // A header only is an empty log; nothing at all is an error.
    assert!(
        read_log(format!("{LOG_HEADER}\n").as_bytes())
            .unwrap()
            .is_empty()
    );
    assert!(matches!(
        read_log("# nothing\n".as_bytes()),
        Err(IdentifyError::MissingHeader)
    ));
}

fn read_error(text: &str) -> (IdentifyError, String) {
    let err = read_log(text.as_bytes()).unwrap_err();
    let message = err.to_string();
    (err, message)
}

#[test]
fn csv_errors_name_the_line_and_the_column() {
    // Missing column in the header.
    let (err, message) = read_error("t,q,qd,qdd,tau_ff,damping,q_d,qd_d\n0,0,0,0,0,0,0,0\n");
    assert!(
        matches!(
            err,
            IdentifyError::MissingColumn {
                line: 1,
                column: "stiffness"
            }
        ),
        "{err:?}"
    );
    assert!(
        message.contains("line 1") && message.contains("stiffness"),
        "{message}"
    );

    // Unknown column (after a comment line).
    let (err, message) = read_error("# log\nt,q,qd,qdd,tau_ff,stiffness,damping,q_d,qd_d,torque\n");
    assert!(
        matches!(err, IdentifyError::UnknownColumn { line: 2, .. }),
        "{err:?}"
    );
    assert!(
        message.contains("line 2") && message.contains("`torque`"),
        "{message}"
    );

    // Duplicate column.
    let (err, _) = read_error("t,q,qd,qdd,tau_ff,stiffness,damping,q_d,qd_d,q\n");
    assert!(
        matches!(err, IdentifyError::BadHeader { line: 1, .. }),
        "{err:?}"
    );

    // Non-number at line 7, column `tau_ff`.
    let mut text = format!("{LOG_HEADER}\n");
    for i in 0..5 {
        text.push_str(&format!("{i},0,0,0,0.5,1,0.2,0,0\n"));
    }
    text.push_str("5,0,0,0,oops,1,0.2,0,0\n");
    let (err, message) = read_error(&text);
    match &err {
        IdentifyError::BadNumber {
            line,
            column,
            value,
        } => {
            assert_eq!(
                (*line, column.as_str(), value.as_str()),
                (7, "tau_ff", "oops")
            );
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(message, "line 7, column `tau_ff`: `oops` is not a number");

    // Too few fields: names the first missing column.
    let (err, message) = read_error(&format!("{LOG_HEADER}\n0,0,0,0,0,0,0\n"));
    assert!(
        matches!(&err, IdentifyError::MissingField { line: 2, column, found: 7, expected: 9 } if column == "q_d"),
        "{err:?}"
    );
    assert!(
        message.contains("line 2") && message.contains("q_d"),
        "{message}"
    );

    // Too many fields.
    let (err, _) = read_error(&format!("{LOG_HEADER}\n0,0,0,0,0,0,0,0,0,0\n"));
    assert!(
        matches!(
            err,
            IdentifyError::ExtraField {
                line: 2,
                found: 10,
                expected: 9
            }
        ),
        "{err:?}"
    );

    // Empty field and non-finite values.
    let (err, _) = read_error(&format!("{LOG_HEADER}\n0,0,,0,0,0,0,0,0\n"));
    assert!(
        matches!(&err, IdentifyError::BadNumber { line: 2, column, .. } if column == "qd"),
        "{err:?}"
    );
    let (err, _) = read_error(&format!("{LOG_HEADER}\n\n\n0,NaN,0,0,0,0,0,0,0\n"));
    assert!(
        matches!(&err, IdentifyError::NonFinite { line: 4, column, .. } if column == "q"),
        "{err:?}"
    );
}

#[test]
fn identify_reports_too_few_bins() {
    let (qd, e) = synthetic_errors(100, 61);
    let err = identify_samples(&qd, &e, &IdentifyOptions::default()).unwrap_err();
    assert!(err.to_string().contains("bins"), "{err}");
    let options = IdentifyOptions {
        bins: 5,
        min_bin_count: 10,
        ..IdentifyOptions::default()
    };
    assert!(identify_samples(&qd, &e, &options).is_ok());
}
