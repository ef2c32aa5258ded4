//! Fig. 1: the two-link arm (hand paths with the final-position ellipse, joint angles and
//! velocities, commands).

use super::*;

/// Pixel heights of the arm figure's panels: hand path (with the title), angle, velocity,
/// torque, stiffness (the last one only when some column has stiffness commands).
pub(super) const ARM_HAND_HEIGHT: u32 = 400;
pub(super) const ARM_TIME_HEIGHT: u32 = 185;

pub(super) struct ArmFigure<'a> {
    pub(super) axes: ColumnAxes<'a>,
    pub(super) stats: Vec<ArmStats>,
    /// Hand-path region shared by all columns (before equalising the axis scales).
    pub(super) hand_view: View,
}

/// Per knot: mean and standard deviation.
pub(super) type MeanStd = (Vec<f64>, Vec<f64>);
/// A polygon's vertices in data coordinates.
pub(super) type Polygon2 = Vec<(f64, f64)>;

/// Per-column statistics over trials.
pub(super) struct ArmStats {
    /// Per joint: mean and std of the angle [deg] and of the velocity [deg/s] at each knot.
    pub(super) angle: Vec<MeanStd>,
    pub(super) velocity: Vec<MeanStd>,
    pub(super) hand_mean: Vec<(f64, f64)>,
    /// ±1 std across the mean path, as polygons.
    pub(super) hand_band: Vec<Vec<(f64, f64)>>,
}

impl<'a> ArmFigure<'a> {
    pub(super) fn new(columns: &'a [ColumnPlot]) -> Self {
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
        let angle = shared_range(
            band_values(|s| &s.angle),
            &reference_degrees(columns),
            false,
        );
        let velocity = shared_range(band_values(|s| &s.velocity), &[], false);
        ArmFigure {
            axes: ColumnAxes::new(columns, angle, velocity),
            hand_view: hand_view(columns, &stats),
            stats,
        }
    }

    pub(super) fn draw_hand<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        c: usize,
    ) -> DrawResult<(), DB> {
        let col = &self.axes.columns[c];
        let stats = &self.stats[c];
        let area = column_titled(area, self.axes.columns, c, true)?;
        let (w, h) = hand_chart(&area, self.hand_view)?
            .plotting_area()
            .dim_in_pixel();
        let view = equal_aspect(self.hand_view, w, h);
        let mut chart = hand_chart(&area, view)?;
        house_mesh(&mut chart.configure_mesh(), 5, 6)
            .x_desc("x [m]")
            .y_desc("y [m]")
            .draw()?;
        if col.hand.is_empty() {
            return note(&mut chart, "no hand path");
        }
        for trial in col.kept(&col.hand) {
            lines(
                &mut chart,
                &view,
                trial.iter().map(|p| (p[0], p[1])),
                thin(&TRIAL_GREY),
            )?;
        }
        for trial in col.lost(&col.hand) {
            let points: Vec<(f64, f64)> = trial.iter().map(|p| (p[0], p[1])).collect();
            dashed(&mut chart, &view, &points, diverged_style())?;
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
            if self.axes.columns.iter().any(|c| c.n_diverged() > 0) {
                legend_dashed(&mut chart, "diverged trial", diverged_style())?;
            }
            let drawn: Vec<(f64, f64)> = col
                .kept(&col.hand)
                .flatten()
                .map(|p| (p[0], p[1]))
                .chain(stats.hand_band.iter().flatten().copied())
                .collect();
            legend(&mut chart, quiet_corner(&view, &drawn))?;
        }
        Ok(())
    }

    /// Mean ± std of one joint quantity (angles or velocities) of every joint.
    pub(super) fn draw_joint_stats<'c, DB: DrawingBackend + 'c>(
        &self,
        chart: &mut Chart<'c, DB>,
        c: usize,
        angles: bool,
    ) -> DrawResult<(), DB> {
        let col = &self.axes.columns[c];
        let view = View::of(chart);
        let stats = if angles {
            &self.stats[c].angle
        } else {
            &self.stats[c].velocity
        };
        let mut drawn = Vec::new();
        let trials = if angles { &col.q } else { &col.qd };
        for (j, (mean, sd)) in stats.iter().enumerate() {
            let colour = joint_colour(j);
            // Diverged trials are left out of the mean and the band; each is drawn on its own.
            for trial in col.lost(trials) {
                let points = joint_degrees(&col.time, trial, j);
                dashed(
                    chart,
                    &view,
                    &points,
                    colour.mix(DIVERGED_ALPHA).stroke_width(1),
                )?;
            }
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
                let reference = joint_degrees(&col.time, &col.reference_q, j);
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

impl ColumnFigure for ArmFigure<'_> {
    const LETTER_PANELS: [usize; 3] = [0, 1, 3];

    fn axes(&self) -> &ColumnAxes<'_> {
        &self.axes
    }

    fn own_heights(&self) -> (Vec<u32>, u32) {
        let h = vec![ARM_HAND_HEIGHT, ARM_TIME_HEIGHT, ARM_TIME_HEIGHT];
        (h, ARM_TIME_HEIGHT)
    }

    fn draw_own<DB: DrawingBackend>(
        &self,
        c: usize,
        panels: &[DrawingArea<DB, Shift>],
    ) -> DrawResult<(), DB> {
        self.draw_hand(&panels[0], c)?;
        let rows: [(&str, (f64, f64)); 2] = [
            ("angle [deg]", self.axes.angle),
            ("velocity [deg/s]", self.axes.velocity),
        ];
        for (r, (desc, range)) in rows.into_iter().enumerate() {
            let mut chart = time_chart(&panels[1 + r], self.axes.time, range, desc, false)?;
            self.draw_joint_stats(&mut chart, c, r == 0)?;
        }
        Ok(())
    }
}

/// The statistics of the trials of `col` that did not diverge.
pub(super) fn arm_stats(col: &ColumnPlot) -> ArmStats {
    let knots = col.time.len();
    let joint = |data: &[Vec<Vec<f64>>]| -> Vec<MeanStd> {
        let kept: Vec<Vec<Vec<f64>>> = col.kept(data).cloned().collect();
        (0..col.dof)
            .map(|j| mean_std(&kept, knots, |knot| knot.get(j).map(|v| v * RAD_TO_DEG)))
            .collect()
    };
    let hand: Vec<Vec<[f64; 2]>> = col.kept(&col.hand).cloned().collect();
    let (hand_mean, hand_band) = hand_statistics(&hand, knots);
    ArmStats {
        angle: joint(&col.q),
        velocity: joint(&col.qd),
        hand_mean,
        hand_band,
    }
}

/// Per knot: mean and sample std over the trials with a finite value there (NaN where undefined).
pub(super) fn mean_std(
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
pub(super) fn hand_statistics(
    hand: &[Vec<[f64; 2]>],
    knots: usize,
) -> (Vec<(f64, f64)>, Vec<Polygon2>) {
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
/// trials that did not diverge (central 95 %) and its ellipses unless that column is an outlier (it spreads more than
/// twice as far as the reference path or the median column), plus a margin.
pub(super) fn hand_view(columns: &[ColumnPlot], stats: &[ArmStats]) -> View {
    let reference = Bounds::of(
        columns
            .iter()
            .flat_map(|c| c.reference_hand.iter().map(|p| (p[0], p[1]))),
    );
    let column_bounds: Vec<Bounds> = columns
        .iter()
        .zip(stats)
        .map(|(c, s)| {
            let points = c.kept(&c.hand).flatten();
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
pub(super) fn equal_aspect(view: View, w: u32, h: u32) -> View {
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

pub(super) fn hand_chart<'a, DB: DrawingBackend>(
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

/// A diverged trial's hand path: dashed, faded.
pub(super) fn diverged_style() -> ShapeStyle {
    DIVERGED.mix(DIVERGED_ALPHA).stroke_width(1)
}

pub(super) fn ellipse_points(centre: [f64; 2], axes: [f64; 2], angle: f64) -> Vec<(f64, f64)> {
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
