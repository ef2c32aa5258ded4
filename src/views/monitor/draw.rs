//! The live view drawn from an [`App`]: nothing here reads a clock, the transport or the terminal,
//! so a `TestBackend` renders exactly what a terminal shows.

use super::{App, JointSeries, Series, bounds};
use ratatui::Frame;
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::{
    Axis, Block, Borders, Chart, Dataset, GraphType, LegendPosition, Paragraph, Row, Sparkline,
    Table, Wrap,
};

/// A colour per joint (the legend names them "joint 1", "joint 2").
const JOINT_COLORS: [Color; 2] = [Color::Cyan, Color::Magenta];

/// Renders the whole view into `frame`.
pub(crate) fn draw(frame: &mut Frame, app: &App) {
    let [banner, plots, panels, keys] = Layout::vertical([
        Constraint::Length(3),
        Constraint::Min(8),
        Constraint::Length(9),
        Constraint::Length(1),
    ])
    .areas(frame.area());
    draw_banner(frame, banner, app);
    draw_plots(frame, plots, app);
    let [lp, rej, dist] = Layout::horizontal([
        Constraint::Percentage(36),
        Constraint::Percentage(28),
        Constraint::Percentage(36),
    ])
    .areas(panels);
    draw_loop(frame, lp, app);
    draw_rejections(frame, rej, app);
    draw_disturbances(frame, dist, app);
    frame.render_widget(
        Paragraph::new(format!(
            " p/P pulse ±{} N m on joint {} · 1-{} joint · f field · r reset · q quit",
            app.settings.pulse_torque,
            app.joint + 1,
            app.joints
        ))
        .style(Style::new().add_modifier(Modifier::REVERSED)),
        keys,
    );
}

fn draw_banner(frame: &mut Frame, area: Rect, app: &App) {
    let color = match app.status.as_ref().map(|s| s.mode.as_str()) {
        None => Color::DarkGray,
        Some("running") => Color::Green,
        Some("idle") => Color::Cyan,
        Some("safe-hold") => Color::Yellow,
        Some(_) => Color::Red,
    };
    let detail = match &app.status {
        Some(s) => format!(
            "  tick {} at {:.1} Hz, trial {}",
            s.tick, s.tick_rate_hz, s.trial
        ),
        None => String::new(),
    };
    let text = Line::from(vec![
        Span::styled(
            app.banner(),
            Style::new().fg(color).add_modifier(Modifier::BOLD),
        ),
        Span::raw(detail),
    ]);
    let title = format!(" vic monitor · namespace \"{}\" ", app.namespace);
    frame.render_widget(
        Paragraph::new(text).block(Block::bordered().title(title).border_style(color)),
        area,
    );
}

fn draw_plots(frame: &mut Frame, area: Rect, app: &App) {
    let [top, bottom] = Layout::vertical([Constraint::Fill(1); 2]).areas(area);
    let [q, err] = Layout::horizontal([Constraint::Fill(1); 2]).areas(top);
    let [k, tau] = Layout::horizontal([Constraint::Fill(1); 2]).areas(bottom);
    let n = app.joints;
    fn joints(s: &JointSeries, n: usize) -> Vec<&Series> {
        s[..n].iter().collect()
    }
    // Each joint about its own mean over the window: a push of a few mrad shows on joints that
    // sit radians apart.
    let centred: Vec<Series> = app.q[..n].iter().map(Series::centred).collect();
    let centred: Vec<&Series> = centred.iter().collect();
    plot(
        frame,
        q,
        app,
        "joint angle q − its mean [rad]",
        &centred,
        2e-3,
    );
    plot(
        frame,
        err,
        app,
        "tracking error [rad]",
        &[&app.tracking_error],
        0.01,
    );
    plot(
        frame,
        k,
        app,
        "stiffness K [N m/rad]",
        &joints(&app.stiffness, n),
        1.0,
    );
    plot(
        frame,
        tau,
        app,
        "joint torque τ [N m]",
        &joints(&app.tau, n),
        0.5,
    );
}

/// "1.23" / "0.0123" / "1.2e3": short enough for an axis label.
pub(super) fn short(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e4).contains(&a) {
        format!("{v:.1e}")
    } else if a >= 100.0 {
        format!("{v:.0}")
    } else if a >= 1.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.3}")
    }
}

/// A rolling chart of `series` (one per joint, named "joint 1", … in the legend; or the one
/// tracking error) over the last `window_s` seconds, its y axis following the data (see
/// [`bounds`]).
fn plot(frame: &mut Frame, area: Rect, app: &App, title: &str, series: &[&Series], span: f64) {
    let data: Vec<Vec<(f64, f64)>> = series.iter().map(|s| s.points()).collect();
    let joints = !title.starts_with("tracking");
    let datasets: Vec<Dataset> = data
        .iter()
        .enumerate()
        .map(|(j, d)| {
            let mut ds = Dataset::default()
                .marker(Marker::Braille)
                .graph_type(GraphType::Line)
                .style(Style::new().fg(JOINT_COLORS[j % JOINT_COLORS.len()]))
                .data(d);
            if joints {
                ds = ds.name(format!("joint {}", j + 1));
            }
            ds
        })
        .collect();
    let x = [app.now_s - app.settings.window_s, app.now_s];
    let y = bounds(series, span);
    let chart = Chart::new(datasets)
        .block(Block::bordered().title(title.to_string()))
        .x_axis(Axis::default().bounds(x).labels([
            format!("-{:.0} s", app.settings.window_s),
            "now".to_string(),
        ]))
        .y_axis(Axis::default().bounds(y).labels([short(y[0]), short(y[1])]))
        .legend_position(Some(LegendPosition::TopLeft))
        .hidden_legend_constraints((Constraint::Percentage(50), Constraint::Percentage(60)));
    frame.render_widget(chart, area);
}

fn draw_loop(frame: &mut Frame, area: Rect, app: &App) {
    let block = Block::bordered().title("1 kHz loop");
    let inner = block.inner(area);
    frame.render_widget(block, area);
    let [text, spark] = Layout::vertical([Constraint::Length(4), Constraint::Fill(1)]).areas(inner);
    let lines = match &app.status {
        Some(s) => vec![
            Line::from(format!(
                "jitter p50/p99/max {:.0}/{:.0}/{:.0} µs",
                s.jitter_us.p50, s.jitter_us.p99, s.jitter_us.max
            )),
            Line::from(format!(
                "late ticks {}, periods missed {}",
                s.late_ticks, s.missed_periods
            )),
            Line::from(format!(
                "command age p50/p99 {:.0}/{:.0} µs",
                s.command_age_us.p50, s.command_age_us.p99
            )),
            Line::from(format!(
                "work p99 {:.1} µs; watchdog trips {}",
                s.work_us.p99, s.watchdog_trips
            )),
        ],
        None => vec![Line::from("no telemetry yet")],
    };
    frame.render_widget(Paragraph::new(lines), text);
    let bars: Vec<u64> = app.jitter_p99.iter().copied().collect();
    frame.render_widget(
        Sparkline::default()
            .block(Block::new().borders(Borders::TOP).title("jitter p99 [µs]"))
            .data(&bars)
            .style(Style::new().fg(Color::Yellow)),
        spark,
    );
}

fn draw_rejections(frame: &mut Frame, area: Rect, app: &App) {
    let total = app.status.as_ref().map_or(0, |s| s.rejected_messages);
    let dropped = app.status.as_ref().map_or(0, |s| s.dropped_messages);
    let mut rows: Vec<Row> = app
        .status
        .iter()
        .flat_map(|s| s.rejected_by_reason.iter())
        .map(|(reason, n)| Row::new([reason.clone(), n.to_string()]))
        .collect();
    // Messages lost before the board saw them (not rejections: sequence gaps), under the reasons.
    if dropped > 0 {
        rows.push(
            Row::new(["dropped (sequence gaps)".to_string(), dropped.to_string()])
                .style(Style::new().add_modifier(Modifier::ITALIC)),
        );
    }
    let empty = rows.is_empty();
    let table = Table::new(rows, [Constraint::Fill(1), Constraint::Length(8)])
        .header(Row::new(["reason", "count"]).style(Style::new().add_modifier(Modifier::BOLD)))
        .block(Block::bordered().title(format!("rejected messages: {total}")));
    frame.render_widget(table, area);
    if empty {
        let inner = Block::bordered().inner(area);
        if inner.height > 1 {
            let none = Rect {
                y: inner.y + 1,
                height: 1,
                ..inner
            };
            frame.render_widget(Paragraph::new("none"), none);
        }
    }
}

fn draw_disturbances(frame: &mut Frame, area: Rect, app: &App) {
    let mut lines = Vec::new();
    if let Some(s) = &app.status {
        let tau: Vec<String> = s
            .tau_ext
            .iter()
            .enumerate()
            .map(|(j, t)| format!("joint {} {t:+.2}", j + 1))
            .collect();
        lines.push(Line::from(format!("τ_ext {} N m", tau.join(", "))));
        lines.push(Line::from(format!(
            "field β {} N/m, noise ×{}",
            s.field_beta, s.noise_factor
        )));
    }
    lines.push(Line::from(format!(
        "pulses sent {}, acknowledged {}",
        app.pulses_sent, app.pulses_acked
    )));
    lines.extend(app.log.iter().rev().map(|l| Line::from(l.clone())));
    frame.render_widget(
        Paragraph::new(lines)
            .wrap(Wrap { trim: true })
            .block(Block::bordered().title("disturbances")),
        area,
    );
}
