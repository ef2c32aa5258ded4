//! Figures of the paper from Monte Carlo trials: Fig. 1 (two-link arm in a divergent field) and
//! Fig. 2 (single joint with feedback delays), written as PNG and SVG with `plotters`.
//!
//! Text is set in DejaVu Sans, embedded through the `dejavu` crate and registered with plotters'
//! `ab_glyph` renderer on first use, so rendering needs no system fonts.
//!
//! Conventions:
//! - Columns are conditions (actuator types, delays), side by side, each with its title on top.
//! - Rows that are compared across columns share their axes. Their ranges are robust: a column
//!   whose trials diverge far beyond the others does not widen the shared range, and its curves
//!   simply leave the frame (everything is clipped to the plotting area).
//! - Non-finite values are skipped: a curve breaks where a value is NaN or infinite.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::FontStyle;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// One column of a figure: Monte Carlo trials of one condition.
#[derive(Debug, Clone, Default)]
pub struct ColumnPlot {
    pub title: String,
    /// Knot times [s], N+1 values.
    pub time: Vec<f64>,
    /// Number of joints (1 or 2).
    pub dof: usize,
    /// Per trial, per knot: hand position (x, y) [m]; empty for a single joint.
    pub hand: Vec<Vec<[f64; 2]>>,
    /// Per trial, per knot: joint angles [rad] (dof values).
    pub q: Vec<Vec<Vec<f64>>>,
    /// Per trial, per knot: joint velocities [rad/s].
    pub qd: Vec<Vec<Vec<f64>>>,
    /// Per trial, per step (N values): executed commands, torques first then stiffnesses
    /// (`control_names` says which).
    pub u: Vec<Vec<Vec<f64>>>,
    pub control_names: Vec<String>,
    /// Reference hand path (per knot) for the arm, reference joint angles for a joint.
    pub reference_hand: Vec<[f64; 2]>,
    pub reference_q: Vec<Vec<f64>>,
    /// 95 % confidence ellipse of the final hand position: centre [m], semi-axes [m] (major first),
    /// major-axis angle [rad]; None for a joint. A second optional "dashed" ellipse (paper Fig. 1
    /// column 4 shows B/10 dashed) may be given.
    pub ellipse: Option<([f64; 2], [f64; 2], f64)>,
    pub dashed_ellipse: Option<([f64; 2], [f64; 2], f64)>,
}

/// Why a figure could not be written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// There is nothing to draw (no columns, or no knot times).
    #[error("cannot plot {path}: {reason}")]
    NoData { path: PathBuf, reason: String },
    /// Drawing failed (this includes encoding and writing the PNG).
    #[error("cannot draw {path}: {message}")]
    Draw { path: PathBuf, message: String },
    /// Writing the SVG failed.
    #[error("cannot write {path}: {source}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// Fig. 1 layout: columns side by side; row A: hand paths in the (x, y) plane (every trial light
/// grey, the mean thick, ±1 std shaded band across the path, the 95 % ellipse at the end, equal
/// axis scale, metres), row B: joint angles and velocities vs time (mean ± std shaded, both
/// joints, with the reference angles dashed), row C: the commands (torques, then stiffnesses
/// when any column has them; every trial, held over each step). Writes both PNG and SVG, each
/// `28 + 400 × columns` px wide and 1078 px tall (913 without stiffness commands).
///
/// `dashed_ellipse`, when given, is drawn dashed next to the solid 95 % ellipse. The legends sit
/// in the first column, in the panel corner with the fewest data.
///
/// The hand-path view is the same for all columns: the reference paths, plus the spread of the
/// trials of every column that does not diverge, plus a margin. Time rows share their y ranges.
pub fn arm_figure(columns: &[ColumnPlot], png: &Path, svg: &Path) -> Result<(), PlotError> {
    check_columns(columns, png)?;
    render(&ArmFigure::new(columns), png, svg)
}

/// Fig. 2 layout for a single joint: columns side by side; rows: angle [deg] of every trial with
/// the reference, velocity [deg/s] of every trial, commands (torque, stiffness) of every trial.
/// Rows share their y ranges across columns; a second stiffness panel is added to row C when any
/// column has stiffness commands. Writes both PNG and SVG, `28 + 400 × columns` px wide and 1003
/// px tall (768 without stiffness commands).
pub fn joint_figure(columns: &[ColumnPlot], png: &Path, svg: &Path) -> Result<(), PlotError> {
    check_columns(columns, png)?;
    render(&JointFigure::new(columns), png, svg)
}

// ---------------------------------------------------------------------------------------------
// Rendering to files

const FONT: &str = "sans-serif";
const COLUMN_WIDTH: u32 = 400;
/// Left strip holding the row letters A, B, C.
const GUTTER: u32 = 28;
const TITLE_SIZE: f64 = 17.0;
const TICK_SIZE: f64 = 12.0;
const DESC_SIZE: f64 = 13.0;
const Y_LABEL_AREA: u32 = 62;
const X_LABEL_AREA: u32 = 24;
const X_LABEL_AREA_DESC: u32 = 42;
/// More points than this per curve are thinned (a panel is < 400 px wide).
const MAX_POINTS: usize = 1500;
/// A column's spread larger than this many times the median column's is an outlier.
const OUTLIER_FACTOR: f64 = 4.0;
/// Tail fraction left out on each side when measuring a column's range of a time series (none:
/// a column's own trials all fit unless the column is an outlier).
const TAIL: f64 = 0.0;
/// Tail fraction left out on each side when measuring a column's spread of hand positions.
const HAND_TAIL: f64 = 0.025;
const RAD_TO_DEG: f64 = 180.0 / std::f64::consts::PI;

const TRIAL_GREY: RGBColor = RGBColor(190, 190, 190);
const MEAN_GREY: RGBColor = RGBColor(40, 40, 40);
const BAND_BLUE: RGBColor = RGBColor(70, 130, 200);
const ELLIPSE_RED: RGBColor = RGBColor(200, 30, 45);
const GRID: RGBColor = RGBColor(228, 228, 228);
/// Per joint (torque and stiffness of joint i share joint i's colour).
const JOINT_COLOURS: [RGBColor; 4] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
];

type DrawResult<T, DB> = Result<T, DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;
type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A figure that can be drawn on any backend.
trait Figure {
    /// Width and height [px].
    fn size(&self) -> (u32, u32);
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<(), DB>;
}

fn check_columns(columns: &[ColumnPlot], path: &Path) -> Result<(), PlotError> {
    let reason = if columns.is_empty() {
        "no columns".to_string()
    } else if let Some(c) = columns.iter().find(|c| c.time.is_empty()) {
        format!("column \"{}\" has no knot times", c.title)
    } else {
        return Ok(());
    };
    Err(PlotError::NoData {
        path: path.to_path_buf(),
        reason,
    })
}

/// Registers DejaVu Sans (regular and bold) as plotters' "sans-serif", once per process.
fn register_fonts() -> Result<(), String> {
    static REGISTERED: OnceLock<Result<(), String>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            let fonts = [
                (FontStyle::Normal, dejavu::sans::regular()),
                (FontStyle::Bold, dejavu::sans::bold()),
            ];
            for (style, bytes) in fonts {
                plotters::style::register_font(FONT, style, bytes).map_err(|_| {
                    "the embedded DejaVu Sans font could not be registered".to_string()
                })?;
            }
            Ok(())
        })
        .clone()
}

fn draw_error<E: std::error::Error + Send + Sync>(
    path: &Path,
    error: DrawingAreaErrorKind<E>,
) -> PlotError {
    PlotError::Draw {
        path: path.to_path_buf(),
        message: error.to_string(),
    }
}

fn render(figure: &impl Figure, png: &Path, svg: &Path) -> Result<(), PlotError> {
    register_fonts().map_err(|message| PlotError::Draw {
        path: png.to_path_buf(),
        message,
    })?;
    let size = figure.size();
    {
        let root = BitMapBackend::new(png, size).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_error(png, e))?;
        figure.draw(&root).map_err(|e| draw_error(png, e))?;
        root.present().map_err(|e| draw_error(png, e))?;
    }
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, size).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_error(svg, e))?;
        figure.draw(&root).map_err(|e| draw_error(svg, e))?;
        root.present().map_err(|e| draw_error(svg, e))?;
    }
    std::fs::write(svg, text).map_err(|source| PlotError::Write {
        path: svg.to_path_buf(),
        source,
    })
}

// ---------------------------------------------------------------------------------------------
// Fig. 1: the two-link arm

/// Pixel heights of the arm figure's panels: hand path (with the title), angle, velocity,
/// torque, stiffness (the last one only when some column has stiffness commands).
const ARM_HAND_HEIGHT: u32 = 400;
const ARM_TIME_HEIGHT: u32 = 165;

struct ArmFigure<'a> {
    columns: &'a [ColumnPlot],
    stats: Vec<ArmStats>,
    /// Hand-path region shared by all columns (before equalising the axis scales).
    hand_view: View,
    time: (f64, f64),
    angle: (f64, f64),
    velocity: (f64, f64),
    torque: (f64, f64),
    /// None when no column has stiffness commands (the row is left out).
    stiffness: Option<(f64, f64)>,
}

/// Per knot: mean and standard deviation.
type MeanStd = (Vec<f64>, Vec<f64>);
/// A polygon's vertices in data coordinates.
type Polygon2 = Vec<(f64, f64)>;

/// Per-column statistics over trials.
struct ArmStats {
    /// Per joint: mean and std of the angle [deg] and of the velocity [deg/s] at each knot.
    angle: Vec<MeanStd>,
    velocity: Vec<MeanStd>,
    hand_mean: Vec<(f64, f64)>,
    /// ±1 std across the mean path, as polygons.
    hand_band: Vec<Vec<(f64, f64)>>,
}

impl<'a> ArmFigure<'a> {
    fn new(columns: &'a [ColumnPlot]) -> Self {
        let stats: Vec<ArmStats> = columns.iter().map(arm_stats).collect();
        let band_values = |pick: fn(&ArmStats) -> &Vec<MeanStd>| -> Vec<Vec<f64>> {
            stats
                .iter()
                .map(|s| {
                    pick(s)
                        .iter()
                        .flat_map(|(m, sd)| {
                            m.iter()
                                .zip(sd)
                                .flat_map(|(m, sd)| [m - sd.max(0.0), m + sd.max(0.0)])
                                .chain(m.iter().copied())
                        })
                        .collect()
                })
                .collect()
        };
        let reference_angles: Vec<f64> = columns
            .iter()
            .flat_map(|c| c.reference_q.iter().flatten().map(|q| q * RAD_TO_DEG))
            .collect();
        let angle = shared_range(band_values(|s| &s.angle), &reference_angles, false);
        let velocity = shared_range(band_values(|s| &s.velocity), &[], false);
        let torque = shared_range(command_values(columns, Commands::Torque), &[], true);
        let stiffness = columns
            .iter()
            .any(|c| n_controls(c) > n_torques(c))
            .then(|| shared_range(command_values(columns, Commands::Stiffness), &[], true));
        ArmFigure {
            columns,
            hand_view: hand_view(columns, &stats),
            stats,
            time: time_range(columns),
            angle,
            velocity,
            torque,
            stiffness,
        }
    }

    fn heights(&self) -> Vec<u32> {
        let mut h = vec![
            ARM_HAND_HEIGHT,
            ARM_TIME_HEIGHT,
            ARM_TIME_HEIGHT,
            ARM_TIME_HEIGHT,
        ];
        if self.stiffness.is_some() {
            h.push(ARM_TIME_HEIGHT);
        }
        // The bottom panel also holds the time axis' description.
        *h.last_mut().unwrap() += X_LABEL_AREA_DESC - X_LABEL_AREA;
        h
    }

    fn draw_hand<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        c: usize,
    ) -> DrawResult<(), DB> {
        let col = &self.columns[c];
        let stats = &self.stats[c];
        let area = titled(area, &col.title)?;
        let (w, h) = hand_chart(&area, self.hand_view)?
            .plotting_area()
            .dim_in_pixel();
        let view = equal_aspect(self.hand_view, w, h);
        let mut chart = hand_chart(&area, view)?;
        chart
            .configure_mesh()
            .x_labels(5)
            .y_labels(6)
            .max_light_lines(0)
            .bold_line_style(GRID)
            .x_label_formatter(&tick)
            .y_label_formatter(&tick)
            .label_style((FONT, TICK_SIZE))
            .axis_desc_style((FONT, DESC_SIZE))
            .x_desc("x [m]")
            .y_desc("y [m]")
            .draw()?;
        if col.hand.is_empty() {
            return note(&mut chart, "no hand path");
        }
        for trial in &col.hand {
            lines(
                &mut chart,
                &view,
                trial.iter().map(|p| (p[0], p[1])),
                thin(&TRIAL_GREY),
            )?;
        }
        for polygon in &stats.hand_band {
            fill(&mut chart, &view, polygon, BAND_BLUE.mix(0.3))?;
        }
        lines(
            &mut chart,
            &view,
            stats.hand_mean.iter().copied(),
            MEAN_GREY.stroke_width(3),
        )?;
        let reference: Vec<(f64, f64)> = col.reference_hand.iter().map(|p| (p[0], p[1])).collect();
        dashed(&mut chart, &view, &reference, BLACK.stroke_width(1))?;
        if let Some(&end) = reference.last()
            && view.contains(end)
        {
            chart.draw_series(std::iter::once(Circle::new(end, 4, BLACK.stroke_width(1))))?;
        }
        if let Some((centre, axes, angle)) = col.ellipse {
            let points = ellipse_points(centre, axes, angle);
            lines(&mut chart, &view, points, ELLIPSE_RED.stroke_width(2))?;
        }
        if let Some((centre, axes, angle)) = col.dashed_ellipse {
            let points = ellipse_points(centre, axes, angle);
            dashed(&mut chart, &view, &points, ELLIPSE_RED.stroke_width(2))?;
        }
        if c == 0 {
            legend_line(&mut chart, "trials", thin(&TRIAL_GREY))?;
            legend_line(&mut chart, "mean", MEAN_GREY.stroke_width(3))?;
            legend_band(&mut chart, "±1 std", BAND_BLUE.mix(0.3))?;
            if col.ellipse.is_some() || col.dashed_ellipse.is_some() {
                legend_line(&mut chart, "95 % ellipse", ELLIPSE_RED.stroke_width(2))?;
            }
            let drawn: Vec<(f64, f64)> = col
                .hand
                .iter()
                .flatten()
                .map(|p| (p[0], p[1]))
                .chain(stats.hand_band.iter().flatten().copied())
                .collect();
            legend(&mut chart, quiet_corner(&view, &drawn))?;
        }
        Ok(())
    }

    /// Mean ± std of one joint quantity (angles or velocities) of every joint.
    fn draw_joint_stats<'c, DB: DrawingBackend + 'c>(
        &self,
        chart: &mut Chart<'c, DB>,
        c: usize,
        angles: bool,
    ) -> DrawResult<(), DB> {
        let col = &self.columns[c];
        let view = View::of(chart);
        let stats = if angles {
            &self.stats[c].angle
        } else {
            &self.stats[c].velocity
        };
        let mut drawn = Vec::new();
        for (j, (mean, sd)) in stats.iter().enumerate() {
            let colour = joint_colour(j);
            let upper: Vec<f64> = mean.iter().zip(sd).map(|(m, s)| m + s).collect();
            let lower: Vec<f64> = mean.iter().zip(sd).map(|(m, s)| m - s).collect();
            for polygon in band_polygons(
                col.time.iter().zip(&upper).map(|(&t, &y)| (t, y)).collect(),
                col.time.iter().zip(&lower).map(|(&t, &y)| (t, y)).collect(),
            ) {
                fill(chart, &view, &polygon, colour.mix(0.25))?;
                drawn.extend(polygon);
            }
            lines(
                chart,
                &view,
                col.time.iter().zip(mean).map(|(&t, &y)| (t, y)),
                colour.stroke_width(2),
            )?;
            if angles {
                let reference: Vec<(f64, f64)> = col
                    .time
                    .iter()
                    .zip(&col.reference_q)
                    .map(|(&t, q)| (t, q.get(j).map_or(f64::NAN, |q| q * RAD_TO_DEG)))
                    .collect();
                dashed(chart, &view, &reference, BLACK.stroke_width(1))?;
            }
            if c == 0 {
                legend_band(chart, &format!("joint {}", j + 1), colour.mix(0.35))?;
            }
        }
        if c == 0 && !stats.is_empty() {
            legend(chart, quiet_corner(&view, &drawn))?;
        }
        Ok(())
    }
}

impl Figure for ArmFigure<'_> {
    fn size(&self) -> (u32, u32) {
        let width = GUTTER + COLUMN_WIDTH * self.columns.len() as u32;
        (width, self.heights().iter().sum())
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<(), DB> {
        let heights = self.heights();
        let breaks = breakpoints(&heights);
        let (gutter, body) = root.split_horizontally(GUTTER);
        let bottom = heights.len() - 1;
        for (c, column) in body
            .split_evenly((1, self.columns.len()))
            .iter()
            .enumerate()
        {
            let panels = column.split_by_breakpoints::<i32, i32, _, _>([], &breaks);
            self.draw_hand(&panels[0], c)?;
            let rows: [(&str, (f64, f64)); 2] = [
                ("angle [deg]", self.angle),
                ("velocity [deg/s]", self.velocity),
            ];
            for (r, (desc, range)) in rows.into_iter().enumerate() {
                let mut chart = time_chart(&panels[1 + r], self.time, range, desc, false)?;
                self.draw_joint_stats(&mut chart, c, r == 0)?;
            }
            let mut commands = vec![(Commands::Torque, self.torque)];
            if let Some(range) = self.stiffness {
                commands.push((Commands::Stiffness, range));
            }
            for (r, (kind, range)) in commands.into_iter().enumerate() {
                let panel = 3 + r;
                let mut chart = time_chart(
                    &panels[panel],
                    self.time,
                    range,
                    kind.desc(),
                    panel == bottom,
                )?;
                draw_commands(&mut chart, &self.columns[c], kind, c == 0)?;
            }
        }
        let starts = [0, breaks[0], breaks[2]];
        row_letters(&gutter, &starts, &[0, 4, 4])
    }
}

fn arm_stats(col: &ColumnPlot) -> ArmStats {
    let knots = col.time.len();
    let joint = |data: &[Vec<Vec<f64>>]| -> Vec<MeanStd> {
        (0..col.dof)
            .map(|j| mean_std(data, knots, |knot| knot.get(j).map(|v| v * RAD_TO_DEG)))
            .collect()
    };
    let (hand_mean, hand_band) = hand_statistics(&col.hand, knots);
    ArmStats {
        angle: joint(&col.q),
        velocity: joint(&col.qd),
        hand_mean,
        hand_band,
    }
}

/// Per knot: mean and sample std over the trials with a finite value there (NaN where undefined).
fn mean_std(
    data: &[Vec<Vec<f64>>],
    knots: usize,
    value: impl Fn(&Vec<f64>) -> Option<f64>,
) -> (Vec<f64>, Vec<f64>) {
    (0..knots)
        .map(|k| {
            let values: Vec<f64> = data
                .iter()
                .filter_map(|trial| trial.get(k).and_then(&value))
                .filter(|v| v.is_finite())
                .collect();
            let n = values.len() as f64;
            if values.is_empty() {
                return (f64::NAN, f64::NAN);
            }
            let mean = values.iter().sum::<f64>() / n;
            let std = if values.len() < 2 {
                f64::NAN
            } else {
                (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
            };
            (mean, std)
        })
        .unzip()
}

/// Mean hand path and the ±1 std band across it (the std of the hand position along the normal
/// of the mean path).
fn hand_statistics(hand: &[Vec<[f64; 2]>], knots: usize) -> (Vec<(f64, f64)>, Vec<Polygon2>) {
    let mut mean = Vec::with_capacity(knots);
    let mut cov = Vec::with_capacity(knots);
    for k in 0..knots {
        let points: Vec<[f64; 2]> = hand
            .iter()
            .filter_map(|trial| trial.get(k).copied())
            .filter(|p| p[0].is_finite() && p[1].is_finite())
            .collect();
        if points.is_empty() {
            mean.push((f64::NAN, f64::NAN));
            cov.push([f64::NAN; 3]);
            continue;
        }
        let n = points.len() as f64;
        let m = (
            points.iter().map(|p| p[0]).sum::<f64>() / n,
            points.iter().map(|p| p[1]).sum::<f64>() / n,
        );
        mean.push(m);
        if points.len() < 2 {
            cov.push([f64::NAN; 3]);
            continue;
        }
        let mut c = [0.0; 3];
        for p in &points {
            let (dx, dy) = (p[0] - m.0, p[1] - m.1);
            c[0] += dx * dx;
            c[1] += dx * dy;
            c[2] += dy * dy;
        }
        cov.push(c.map(|v| v / (n - 1.0)));
    }
    if mean.is_empty() {
        return (mean, Vec::new());
    }
    // Overall direction, for knots where the mean does not move.
    let finite: Vec<(f64, f64)> = mean.iter().copied().filter(|p| is_finite(*p)).collect();
    let overall = match (finite.first(), finite.last()) {
        (Some(a), Some(b)) => (b.0 - a.0, b.1 - a.1),
        _ => (0.0, 1.0),
    };
    let window = (knots / 25).max(1);
    let mut upper = Vec::with_capacity(knots);
    let mut lower = Vec::with_capacity(knots);
    for k in 0..knots {
        let a = mean[k.saturating_sub(window)];
        let b = mean[(k + window).min(knots - 1)];
        let mut tangent = (b.0 - a.0, b.1 - a.1);
        let norm = |t: (f64, f64)| t.0.hypot(t.1);
        let usable = |t: (f64, f64)| norm(t).is_finite() && norm(t) > 1e-12;
        if !usable(tangent) {
            tangent = overall;
        }
        if !usable(tangent) {
            tangent = (0.0, 1.0);
        }
        let length = norm(tangent);
        let normal = (-tangent.1 / length, tangent.0 / length);
        let c = cov[k];
        let variance = normal.0 * normal.0 * c[0]
            + 2.0 * normal.0 * normal.1 * c[1]
            + normal.1 * normal.1 * c[2];
        let sd = variance.max(0.0).sqrt();
        let m = mean[k];
        upper.push((m.0 + sd * normal.0, m.1 + sd * normal.1));
        lower.push((m.0 - sd * normal.0, m.1 - sd * normal.1));
    }
    (mean, band_polygons(upper, lower))
}

/// The hand-path region: the reference paths of all columns, plus the spread of each column's
/// trials (central 95 %) and its ellipses unless that column is an outlier (it spreads more than
/// twice as far as the reference path or the median column), plus a margin.
fn hand_view(columns: &[ColumnPlot], stats: &[ArmStats]) -> View {
    let reference = Bounds::of(
        columns
            .iter()
            .flat_map(|c| c.reference_hand.iter().map(|p| (p[0], p[1]))),
    );
    let column_bounds: Vec<Bounds> = columns
        .iter()
        .zip(stats)
        .map(|(c, s)| {
            let points = c.hand.iter().flatten();
            let xs = quantile_range(points.clone().map(|p| p[0]).collect(), HAND_TAIL);
            let ys = quantile_range(points.map(|p| p[1]).collect(), HAND_TAIL);
            let mut b = Bounds::default();
            if let (Some(x), Some(y)) = (xs, ys) {
                b.add((x.0, y.0));
                b.add((x.1, y.1));
            }
            if b.is_empty() {
                b = Bounds::of(s.hand_mean.iter().copied());
            }
            for (centre, axes, angle) in [c.ellipse, c.dashed_ellipse].into_iter().flatten() {
                b.extend(&Bounds::of(ellipse_points(centre, axes, angle)));
            }
            b
        })
        .collect();
    let sizes: Vec<Option<f64>> = column_bounds.iter().map(Bounds::size).collect();
    let keep = non_outliers(&sizes, 2.0, reference.size().unwrap_or(0.0));
    let mut region = reference;
    for (b, keep) in column_bounds.iter().zip(keep) {
        if keep {
            region.extend(b);
        }
    }
    match region.size() {
        Some(size) => {
            let margin = 0.08 * size + 0.01;
            View {
                x0: region.x0 - margin,
                x1: region.x1 + margin,
                y0: region.y0 - margin,
                y1: region.y1 + margin,
            }
        }
        None => View {
            x0: -0.1,
            x1: 0.1,
            y0: 0.0,
            y1: 0.2,
        },
    }
}

/// Widens `view` around its centre so that one metre is as long on both axes of a `w`×`h` px
/// plotting area.
fn equal_aspect(view: View, w: u32, h: u32) -> View {
    let (w, h) = (f64::from(w.max(1)), f64::from(h.max(1)));
    let scale = ((view.x1 - view.x0) / w).max((view.y1 - view.y0) / h);
    let (cx, cy) = ((view.x0 + view.x1) / 2.0, (view.y0 + view.y1) / 2.0);
    View {
        x0: cx - scale * w / 2.0,
        x1: cx + scale * w / 2.0,
        y0: cy - scale * h / 2.0,
        y1: cy + scale * h / 2.0,
    }
}

fn hand_chart<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    view: View,
) -> DrawResult<Chart<'a, DB>, DB> {
    ChartBuilder::on(area)
        .margin_top(4)
        .margin_bottom(6)
        .margin_left(4)
        .margin_right(14)
        .x_label_area_size(X_LABEL_AREA_DESC)
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(view.x0..view.x1, view.y0..view.y1)
}

fn ellipse_points(centre: [f64; 2], axes: [f64; 2], angle: f64) -> Vec<(f64, f64)> {
    let (sin, cos) = angle.sin_cos();
    (0..=120)
        .map(|i| {
            let s = std::f64::consts::TAU * f64::from(i) / 120.0;
            let (ex, ey) = (axes[0] * s.cos(), axes[1] * s.sin());
            (
                centre[0] + ex * cos - ey * sin,
                centre[1] + ex * sin + ey * cos,
            )
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Fig. 2: the single joint

const JOINT_ANGLE_HEIGHT: u32 = 280;
const JOINT_TIME_HEIGHT: u32 = 235;

struct JointFigure<'a> {
    columns: &'a [ColumnPlot],
    time: (f64, f64),
    angle: (f64, f64),
    velocity: (f64, f64),
    torque: (f64, f64),
    stiffness: Option<(f64, f64)>,
}

impl<'a> JointFigure<'a> {
    fn new(columns: &'a [ColumnPlot]) -> Self {
        let trial_values = |data: fn(&ColumnPlot) -> &Vec<Vec<Vec<f64>>>| -> Vec<Vec<f64>> {
            columns
                .iter()
                .map(|c| {
                    data(c)
                        .iter()
                        .flatten()
                        .flat_map(|knot| knot.iter().take(c.dof).map(|v| v * RAD_TO_DEG))
                        .collect()
                })
                .collect()
        };
        let reference: Vec<f64> = columns
            .iter()
            .flat_map(|c| c.reference_q.iter().flatten().map(|q| q * RAD_TO_DEG))
            .collect();
        JointFigure {
            columns,
            time: time_range(columns),
            angle: shared_range(trial_values(|c| &c.q), &reference, false),
            velocity: shared_range(trial_values(|c| &c.qd), &[], false),
            torque: shared_range(command_values(columns, Commands::Torque), &[], true),
            stiffness: columns
                .iter()
                .any(|c| n_controls(c) > n_torques(c))
                .then(|| shared_range(command_values(columns, Commands::Stiffness), &[], true)),
        }
    }

    fn heights(&self) -> Vec<u32> {
        let mut h = vec![JOINT_ANGLE_HEIGHT, JOINT_TIME_HEIGHT, JOINT_TIME_HEIGHT];
        if self.stiffness.is_some() {
            h.push(JOINT_TIME_HEIGHT);
        }
        *h.last_mut().unwrap() += X_LABEL_AREA_DESC - X_LABEL_AREA;
        h
    }

    /// Every trial of every joint's angle [deg] (with the reference) or velocity [deg/s].
    fn draw_trials<'c, DB: DrawingBackend + 'c>(
        &self,
        chart: &mut Chart<'c, DB>,
        c: usize,
        angles: bool,
    ) -> DrawResult<(), DB> {
        let col = &self.columns[c];
        let view = View::of(chart);
        let data = if angles { &col.q } else { &col.qd };
        let mut drawn = Vec::new();
        for j in 0..col.dof {
            let colour = joint_colour(j);
            for trial in data {
                let points: Vec<(f64, f64)> = col
                    .time
                    .iter()
                    .zip(trial)
                    .map(|(&t, knot)| (t, knot.get(j).map_or(f64::NAN, |v| v * RAD_TO_DEG)))
                    .collect();
                lines(
                    chart,
                    &view,
                    points.iter().copied(),
                    colour.mix(0.45).stroke_width(1),
                )?;
                drawn.extend(points);
            }
            if angles {
                let reference: Vec<(f64, f64)> = col
                    .time
                    .iter()
                    .zip(&col.reference_q)
                    .map(|(&t, q)| (t, q.get(j).map_or(f64::NAN, |q| q * RAD_TO_DEG)))
                    .collect();
                dashed(chart, &view, &reference, BLACK.stroke_width(2))?;
            }
        }
        // The legend once, on the first column's angles.
        if c == 0 && angles {
            if col.dof > 1 {
                for j in 0..col.dof {
                    legend_line(
                        chart,
                        &format!("joint {}", j + 1),
                        joint_colour(j).stroke_width(2),
                    )?;
                }
            } else {
                legend_line(chart, "trials", joint_colour(0).mix(0.6).stroke_width(1))?;
            }
            if !col.reference_q.is_empty() {
                legend_dashed(chart, "reference", BLACK.stroke_width(2))?;
            }
            legend(chart, quiet_corner(&view, &drawn))?;
        }
        Ok(())
    }
}

impl Figure for JointFigure<'_> {
    fn size(&self) -> (u32, u32) {
        let width = GUTTER + COLUMN_WIDTH * self.columns.len() as u32;
        (width, self.heights().iter().sum())
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<(), DB> {
        let heights = self.heights();
        let breaks = breakpoints(&heights);
        let (gutter, body) = root.split_horizontally(GUTTER);
        let bottom = heights.len() - 1;
        for (c, column) in body
            .split_evenly((1, self.columns.len()))
            .iter()
            .enumerate()
        {
            let panels = column.split_by_breakpoints::<i32, i32, _, _>([], &breaks);
            let top = titled(&panels[0], &self.columns[c].title)?;
            let mut chart = time_chart(&top, self.time, self.angle, "angle [deg]", false)?;
            self.draw_trials(&mut chart, c, true)?;
            let mut chart = time_chart(
                &panels[1],
                self.time,
                self.velocity,
                "velocity [deg/s]",
                false,
            )?;
            self.draw_trials(&mut chart, c, false)?;
            let mut commands = vec![(Commands::Torque, self.torque)];
            if let Some(range) = self.stiffness {
                commands.push((Commands::Stiffness, range));
            }
            for (r, (kind, range)) in commands.into_iter().enumerate() {
                let panel = 2 + r;
                let mut chart = time_chart(
                    &panels[panel],
                    self.time,
                    range,
                    kind.desc(),
                    panel == bottom,
                )?;
                draw_commands(&mut chart, &self.columns[c], kind, c == 0)?;
            }
        }
        let starts = [0, breaks[0], breaks[1]];
        row_letters(&gutter, &starts, &[0, 4, 4])
    }
}

// ---------------------------------------------------------------------------------------------
// Shared panels

#[derive(Clone, Copy, PartialEq)]
enum Commands {
    Torque,
    Stiffness,
}

impl Commands {
    fn name(self) -> &'static str {
        match self {
            Commands::Torque => "torque",
            Commands::Stiffness => "stiffness",
        }
    }

    fn desc(self) -> &'static str {
        match self {
            Commands::Torque => "torque [N m]",
            Commands::Stiffness => "stiffness [N m/rad]",
        }
    }

    /// Indices of this kind of command in a column's control vector.
    fn indices(self, col: &ColumnPlot) -> std::ops::Range<usize> {
        match self {
            Commands::Torque => 0..n_torques(col),
            Commands::Stiffness => n_torques(col)..n_controls(col),
        }
    }
}

/// Number of commands per step (from the names, or the data when they are missing).
fn n_controls(col: &ColumnPlot) -> usize {
    if col.control_names.is_empty() {
        col.u.iter().flatten().map(Vec::len).max().unwrap_or(0)
    } else {
        col.control_names.len()
    }
}

/// The first `dof` commands are torques, the rest stiffnesses.
fn n_torques(col: &ColumnPlot) -> usize {
    n_controls(col).min(col.dof.max(1))
}

fn control_name(col: &ColumnPlot, i: usize) -> String {
    col.control_names
        .get(i)
        .cloned()
        .unwrap_or_else(|| format!("u{}", i + 1))
}

fn command_values(columns: &[ColumnPlot], kind: Commands) -> Vec<Vec<f64>> {
    columns
        .iter()
        .map(|c| {
            let range = kind.indices(c);
            c.u.iter()
                .flatten()
                .flat_map(|step| step.get(range.clone()).unwrap_or_default().iter().copied())
                .collect()
        })
        .collect()
}

/// Every trial's commands of one kind, held over each step.
fn draw_commands<'c, DB: DrawingBackend + 'c>(
    chart: &mut Chart<'c, DB>,
    col: &ColumnPlot,
    kind: Commands,
    with_legend: bool,
) -> DrawResult<(), DB> {
    let view = View::of(chart);
    let range = kind.indices(col);
    if range.is_empty() {
        return note(chart, &format!("no {} commands", kind.name()));
    }
    let alpha = if col.u.len() > 1 { 0.45 } else { 1.0 };
    let mut drawn = Vec::new();
    for i in range.clone() {
        let colour = joint_colour(i - range.start);
        for trial in &col.u {
            let mut points = Vec::with_capacity(2 * trial.len());
            for (k, step) in trial.iter().enumerate() {
                let (Some(&t0), Some(&v)) = (col.time.get(k), step.get(i)) else {
                    continue;
                };
                let t1 = match (
                    col.time.get(k + 1),
                    k.checked_sub(1).and_then(|p| col.time.get(p)),
                ) {
                    (Some(&t1), _) => t1,
                    (None, Some(&before)) => t0 + (t0 - before),
                    (None, None) => t0,
                };
                points.push((t0, v));
                points.push((t1, v));
            }
            lines(
                chart,
                &view,
                points.iter().copied(),
                colour.mix(alpha).stroke_width(2),
            )?;
            drawn.extend(points);
        }
        if with_legend {
            legend_line(chart, &control_name(col, i), colour.stroke_width(2))?;
        }
    }
    if with_legend {
        legend(chart, quiet_corner(&view, &drawn))?;
    }
    Ok(())
}

/// A panel with time on the x axis.
fn time_chart<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    time: (f64, f64),
    y: (f64, f64),
    y_desc: &str,
    bottom: bool,
) -> DrawResult<Chart<'a, DB>, DB> {
    let mut chart = ChartBuilder::on(area)
        .margin_top(6)
        .margin_bottom(2)
        .margin_left(4)
        .margin_right(14)
        .x_label_area_size(if bottom {
            X_LABEL_AREA_DESC
        } else {
            X_LABEL_AREA
        })
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(time.0..time.1, y.0..y.1)?;
    let mut mesh = chart.configure_mesh();
    mesh.x_labels(6)
        .y_labels(5)
        .max_light_lines(0)
        .bold_line_style(GRID)
        .x_label_formatter(&tick)
        .y_label_formatter(&tick)
        .label_style((FONT, TICK_SIZE))
        .axis_desc_style((FONT, DESC_SIZE))
        .y_desc(y_desc);
    if bottom {
        mesh.x_desc("time [s]");
    }
    mesh.draw()?;
    Ok(chart)
}

/// Draws `title` (bold, shrunk to fit the width) on top of `area`; returns the area below.
fn titled<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
) -> DrawResult<DrawingArea<DB, Shift>, DB> {
    let (width, _) = area.dim_in_pixel();
    let mut size = TITLE_SIZE;
    let style = loop {
        let style = TextStyle::from(bold(size));
        let (w, _) = area.estimate_text_size(title, &style)?;
        if w + 16 <= width || size <= 9.0 {
            break style;
        }
        size -= 1.0;
    };
    area.titled(title, style)
}

/// Bold letters A, B, C in the left strip at the top of each row.
fn row_letters<DB: DrawingBackend>(
    gutter: &DrawingArea<DB, Shift>,
    starts: &[i32],
    offsets: &[i32],
) -> DrawResult<(), DB> {
    let style = TextStyle::from(bold(20.0));
    for ((letter, &y), &dy) in ["A", "B", "C"].iter().zip(starts).zip(offsets) {
        gutter.draw_text(letter, &style, (7, y + 4 + dy))?;
    }
    Ok(())
}

/// Cumulative heights: where each panel but the first starts.
fn breakpoints(heights: &[u32]) -> Vec<i32> {
    heights[..heights.len() - 1]
        .iter()
        .scan(0, |y, &h| {
            *y += h as i32;
            Some(*y)
        })
        .collect()
}

/// DejaVu Sans Bold (`FontDesc::style` would keep the regular face's glyphs).
fn bold(size: f64) -> FontDesc<'static> {
    FontDesc::new(FontFamily::Name(FONT), size, FontStyle::Bold)
}

/// Tick labels with as many decimals as the value needs: "0.35", "100", "-2".
fn tick(v: &f64) -> String {
    let s = format!("{v:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".to_string()
    } else {
        s.to_string()
    }
}

/// A grey note centred in a panel that has nothing to show.
fn note<'c, DB: DrawingBackend + 'c>(chart: &mut Chart<'c, DB>, text: &str) -> DrawResult<(), DB> {
    let view = View::of(chart);
    let style = TextStyle::from((FONT, DESC_SIZE).into_font())
        .color(&MEAN_GREY)
        .pos(Pos::new(HPos::Center, VPos::Center));
    let centre = ((view.x0 + view.x1) / 2.0, (view.y0 + view.y1) / 2.0);
    chart.draw_series(std::iter::once(Text::new(text.to_string(), centre, style)))?;
    Ok(())
}

/// The corner of `view` with the fewest of `points` (the legend goes there).
fn quiet_corner(view: &View, points: &[(f64, f64)]) -> SeriesLabelPosition {
    let (w, h) = (0.4 * (view.x1 - view.x0), 0.4 * (view.y1 - view.y0));
    let corners = [
        (SeriesLabelPosition::UpperRight, view.x1 - w, view.y1 - h),
        (SeriesLabelPosition::UpperLeft, view.x0, view.y1 - h),
        (SeriesLabelPosition::LowerRight, view.x1 - w, view.y0),
        (SeriesLabelPosition::LowerLeft, view.x0, view.y0),
    ];
    let mut best = (usize::MAX, SeriesLabelPosition::UpperRight);
    for (position, x0, y0) in corners {
        let count = points
            .iter()
            .filter(|p| (x0..=x0 + w).contains(&p.0) && (y0..=y0 + h).contains(&p.1))
            .count();
        if count < best.0 {
            best = (count, position);
        }
    }
    best.1
}

fn joint_colour(j: usize) -> RGBColor {
    JOINT_COLOURS[j % JOINT_COLOURS.len()]
}

fn thin(colour: &RGBColor) -> ShapeStyle {
    colour.stroke_width(1)
}

/// The span of all knot times (0..1 s when there is none).
fn time_range(columns: &[ColumnPlot]) -> (f64, f64) {
    let b = Bounds::of(
        columns
            .iter()
            .flat_map(|c| c.time.iter().map(|&t| (t, 0.0))),
    );
    match b.size() {
        Some(span) if span > 0.0 => (b.x0, b.x1),
        Some(_) => (b.x0, b.x0 + 1.0),
        None => (0.0, 1.0),
    }
}

// ---------------------------------------------------------------------------------------------
// Legends

fn legend_line<'c, DB: DrawingBackend + 'c>(
    chart: &mut Chart<'c, DB>,
    label: &str,
    style: ShapeStyle,
) -> DrawResult<(), DB> {
    chart
        .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())?
        .label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], style));
    Ok(())
}

fn legend_dashed<'c, DB: DrawingBackend + 'c>(
    chart: &mut Chart<'c, DB>,
    label: &str,
    style: ShapeStyle,
) -> DrawResult<(), DB> {
    chart
        .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())?
        .label(label)
        .legend(move |(x, y)| {
            EmptyElement::at((x, y))
                + PathElement::new(vec![(0, 0), (6, 0)], style)
                + PathElement::new(vec![(11, 0), (17, 0)], style)
        });
    Ok(())
}

fn legend_band<'c, DB: DrawingBackend + 'c>(
    chart: &mut Chart<'c, DB>,
    label: &str,
    colour: RGBAColor,
) -> DrawResult<(), DB> {
    chart
        .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())?
        .label(label)
        .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 18, y + 5)], colour.filled()));
    Ok(())
}

fn legend<'c, DB: DrawingBackend + 'c>(
    chart: &mut Chart<'c, DB>,
    position: SeriesLabelPosition,
) -> DrawResult<(), DB> {
    chart
        .configure_series_labels()
        .position(position)
        .margin(6)
        .legend_area_size(24)
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(180, 180, 180))
        .label_font((FONT, 11.0))
        .draw()
}

// ---------------------------------------------------------------------------------------------
// Clipped drawing (plotters does not clip series to the plotting area)

/// Draws a polyline, broken at non-finite points and clipped to `view`.
fn lines<'c, DB: DrawingBackend + 'c>(
    chart: &mut Chart<'c, DB>,
    view: &View,
    points: impl IntoIterator<Item = (f64, f64)>,
    style: ShapeStyle,
) -> DrawResult<(), DB> {
    for run in clip_polyline(thin_out(points.into_iter().collect()), view) {
        chart.draw_series(LineSeries::new(run, style))?;
    }
    Ok(())
}

fn dashed<'c, DB: DrawingBackend + 'c>(
    chart: &mut Chart<'c, DB>,
    view: &View,
    points: &[(f64, f64)],
    style: ShapeStyle,
) -> DrawResult<(), DB> {
    for run in clip_polyline(thin_out(points.to_vec()), view) {
        chart.draw_series(DashedLineSeries::new(run, 7, 5, style))?;
    }
    Ok(())
}

/// Fills a polygon clipped to `view`.
fn fill<'c, DB: DrawingBackend + 'c>(
    chart: &mut Chart<'c, DB>,
    view: &View,
    polygon: &[(f64, f64)],
    colour: RGBAColor,
) -> DrawResult<(), DB> {
    let clipped = clip_polygon(&thin_out(polygon.to_vec()), view);
    if clipped.len() >= 3 {
        chart.draw_series(std::iter::once(Polygon::new(clipped, colour.filled())))?;
    }
    Ok(())
}

/// Keeps at most about `MAX_POINTS` points (every k-th, and the last).
fn thin_out(points: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    if points.len() <= MAX_POINTS {
        return points;
    }
    let stride = points.len().div_ceil(MAX_POINTS);
    let last = points.len() - 1;
    points
        .into_iter()
        .enumerate()
        .filter(|(i, _)| i % stride == 0 || *i == last)
        .map(|(_, p)| p)
        .collect()
}

/// Polygons between an upper and a lower edge (same length), one per run of knots where both
/// edges are finite.
fn band_polygons(upper: Vec<(f64, f64)>, lower: Vec<(f64, f64)>) -> Vec<Vec<(f64, f64)>> {
    let mut polygons = Vec::new();
    let mut start = 0;
    let n = upper.len().min(lower.len());
    while start < n {
        let ok = |k: usize| is_finite(upper[k]) && is_finite(lower[k]);
        if !ok(start) {
            start += 1;
            continue;
        }
        let mut end = start;
        while end < n && ok(end) {
            end += 1;
        }
        if end - start >= 2 {
            let mut polygon: Vec<(f64, f64)> = upper[start..end].to_vec();
            polygon.extend(lower[start..end].iter().rev());
            polygons.push(polygon);
        }
        start = end;
    }
    polygons
}

/// A rectangle in data coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
struct View {
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
}

impl View {
    fn of<'c, DB: DrawingBackend + 'c>(chart: &Chart<'c, DB>) -> View {
        let (x, y) = (chart.x_range(), chart.y_range());
        View {
            x0: x.start,
            x1: x.end,
            y0: y.start,
            y1: y.end,
        }
    }

    fn contains(&self, p: (f64, f64)) -> bool {
        (self.x0..=self.x1).contains(&p.0) && (self.y0..=self.y1).contains(&p.1)
    }
}

fn is_finite(p: (f64, f64)) -> bool {
    p.0.is_finite() && p.1.is_finite()
}

/// Bounds huge values so that differences cannot overflow (far outside any view anyway).
fn tame(p: (f64, f64)) -> (f64, f64) {
    const BIG: f64 = 1e12;
    (p.0.clamp(-BIG, BIG), p.1.clamp(-BIG, BIG))
}

/// Liang–Barsky: the part of segment a–b inside `v`, if any.
fn clip_segment(a: (f64, f64), b: (f64, f64), v: &View) -> Option<((f64, f64), (f64, f64))> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0_f64, 1.0_f64);
    for (p, q) in [
        (-dx, a.0 - v.x0),
        (dx, v.x1 - a.0),
        (-dy, a.1 - v.y0),
        (dy, v.y1 - a.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
            continue;
        }
        let r = q / p;
        if p < 0.0 {
            t0 = t0.max(r);
        } else {
            t1 = t1.min(r);
        }
        if t0 > t1 {
            return None;
        }
    }
    let at = |t: f64| {
        if t == 0.0 {
            a
        } else if t == 1.0 {
            b
        } else {
            (a.0 + t * dx, a.1 + t * dy)
        }
    };
    Some((at(t0), at(t1)))
}

/// The pieces of a polyline inside `v`; non-finite points break the line.
fn clip_polyline(points: Vec<(f64, f64)>, v: &View) -> Vec<Vec<(f64, f64)>> {
    fn flush(runs: &mut Vec<Vec<(f64, f64)>>, run: &mut Vec<(f64, f64)>) {
        if run.len() >= 2 {
            runs.push(std::mem::take(run));
        } else {
            run.clear();
        }
    }
    let mut runs = Vec::new();
    let mut run: Vec<(f64, f64)> = Vec::new();
    let mut previous: Option<(f64, f64)> = None;
    for p in points {
        if !is_finite(p) {
            flush(&mut runs, &mut run);
            previous = None;
            continue;
        }
        let p = tame(p);
        if let Some(a) = previous {
            match clip_segment(a, p, v) {
                Some((s, e)) => {
                    if run.last() != Some(&s) {
                        flush(&mut runs, &mut run);
                        run.push(s);
                    }
                    run.push(e);
                }
                None => flush(&mut runs, &mut run),
            }
        }
        previous = Some(p);
    }
    flush(&mut runs, &mut run);
    runs
}

/// Sutherland–Hodgman: `polygon` clipped to `v` (non-finite vertices are dropped).
fn clip_polygon(polygon: &[(f64, f64)], v: &View) -> Vec<(f64, f64)> {
    let mut poly: Vec<(f64, f64)> = polygon
        .iter()
        .copied()
        .filter(|p| is_finite(*p))
        .map(tame)
        .collect();
    for edge in 0..4 {
        let Some(&last) = poly.last() else {
            break;
        };
        let inside = |p: (f64, f64)| match edge {
            0 => p.0 >= v.x0,
            1 => p.0 <= v.x1,
            2 => p.1 >= v.y0,
            _ => p.1 <= v.y1,
        };
        let cross = |a: (f64, f64), b: (f64, f64)| match edge {
            0 | 1 => {
                let x = if edge == 0 { v.x0 } else { v.x1 };
                (x, a.1 + (x - a.0) / (b.0 - a.0) * (b.1 - a.1))
            }
            _ => {
                let y = if edge == 2 { v.y0 } else { v.y1 };
                (a.0 + (y - a.1) / (b.1 - a.1) * (b.0 - a.0), y)
            }
        };
        let input = std::mem::take(&mut poly);
        let mut previous = last;
        for current in input {
            match (inside(previous), inside(current)) {
                (true, true) => poly.push(current),
                (true, false) => poly.push(cross(previous, current)),
                (false, true) => {
                    poly.push(cross(previous, current));
                    poly.push(current);
                }
                (false, false) => {}
            }
            previous = current;
        }
    }
    poly.retain(|p| is_finite(*p));
    poly
}

// ---------------------------------------------------------------------------------------------
// Ranges

/// Bounding box of finite points.
#[derive(Clone, Copy, Debug)]
struct Bounds {
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
}

impl Default for Bounds {
    fn default() -> Self {
        Bounds {
            x0: f64::INFINITY,
            x1: f64::NEG_INFINITY,
            y0: f64::INFINITY,
            y1: f64::NEG_INFINITY,
        }
    }
}

impl Bounds {
    fn of(points: impl IntoIterator<Item = (f64, f64)>) -> Bounds {
        let mut b = Bounds::default();
        for p in points {
            b.add(p);
        }
        b
    }

    fn add(&mut self, p: (f64, f64)) {
        if is_finite(p) {
            self.x0 = self.x0.min(p.0);
            self.x1 = self.x1.max(p.0);
            self.y0 = self.y0.min(p.1);
            self.y1 = self.y1.max(p.1);
        }
    }

    fn extend(&mut self, other: &Bounds) {
        if !other.is_empty() {
            self.add((other.x0, other.y0));
            self.add((other.x1, other.y1));
        }
    }

    fn is_empty(&self) -> bool {
        self.x0 > self.x1
    }

    /// The longer side, None when empty.
    fn size(&self) -> Option<f64> {
        (!self.is_empty()).then(|| (self.x1 - self.x0).max(self.y1 - self.y0))
    }
}

/// The `tail` and `1 - tail` quantiles of the finite values.
fn quantile_range(mut values: Vec<f64>, tail: f64) -> Option<(f64, f64)> {
    values.retain(|v| v.is_finite());
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let last = (values.len() - 1) as f64;
    let at = |q: f64| values[(last * q).round() as usize];
    Some((at(tail), at(1.0 - tail)))
}

/// Which columns to keep when fitting a shared range: those whose size is at most `factor` times
/// the (lower) median positive size, or `anchor` if larger.
fn non_outliers(sizes: &[Option<f64>], factor: f64, anchor: f64) -> Vec<bool> {
    let mut positive: Vec<f64> = sizes
        .iter()
        .flatten()
        .copied()
        .filter(|s| *s > 0.0)
        .collect();
    positive.sort_by(f64::total_cmp);
    let cap = match positive.get(positive.len().saturating_sub(1) / 2) {
        Some(median) => factor * median.max(anchor),
        None => f64::INFINITY,
    };
    sizes
        .iter()
        .map(|s| matches!(s, Some(s) if *s <= cap))
        .collect()
}

/// A y range shared by all columns: the union of each column's central range, leaving out
/// columns that spread `OUTLIER_FACTOR` times more than the median one, plus `always`, padded.
fn shared_range(per_column: Vec<Vec<f64>>, always: &[f64], include_zero: bool) -> (f64, f64) {
    let ranges: Vec<Option<(f64, f64)>> = per_column
        .into_iter()
        .map(|v| quantile_range(v, TAIL))
        .collect();
    let sizes: Vec<Option<f64>> = ranges.iter().map(|r| r.map(|(lo, hi)| hi - lo)).collect();
    let keep = non_outliers(&sizes, OUTLIER_FACTOR, 0.0);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (range, keep) in ranges.iter().zip(keep) {
        if let (Some((a, b)), true) = (range, keep) {
            lo = lo.min(*a);
            hi = hi.max(*b);
        }
    }
    for &v in always.iter().filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if include_zero {
        lo = lo.min(0.0);
        hi = hi.max(0.0);
    }
    pad(lo, hi)
}

/// `lo..hi` with 6 % margins; a default or widened range when empty or flat.
fn pad(lo: f64, hi: f64) -> (f64, f64) {
    if !(lo.is_finite() && hi.is_finite()) {
        return (-1.0, 1.0);
    }
    let width = hi - lo;
    if width <= 1e-9 * lo.abs().max(hi.abs()).max(1e-300) {
        let half = (0.1 * lo.abs()).max(1.0);
        return (lo - half, hi + half);
    }
    (lo - 0.06 * width, hi + 0.06 * width)
}

#[cfg(test)]
mod tests {
    use super::*;

    const UNIT: View = View {
        x0: 0.0,
        x1: 1.0,
        y0: 0.0,
        y1: 1.0,
    };

    #[test]
    fn segments_are_clipped_to_the_view() {
        assert_eq!(
            clip_segment((-1.0, 0.5), (2.0, 0.5), &UNIT),
            Some(((0.0, 0.5), (1.0, 0.5)))
        );
        assert_eq!(clip_segment((-1.0, 2.0), (2.0, 2.0), &UNIT), None);
        assert_eq!(
            clip_segment((0.2, 0.2), (0.4, 0.6), &UNIT),
            Some(((0.2, 0.2), (0.4, 0.6)))
        );
    }

    #[test]
    fn polylines_break_at_non_finite_points_and_at_the_border() {
        let runs = clip_polyline(
            vec![
                (0.1, 0.1),
                (0.2, 0.2),
                (f64::NAN, 0.3),
                (0.3, 0.3),
                (0.4, 0.4),
                (0.5, 5.0),
                (0.6, 0.5),
                (0.7, f64::INFINITY),
            ],
            &UNIT,
        );
        assert_eq!(runs.len(), 3);
        assert_eq!(runs[0], vec![(0.1, 0.1), (0.2, 0.2)]);
        assert_eq!(runs[1][..2], [(0.3, 0.3), (0.4, 0.4)]);
        assert!(runs.iter().flatten().all(|p| UNIT.contains(*p)));
    }

    #[test]
    fn polygons_are_clipped_to_the_view() {
        let square = [(-1.0, -1.0), (2.0, -1.0), (2.0, 2.0), (-1.0, 2.0)];
        let clipped = clip_polygon(&square, &UNIT);
        assert_eq!(clipped.len(), 4);
        assert!(clipped.iter().all(|p| UNIT.contains(*p)));
        assert!(clip_polygon(&[(5.0, 5.0), (6.0, 5.0), (6.0, 6.0)], &UNIT).is_empty());
    }

    #[test]
    fn a_diverging_column_does_not_set_the_shared_range() {
        let calm = vec![0.0, 1.0];
        let wild = vec![-100.0, 100.0];
        let (lo, hi) = shared_range(vec![calm.clone(), wild, calm], &[], false);
        assert!(lo > -1.0 && hi < 2.0, "{lo}..{hi}");
    }

    #[test]
    fn ticks_show_the_decimals_they_need() {
        assert_eq!(tick(&0.30000000000000004), "0.3");
        assert_eq!(tick(&0.35), "0.35");
        assert_eq!(tick(&100.0), "100");
        assert_eq!(tick(&-0.0), "0");
        assert_eq!(tick(&-2.5), "-2.5");
    }

    #[test]
    fn the_legend_goes_where_the_data_is_not() {
        let rising: Vec<(f64, f64)> = (0..=10).map(|i| (0.1 * i as f64, 0.1 * i as f64)).collect();
        assert!(matches!(
            quiet_corner(&UNIT, &rising),
            SeriesLabelPosition::UpperLeft
        ));
    }

    #[test]
    fn equal_aspect_gives_both_axes_the_same_scale() {
        let v = equal_aspect(UNIT, 300, 150);
        assert!(((v.x1 - v.x0) / 300.0 - (v.y1 - v.y0) / 150.0).abs() < 1e-12);
        assert!(v.x0 <= 0.0 && v.x1 >= 1.0 && v.y0 <= 0.0 && v.y1 >= 1.0);
    }
}
