//! Figures of the paper from Monte Carlo trials: Fig. 1 (two-link arm in a divergent field) and
//! Fig. 2 (single joint with feedback delays), written as PNG and SVG with `plotters`.
//!
//! Text is set in DejaVu Sans, embedded through the `dejavu` crate and registered with plotters'
//! `ab_glyph` renderer on first use, so rendering needs no system fonts.
//!
//! Conventions:
//! - Columns are conditions (actuator types, delays), side by side, each with its title on top.
//! - Rows that are compared across columns share their axes, except the torques, which differ
//!   between columns by orders of magnitude: each column has its own torque range. The shared
//!   ranges are robust: a column whose trials diverge far beyond the others does not widen them,
//!   and its curves simply leave the frame (everything is clipped to the plotting area).
//! - Non-finite values are skipped: a curve breaks where a value is NaN or infinite.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::chart::MeshStyle;
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::FontStyle;
use plotters::style::text_anchor::{HPos, Pos, VPos};

mod arm;
mod caption;
mod clip;
mod curves;
mod joint;
mod lag;
pub use lag::LagPlot;
mod panels;
mod ranges;

use arm::*;
pub use caption::Caption;
use caption::Captioned;
use clip::*;
pub(crate) use curves::Curve;
use curves::CurveFigure;
use joint::*;
use panels::*;
use ranges::*;

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
    /// Per trial: whether it diverged (a trial without an entry did not). A diverged trial is
    /// drawn dashed and faded, counted under the column's title, and left out of the means,
    /// the spreads and every axis range: one trial that left the workspace would otherwise set
    /// the scale of every panel. The ellipse, given by the caller, should be of the others.
    pub diverged: Vec<bool>,
}

impl ColumnPlot {
    /// Whether trial `i` diverged.
    pub(super) fn is_diverged(&self, i: usize) -> bool {
        self.diverged.get(i).copied().unwrap_or(false)
    }

    /// Number of trials (those with joint angles, or hand paths).
    pub(super) fn trials(&self) -> usize {
        self.q.len().max(self.hand.len()).max(self.u.len())
    }

    /// Number of trials that diverged.
    pub(super) fn n_diverged(&self) -> usize {
        (0..self.trials()).filter(|&i| self.is_diverged(i)).count()
    }

    /// The trials of `data` (one entry per trial) that did not diverge.
    pub(super) fn kept<'a, T>(&'a self, data: &'a [T]) -> impl Iterator<Item = &'a T> + Clone + 'a {
        data.iter()
            .enumerate()
            .filter(|(i, _)| !self.is_diverged(*i))
            .map(|(_, t)| t)
    }

    /// The trials of `data` that diverged.
    pub(super) fn lost<'a, T>(&'a self, data: &'a [T]) -> impl Iterator<Item = &'a T> + 'a {
        data.iter()
            .enumerate()
            .filter(|(i, _)| self.is_diverged(*i))
            .map(|(_, t)| t)
    }
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
/// `28 + 400 × columns` px wide and 1162 px tall (977 without stiffness commands).
///
/// `dashed_ellipse`, when given, is drawn dashed next to the solid 95 % ellipse. The legends sit
/// in the first column, in the panel corner with the fewest data.
///
/// The hand-path view is the same for all columns: the reference paths, plus the spread of the
/// trials of every column that does not diverge, plus a margin. Time rows share their y ranges,
/// but for the torques (each column its own).
pub fn arm_figure(columns: &[ColumnPlot], png: &Path, svg: &Path) -> Result<(), PlotError> {
    check_columns(columns, png)?;
    render(&ArmFigure::new(columns), png, svg)
}

/// [`arm_figure`] or, for a single joint, [`joint_figure`] (by the columns' `dof`) with a title
/// above and a caption below: a figure that stands alone.
pub fn captioned_figure(
    columns: &[ColumnPlot],
    caption: &Caption,
    png: &Path,
    svg: &Path,
) -> Result<(), PlotError> {
    check_columns(columns, png)?;
    if columns[0].dof == 2 {
        let figure = ArmFigure::new(columns);
        render(
            &Captioned {
                figure: &figure,
                caption,
            },
            png,
            svg,
        )
    } else {
        let figure = JointFigure::new(columns);
        render(
            &Captioned {
                figure: &figure,
                caption,
            },
            png,
            svg,
        )
    }
}

/// Lines of an error (log scale) against the feedback latency, one per strategy, with a bar from
/// the mean to the worst trial at each measured latency (neighbouring strategies' bars side by
/// side); a point with diverged trials is hollow, a latency where every trial diverged is a
/// cross at the top. The title above and the caption below. Writes PNG and SVG, 1070 px wide
/// (the legend in a strip on the right).
pub(crate) fn curve_figure(
    curves: &[Curve],
    caption: &Caption,
    y_label: &str,
    png: &Path,
    svg: &Path,
) -> Result<(), PlotError> {
    if curves.iter().all(|c| c.points.is_empty()) {
        return Err(PlotError::NoData {
            path: png.to_path_buf(),
            reason: "no points".into(),
        });
    }
    let figure = CurveFigure { curves, y_label };
    render(
        &Captioned {
            figure: &figure,
            caption,
        },
        png,
        svg,
    )
}

/// The stiffness lag study (`vic sweep stiffness-lag`): the realised stiffness of each time
/// constant's SOOC plan and the delay crossing against the time constant. PNG and SVG, 1100 ×
/// 480 px.
pub fn lag_figure(plot: &LagPlot, png: &Path, svg: &Path) -> Result<(), PlotError> {
    if plot.stiffness.is_empty() || plot.time.is_empty() {
        return Err(PlotError::NoData {
            path: png.to_path_buf(),
            reason: "no time constant".into(),
        });
    }
    render(&lag::LagFigure { plot }, png, svg)
}

/// Fig. 2 layout for a single joint: columns side by side; rows: angle [deg] of every trial with
/// the reference, velocity [deg/s] of every trial, commands (torque, stiffness) of every trial.
/// Rows share their y ranges across columns (the torques: each column its own); a second stiffness panel is added to row C when any
/// column has stiffness commands. Writes both PNG and SVG, `28 + 400 × columns` px wide and 1007
/// px tall (772 without stiffness commands).
pub fn joint_figure(columns: &[ColumnPlot], png: &Path, svg: &Path) -> Result<(), PlotError> {
    check_columns(columns, png)?;
    render(&JointFigure::new(columns), png, svg)
}

// ---------------------------------------------------------------------------------------------
// Rendering to files

pub(super) const FONT: &str = "sans-serif";
// Text sizes [px] chosen for a slide: a figure of five columns (2028 px) shown 1280 px wide
// keeps its tick labels at 9 px and its axis names at 10 px.
pub(super) const COLUMN_WIDTH: u32 = 400;
/// Left strip holding the row letters A, B, C.
pub(super) const GUTTER: u32 = 28;
/// Legend text [px].
pub(super) const LEGEND_SIZE: f64 = 14.0;
pub(super) const TITLE_SIZE: f64 = 20.0;
pub(super) const TICK_SIZE: f64 = 15.0;
pub(super) const DESC_SIZE: f64 = 16.0;
pub(super) const Y_LABEL_AREA: u32 = 76;
pub(super) const X_LABEL_AREA: u32 = 30;
pub(super) const X_LABEL_AREA_DESC: u32 = 52;
/// More points than this per curve are thinned (a panel is < 400 px wide).
pub(super) const MAX_POINTS: usize = 1500;
/// A column's spread larger than this many times the median column's is an outlier.
pub(super) const OUTLIER_FACTOR: f64 = 4.0;
/// Tail fraction left out on each side when measuring a column's range of a time series (none:
/// a column's own trials all fit unless the column is an outlier).
pub(super) const TAIL: f64 = 0.0;
/// Tail fraction left out on each side when measuring a column's spread of hand positions.
pub(super) const HAND_TAIL: f64 = 0.025;
pub(super) const RAD_TO_DEG: f64 = 180.0 / std::f64::consts::PI;

pub(super) const TRIAL_GREY: RGBColor = RGBColor(190, 190, 190);
pub(super) const MEAN_GREY: RGBColor = RGBColor(40, 40, 40);
pub(super) const BAND_BLUE: RGBColor = RGBColor(70, 130, 200);
pub(super) const ELLIPSE_RED: RGBColor = RGBColor(200, 30, 45);
pub(super) const GRID: RGBColor = RGBColor(228, 228, 228);
/// Diverged trials: their count, and their lines in the hand panel.
pub(super) const DIVERGED: RGBColor = RGBColor(215, 110, 0);
/// Opacity of a diverged trial's dashed line.
pub(super) const DIVERGED_ALPHA: f64 = 0.5;
/// Per joint (torque and stiffness of joint i share joint i's colour).
pub(super) const JOINT_COLOURS: [RGBColor; 4] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
];

pub(super) type DrawResult<T, DB> =
    Result<T, DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;
pub(super) type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A figure that can be drawn on any backend.
pub(super) trait Figure {
    /// Width and height [px].
    fn size(&self) -> (u32, u32);
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<(), DB>;
}

pub(super) fn check_columns(columns: &[ColumnPlot], path: &Path) -> Result<(), PlotError> {
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

/// The embedded DejaVu Sans font could not be registered with plotters.
#[derive(Debug, Clone, Copy, thiserror::Error)]
#[error("the embedded DejaVu Sans font could not be registered")]
pub(super) struct FontError;

/// Registers DejaVu Sans (regular and bold) as plotters' "sans-serif", once per process.
pub(super) fn register_fonts() -> Result<(), FontError> {
    static REGISTERED: OnceLock<Result<(), FontError>> = OnceLock::new();
    *REGISTERED.get_or_init(|| {
        let fonts = [
            (FontStyle::Normal, dejavu::sans::regular()),
            (FontStyle::Bold, dejavu::sans::bold()),
        ];
        for (style, bytes) in fonts {
            plotters::style::register_font(FONT, style, bytes).map_err(|_| FontError)?;
        }
        Ok(())
    })
}

pub(super) fn draw_error<E: std::error::Error + Send + Sync>(
    path: &Path,
    error: DrawingAreaErrorKind<E>,
) -> PlotError {
    PlotError::Draw {
        path: path.to_path_buf(),
        message: error.to_string(),
    }
}

pub(super) fn render(figure: &impl Figure, png: &Path, svg: &Path) -> Result<(), PlotError> {
    register_fonts().map_err(|e| PlotError::Draw {
        path: png.to_path_buf(),
        message: e.to_string(),
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

    /// A single joint's column: per trial `(angle scale [rad], torque)`; trial `i`'s angle
    /// rises linearly to its scale over 1 s, its torque is constant.
    fn joint_column(trials: &[(f64, f64)], diverged: Vec<bool>) -> ColumnPlot {
        let time: Vec<f64> = (0..=10).map(|k| 0.1 * k as f64).collect();
        ColumnPlot {
            title: "c".into(),
            dof: 1,
            q: trials
                .iter()
                .map(|(a, _)| time.iter().map(|t| vec![a * t]).collect())
                .collect(),
            qd: trials
                .iter()
                .map(|(a, _)| time.iter().map(|_| vec![*a]).collect())
                .collect(),
            u: trials
                .iter()
                .map(|(_, tau)| time[1..].iter().map(|_| vec![*tau]).collect())
                .collect(),
            control_names: vec!["tau1".into()],
            reference_q: time.iter().map(|t| vec![*t]).collect(),
            time,
            diverged,
            ..Default::default()
        }
    }

    #[test]
    fn a_diverged_trial_sets_no_axis_range() {
        let trials = [(1.0, 0.5), (1.1, -0.4), (200.0, 5e4)];
        let marked = [joint_column(&trials, vec![false, false, true])];
        let f = JointFigure::new(&marked);
        let deg = RAD_TO_DEG;
        assert!(f.axes.angle.1 < 1.2 * deg, "{:?}", f.axes.angle);
        assert!(f.axes.velocity.1 < 1.2 * deg, "{:?}", f.axes.velocity);
        assert!(f.axes.torque[0].1 < 1.0, "{:?}", f.axes.torque);
        // The same trials unmarked: the blow-up sets the ranges (the property above can fail).
        let unmarked = [joint_column(&trials, vec![])];
        let f = JointFigure::new(&unmarked);
        assert!(f.axes.angle.1 > 100.0 * deg && f.axes.torque[0].1 >= 5e4);
    }

    #[test]
    fn each_columns_torque_range_comes_from_its_own_trials() {
        let columns = [
            joint_column(&[(1.0, 0.3), (1.0, -0.2)], vec![]),
            joint_column(&[(1.0, 80.0), (1.0, -10.0)], vec![]),
            // Every trial diverged: the others' range, not its blow-up.
            joint_column(&[(1.0, 1e6), (1.0, -1e6)], vec![true, true]),
        ];
        let t = JointFigure::new(&columns).axes.torque;
        assert!(t[0].0 < -0.2 && t[0].1 > 0.3 && t[0].1 < 0.5, "{t:?}");
        assert!(t[1].0 < -10.0 && t[1].1 > 80.0, "{t:?}");
        assert!(
            t[2].0 >= t[1].0 && t[2].1 <= t[1].1 && t[2].1 > 80.0,
            "{t:?}"
        );
    }

    #[test]
    fn the_arm_leaves_diverged_trials_out_of_its_statistics_and_its_view() {
        let time: Vec<f64> = (0..=10).map(|k| 0.1 * k as f64).collect();
        let path = |dx: f64, far: f64| -> Vec<[f64; 2]> {
            time.iter()
                .map(|t| [dx + far * t * t, 0.3 + 0.25 * t])
                .collect()
        };
        let col = ColumnPlot {
            title: "arm".into(),
            dof: 2,
            hand: vec![path(-0.002, 0.0), path(0.002, 0.0), path(0.0, 3.0)],
            reference_hand: path(0.0, 0.0),
            diverged: vec![false, false, true],
            time: time.clone(),
            ..Default::default()
        };
        let stats = arm_stats(&col);
        let end = stats.hand_mean.last().unwrap();
        assert!(end.0.abs() < 1e-9, "mean of the two kept trials: {end:?}");
        let view = hand_view(std::slice::from_ref(&col), &[stats]);
        assert!(view.x1 < 0.2, "{view:?}");
        let mut all = col.clone();
        all.diverged.clear();
        let stats = arm_stats(&all);
        assert!(stats.hand_mean.last().unwrap().0 > 0.9);
    }

    #[test]
    fn the_note_counts_the_diverged_trials_and_says_what_the_ellipse_is_of() {
        let mut col = joint_column(&[(1.0, 0.0); 4], vec![false, true, false, true]);
        assert_eq!(
            divergence_note(&col, false).as_deref(),
            Some("2 of 4 trials diverged (dashed)")
        );
        col.ellipse = Some(([0.0; 2], [0.01; 2], 0.0));
        assert_eq!(
            divergence_note(&col, true).as_deref(),
            Some("2 of 4 trials diverged (dashed), ellipse of the other 2")
        );
        col.diverged.clear();
        assert_eq!(divergence_note(&col, true), None);
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
