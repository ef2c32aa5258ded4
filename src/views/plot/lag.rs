//! The stiffness lag study (`vic sweep stiffness-lag`): left, the stiffness the SOOC plan
//! realises at the first joint over the movement, one line per time constant `τ_K`; right, the
//! latency up to which the predictor ends closer to the target than the planned stiffness,
//! against `τ_K`.

use super::*;

/// `(τ_K [s], crossing latency [ms], the bracket of sweep latencies it lies in)`.
pub type CrossingPoint = (f64, f64, Option<(f64, f64)>);

/// What the figure draws, per time constant `τ_K` [s].
#[derive(Debug, Clone, Default)]
pub struct LagPlot {
    /// Knot times [s].
    pub time: Vec<f64>,
    /// `(τ_K, the first joint's realised stiffness per knot [N m/rad])`.
    pub stiffness: Vec<(f64, Vec<f64>)>,
    /// Per time constant: where the predictor stops beating the planned stiffness.
    pub crossing: Vec<CrossingPoint>,
}

pub(super) struct LagFigure<'a> {
    pub(super) plot: &'a LagPlot,
}

/// Light (small τ_K) to dark (large τ_K) blue.
fn shade(i: usize, n: usize) -> RGBColor {
    let t = if n > 1 {
        i as f64 / (n - 1) as f64
    } else {
        1.0
    };
    let mix = |a: f64, b: f64| (a + (b - a) * t).round() as u8;
    RGBColor(mix(150.0, 10.0), mix(200.0, 40.0), mix(240.0, 110.0))
}

impl Figure for LagFigure<'_> {
    fn size(&self) -> (u32, u32) {
        (1100, 480)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<(), DB> {
        let s = self.plot;
        let (left, right) = root.split_horizontally(620);
        let k_max = s
            .stiffness
            .iter()
            .flat_map(|(_, k)| k.iter().copied())
            .filter(|v| v.is_finite())
            .fold(1.0, f64::max);
        let t_max = s.time.last().copied().unwrap_or(1.0);
        let mut chart = ChartBuilder::on(&left)
            .caption(
                "Realised stiffness of the SOOC plan, joint 1",
                (FONT, TITLE_SIZE).into_font(),
            )
            .margin(14)
            .x_label_area_size(40)
            .y_label_area_size(Y_LABEL_AREA)
            .build_cartesian_2d(0.0..t_max, 0.0..k_max * 1.1)?;
        chart
            .configure_mesh()
            .light_line_style(GRID)
            .x_desc("time [s]")
            .y_desc("stiffness K1 [N m/rad]")
            .label_style((FONT, TICK_SIZE).into_font())
            .axis_desc_style((FONT, DESC_SIZE).into_font())
            .draw()?;
        let n = s.stiffness.len();
        for (i, (tau, k)) in s.stiffness.iter().enumerate() {
            let colour = shade(i, n);
            let line: Vec<(f64, f64)> = s
                .time
                .iter()
                .zip(k)
                .map(|(t, k)| (*t, *k))
                .filter(|(_, k)| k.is_finite())
                .collect();
            chart
                .draw_series(LineSeries::new(line, colour.stroke_width(2)))?
                .label(format!("τ_K = {tau} s"))
                .legend(move |(x, y)| {
                    PathElement::new([(x, y), (x + 20, y)], colour.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.3))
            .label_font((FONT, TICK_SIZE).into_font())
            .draw()?;

        let tau_max = s.crossing.iter().map(|c| c.0).fold(0.1, f64::max);
        // Up to the highest latency a crossing's bracket reaches.
        let l_max = s
            .crossing
            .iter()
            .map(|&(_, at, bracket)| bracket.map_or(at, |b| b.1))
            .fold(10.0, f64::max);
        let mut chart = ChartBuilder::on(&right)
            .caption("Delay crossing", (FONT, TITLE_SIZE).into_font())
            .margin(14)
            .x_label_area_size(40)
            .y_label_area_size(Y_LABEL_AREA)
            .build_cartesian_2d(-0.02 * tau_max..tau_max * 1.05, 0.0..l_max * 1.05)?;
        chart
            .configure_mesh()
            .light_line_style(GRID)
            .x_desc("stiffness time constant τ_K [s]")
            .y_desc("predictor better up to [ms]")
            .label_style((FONT, TICK_SIZE).into_font())
            .axis_desc_style((FONT, DESC_SIZE).into_font())
            .draw()?;
        let crossing: Vec<(f64, f64)> = s.crossing.iter().map(|c| (c.0, c.1)).collect();
        let ink = RGBColor(200, 30, 45);
        chart.draw_series(LineSeries::new(crossing.clone(), ink.stroke_width(2)))?;
        chart.draw_series(crossing.iter().map(|&p| Circle::new(p, 4, ink.filled())))?;
        // The bracket of sweep latencies the crossing lies in.
        chart.draw_series(s.crossing.iter().filter_map(|&(tau, _, bracket)| {
            let (below, above) = bracket?;
            Some(PathElement::new(
                [(tau, below), (tau, above)],
                ink.mix(0.5).stroke_width(1),
            ))
        }))?;
        Ok(())
    }
}
