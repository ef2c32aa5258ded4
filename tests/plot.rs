//! The figures render to PNG and SVG from synthetic Monte Carlo trials, with no system fonts.

use std::path::{Path, PathBuf};

use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use vic::views::plot::{ColumnPlot, arm_figure, joint_figure};

const KNOTS: usize = 61;
const TRIALS: usize = 20;
const L1: f64 = 0.30;
const L2: f64 = 0.33;

/// A fresh directory under the system temp dir, removed on drop.
struct TempDir(PathBuf);

impl TempDir {
    fn new(tag: &str) -> TempDir {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos());
        let dir =
            std::env::temp_dir().join(format!("vic-plot-{tag}-{}-{nanos}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        TempDir(dir)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Joint angles of the two-link arm reaching `hand` (elbow up).
fn inverse_kinematics(hand: [f64; 2]) -> [f64; 2] {
    let (x, y) = (hand[0], hand[1]);
    let c2 = ((x * x + y * y - L1 * L1 - L2 * L2) / (2.0 * L1 * L2)).clamp(-1.0, 1.0);
    let q2 = c2.acos();
    let q1 = y.atan2(x) - (L2 * q2.sin()).atan2(L1 + L2 * c2);
    [q1, q2]
}

/// Smooth 0 → 1 (minimum jerk).
fn s_curve(s: f64) -> f64 {
    s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)
}

/// `TRIALS` noisy reaches from (0, 0.31) to (0, 0.56) m; the lateral noise grows as `spread`
/// times a random walk. Stiffness commands when `stiffness`.
fn arm_column(title: &str, spread: f64, stiffness: bool, rng: &mut StdRng) -> ColumnPlot {
    let duration = 0.6;
    let time: Vec<f64> = (0..KNOTS)
        .map(|k| duration * k as f64 / (KNOTS - 1) as f64)
        .collect();
    let reference_hand: Vec<[f64; 2]> = time
        .iter()
        .map(|t| [0.0, 0.31 + 0.25 * s_curve(t / duration)])
        .collect();
    let reference_q: Vec<Vec<f64>> = reference_hand
        .iter()
        .map(|&p| inverse_kinematics(p).to_vec())
        .collect();
    let mut hand = Vec::new();
    let mut q = Vec::new();
    let mut qd = Vec::new();
    for _ in 0..TRIALS {
        let mut drift = [0.0, 0.0];
        let mut path = Vec::with_capacity(KNOTS);
        for p in &reference_hand {
            let e: [f64; 2] = [rng.sample(StandardNormal), rng.sample(StandardNormal)];
            drift[0] += spread * e[0];
            drift[1] += 0.3 * spread * e[1];
            path.push([p[0] + drift[0], p[1] + drift[1]]);
        }
        let angles: Vec<Vec<f64>> = path
            .iter()
            .map(|&p| inverse_kinematics(p).to_vec())
            .collect();
        let dt = time[1] - time[0];
        let velocities: Vec<Vec<f64>> = (0..KNOTS)
            .map(|k| {
                let (a, b) = (k.saturating_sub(1), (k + 1).min(KNOTS - 1));
                (0..2)
                    .map(|j| (angles[b][j] - angles[a][j]) / ((b - a) as f64 * dt))
                    .collect()
            })
            .collect();
        hand.push(path);
        q.push(angles);
        qd.push(velocities);
    }
    let plan: Vec<Vec<f64>> = (0..KNOTS - 1)
        .map(|k| {
            let s = time[k] / duration;
            let mut u = vec![
                2.0 * (std::f64::consts::TAU * s).sin(),
                -1.2 * (std::f64::consts::TAU * s).sin() + 0.3,
            ];
            if stiffness {
                u.extend([10.0 + 20.0 * s_curve(s), 5.0 + 8.0 * s]);
            }
            u
        })
        .collect();
    let mut control_names = vec!["tau1".to_string(), "tau2".to_string()];
    if stiffness {
        control_names.extend(["k1".to_string(), "k2".to_string()]);
    }
    let ends: Vec<[f64; 2]> = hand.iter().map(|h| h[KNOTS - 1]).collect();
    let mean = [
        ends.iter().map(|p| p[0]).sum::<f64>() / TRIALS as f64,
        ends.iter().map(|p| p[1]).sum::<f64>() / TRIALS as f64,
    ];
    let sx = (ends.iter().map(|p| (p[0] - mean[0]).powi(2)).sum::<f64>() / 19.0).sqrt();
    let sy = (ends.iter().map(|p| (p[1] - mean[1]).powi(2)).sum::<f64>() / 19.0).sqrt();
    ColumnPlot {
        title: title.to_string(),
        time,
        dof: 2,
        hand,
        q,
        qd,
        u: vec![plan; TRIALS],
        control_names,
        reference_hand,
        reference_q,
        ellipse: Some((mean, [2.45 * sx, 2.45 * sy], 0.0)),
        dashed_ellipse: None,
        diverged: Vec::new(),
    }
}

fn arm_columns() -> Vec<ColumnPlot> {
    let mut rng = StdRng::seed_from_u64(7);
    let mut columns = vec![
        arm_column("Deterministic", 0.0, false, &mut rng),
        arm_column("Torque only", 0.004, false, &mut rng),
        arm_column("Torque + stiffness", 0.0008, true, &mut rng),
        arm_column("VSA", 0.0012, true, &mut rng),
    ];
    // A diverging trial and a few non-finite values must neither panic nor squash the view.
    columns[1].hand[0] = columns[1].hand[0]
        .iter()
        .enumerate()
        .map(|(k, p)| [p[0] + 0.05 * (k as f64 / 6.0).exp(), p[1]])
        .collect();
    columns[1].diverged = vec![true];
    columns[1].hand[1][30] = [f64::NAN, 0.4];
    columns[1].q[1][30][0] = f64::INFINITY;
    let ellipse = columns[3].ellipse.unwrap();
    columns[3].dashed_ellipse = Some((ellipse.0, [ellipse.1[0] * 0.5, ellipse.1[1] * 0.5], 0.3));
    columns
}

/// A single joint from 0 to 1 rad in 0.5 s; feedback-like commands differ per trial.
fn joint_column(title: &str, noise: f64, stiffness: bool, rng: &mut StdRng) -> ColumnPlot {
    let duration = 0.5;
    let time: Vec<f64> = (0..51).map(|k| duration * k as f64 / 50.0).collect();
    let reference: Vec<f64> = time.iter().map(|t| s_curve(t / duration)).collect();
    let mut q = Vec::new();
    let mut qd = Vec::new();
    let mut u = Vec::new();
    for _ in 0..TRIALS {
        let phase: f64 = rng.random::<f64>();
        let amplitude = noise * rng.sample::<f64, _>(StandardNormal);
        let angles: Vec<f64> = time
            .iter()
            .zip(&reference)
            .map(|(t, r)| r + amplitude * (20.0 * t + phase).sin() * t)
            .collect();
        q.push(angles.iter().map(|&a| vec![a]).collect::<Vec<_>>());
        qd.push(
            (0..time.len())
                .map(|k| {
                    let (a, b) = (k.saturating_sub(1), (k + 1).min(time.len() - 1));
                    vec![(angles[b] - angles[a]) / (time[b] - time[a])]
                })
                .collect::<Vec<_>>(),
        );
        u.push(
            (0..time.len() - 1)
                .map(|k| {
                    let s = time[k] / duration;
                    let mut c = vec![
                        3.0 * (std::f64::consts::TAU * s).sin() - 5.0 * (angles[k] - reference[k]),
                    ];
                    if stiffness {
                        c.push(4.0 + 6.0 * s_curve(s));
                    }
                    c
                })
                .collect::<Vec<_>>(),
        );
    }
    ColumnPlot {
        title: title.to_string(),
        dof: 1,
        reference_q: reference.iter().map(|&r| vec![r]).collect(),
        time,
        hand: Vec::new(),
        q,
        qd,
        u,
        control_names: if stiffness {
            vec!["tau".to_string(), "k".to_string()]
        } else {
            vec!["tau".to_string()]
        },
        reference_hand: Vec::new(),
        ellipse: None,
        dashed_ellipse: None,
        diverged: Vec::new(),
    }
}

fn joint_columns() -> Vec<ColumnPlot> {
    let mut rng = StdRng::seed_from_u64(11);
    vec![
        joint_column("Feedforward, no delay", 0.02, true, &mut rng),
        joint_column("Feedback, 200 ms, no stiffness", 0.4, false, &mut rng),
        joint_column("Feedforward + stiffness, 200 ms", 0.05, true, &mut rng),
    ]
}

/// Width and height from the PNG's IHDR chunk.
fn png_size(path: &Path) -> (u32, u32) {
    let bytes = std::fs::read(path).unwrap();
    assert!(
        bytes.len() > 10_000,
        "{} is only {} bytes",
        path.display(),
        bytes.len()
    );
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "PNG signature");
    assert_eq!(&bytes[12..16], b"IHDR");
    let word = |i: usize| u32::from_be_bytes(bytes[i..i + 4].try_into().unwrap());
    (word(16), word(20))
}

fn check_svg(path: &Path, titles: &[&str]) {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(
        text.len() > 10_000,
        "{} is only {} bytes",
        path.display(),
        text.len()
    );
    let start = text.trim_start();
    assert!(start.starts_with("<svg") || start.starts_with("<?xml"));
    assert!(text.trim_end().ends_with("</svg>"));
    // Text elements' contents, e.g. `<text x=".." ..>\nTitle\n</text>`.
    let texts: Vec<&str> = text
        .split("<text")
        .skip(1)
        .filter_map(|t| Some(t.split_once('>')?.1.split_once("</text>")?.0.trim()))
        .collect();
    for title in titles {
        assert!(
            texts.contains(title),
            "title {title:?} missing from the text elements {texts:?}"
        );
    }
}

#[test]
fn arm_figure_renders_png_and_svg() {
    let dir = TempDir::new("arm");
    let (png, svg) = (dir.0.join("fig1.png"), dir.0.join("fig1.svg"));
    let columns = arm_columns();
    arm_figure(&columns, &png, &svg).unwrap();
    let (w, h) = png_size(&png);
    assert_eq!(w, 28 + 400 * 4);
    assert!((900..=1200).contains(&h), "height {h}");
    let mut titles: Vec<&str> = columns.iter().map(|c| c.title.as_str()).collect();
    // The diverging trial is counted under its column's title.
    titles.push("1 of 20 trials diverged (dashed), ellipse of the other 19");
    check_svg(&svg, &titles);
    if let Ok(out) = std::env::var("VIC_PLOT_CHECK") {
        arm_figure(&columns, Path::new(&out), &dir.0.join("check.svg")).unwrap();
    }
}

#[test]
fn joint_figure_renders_png_and_svg() {
    let dir = TempDir::new("joint");
    let (png, svg) = (dir.0.join("fig2.png"), dir.0.join("fig2.svg"));
    let columns = joint_columns();
    joint_figure(&columns, &png, &svg).unwrap();
    let (w, h) = png_size(&png);
    assert_eq!(w, 28 + 400 * 3);
    assert!((900..=1200).contains(&h), "height {h}");
    let titles: Vec<&str> = columns.iter().map(|c| c.title.as_str()).collect();
    check_svg(&svg, &titles);
    if let Ok(out) = std::env::var("VIC_PLOT_CHECK_JOINT") {
        joint_figure(&columns, Path::new(&out), &dir.0.join("check.svg")).unwrap();
    }
}

#[test]
fn empty_input_is_an_error_not_a_panic() {
    let dir = TempDir::new("empty");
    let (png, svg) = (dir.0.join("e.png"), dir.0.join("e.svg"));
    assert!(arm_figure(&[], &png, &svg).is_err());
    let column = ColumnPlot {
        title: "nothing".into(),
        time: vec![0.0, 0.1],
        dof: 2,
        ..Default::default()
    };
    // Trials missing altogether still render (empty panels).
    arm_figure(std::slice::from_ref(&column), &png, &svg).unwrap();
    joint_figure(std::slice::from_ref(&column), &png, &svg).unwrap();
}

#[test]
fn unwritable_path_reports_the_path() {
    let missing = std::env::temp_dir().join("vic-plot-no-such-dir-4242/sub");
    let err = joint_figure(
        &joint_columns(),
        &missing.join("a.png"),
        &missing.join("a.svg"),
    )
    .unwrap_err();
    assert!(err.to_string().contains("a.png"), "{err}");
}
