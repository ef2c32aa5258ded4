//! `vic inject`, `vic status` and `vic monitor`: the operator's commands on a running board, from
//! the flags as typed (checked here) to the printed acknowledgement, snapshot or live view. The
//! waiting and matching are [`crate::views::operator`]'s.

use crate::cli::{Classify, input_error, print_json, stop_on_signal};
use crate::views::operator::{Ack, Request, inject, monitor, status};
use std::io::{IsTerminal, Write};
use std::time::Duration;

/// One or two finite joint torques [N m] given with --torque; a missing second joint gets 0.
pub fn joint_torques(v: &[f64]) -> anyhow::Result<[f64; 2]> {
    if v.is_empty() || v.len() > 2 || v.iter().any(|x| !x.is_finite()) {
        return Err(input_error(format!(
            "--torque {v:?}: give one or two finite joint torques in N m, e.g. --torque 1.5,0"
        )));
    }
    let mut t = [0.0; 2];
    t[..v.len()].copy_from_slice(v);
    Ok(t)
}

/// A torque pulse of `duration_ms` (positive).
pub fn pulse(torque: &[f64], duration_ms: f64) -> anyhow::Result<Request> {
    if !(duration_ms.is_finite() && duration_ms > 0.0) {
        return Err(input_error(format!(
            "--duration-ms {duration_ms}: must be a positive number of milliseconds"
        )));
    }
    Ok(Request::Pulse {
        torque: joint_torques(torque)?,
        duration: duration_ms / 1e3,
    })
}

/// A steady load torque.
pub fn load(torque: &[f64]) -> anyhow::Result<Request> {
    Ok(Request::Load {
        torque: joint_torques(torque)?,
    })
}

/// The divergent field's β [N/m] (finite).
pub fn field(beta: f64) -> anyhow::Result<Request> {
    if !beta.is_finite() {
        return Err(input_error("--beta must be a finite number of N/m"));
    }
    Ok(Request::Field { beta })
}

/// The noise factor (≥ 0).
pub fn noise(factor: f64) -> anyhow::Result<Request> {
    if !(factor.is_finite() && factor >= 0.0) {
        return Err(input_error(format!("--factor {factor}: must be ≥ 0")));
    }
    Ok(Request::Noise { factor })
}

/// Sends `request` to the board of `namespace` and prints its acknowledgement.
pub fn run_inject(
    namespace: &str,
    request: Request,
    timeout: Duration,
    json: bool,
) -> anyhow::Result<()> {
    let ack = inject(namespace, request, timeout)?;
    if json {
        print_json(&ack)
    } else {
        println!("{}", ack_line(&ack));
        Ok(())
    }
}

fn ack_line(ack: &Ack) -> String {
    let effect = match ack.effect_after_ticks {
        Some(0) => ", in effect at that tick".to_string(),
        Some(n) => format!(", in effect {n} tick(s) later"),
        None => String::new(),
    };
    format!(
        "applied by the board in \"{}\" at tick {} ({:.0} µs after sending{effect}); mode {}, τ_ext {:?} N m",
        ack.namespace, ack.tick, ack.latency_us, ack.mode, ack.tau_ext
    )
}

/// Prints one snapshot of the telemetry of the board in `namespace`.
pub fn run_status(namespace: &str, timeout: Duration, json: bool) -> anyhow::Result<()> {
    let s = status(namespace, timeout)?;
    if json {
        print_json(&s)
    } else {
        println!("{}", s.render());
        Ok(())
    }
}

/// What `vic monitor` was asked for.
#[derive(Debug, Clone, Copy)]
pub struct MonitorOptions {
    /// Seconds between lines (piped or `--plain`; at least 0.1).
    pub interval_s: f64,
    /// Stop after this many lines (implies `plain`).
    pub count: Option<u64>,
    /// Lines even on a terminal.
    pub plain: bool,
    /// The pulse of the `p` key [N m] and its duration [ms].
    pub pulse_nm: f64,
    pub pulse_ms: f64,
    /// β the `f` key switches on [N/m].
    pub field_beta: f64,
    /// Seconds of history in the plots.
    pub window_s: f64,
}

/// Watches the board of `namespace`: the live view (`--features tui`) when stdin and stdout are
/// a terminal, otherwise one line per interval until Ctrl-C or `count` lines.
pub fn run_monitor(namespace: &str, o: MonitorOptions) -> anyhow::Result<()> {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn torques_are_one_or_two_finite_values() {
        assert_eq!(joint_torques(&[1.5]).unwrap(), [1.5, 0.0]);
        assert_eq!(joint_torques(&[1.0, -2.0]).unwrap(), [1.0, -2.0]);
        for bad in [
            &[][..],
            &[1.0, 2.0, 3.0],
            &[f64::NAN],
            &[f64::INFINITY, 0.0],
        ] {
            let e = joint_torques(bad).unwrap_err();
            assert_eq!(crate::cli::exit_code(&e), 2, "{bad:?}");
        }
    }

    #[test]
    fn requests_check_their_values() {
        assert_eq!(
            pulse(&[2.0], 50.0).unwrap(),
            Request::Pulse {
                torque: [2.0, 0.0],
                duration: 0.05
            }
        );
        assert!(pulse(&[2.0], 0.0).is_err());
        assert!(pulse(&[2.0], f64::NAN).is_err());
        assert!(field(f64::INFINITY).is_err());
        assert_eq!(field(-3.0).unwrap(), Request::Field { beta: -3.0 });
        assert!(noise(-0.5).is_err());
        assert_eq!(noise(0.0).unwrap(), Request::Noise { factor: 0.0 });
    }
}
