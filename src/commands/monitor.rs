//! `vic monitor`: watch a running board: the live view on a terminal (feature `tui`,
//! `crate::views::monitor`), else one line per interval.

use crate::cli::{Classify, NamespaceArgs, stop_on_signal};
use crate::ranges::{
    MAX_FIELD_BETA, MAX_PULSE_MS, MAX_TORQUE_NM, MAX_WAIT_S, real, seconds, whole,
};
use crate::views::operator::monitor;
use std::io::{IsTerminal, Write};

#[derive(clap::Args)]
pub(crate) struct Args {
    #[command(flatten)]
    namespace: NamespaceArgs,
    /// Seconds between lines when piped or --plain. [range: 0.1 to 3600]
    #[arg(long, default_value_t = 1.0, value_parser = real(0.1, MAX_WAIT_S))]
    interval_s: f64,
    /// Stop after this many lines (implies --plain; default: until Ctrl-C).
    /// [range: 1 to 1000000000]
    #[arg(long, value_parser = whole(1u64, 1_000_000_000))]
    count: Option<u64>,
    /// One line per interval even on a terminal (as when piped).
    #[arg(long)]
    plain: bool,
    /// Torque of the pulse the p / P keys inject [N m] (P pushes the other way).
    /// [range: 0.001 to 200]
    #[arg(long, default_value_t = 2.0, value_parser = real(0.001, MAX_TORQUE_NM))]
    pulse_nm: f64,
    /// Duration of that pulse [ms]. [range: 0.001 to 10000]
    #[arg(long, default_value_t = 100.0, value_parser = real(0.001, MAX_PULSE_MS))]
    pulse_ms: f64,
    /// β of the divergent field the f key switches on [N/m] (two-link arm only).
    /// [range: 0 to 5000]
    #[arg(long, default_value_t = 50.0, allow_negative_numbers = true,
          value_parser = real(0.0, MAX_FIELD_BETA))]
    field_beta: f64,
    /// Seconds of history in the plots. [range: 1 to 600]
    #[arg(long, default_value_t = 10.0, value_parser = real(1.0, 600.0))]
    window_s: f64,
}

/// Watches the board of `--namespace`: the live view (`--features tui`) when stdin and stdout
/// are a terminal, otherwise one line per interval until Ctrl-C or `--count` lines.
pub(crate) fn run(o: Args) -> anyhow::Result<()> {
    let namespace = o.namespace.validated()?;
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
    monitor(namespace, seconds(o.interval_s), &stop, |s| {
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
    })
    .runtime()
}
