//! Error versus latency, one line per strategy: the delay-versus-stiffness curve.

use super::*;

/// One strategy's line: `(latency [ms], mean, max)` per latency; a missing value (every trial
/// diverged) breaks the line and is marked at the top of the frame.
#[derive(Debug, Clone)]
pub(crate) struct Curve {
    pub(crate) name: String,
    pub(crate) points: Vec<(f64, Option<f64>, Option<f64>)>,
}

pub(super) struct CurveFigure<'a> {
    pub(super) curves: &'a [Curve],
    pub(super) title: &'a str,
    pub(super) y_label: &'a str,
}

const CURVE_COLOURS: [RGBColor; 5] = [
    RGBColor(200, 30, 45),
    RGBColor(70, 130, 200),
    RGBColor(40, 40, 40),
    RGBColor(230, 140, 20),
    RGBColor(60, 160, 90),
];

impl Figure for CurveFigure<'_> {
    fn size(&self) -> (u32, u32) {
        (760 + LEGEND_WIDTH, 520)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<(), DB> {
        let values: Vec<f64> = self
            .curves
            .iter()
            .flat_map(|c| c.points.iter().flat_map(|p| [p.1, p.2]).flatten())
            .filter(|v| v.is_finite() && *v > 0.0)
            .collect();
        let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = values.iter().copied().fold(0.0, f64::max);
        // The bottom at a power of ten: plotters labels a log axis from its first power of ten.
        let (lo, hi) = if lo.is_finite() && hi > lo {
            (0.999 * 10f64.powf((lo / 1.5).log10().floor()), hi * 2.0)
        } else {
            (1e-3, 1.0)
        };
        let x_max = self
            .curves
            .iter()
            .flat_map(|c| c.points.iter().map(|p| p.0))
            .fold(1.0, f64::max);
        // The legend has a strip of its own on the right, so that it never hides a curve or the
        // crosses of diverged points at the top of the frame.
        let (plot, key) = root.split_horizontally(760);
        let mut chart = ChartBuilder::on(&plot)
            .caption(self.title, (FONT, TITLE_SIZE).into_font())
            .margin(14)
            .x_label_area_size(40)
            .y_label_area_size(Y_LABEL_AREA + 10)
            .build_cartesian_2d(0.0..x_max * 1.03, (lo..hi).log_scale())?;
        chart
            .configure_mesh()
            .light_line_style(GRID)
            .x_desc("feedback latency [ms]")
            .y_desc(self.y_label)
            .y_labels(40)
            .y_label_formatter(&|v| log_tick(*v))
            .x_label_formatter(&|v| tick(*v))
            .label_style((FONT, TICK_SIZE).into_font())
            .axis_desc_style((FONT, DESC_SIZE).into_font())
            .draw()?;
        for (i, c) in self.curves.iter().enumerate() {
            let colour = CURVE_COLOURS[i % CURVE_COLOURS.len()];
            // The spread from the mean to the worst trial, shaded, broken where a latency has
            // no value like the line.
            for band in runs(c.points.iter().map(|&(x, m, w)| Some((x, m?, w?)))) {
                if band.len() > 1 {
                    let mut poly: Vec<(f64, f64)> = band.iter().map(|p| (p.0, p.2)).collect();
                    poly.extend(band.iter().rev().map(|p| (p.0, p.1)));
                    chart.draw_series(std::iter::once(Polygon::new(poly, colour.mix(0.15))))?;
                }
            }
            let segments = runs(
                c.points
                    .iter()
                    .map(|&(x, m, _)| m.filter(|m| *m > 0.0).map(|m| (x, m))),
            );
            let style = colour.stroke_width(2);
            for s in segments.into_iter().filter(|s| !s.is_empty()) {
                chart.draw_series(LineSeries::new(s.clone(), style))?;
                chart.draw_series(s.iter().map(|&p| Circle::new(p, 3, colour.filled())))?;
            }
            // Every trial diverged: a cross at the top of the frame.
            chart.draw_series(
                c.points
                    .iter()
                    .filter(|p| p.1.is_none())
                    .map(|p| Cross::new((p.0, hi / 1.3), 6, colour.stroke_width(2))),
            )?;
        }
        draw_key(&key, self.curves)?;
        Ok(())
    }
}

/// Width of the legend's strip right of the chart [px].
const LEGEND_WIDTH: u32 = 170;

/// The legend, in its own strip: one line per curve, and what a cross means.
fn draw_key<DB: DrawingBackend>(
    key: &DrawingArea<DB, Shift>,
    curves: &[Curve],
) -> DrawResult<(), DB> {
    let font = (FONT, TICK_SIZE).into_font();
    let row = |i: usize| 60 + 22 * i as i32;
    for (i, c) in curves.iter().enumerate() {
        let style = CURVE_COLOURS[i % CURVE_COLOURS.len()].stroke_width(2);
        key.draw(&PathElement::new([(4, row(i)), (26, row(i))], style))?;
        key.draw(&Text::new(c.name.clone(), (32, row(i) - 7), font.clone()))?;
    }
    if curves
        .iter()
        .any(|c| c.points.iter().any(|p| p.1.is_none()))
    {
        let y = row(curves.len()) + 8;
        key.draw(&Cross::new((15, y), 6, BLACK.stroke_width(2)))?;
        key.draw(&Text::new("all trials diverged", (32, y - 7), font))?;
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
}
