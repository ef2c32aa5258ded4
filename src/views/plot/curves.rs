//! Error versus latency, one line per strategy: the delay-versus-stiffness curve.

use super::*;

/// One strategy's line: `(latency [ms], mean, max, diverged fraction)` per latency, the mean and
/// max over the trials that did not diverge; a missing value (every trial diverged) breaks the
/// line and is marked at the top of the frame.
#[derive(Debug, Clone)]
pub(crate) struct Curve {
    pub(crate) name: String,
    pub(crate) points: Vec<CurvePoint>,
}

/// `(latency [ms], mean, max, diverged fraction)`.
pub(crate) type CurvePoint = (f64, Option<f64>, Option<f64>, f64);

pub(super) struct CurveFigure<'a> {
    pub(super) curves: &'a [Curve],
    pub(super) y_label: &'a str,
}

const CURVE_COLOURS: [RGBColor; 5] = [
    RGBColor(200, 30, 45),
    RGBColor(70, 130, 200),
    RGBColor(40, 40, 40),
    RGBColor(230, 140, 20),
    RGBColor(60, 160, 90),
];

/// Width of the plot, left of the legend's strip [px].
const PLOT_WIDTH: u32 = 820;
/// Width of the legend's strip right of the chart [px].
const LEGEND_WIDTH: u32 = 250;
/// Sideways offset between the error bars of neighbouring strategies at one latency, as a
/// fraction of the latency axis: bars at the same latency stand side by side, not on top of
/// each other.
const DODGE: f64 = 0.007;
/// Half the width of an error bar's cap, as a fraction of the latency axis.
const CAP: f64 = 0.35 * DODGE;

/// The sideways offset [ms] of strategy `i` of `n` at every latency of an axis to `x_max`.
pub(super) fn dodge(i: usize, n: usize, x_max: f64) -> f64 {
    (i as f64 - (n as f64 - 1.0) / 2.0) * DODGE * x_max
}

/// The y range of a log axis over the finite positive means and maxima: from a power of ten
/// below the smallest (plotters labels a log axis from its first power of ten) to twice the
/// largest, which leaves room for the crosses of all-diverged points at the top.
pub(super) fn curve_y_range(curves: &[Curve]) -> (f64, f64) {
    let values: Vec<f64> = curves
        .iter()
        .flat_map(|c| c.points.iter().flat_map(|p| [p.1, p.2]).flatten())
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(0.0, f64::max);
    if lo.is_finite() && hi > lo {
        (0.999 * 10f64.powf((lo / 1.5).log10().floor()), hi * 2.0)
    } else if lo.is_finite() {
        (0.999 * 10f64.powf((lo / 1.5).log10().floor()), lo * 10.0)
    } else {
        (1e-3, 1.0)
    }
}

/// The horizontal grid lines of a log axis over `lo..hi`: at 1, 2 and 5 times a power of ten.
pub(super) fn log_grid(lo: f64, hi: f64) -> Vec<f64> {
    let mut out = Vec::new();
    let mut decade = 10f64.powf(lo.log10().floor());
    while decade <= hi {
        for m in [1.0, 2.0, 5.0] {
            let v = m * decade;
            if v >= lo && v <= hi {
                out.push(v);
            }
        }
        decade *= 10.0;
    }
    out
}

impl Figure for CurveFigure<'_> {
    fn size(&self) -> (u32, u32) {
        (PLOT_WIDTH + LEGEND_WIDTH, 560)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<(), DB> {
        let (lo, hi) = curve_y_range(self.curves);
        let x_max = self
            .curves
            .iter()
            .flat_map(|c| c.points.iter().map(|p| p.0))
            .fold(1.0, f64::max);
        let pad = 0.04 * x_max;
        // The legend has a strip of its own on the right, so that it never hides a curve or the
        // crosses of diverged points at the top of the frame.
        let (plot, key) = root.split_horizontally(PLOT_WIDTH);
        let mut chart = ChartBuilder::on(&plot)
            .margin(14)
            .x_label_area_size(50)
            .y_label_area_size(Y_LABEL_AREA + 16)
            .build_cartesian_2d(-pad..x_max + pad, (lo..hi).log_scale())?;
        // Grid lines only where there is a label: the log axis' lines at every integer
        // multiple of a power of ten make grey bands.
        chart
            .configure_mesh()
            .disable_y_mesh()
            .max_light_lines(0)
            .bold_line_style(GRID)
            .x_desc("feedback latency [ms]")
            .y_desc(self.y_label)
            .y_labels(40)
            .y_label_formatter(&|v| log_tick(*v))
            .x_label_formatter(&|v| tick(*v))
            .label_style((FONT, TICK_SIZE).into_font())
            .axis_desc_style((FONT, DESC_SIZE).into_font())
            .draw()?;
        for y in log_grid(lo, hi) {
            chart.draw_series(std::iter::once(PathElement::new(
                vec![(-pad, y), (x_max + pad, y)],
                GRID.stroke_width(1),
            )))?;
        }
        let n = self.curves.len();
        for (i, c) in self.curves.iter().enumerate() {
            let colour = CURVE_COLOURS[i % CURVE_COLOURS.len()];
            let dx = dodge(i, n, x_max);
            // The spread from the mean to the worst trial: a bar at each measured latency.
            for &(x, m, w, _) in &c.points {
                if let (Some(m), Some(w)) = (m, w)
                    && m > 0.0
                    && w >= m
                {
                    let x = x + dx;
                    let bar = colour.mix(0.55).stroke_width(2);
                    chart.draw_series(std::iter::once(PathElement::new(
                        vec![(x, m), (x, w)],
                        bar,
                    )))?;
                    let cap = CAP * x_max;
                    chart.draw_series(std::iter::once(PathElement::new(
                        vec![(x - cap, w), (x + cap, w)],
                        bar,
                    )))?;
                }
            }
            let segments = runs(
                c.points
                    .iter()
                    .map(|&(x, m, _, _)| m.filter(|m| *m > 0.0).map(|m| (x + dx, m))),
            );
            let style = colour.stroke_width(3);
            for s in segments.into_iter().filter(|s| !s.is_empty()) {
                chart.draw_series(LineSeries::new(s, style))?;
            }
            // A point whose mean leaves some diverged trials out: a hollow marker.
            for &(x, m, _, lost) in &c.points {
                let Some(m) = m.filter(|m| *m > 0.0) else {
                    continue;
                };
                let p = (x + dx, m);
                if lost > 0.0 {
                    chart.draw_series(std::iter::once(Circle::new(p, 6, WHITE.filled())))?;
                    chart.draw_series(std::iter::once(Circle::new(
                        p,
                        6,
                        colour.stroke_width(2),
                    )))?;
                } else {
                    chart.draw_series(std::iter::once(Circle::new(p, 5, colour.filled())))?;
                }
            }
            // Every trial diverged: a cross at the top of the frame.
            chart.draw_series(
                c.points
                    .iter()
                    .filter(|p| p.1.is_none())
                    .map(|p| Cross::new((p.0 + dx, hi / 1.3), 7, colour.stroke_width(3))),
            )?;
        }
        draw_key(&key, self.curves)?;
        Ok(())
    }
}

/// The legend, in its own strip: one line per curve, then what a bar, a hollow marker and a
/// cross mean.
fn draw_key<DB: DrawingBackend>(
    key: &DrawingArea<DB, Shift>,
    curves: &[Curve],
) -> DrawResult<(), DB> {
    let font = (FONT, DESC_SIZE).into_font();
    let row = |i: usize| 40 + 26 * i as i32;
    for (i, c) in curves.iter().enumerate() {
        let colour = CURVE_COLOURS[i % CURVE_COLOURS.len()];
        key.draw(&PathElement::new(
            [(4, row(i)), (30, row(i))],
            colour.stroke_width(3),
        ))?;
        key.draw(&Circle::new((17, row(i)), 5, colour.filled()))?;
        key.draw(&Text::new(c.name.clone(), (38, row(i) - 8), font.clone()))?;
    }
    let grey = RGBColor(90, 90, 90);
    let mut y = row(curves.len()) + 14;
    key.draw(&PathElement::new(
        [(17, y - 9), (17, y + 9)],
        grey.stroke_width(2),
    ))?;
    key.draw(&PathElement::new(
        [(12, y - 9), (22, y - 9)],
        grey.stroke_width(2),
    ))?;
    key.draw(&Text::new("mean to worst trial", (38, y - 8), font.clone()))?;
    let points = || curves.iter().flat_map(|c| c.points.iter());
    if points().any(|p| p.1.is_some() && p.3 > 0.0) {
        y += 26;
        key.draw(&Circle::new((17, y), 6, grey.stroke_width(2)))?;
        key.draw(&Text::new(
            "some trials diverged",
            (38, y - 8),
            font.clone(),
        ))?;
    }
    if points().any(|p| p.1.is_none()) {
        y += 26;
        key.draw(&Cross::new((17, y), 7, grey.stroke_width(3)))?;
        key.draw(&Text::new("all trials diverged", (38, y - 8), font))?;
    }
    Ok(())
}

/// A label at 1, 2 and 5 times a power of ten (`tick`), none at the grid's other lines.
fn log_tick(v: f64) -> String {
    let mantissa = v / 10f64.powf(v.log10().floor());
    match [1.0, 2.0, 5.0, 10.0]
        .iter()
        .any(|m| (mantissa - m).abs() < 1e-6 * m)
    {
        true => tick(v),
        false => String::new(),
    }
}

/// A tick label: as few digits as the value needs (`5`, `0.05`, `200`).
fn tick(v: f64) -> String {
    if v != 0.0 && v.abs() < 1e-3 {
        return format!("{v:.0e}");
    }
    let s = format!("{v:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    s.to_string()
}

/// The runs of consecutive `Some` values.
fn runs<T>(values: impl Iterator<Item = Option<T>>) -> Vec<Vec<T>> {
    let mut out = vec![Vec::new()];
    for v in values {
        match v {
            Some(v) => out.last_mut().expect("non-empty").push(v),
            None => out.push(Vec::new()),
        }
    }
    out.retain(|r| !r.is_empty());
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_axis_labels_only_1_2_5_and_with_no_trailing_zeros() {
        let labels: Vec<String> = [0.01, 0.03, 0.05, 0.2, 1.0, 3.0, 20.0, 500.0, 700.0]
            .iter()
            .map(|v| log_tick(*v))
            .collect();
        assert_eq!(
            labels,
            ["0.01", "", "0.05", "0.2", "1", "", "20", "500", ""]
        );
        assert_eq!(tick(1.8e-4), "2e-4");
        assert_eq!(tick(250.0), "250");
    }

    #[test]
    fn grid_lines_only_at_the_labelled_values() {
        let lines = log_grid(0.0999, 60.0);
        let expected = [0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0];
        assert_eq!(lines.len(), expected.len(), "{lines:?}");
        for (v, e) in lines.iter().zip(expected) {
            assert!((v / e - 1.0).abs() < 1e-9, "{lines:?}");
        }
        assert!(lines.iter().all(|v| !log_tick(*v).is_empty()));
    }

    #[test]
    fn the_bars_of_strategies_at_one_latency_stand_apart() {
        let x_max = 300.0;
        for n in 1..=5 {
            let offsets: Vec<f64> = (0..n).map(|i| dodge(i, n, x_max)).collect();
            // Centred on the latency, and no two bars' caps touch.
            assert!(offsets.iter().sum::<f64>().abs() < 1e-9, "{offsets:?}");
            for w in offsets.windows(2) {
                assert!(w[1] - w[0] > 2.0 * CAP * x_max, "{offsets:?}");
            }
            // Still well inside the spacing of the sweep's latencies (20 ms at 300).
            assert!(offsets.iter().all(|d| d.abs() < 0.3 * 20.0), "{offsets:?}");
        }
    }

    #[test]
    fn the_y_range_holds_every_mean_and_worst_trial() {
        let curves = [
            Curve {
                name: "a".into(),
                points: vec![(0.0, Some(0.02), Some(0.05), 0.0), (100.0, None, None, 1.0)],
            },
            Curve {
                name: "b".into(),
                points: vec![(0.0, Some(3.0), Some(40.0), 0.1)],
            },
        ];
        let (lo, hi) = curve_y_range(&curves);
        assert!(lo <= 0.02 && hi >= 40.0 * 1.3, "{lo}..{hi}");
        assert!(lo > 0.001, "{lo}");
    }
}
