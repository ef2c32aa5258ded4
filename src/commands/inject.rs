//! `vic inject`: a disturbance (torque pulse, load, field, noise factor) sent to a running board,
//! checked here as typed, and the board's acknowledgement printed. The waiting and matching are
//! [`crate::views::operator`]'s.

use crate::cli::{JsonArg, NamespaceArgs, input_error, print_json};
use crate::ranges::{
    MAX_FIELD_BETA, MAX_NOISE_FACTOR, MAX_PULSE_MS, MAX_TORQUE_NM, MAX_WAIT_S, real, seconds,
};
use crate::views::operator::{Ack, Request, inject};
use clap::Subcommand;

#[derive(clap::Args)]
#[command(
    mut_arg("namespace", |a| a.global(true)),
    mut_arg("json", |a| a.global(true).help("Print the acknowledgement as JSON")),
)]
pub(crate) struct Args {
    #[command(subcommand)]
    what: InjectWhat,
    #[command(flatten)]
    namespace: NamespaceArgs,
    /// Seconds to wait for the board and its acknowledgement. [range: 0.001 to 3600]
    #[arg(long, global = true, default_value_t = 2.0, value_parser = real(0.001, MAX_WAIT_S))]
    timeout_s: f64,
    #[command(flatten)]
    json: JsonArg,
}

#[derive(Subcommand)]
enum InjectWhat {
    /// A torque pulse on the joints.
    Pulse {
        #[command(flatten)]
        torque: TorqueArg,
        /// Pulse duration [ms] (the board refuses one longer than its
        /// board.max_pulse_duration). [range: 0.001 to 10000]
        #[arg(long, default_value_t = 50.0, value_parser = real(0.001, MAX_PULSE_MS))]
        duration_ms: f64,
    },
    /// A steady load torque until changed (all zeros remove it).
    Load {
        #[command(flatten)]
        torque: TorqueArg,
    },
    /// Switch the divergent force field on (β > 0) or off (0). Two-link arm only.
    Field {
        /// β [N/m] (the board refuses one above its board.max_field_beta). [range: 0 to 5000]
        #[arg(long, allow_negative_numbers = true, value_parser = real(0.0, MAX_FIELD_BETA))]
        beta: f64,
    },
    /// Scale the plant noise (1: as configured, 0: none).
    Noise {
        /// The factor (the board refuses one above its board.max_noise_factor).
        /// [range: 0 to 100]
        #[arg(long, allow_negative_numbers = true, value_parser = real(0.0, MAX_NOISE_FACTOR))]
        factor: f64,
    },
}

/// `--torque T1[,T2]` of a pulse or a load.
#[derive(clap::Args)]
struct TorqueArg {
    /// Joint torques [N m], comma-separated (one per joint; missing joints get 0; the board
    /// refuses more than its board.max_pulse_torque or max_load_torque). [range: -200 to 200]
    #[arg(
        long,
        value_name = "T1[,T2]",
        value_delimiter = ',',
        allow_negative_numbers = true,
        value_parser = real(-MAX_TORQUE_NM, MAX_TORQUE_NM)
    )]
    torque: Vec<f64>,
}

/// Sends the disturbance to the board of `--namespace` and prints its acknowledgement.
pub(crate) fn run(a: Args) -> anyhow::Result<()> {
    let namespace = a.namespace.validated()?;
    let timeout = seconds(a.timeout_s);
    let request = match &a.what {
        InjectWhat::Pulse {
            torque,
            duration_ms,
        } => pulse(&torque.torque, *duration_ms)?,
        InjectWhat::Load { torque } => load(&torque.torque)?,
        InjectWhat::Field { beta } => field(*beta)?,
        InjectWhat::Noise { factor } => noise(*factor)?,
    };
    let ack = inject(namespace, request, timeout)?;
    if a.json.json {
        print_json(&ack)
    } else {
        println!("{}", ack_line(&ack));
        Ok(())
    }
}

/// One or two finite joint torques [N m] given with --torque; a missing second joint gets 0.
pub(crate) fn joint_torques(v: &[f64]) -> anyhow::Result<[f64; 2]> {
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
pub(crate) fn pulse(torque: &[f64], duration_ms: f64) -> anyhow::Result<Request> {
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
pub(crate) fn load(torque: &[f64]) -> anyhow::Result<Request> {
    Ok(Request::Load {
        torque: joint_torques(torque)?,
    })
}

/// The divergent field's β [N/m] (finite).
pub(crate) fn field(beta: f64) -> anyhow::Result<Request> {
    if !beta.is_finite() {
        return Err(input_error("--beta must be a finite number of N/m"));
    }
    Ok(Request::Field { beta })
}

/// The noise factor (≥ 0).
pub(crate) fn noise(factor: f64) -> anyhow::Result<Request> {
    if !(factor.is_finite() && factor >= 0.0) {
        return Err(input_error(format!("--factor {factor}: must be ≥ 0")));
    }
    Ok(Request::Noise { factor })
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
