//! What an operator does to a running board from the command line: inject a disturbance and see
//! it applied (`vic inject`), read one snapshot of its telemetry (`vic status`), watch it live
//! (`vic monitor`). The binaries parse arguments and print; the waiting, matching and reporting
//! live here.
//!
//! Every wait is woken by the board's iceoryx2 events ([`vic_rt::transport::BoardEvent`]): the
//! tools sleep in the kernel until the board says it applied something or published telemetry.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};
use vic_rt::board::live::PercentilesJson;
use vic_rt::board::{FaultReason, Rejection};
use vic_rt::transport::{
    Disturbance, DisturbanceKind, Header, MAX_JOINTS, Mode, NodeInfo, NodeLiveness, ObserverPorts,
    Telemetry, ToolPorts, list_nodes, monotonic_ns, session_seq,
};

/// Why a tool failed.
#[derive(Debug, thiserror::Error)]
pub(crate) enum OperatorError {
    #[error("no board in namespace \"{0}\" (start one with vic-board --namespace {0})")]
    NoBoard(String),
    /// A board process is alive but published no telemetry in time.
    #[error(
        "namespace \"{namespace}\": the board (vic-board pid {pid}) is not responding: no \
         telemetry within {waited_ms} ms; {why}"
    )]
    NotResponding {
        namespace: String,
        pid: u32,
        waited_ms: u128,
        why: String,
    },
    #[error("namespace \"{namespace}\": the board rejected the disturbance ({reason}){hint}")]
    Rejected {
        namespace: String,
        reason: String,
        /// Which keys of the board's scenario bound this disturbance, when it was out of them.
        hint: String,
    },
    #[error(
        "namespace \"{0}\": the board did not acknowledge the disturbance (no state with its \
         sequence number)"
    )]
    NoAck(String),
    #[error("{0}")]
    Transport(#[from] vic_rt::transport::TransportError),
    /// `vic status` failed; the processes of the namespace are listed anyway (who holds it).
    #[error("{source}\nprocesses of namespace \"{namespace}\": {nodes}")]
    WithNodes {
        namespace: String,
        source: Box<OperatorError>,
        nodes: String,
    },
}

/// A disturbance as the operator states it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Request {
    /// Torque pulse [N m] for a duration [s].
    Pulse {
        torque: [f64; MAX_JOINTS],
        duration: f64,
    },
    /// Steady torque [N m] until changed (zero removes it).
    Load { torque: [f64; MAX_JOINTS] },
    /// Divergent field β [N/m] (0: off).
    Field { beta: f64 },
    /// Noise factor (1: as configured, 0: none).
    Noise { factor: f64 },
}

impl Request {
    /// The keys of the board's scenario (`[board]`) that bound this disturbance, for the message
    /// of a rejection: the board reports only that a limit was passed, not which.
    pub(crate) fn limits(&self) -> &'static str {
        match self {
            Request::Pulse { .. } => {
                "a pulse is bounded by the board's [board] max_pulse_torque (N m, each joint) and \
                 max_pulse_duration (s)"
            }
            Request::Load { .. } => {
                "a load is bounded by the board's [board] max_load_torque (N m, each joint)"
            }
            Request::Field { .. } => {
                "a field is bounded by the board's [board] max_field_beta (N/m), and only a \
                 two-link arm takes one"
            }
            Request::Noise { .. } => {
                "a noise factor is bounded by the board's [board] max_noise_factor (and at least 0)"
            }
        }
    }

    /// The message (sequence number and time stamp are set when it is sent).
    pub(crate) fn message(&self) -> Disturbance {
        let mut d = Disturbance {
            header: Header::new(0, 0),
            ..Default::default()
        };
        match *self {
            Request::Pulse { torque, duration } => {
                d.kind = DisturbanceKind::Pulse as u32;
                d.torque = torque;
                d.duration_ns = (duration.max(0.0) * 1e9).round() as u64;
            }
            Request::Load { torque } => {
                d.kind = DisturbanceKind::Load as u32;
                d.torque = torque;
            }
            Request::Field { beta } => {
                d.kind = DisturbanceKind::Field as u32;
                d.value = beta;
            }
            Request::Noise { factor } => {
                d.kind = DisturbanceKind::Noise as u32;
                d.value = factor;
            }
        }
        d
    }
}

/// The board's acknowledgement of a disturbance, read from its state stream.
#[derive(Debug, Clone, serde::Serialize)]
pub(crate) struct Ack {
    pub(crate) namespace: String,
    pub(crate) seq: u64,
    /// The board tick that applied it, and that tick's publish time [ns, monotonic].
    pub(crate) tick: u64,
    pub(crate) board_time_ns: u64,
    /// From our publish to the acknowledging state's publish [µs].
    pub(crate) latency_us: f64,
    /// First tick whose state shows the external torque (pulse and load), and how many ticks
    /// after the acknowledgement that was.
    pub(crate) effect_tick: Option<u64>,
    pub(crate) effect_after_ticks: Option<u64>,
    /// External torque in force at the acknowledgement [N m].
    pub(crate) tau_ext: [f64; MAX_JOINTS],
    pub(crate) mode: String,
}

/// Sends `request` to the board of `namespace` and waits up to `timeout` for the state that
/// acknowledges it.
pub(crate) fn inject(
    namespace: &str,
    request: Request,
    timeout: Duration,
) -> Result<Ack, OperatorError> {
    let ep = ToolPorts::open(namespace)?;
    let before = ep
        .wait_for_telemetry(timeout)
        .ok_or(OperatorError::NoBoard(namespace.into()))?;
    let mut d = request.message();
    d.header = Header::new(session_seq(), monotonic_ns());
    ep.latest_state(); // drop what came before
    ep.publish_disturbance(&d)?;
    let t0 = Instant::now();
    let mut ack: Option<Ack> = None;
    let wants_effect = matches!(request, Request::Pulse { .. } | Request::Load { .. })
        && request.message().torque.iter().any(|v| *v != 0.0);
    loop {
        let mut done = false;
        ep.drain_states(|s| {
            if let Some(a) = &mut ack {
                if a.effect_tick.is_none() && s.tau_ext.iter().any(|v| *v != 0.0) {
                    a.effect_tick = Some(s.tick);
                    a.effect_after_ticks = Some(s.tick.saturating_sub(a.tick));
                }
            } else if s.disturbance_seq == d.header.seq {
                let mut a = Ack {
                    namespace: namespace.into(),
                    seq: d.header.seq,
                    tick: s.disturbance_tick,
                    board_time_ns: s.header.time_ns,
                    latency_us: s.header.time_ns.saturating_sub(d.header.time_ns) as f64 / 1e3,
                    effect_tick: None,
                    effect_after_ticks: None,
                    tau_ext: s.tau_ext,
                    mode: Mode::from_u32(s.mode).name().into(),
                };
                if s.tau_ext.iter().any(|v| *v != 0.0) {
                    a.effect_tick = Some(s.tick);
                    a.effect_after_ticks = Some(s.tick.saturating_sub(a.tick));
                }
                ack = Some(a);
            }
            if let Some(a) = &ack {
                done = !wants_effect || a.effect_tick.is_some() || s.tick > a.tick + 10;
            }
        });
        if done {
            return Ok(ack.expect("done implies an ack"));
        }
        if t0.elapsed() > timeout {
            break;
        }
        ep.wait_event(Duration::from_millis(20));
    }
    if let Some(a) = ack {
        return Ok(a);
    }
    // No acknowledgement: did the board reject it? Its telemetry counts rejections by reason.
    let after = ep
        .wait_for_telemetry(Duration::from_millis(500))
        .ok_or(OperatorError::NoBoard(namespace.into()))?;
    let reasons: Vec<String> = Rejection::ALL
        .iter()
        .filter(|r| {
            after.rejected_by_reason[**r as usize] > before.rejected_by_reason[**r as usize]
        })
        .map(|r| r.name().to_string())
        .collect();
    if reasons.is_empty() {
        Err(OperatorError::NoAck(namespace.into()))
    } else {
        let out_of_bounds = Rejection::DisturbanceOutOfBounds.name();
        let hint = if reasons.iter().any(|r| r == out_of_bounds) {
            format!(": {}", request.limits())
        } else {
            String::new()
        };
        Err(OperatorError::Rejected {
            namespace: namespace.into(),
            reason: reasons.join(", "),
            hint,
        })
    }
}

/// One snapshot of a board's telemetry, for people and scripts.
#[derive(Debug, Clone, serde::Serialize)]
pub(crate) struct Status {
    pub(crate) namespace: String,
    pub(crate) mode: String,
    pub(crate) fault: String,
    pub(crate) trial: u32,
    pub(crate) tick: u64,
    pub(crate) tick_rate_hz: f64,
    pub(crate) jitter_us: PercentilesJson,
    pub(crate) work_us: PercentilesJson,
    pub(crate) command_age_us: PercentilesJson,
    pub(crate) late_ticks: u64,
    pub(crate) missed_periods: u64,
    pub(crate) rejected_messages: u64,
    pub(crate) rejected_by_reason: BTreeMap<String, u64>,
    /// Messages lost before the board saw them (gaps in a sender's sequence numbers).
    pub(crate) dropped_messages: u64,
    pub(crate) safe_hold_ticks: u64,
    pub(crate) watchdog_trips: u64,
    /// Distance of the joints to the commanded equilibrium [rad].
    pub(crate) tracking_error: f64,
    pub(crate) stiffness: Vec<f64>,
    pub(crate) tau_ext: Vec<f64>,
    pub(crate) field_beta: f64,
    pub(crate) noise_factor: f64,
    pub(crate) last_disturbance_seq: u64,
    pub(crate) last_disturbance_tick: u64,
    /// The namespace's other processes (iceoryx2 nodes, alive or dead) when `vic status` looked
    /// (`vic status` only; empty for `vic monitor`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub(crate) nodes: Vec<NodeInfo>,
}

impl Status {
    pub(crate) fn from_telemetry(namespace: &str, t: &Telemetry) -> Status {
        let n = (t.joints as usize).clamp(1, MAX_JOINTS);
        Status {
            namespace: namespace.into(),
            mode: Mode::from_u32(t.mode).name().into(),
            fault: FaultReason::from_u32(t.fault_reason).name().into(),
            trial: t.trial,
            tick: t.tick,
            tick_rate_hz: t.tick_rate_hz,
            jitter_us: t.jitter_us,
            work_us: t.work_us,
            command_age_us: t.command_age_us,
            late_ticks: t.late_ticks,
            missed_periods: t.missed_periods,
            rejected_messages: t.rejected_messages,
            rejected_by_reason: vic_rt::board::live::rejections_by_name(&t.rejected_by_reason),
            dropped_messages: t.dropped_messages,
            safe_hold_ticks: t.safe_hold_ticks,
            watchdog_trips: t.watchdog_trips,
            tracking_error: t.tracking_error,
            stiffness: t.stiffness[..n].to_vec(),
            tau_ext: t.tau_ext[..n].to_vec(),
            field_beta: t.field_beta,
            noise_factor: t.noise_factor,
            last_disturbance_seq: t.disturbance_seq,
            last_disturbance_tick: t.disturbance_tick,
            nodes: Vec::new(),
        }
    }

    /// A few lines for a terminal.
    pub(crate) fn render(&self) -> String {
        let p = |v: &PercentilesJson| format!("{:.1} / {:.1} / {:.1}", v.p50, v.p99, v.max);
        let rejected = if self.rejected_by_reason.is_empty() {
            String::new()
        } else {
            let r: Vec<String> = self
                .rejected_by_reason
                .iter()
                .map(|(k, v)| format!("{k} {v}"))
                .collect();
            format!(" ({})", r.join(", "))
        };
        let fault = if self.mode == "fault" {
            format!(" ({})", self.fault)
        } else {
            String::new()
        };
        let nodes = if self.nodes.is_empty() {
            String::new()
        } else {
            format!("\nprocesses            {}", describe_nodes(&self.nodes))
        };
        format!(
            "board \"{ns}\": {mode}{fault}, trial {trial}, tick {tick} at {rate:.1} Hz\n\
             jitter p50/p99/max   {jit} µs   ({late} late ticks, {missed} periods missed)\n\
             work p50/p99/max     {work} µs\n\
             command age          {age} µs\n\
             tracking error       {err:.4} rad; stiffness {k:?} N m/rad\n\
             disturbances         τ_ext {tau:?} N m, field β {beta} N/m, noise ×{noise}\n\
             rejected messages    {rej}{rejected}; safe-hold ticks {hold}, watchdog trips {trips}\n\
             dropped messages     {dropped} (lost before the board saw them: sequence gaps)\
             {nodes}",
            ns = self.namespace,
            mode = self.mode,
            trial = self.trial,
            tick = self.tick,
            rate = self.tick_rate_hz,
            jit = p(&self.jitter_us),
            late = self.late_ticks,
            missed = self.missed_periods,
            work = p(&self.work_us),
            age = p(&self.command_age_us),
            err = self.tracking_error,
            k = self.stiffness,
            tau = self.tau_ext,
            beta = self.field_beta,
            noise = self.noise_factor,
            rej = self.rejected_messages,
            dropped = self.dropped_messages,
            hold = self.safe_hold_ticks,
            trips = self.watchdog_trips,
        )
    }

    /// One line (for `vic monitor` when piped).
    pub(crate) fn line(&self) -> String {
        format!(
            "mode={} tick={} rate_hz={:.1} jitter_p50_us={:.1} jitter_p99_us={:.1} \
             jitter_max_us={:.1} command_age_p50_us={:.0} tracking_error_rad={:.4} \
             stiffness={:?} tau_ext={:?} rejected={} dropped={} safe_hold_ticks={}",
            self.mode,
            self.tick,
            self.tick_rate_hz,
            self.jitter_us.p50,
            self.jitter_us.p99,
            self.jitter_us.max,
            self.command_age_us.p50,
            self.tracking_error,
            self.stiffness,
            self.tau_ext,
            self.rejected_messages,
            self.dropped_messages,
            self.safe_hold_ticks
        )
    }
}

/// "vic-board pid 12, vic-observer pid 13, vic-observer pid 14 (dead)": the nodes for people.
pub(crate) fn describe_nodes(nodes: &[NodeInfo]) -> String {
    if nodes.is_empty() {
        return "none".into();
    }
    let one = |n: &NodeInfo| {
        let name = if n.name.is_empty() { "?" } else { &n.name };
        match n.state {
            NodeLiveness::Alive => format!("{name} pid {}", n.pid),
            NodeLiveness::Dead => format!("{name} pid {} (dead)", n.pid),
            NodeLiveness::Inaccessible => format!("node {} (inaccessible)", n.id),
            NodeLiveness::Undefined => format!("node {} (incomplete)", n.id),
        }
    };
    nodes.iter().map(one).collect::<Vec<_>>().join(", ")
}

/// One snapshot of the board's telemetry in `namespace`, with the namespace's processes. When
/// no board answers or a service is full, the error lists the processes too.
pub(crate) fn status(namespace: &str, timeout: Duration) -> Result<Status, OperatorError> {
    // Listed before this tool opens its own node: that needs no port (it works when every
    // port of a service is taken), and a killed process is still listed as dead before the
    // new node cleans up after it. This tool is not among them.
    let nodes = list_nodes(namespace)?;
    let snapshot = ObserverPorts::open(namespace)
        .map_err(OperatorError::from)
        .and_then(|ep| {
            ep.wait_for_telemetry(timeout)
                .ok_or(OperatorError::NoBoard(namespace.into()))
        });
    match snapshot {
        Ok(t) => {
            let mut s = Status::from_telemetry(namespace, &t);
            // Listed again now that the board answered (it may have started after the first
            // listing), without this tool's own node, keeping the dead ones its node cleaned.
            let own = std::process::id();
            let mut now: Vec<NodeInfo> = list_nodes(namespace)
                .unwrap_or_default()
                .into_iter()
                .filter(|n| n.pid != own)
                .collect();
            let cleaned: Vec<NodeInfo> = nodes
                .into_iter()
                .filter(|n| n.state == NodeLiveness::Dead && !now.iter().any(|m| m.id == n.id))
                .collect();
            now.extend(cleaned);
            s.nodes = now;
            Ok(s)
        }
        Err(e) => {
            // A board process that is alive but silent is not "no board": say what it is.
            let e = match (e, alive_board(&nodes)) {
                (OperatorError::NoBoard(_), Some(pid)) => OperatorError::NotResponding {
                    namespace: namespace.into(),
                    pid,
                    waited_ms: timeout.as_millis(),
                    why: process_state(pid),
                },
                (e, _) => e,
            };
            Err(OperatorError::WithNodes {
                namespace: namespace.into(),
                source: Box::new(e),
                nodes: describe_nodes(&nodes),
            })
        }
    }
}

/// The pid of a live `vic-board` node among `nodes`.
fn alive_board(nodes: &[NodeInfo]) -> Option<u32> {
    nodes
        .iter()
        .find(|n| n.name == "vic-board" && n.state == NodeLiveness::Alive && n.pid != 0)
        .map(|n| n.pid)
}

/// What the kernel says process `pid` is doing (the state field of `/proc/PID/stat`).
fn process_state(pid: u32) -> String {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    // The state follows the command name in parentheses, which may itself hold ") ".
    let state = stat
        .rfind(')')
        .and_then(|i| stat[i + 1..].split_whitespace().next())
        .unwrap_or("");
    match state {
        "T" => format!("it is stopped (SIGSTOP or Ctrl-Z: kill -CONT {pid} resumes it)"),
        "t" => "it is stopped by a debugger".into(),
        "Z" => "it has exited (a zombie its parent has not reaped)".into(),
        "D" => "it is blocked in the kernel (uninterruptible I/O)".into(),
        "" => "it may have just exited".into(),
        s => format!("it runs (state {s}) but publishes nothing: hung, or starved of CPU time"),
    }
}

/// Calls `show` with a snapshot about every `interval` until it returns false or `stop` is set;
/// `show(None)` when the board has not answered for `interval` (it may come back).
pub(crate) fn monitor(
    namespace: &str,
    interval: Duration,
    stop: &std::sync::atomic::AtomicBool,
    mut show: impl FnMut(Option<&Status>) -> bool,
) -> Result<(), OperatorError> {
    use std::sync::atomic::Ordering;
    let ep = ObserverPorts::open(namespace)?;
    while !stop.load(Ordering::Relaxed) {
        let start = Instant::now();
        let t = ep.wait_for_telemetry(interval);
        if !show(t.map(|t| Status::from_telemetry(namespace, &t)).as_ref()) {
            break;
        }
        // Sleep out the interval in the board's events (the telemetry waits in its buffer).
        while let Some(left) = interval.checked_sub(start.elapsed()) {
            if stop.load(Ordering::Relaxed) || left.is_zero() {
                break;
            }
            ep.wait_event(left.min(Duration::from_millis(100)));
        }
    }
    Ok(())
}
