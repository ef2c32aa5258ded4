//! Error versus latency, one line per strategy: the delay-versus-stiffness curve.

use super::*;

/// One strategy's line: `(latency [ms], mean, max)` per latency; a missing value (every trial
/// diverged) breaks the line and is marked at the top of the frame.
#[derive(Debug, Clone)]
pub struct Curve {
    pub name: String,
    pub points: Vec<(f64, Option<f64>, Option<f64>)>,
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
        (760, 520)
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
        let (lo, hi) = if lo.is_finite() && hi > lo {
            (lo / 2.0, hi * 2.0)
        } else {
            (1e-3, 1.0)
        };
        let x_max = self
            .curves
            .iter()
            .flat_map(|c| c.points.iter().map(|p| p.0))
            .fold(1.0, f64::max);
        let mut chart = ChartBuilder::on(root)
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
            let mut labelled = false;
            for s in segments.into_iter().filter(|s| !s.is_empty()) {
                let series = chart.draw_series(LineSeries::new(s.clone(), style))?;
                if !labelled {
                    series
                        .label(c.name.as_str())
                        .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], style));
                    labelled = true;
                }
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
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.3))
            .label_font((FONT, TICK_SIZE).into_font())
            .draw()?;
        Ok(())
    }
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
