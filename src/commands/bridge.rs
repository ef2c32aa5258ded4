//! `vic bridge`: one end of a namespace split across two hosts (see [`vic_rt::bridge`]).
//! Runs until SIGINT/SIGTERM or `--duration-s`, printing the counts once a second on stderr and
//! a summary at the end (`--json`: one object). The board side's line ends with the offset
//! between the hosts' clocks (board − central), its uncertainty (± half the best probe's round
//! trip), that round trip and the drift; the central side's with the probes it answered.
//!
//! `vic bridge keygen --out DIR [--name HOST]...` makes a pair's keys ([`vic_rt::bridge::keys`]);
//! the bridges then run with `--keys DIR` on `tls/` endpoints. Plain `tcp/` needs
//! `--insecure-plain-tcp` and a loopback address.

use crate::cli::{Classify, JsonArg, NamespaceArgs, input_error, print_json, stop_on_signal};
use crate::ranges::{MAX_RUN_S, real, seconds, whole};
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};
use vic_rt::bridge::clock::ClockStats;
use vic_rt::bridge::keys::{self, KeyFiles};
use vic_rt::bridge::{self, BridgeError, BridgeOptions, BridgeStats, Link, Security, Side, Stamps};

#[derive(Clone, Copy, clap::ValueEnum)]
enum SideArg {
    /// Beside the board: forwards its state, telemetry and events to the link, and the
    /// commands, resets and disturbances from the link to the board.
    Board,
    /// Beside the central process: plays the board to it (state from the link, its commands to
    /// the link).
    Central,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum StampsArg {
    /// Translate the stamps into this host's clock (measured over the link): two machines.
    Translate,
    /// Forward them unchanged: one machine.
    Keep,
}

#[derive(clap::Subcommand)]
enum Sub {
    /// Make the keys of one pair of bridges in DIR: a private authority's certificate (ca.pem;
    /// its private key is never written, so it signs nothing else) and a certificate and key per
    /// side (board.pem/board.key, central.pem/central.key), all owner-only. Copy ca.pem and the
    /// side's two files to each host (e.g. with scp) and pass --keys DIR to its bridge.
    ///
    /// Example: vic bridge keygen --out lab1-keys --name robot.local --name 192.168.1.20
    Keygen {
        /// The directory to write (created 0700; existing key files are never overwritten).
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// A host name or address under which the listening bridge is reached (the connecting
        /// bridge checks the certificate against the name it dials); repeatable.
        /// localhost, 127.0.0.1 and ::1 are always included.
        #[arg(long, value_name = "HOST")]
        name: Vec<String>,
    },
}

#[derive(clap::Args)]
#[command(mut_arg("json", |a| a.help("Print the final counts as one JSON object")))]
#[command(group(clap::ArgGroup::new("endpoint").required(true).args(["listen", "connect"])))]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub(crate) struct Args {
    #[command(subcommand)]
    sub: Option<Sub>,
    /// Which daemon this bridge stands beside.
    #[arg(long, value_enum, required = true)]
    side: Option<SideArg>,
    #[command(flatten)]
    namespace: NamespaceArgs,
    /// Wait for the other bridge on this Zenoh endpoint, e.g. tls/0.0.0.0:7447.
    #[arg(long, value_name = "ENDPOINT")]
    listen: Option<String>,
    /// Connect to the other bridge, e.g. tls/robot.local:7447 (retried until it answers).
    #[arg(long, value_name = "ENDPOINT")]
    connect: Option<String>,
    /// The pair's key directory (from `vic bridge keygen`): ca.pem and this side's certificate
    /// and key. The link is then mutual TLS (tls/ endpoints): a peer without the other side's
    /// key fails the handshake.
    #[arg(
        long,
        value_name = "DIR",
        required_unless_present = "insecure_plain_tcp"
    )]
    keys: Option<PathBuf>,
    /// INSECURE: a plain TCP link (tcp/ endpoints) with no authentication, so that any process
    /// reaching the port can read the board and drive it. Accepted on a loopback address only
    /// (both bridges on one machine).
    #[arg(long, conflicts_with = "keys")]
    insecure_plain_tcp: bool,
    /// The name both bridges share (key expressions vic/NAME/...); default: the namespace.
    #[arg(long)]
    link_name: Option<String>,
    /// Messages are forwarded as they are published (the local daemons notify the bridge) and as
    /// they arrive from the link; this is only the longest the bridge waits before looking at the
    /// local subscribers without a notification [ms]. [range: 1 to 60000]
    #[arg(long, default_value_t = 100, value_parser = whole(1u64, 60_000))]
    safety_interval_ms: u64,
    /// Board side: what to do with the time stamps of the messages forwarded to the board.
    /// `translate` measures the offset to the central host's clock (probes over the link, a few
    /// per second) and moves every stamp into this host's clock, so that the board's age check
    /// covers the link; nothing is forwarded until the first probe came back. `keep` forwards the
    /// senders' stamps: only when both daemons share one machine's clock.
    #[arg(long, value_enum, default_value = "translate")]
    stamps: StampsArg,
    /// Central side, tests only: pretend this host's clock is ahead by MS milliseconds (at most a
    /// day either way).
    #[arg(long, hide = true, default_value_t = 0, allow_negative_numbers = true,
          value_parser = whole(-86_400_000i64, 86_400_000))]
    clock_skew_ms: i64,
    /// Stop after this many seconds (0: run until SIGINT/SIGTERM). [range: 0 to 604800]
    #[arg(long, default_value_t = 0.0, value_parser = real(0.0, MAX_RUN_S))]
    duration_s: f64,
    #[command(flatten)]
    json: JsonArg,
}

/// Runs the bridge until a signal or `--duration-s`.
pub(crate) fn run(a: Args) -> anyhow::Result<()> {
    if let Some(Sub::Keygen { out, name }) = a.sub {
        return keygen(&out, &name);
    }
    let side = a.side.expect("clap requires --side without a subcommand");
    let namespace = a.namespace.validated()?.to_string();
    let duration = seconds(a.duration_s);
    if a.clock_skew_ms != 0 && !matches!(side, SideArg::Central) {
        return Err(input_error("--clock-skew-ms: only with --side central"));
    }
    let clock_skew_ns = a
        .clock_skew_ms
        .checked_mul(1_000_000)
        .ok_or_else(|| input_error("--clock-skew-ms: too large"))?;
    let link = match (a.listen, a.connect) {
        (Some(e), None) => Link::Listen(e),
        (None, Some(e)) => Link::Connect(e),
        _ => unreachable!("clap requires exactly one of --listen and --connect"),
    };
    let side = match side {
        SideArg::Board => Side::Board,
        SideArg::Central => Side::Central,
    };
    let security = match a.keys {
        Some(dir) => Security::MutualTls(KeyFiles::of(&dir, side).map_err(input_error)?),
        None => Security::PlainLoopback,
    };
    let endpoint = match &link {
        Link::Listen(e) | Link::Connect(e) => e,
    };
    bridge::check_endpoint(endpoint, &security).map_err(input_error)?;
    let options = BridgeOptions {
        link_name: a.link_name.unwrap_or_else(|| namespace.clone()),
        namespace,
        side,
        link,
        security,
        safety_interval: Duration::from_millis(a.safety_interval_ms),
        stamps: match a.stamps {
            StampsArg::Translate => Stamps::Translate,
            StampsArg::Keep => Stamps::Keep,
        },
        clock_skew_ns,
    };
    let json = a.json.json;
    let o = &options;
    let stop = stop_on_signal()?;
    if !duration.is_zero() {
        let stop = stop.clone();
        std::thread::spawn(move || {
            std::thread::sleep(duration);
            stop.store(true, Ordering::Relaxed);
        });
    }
    let start = Instant::now();
    if o.security == Security::PlainLoopback {
        eprintln!(
            "vic bridge: WARNING: plain TCP without authentication (--insecure-plain-tcp): \
             any process on this machine can join the link, read the board and drive it"
        );
    }
    eprintln!(
        "vic bridge: namespace {} as the {:?} side of link \"{}\" ({:?}, {}), woken by events \
         (safety interval {} ms){}",
        o.namespace,
        o.side,
        o.link_name,
        o.link,
        match o.security {
            Security::MutualTls(_) => "mutual TLS",
            Security::PlainLoopback => "plain TCP, loopback only",
        },
        o.safety_interval.as_millis(),
        match (o.side, o.stamps) {
            (Side::Board, Stamps::Translate) => ", stamps translated into this host's clock",
            (Side::Board, Stamps::Keep) => ", senders' stamps kept (one machine)",
            (Side::Central, _) => "",
        }
    );
    let result = bridge::run(o, &stop, |s| {
        if !json {
            eprintln!("{}{}", line(s), clock_line(o.side, &s.clock));
        }
    });
    let stats = match result {
        Err(e @ (BridgeError::LinkName(_) | BridgeError::Endpoint { .. })) => {
            return Err(e).input();
        }
        other => other.runtime()?,
    };
    if json {
        print_json(&serde_json::json!({
            "namespace": o.namespace,
            "link_name": o.link_name,
            "side": format!("{:?}", o.side).to_lowercase(),
            "seconds": start.elapsed().as_secs_f64(),
            "stats": stats,
        }))?;
    } else {
        println!("{}{}", line(&stats), clock_line(o.side, &stats.clock));
    }
    Ok(())
}

/// `vic bridge keygen`: writes the pair's keys and says where each file goes.
fn keygen(out: &std::path::Path, names: &[String]) -> anyhow::Result<()> {
    let written = keys::generate(out, names).map_err(input_error)?;
    for path in &written {
        println!("{}", path.display());
    }
    eprintln!(
        "vic bridge keygen: the board's host needs ca.pem, board.pem and board.key; the central \
         host ca.pem, central.pem and central.key (keep the .key files owner-only); then run \
         each bridge with --keys DIR on tls/ endpoints"
    );
    Ok(())
}

fn line(s: &BridgeStats) -> String {
    let (o, i) = (&s.sent, &s.received);
    format!(
        "out: state {} telemetry {} event {} command {} control {} disturbance {} | \
         in: state {} telemetry {} event {} command {} control {} disturbance {} | \
         malformed: size {} version {} | local errors {}",
        o.state,
        o.telemetry,
        o.event,
        o.command,
        o.control,
        o.disturbance,
        i.state,
        i.telemetry,
        i.event,
        i.command,
        i.control,
        i.disturbance,
        s.malformed_size,
        s.malformed_version,
        s.local_errors
    )
}

/// The clock's part of the line: the estimate on the board side, the answers on the central
/// side.
fn clock_line(side: Side, c: &ClockStats) -> String {
    let ms = |ns: i64| ns as f64 * 1e-6;
    match (side, c.offset_ns, c.uncertainty_ns, c.round_trip_ns) {
        (Side::Central, ..) => format!(
            " | clock: {} probes answered, {} malformed",
            c.probes_answered, c.probes_malformed
        ),
        (Side::Board, Some(offset), Some(u), Some(rtt)) => format!(
            " | clock: offset {:+.3} ms ± {:.3} ms (round trip {:.3} ms, drift {:+.1} ppm), \
             {} probes, {} answers, {} refused, {} held back",
            ms(offset),
            ms(u as i64),
            ms(rtt as i64),
            c.drift_ppb.unwrap_or(0) as f64 / 1000.0,
            c.probes_sent,
            c.answers,
            c.answers_refused,
            c.held_back
        ),
        (Side::Board, ..) if c.probes_sent > 0 => format!(
            " | clock: no answer to {} probes yet, {} messages held back",
            c.probes_sent, c.held_back
        ),
        (Side::Board, ..) => String::new(),
    }
}
