//! Panels and legends shared by both figures.

use super::*;

#[derive(Clone, Copy, PartialEq)]
pub(super) enum Commands {
    Torque,
    Stiffness,
}

impl Commands {
    pub(super) fn name(self) -> &'static str {
        match self {
            Commands::Torque => "torque",
            Commands::Stiffness => "stiffness",
        }
    }

    pub(super) fn desc(self) -> &'static str {
        match self {
            Commands::Torque => "torque [N m]",
            Commands::Stiffness => "stiffness [N m/rad]",
        }
    }

    /// Indices of this kind of command in a column's control vector.
    pub(super) fn indices(self, col: &ColumnPlot) -> std::ops::Range<usize> {
        match self {
            Commands::Torque => 0..n_torques(col),
            Commands::Stiffness => n_torques(col)..n_controls(col),
        }
    }
}

/// Number of commands per step (from the names, or the data when they are missing).
pub(super) fn n_controls(col: &ColumnPlot) -> usize {
    if col.control_names.is_empty() {
        col.u.iter().flatten().map(Vec::len).max().unwrap_or(0)
    } else {
        col.control_names.len()
    }
}

/// The first `dof` commands are torques, the rest stiffnesses.
pub(super) fn n_torques(col: &ColumnPlot) -> usize {
    n_controls(col).min(col.dof.max(1))
}

/// A command's name as a legend writes it: the plan's `tau1` and `k1` as the symbols τ₁ and K₁.
pub(super) fn control_name(col: &ColumnPlot, i: usize) -> String {
    let name = col
        .control_names
        .get(i)
        .cloned()
        .unwrap_or_else(|| format!("u{}", i + 1));
    symbol(&name)
}

/// `tau2` → `τ₂`, `k1` → `K₁`; any other name as it is.
pub(super) fn symbol(name: &str) -> String {
    let subscript = |digits: &str| -> Option<String> {
        let all = !digits.is_empty() && digits.chars().all(|c| c.is_ascii_digit());
        all.then(|| {
            digits
                .chars()
                .filter_map(|c| c.to_digit(10).and_then(|d| char::from_u32(0x2080 + d)))
                .collect()
        })
    };
    let (letter, digits) = match (name.strip_prefix("tau"), name.strip_prefix('k')) {
        (Some(d), _) => ("τ", d),
        (_, Some(d)) => ("K", d),
        _ => return name.to_string(),
    };
    subscript(digits).map_or_else(|| name.to_string(), |d| format!("{letter}{d}"))
}

/// Per column, the commands of one kind of the trials that did not diverge.
pub(super) fn command_values(columns: &[ColumnPlot], kind: Commands) -> Vec<Vec<f64>> {
    columns
        .iter()
        .map(|c| {
            let range = kind.indices(c);
            c.kept(&c.u)
                .flatten()
                .flat_map(|step| step.get(range.clone()).unwrap_or_default().iter().copied())
                .collect()
        })
        .collect()
}

/// Every trial's commands of one kind, held over each step.
pub(super) fn draw_commands<'c, DB: DrawingBackend + 'c>(
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
        for (t, trial) in col.u.iter().enumerate() {
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
            if col.is_diverged(t) {
                dashed(
                    chart,
                    &view,
                    &points,
                    colour.mix(DIVERGED_ALPHA).stroke_width(1),
                )?;
                continue;
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
pub(super) fn time_chart<'a, DB: DrawingBackend>(
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
    house_mesh(&mut mesh, 6, 5).y_desc(y_desc);
    if bottom {
        mesh.x_desc("time [s]");
    }
    mesh.draw()?;
    Ok(chart)
}

/// Draws `title` (bold, shrunk to fit the width) on top of `area`; returns the area below.
pub(super) fn titled<DB: DrawingBackend>(
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

/// Draws a column's title on top of `area` and, when some of its trials diverged, a line
/// under it that counts them (and, for the arm, says what the ellipse is of); returns the
/// area below.
/// The line is reserved in every column of `columns` when one has it, so that the panels
/// below stay aligned.
pub(super) fn column_titled<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    columns: &[ColumnPlot],
    c: usize,
    ellipse: bool,
) -> DrawResult<DrawingArea<DB, Shift>, DB> {
    let col = &columns[c];
    let area = titled(area, &col.title)?;
    if columns.iter().all(|c| c.n_diverged() == 0) {
        return Ok(area);
    }
    if let Some(text) = divergence_note(col, ellipse) {
        let style = TextStyle::from((FONT, DESC_SIZE).into_font())
            .color(&DIVERGED)
            .pos(Pos::new(HPos::Center, VPos::Top));
        let (w, _) = area.dim_in_pixel();
        area.draw_text(&text, &style, (w as i32 / 2, 0))?;
    }
    Ok(area.split_vertically(NOTE_HEIGHT).1)
}

/// Height of the line under a column title that counts its diverged trials [px].
pub(super) const NOTE_HEIGHT: u32 = 20;

/// "2 of 3 trials diverged (dashed)", and for the arm "; ellipse of the other 1" — `None` when
/// no trial diverged.
pub(super) fn divergence_note(col: &ColumnPlot, ellipse: bool) -> Option<String> {
    let (lost, n) = (col.n_diverged(), col.trials());
    if lost == 0 {
        return None;
    }
    let mut text = format!("{lost} of {n} trials diverged (dashed)");
    if ellipse {
        match (n - lost, col.ellipse.is_some()) {
            (_, false) => text.push_str(", no ellipse"),
            (kept, true) => text.push_str(&format!(", ellipse of the other {kept}")),
        }
    }
    Some(text)
}

/// Bold letters A, B, C in the left strip at the top of each row.
pub(super) fn row_letters<DB: DrawingBackend>(
    gutter: &DrawingArea<DB, Shift>,
    starts: &[i32],
    offsets: &[i32],
) -> DrawResult<(), DB> {
    let style = TextStyle::from(bold(24.0));
    for ((letter, &y), &dy) in ["A", "B", "C"].iter().zip(starts).zip(offsets) {
        gutter.draw_text(letter, &style, (7, y + 4 + dy))?;
    }
    Ok(())
}

/// The mesh every panel of the paper's figures shares: `x_labels` × `y_labels` ticks, no light
/// lines, the grid colour, the house fonts and tick labels.
pub(super) fn house_mesh<'m, 'a, 'b, DB: DrawingBackend>(
    mesh: &'m mut MeshStyle<'a, 'b, RangedCoordf64, RangedCoordf64, DB>,
    x_labels: usize,
    y_labels: usize,
) -> &'m mut MeshStyle<'a, 'b, RangedCoordf64, RangedCoordf64, DB> {
    mesh.x_labels(x_labels)
        .y_labels(y_labels)
        .max_light_lines(0)
        .bold_line_style(GRID)
        .x_label_formatter(&tick)
        .y_label_formatter(&tick)
        .label_style((FONT, TICK_SIZE))
        .axis_desc_style((FONT, DESC_SIZE))
}

/// An axis range `(low, high)`.
pub(super) type Span = (f64, f64);

/// What every column figure shares: its columns and the axis ranges common to all of them (the
/// joint angle and velocity rows, and the command rows).
pub(super) struct ColumnAxes<'a> {
    pub(super) columns: &'a [ColumnPlot],
    pub(super) time: Span,
    pub(super) angle: Span,
    pub(super) velocity: Span,
    /// Per column ([`command_ranges`]).
    pub(super) torque: Vec<Span>,
    /// None when no column has stiffness commands (the row is left out).
    pub(super) stiffness: Option<Span>,
}

impl<'a> ColumnAxes<'a> {
    /// The time and command ranges of `columns`, with the figure's own angle and velocity ranges
    /// (the arm's cover the trials' mean ± std bands, the joint's every trial).
    pub(super) fn new(columns: &'a [ColumnPlot], angle: Span, velocity: Span) -> Self {
        let (torque, stiffness) = command_ranges(columns);
        ColumnAxes {
            columns,
            time: time_range(columns),
            angle,
            velocity,
            torque,
            stiffness,
        }
    }
}

/// A figure of plan columns side by side (Fig. 1 and Fig. 2): in each column the figure's own
/// panels, then the command rows (torque, and stiffness when some column has stiffness
/// commands), which the bottom panel's time-axis description closes.
pub(super) trait ColumnFigure {
    /// The panels at which rows A, B and C start.
    const LETTER_PANELS: [usize; 3];
    /// The columns and their shared ranges.
    fn axes(&self) -> &ColumnAxes<'_>;
    /// Pixel heights of the figure's own panels (above the command rows), and of a command row.
    fn own_heights(&self) -> (Vec<u32>, u32);
    /// Draws column `c`'s own panels (the first `own_heights().0.len()` of `panels`).
    fn draw_own<DB: DrawingBackend>(
        &self,
        c: usize,
        panels: &[DrawingArea<DB, Shift>],
    ) -> DrawResult<(), DB>;

    /// Every panel's pixel height, top to bottom.
    fn heights(&self) -> Vec<u32> {
        let (mut h, row) = self.own_heights();
        h.push(row);
        if self.axes().stiffness.is_some() {
            h.push(row);
        }
        // The bottom panel also holds the time axis' description.
        *h.last_mut().expect("panels") += X_LABEL_AREA_DESC - X_LABEL_AREA;
        h
    }
}

impl<F: ColumnFigure> Figure for F {
    fn size(&self) -> (u32, u32) {
        columns_size(self.axes().columns.len(), &self.heights())
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<(), DB> {
        let heights = self.heights();
        let own = self.own_heights().0.len();
        let a = self.axes();
        draw_columns(
            root,
            &heights,
            a.columns.len(),
            F::LETTER_PANELS,
            |c, panels| {
                self.draw_own(c, panels)?;
                let column = &a.columns[c];
                draw_command_rows(
                    &panels[own..],
                    a.time,
                    a.torque[c],
                    a.stiffness,
                    column,
                    c == 0,
                )
            },
        )
    }
}

/// Width and height [px] of a figure of `columns` columns of panels of the given heights.
pub(super) fn columns_size(columns: usize, heights: &[u32]) -> (u32, u32) {
    (GUTTER + COLUMN_WIDTH * columns as u32, heights.iter().sum())
}

/// The layout the arm and joint figures share: a gutter of row letters, then one column per plan,
/// each a stack of panels of the given heights. `draw_column(c, panels)` fills column `c`;
/// `letter_panels` are the panels at which rows A, B and C start.
pub(super) fn draw_columns<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    heights: &[u32],
    columns: usize,
    letter_panels: [usize; 3],
    mut draw_column: impl FnMut(usize, &[DrawingArea<DB, Shift>]) -> DrawResult<(), DB>,
) -> DrawResult<(), DB> {
    let breaks = breakpoints(heights);
    let (gutter, body) = root.split_horizontally(GUTTER);
    for (c, column) in body.split_evenly((1, columns)).iter().enumerate() {
        let panels = column.split_by_breakpoints::<i32, i32, _, _>([], &breaks);
        draw_column(c, &panels)?;
    }
    let starts = letter_panels.map(|p| if p == 0 { 0 } else { breaks[p - 1] });
    row_letters(&gutter, &starts, &[0, 4, 4])
}

/// Cumulative heights: where each panel but the first starts.
pub(super) fn breakpoints(heights: &[u32]) -> Vec<i32> {
    heights[..heights.len() - 1]
        .iter()
        .scan(0, |y, &h| {
            *y += h as i32;
            Some(*y)
        })
        .collect()
}

/// DejaVu Sans Bold (`FontDesc::style` would keep the regular face's glyphs).
pub(super) fn bold(size: f64) -> FontDesc<'static> {
    FontDesc::new(FontFamily::Name(FONT), size, FontStyle::Bold)
}

/// Tick labels with as many decimals as the value needs: "0.35", "100", "-2".
pub(super) fn tick(v: &f64) -> String {
    let s = format!("{v:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".to_string()
    } else {
        s.to_string()
    }
}

/// A grey note centred in a panel that has nothing to show.
pub(super) fn note<'c, DB: DrawingBackend + 'c>(
    chart: &mut Chart<'c, DB>,
    text: &str,
) -> DrawResult<(), DB> {
    let view = View::of(chart);
    let style = TextStyle::from((FONT, DESC_SIZE).into_font())
        .color(&MEAN_GREY)
        .pos(Pos::new(HPos::Center, VPos::Center));
    let centre = ((view.x0 + view.x1) / 2.0, (view.y0 + view.y1) / 2.0);
    chart.draw_series(std::iter::once(Text::new(text.to_string(), centre, style)))?;
    Ok(())
}

/// The corner of `view` with the fewest of `points` (the legend goes there).
pub(super) fn quiet_corner(view: &View, points: &[(f64, f64)]) -> SeriesLabelPosition {
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

pub(super) fn joint_colour(j: usize) -> RGBColor {
    JOINT_COLOURS[j % JOINT_COLOURS.len()]
}

pub(super) fn thin(colour: &RGBColor) -> ShapeStyle {
    colour.stroke_width(1)
}

/// Joint `j` of per-knot values in degrees against the knot times: one trial's angles or
/// velocities, or the reference angles (NaN at a knot without joint `j`, a gap in the line).
pub(super) fn joint_degrees(time: &[f64], knots: &[Vec<f64>], j: usize) -> Vec<(f64, f64)> {
    time.iter()
        .zip(knots)
        .map(|(&t, knot)| (t, knot.get(j).map_or(f64::NAN, |v| v * RAD_TO_DEG)))
        .collect()
}

/// The span of all knot times (0..1 s when there is none).
pub(super) fn time_range(columns: &[ColumnPlot]) -> (f64, f64) {
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

pub(super) fn legend_line<'c, DB: DrawingBackend + 'c>(
    chart: &mut Chart<'c, DB>,
    label: &str,
    style: ShapeStyle,
) -> DrawResult<(), DB> {
    legend_entry(chart, label, move |(x, y)| {
        PathElement::new(vec![(x, y), (x + 18, y)], style)
    })
}

pub(super) fn legend_dashed<'c, DB: DrawingBackend + 'c>(
    chart: &mut Chart<'c, DB>,
    label: &str,
    style: ShapeStyle,
) -> DrawResult<(), DB> {
    legend_entry(chart, label, move |(x, y)| {
        EmptyElement::at((x, y))
            + PathElement::new(vec![(0, 0), (6, 0)], style)
            + PathElement::new(vec![(11, 0), (17, 0)], style)
    })
}

pub(super) fn legend_band<'c, DB: DrawingBackend + 'c>(
    chart: &mut Chart<'c, DB>,
    label: &str,
    colour: RGBAColor,
) -> DrawResult<(), DB> {
    legend_entry(chart, label, move |(x, y)| {
        Rectangle::new([(x, y - 5), (x + 18, y + 5)], colour.filled())
    })
}

/// A legend entry with no data: an empty series that carries only the label and its glyph.
fn legend_entry<'c, DB, E>(
    chart: &mut Chart<'c, DB>,
    label: &str,
    glyph: impl Fn((i32, i32)) -> E + 'c,
) -> DrawResult<(), DB>
where
    DB: DrawingBackend + 'c,
    E: IntoDynElement<'c, DB, (i32, i32)>,
{
    chart
        .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())?
        .label(label)
        .legend(glyph);
    Ok(())
}

pub(super) fn legend<'c, DB: DrawingBackend + 'c>(
    chart: &mut Chart<'c, DB>,
    position: SeriesLabelPosition,
) -> DrawResult<(), DB> {
    chart
        .configure_series_labels()
        .position(position)
        .margin(6)
        .legend_area_size(26)
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(180, 180, 180))
        .label_font((FONT, LEGEND_SIZE))
        .draw()
}

/// The command rows of a column: torque, then stiffness when some column plans it, each on its
/// own panel from `panels[0]` on; the last panel carries the time axis.
pub(super) fn draw_command_rows<DB: DrawingBackend>(
    panels: &[DrawingArea<DB, Shift>],
    time: (f64, f64),
    torque: (f64, f64),
    stiffness: Option<(f64, f64)>,
    column: &ColumnPlot,
    with_legend: bool,
) -> DrawResult<(), DB> {
    let mut rows = vec![(Commands::Torque, torque)];
    if let Some(range) = stiffness {
        rows.push((Commands::Stiffness, range));
    }
    let last = rows.len() - 1;
    for (r, (kind, range)) in rows.into_iter().enumerate() {
        let mut chart = time_chart(&panels[r], time, range, kind.desc(), r == last)?;
        draw_commands(&mut chart, column, kind, with_legend)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::symbol;

    #[test]
    fn the_plans_command_names_become_symbols() {
        assert_eq!(symbol("tau1"), "τ₁");
        assert_eq!(symbol("tau12"), "τ₁₂");
        assert_eq!(symbol("k2"), "K₂");
        // Not a command name of a plan: unchanged.
        for other in ["u3", "k", "kx1", "tau", "theta1"] {
            assert_eq!(symbol(other), other);
        }
    }
}
