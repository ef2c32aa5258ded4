//! `vic inject`: flags, then [`vic::operator_command::run_inject`].

use clap::Subcommand;
use vic::cli::{JsonArg, NamespaceArgs, positive_seconds};
use vic::operator_command::{field, load, noise, pulse, run_inject};

#[derive(clap::Args)]
#[command(
    mut_arg("namespace", |a| a.global(true)),
    mut_arg("json", |a| a.global(true).help("Print the acknowledgement as JSON")),
)]
pub struct InjectArgs {
    #[command(subcommand)]
    what: InjectWhat,
    #[command(flatten)]
    namespace: NamespaceArgs,
    /// Seconds to wait for the board and its acknowledgement.
    #[arg(long, global = true, default_value_t = 2.0)]
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
        /// Pulse duration [ms].
        #[arg(long, default_value_t = 50.0)]
        duration_ms: f64,
    },
    /// A steady load torque until changed (all zeros remove it).
    Load {
        #[command(flatten)]
        torque: TorqueArg,
    },
    /// Switch the divergent force field on (β > 0) or off (0). Two-link arm only.
    Field {
        /// β [N/m].
        #[arg(long, allow_negative_numbers = true)]
        beta: f64,
    },
    /// Scale the plant noise (1: as configured, 0: none).
    Noise {
        /// The factor (≥ 0).
        #[arg(long, allow_negative_numbers = true)]
        factor: f64,
    },
}

/// `--torque T1[,T2]` of a pulse or a load.
#[derive(clap::Args)]
struct TorqueArg {
    /// Joint torques [N m], comma-separated (one per joint; missing joints get 0).
    #[arg(
        long,
        value_name = "T1[,T2]",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    torque: Vec<f64>,
}

impl InjectArgs {
    pub fn run(self) -> anyhow::Result<()> {
        let namespace = self.namespace.validated()?;
        let timeout = positive_seconds("--timeout-s", self.timeout_s)?;
        let request = match &self.what {
            InjectWhat::Pulse {
                torque,
                duration_ms,
            } => pulse(&torque.torque, *duration_ms)?,
            InjectWhat::Load { torque } => load(&torque.torque)?,
            InjectWhat::Field { beta } => field(*beta)?,
            InjectWhat::Noise { factor } => noise(*factor)?,
        };
        run_inject(namespace, request, timeout, self.json.json)
    }
}
