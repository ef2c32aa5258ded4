//! `vic monitor`: watch a running board: the live view on a terminal (feature `tui`,
//! `crate::views::monitor`), else one line per interval.

use super::inject::{field, pulse};
use crate::cli::{Classify, NamespaceArgs, input_error, stop_on_signal};
use crate::views::operator::monitor;
use std::io::{IsTerminal, Write};
use std::time::Duration;

#[derive(clap::Args)]
pub(crate) struct Args {
    #[command(flatten)]
    namespace: NamespaceArgs,
    /// Seconds between lines when piped or --plain (at least 0.1).
    #[arg(long, default_value_t = 1.0)]
    interval_s: f64,
    /// Stop after this many lines (implies --plain; default: until Ctrl-C).
    #[arg(long)]
    count: Option<u64>,
    /// One line per interval even on a terminal (as when piped).
    #[arg(long)]
    plain: bool,
    /// Torque of the pulse the p / P keys inject [N m].
    #[arg(long, default_value_t = 2.0)]
    pulse_nm: f64,
    /// Duration of that pulse [ms].
    #[arg(long, default_value_t = 100.0)]
    pulse_ms: f64,
    /// β of the divergent field the f key switches on [N/m] (two-link arm only).
    #[arg(long, default_value_t = 50.0, allow_negative_numbers = true)]
    field_beta: f64,
    /// Seconds of history in the plots.
    #[arg(long, default_value_t = 10.0)]
    window_s: f64,
}

/// Watches the board of `--namespace`: the live view (`--features tui`) when stdin and stdout
/// are a terminal, otherwise one line per interval until Ctrl-C or `--count` lines.
pub(crate) fn run(o: Args) -> anyhow::Result<()> {
    let namespace = o.namespace.validated()?;
    if !(o.interval_s.is_finite() && o.interval_s >= 0.1) {
        return Err(input_error("--interval-s must be at least 0.1"));
    }
    if !(o.pulse_nm.is_finite() && o.pulse_nm > 0.0) {
        return Err(input_error(format!(
            "--pulse-nm {}: must be a positive torque in N m (P pushes the other way)",
            o.pulse_nm
        )));
    }
    let _ = pulse(&[o.pulse_nm], o.pulse_ms)?;
    let _ = field(o.field_beta)?;
    if !(o.window_s.is_finite() && (1.0..=600.0).contains(&o.window_s)) {
        return Err(input_error(format!(
            "--window-s {}: must be between 1 and 600 seconds",
            o.window_s
        )));
    }
    let stop = stop_on_signal()?;
    let tty = std::io::stdout().is_terminal() && std::io::stdin().is_terminal();
    let plain = o.plain || o.count.is_some() || !tty;
    #[cfg(feature = "tui")]
    if !plain {
        let settings = crate::views::monitor::Settings {
            pulse_torque: o.pulse_nm,
            pulse_duration: o.pulse_ms / 1e3,
            field_beta: o.field_beta,
            window_s: o.window_s,
        };
        return crate::views::monitor::run(namespace, settings, &stop).runtime();
    }
    let mut shown = 0u64;
    monitor(
        namespace,
        Duration::from_secs_f64(o.interval_s),
        &stop,
        |s| {
            let mut out = std::io::stdout().lock();
            let text = match s {
                Some(s) if !plain => s.render(),
                Some(s) => s.line(),
                None => format!("no board in namespace \"{namespace}\" (waiting)"),
            };
            // Without the live view, on a terminal: clear and redraw in place.
            let ok = if !plain {
                write!(out, "\x1b[H\x1b[2J{text}\n(Ctrl-C to quit)\n")
            } else {
                writeln!(out, "{text}")
            };
            let _ = out.flush();
            shown += 1;
            ok.is_ok() && o.count.is_none_or(|c| shown < c)
        },
    )
    .runtime()
}
