//! Messages between the board, the planner and the command-line tools, and the iceoryx2 services
//! that carry them (DESIGN §8).
//!
//! Every payload is a fixed-size `#[repr(C)]` struct with a stable type name, a protocol
//! [`PROTOCOL_VERSION`], a sequence number and a publish time stamp on the monotonic clock that all
//! processes of the machine share ([`monotonic_ns`]). The board and the planner never touch an
//! iceoryx2 builder: they call [`Endpoint`]'s `publish_*` and `latest_*` / `drain_*` methods.
//!
//! Services live under a namespace: the namespace becomes iceoryx2's `global.prefix`, so
//! instances (and parallel tests) never see each other's services or nodes. [`remove_namespace`]
//! deletes what a namespace left in `/dev/shm` once every process in it has stopped.

use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;

/// Version of the message layout; a message with another version is rejected.
pub const PROTOCOL_VERSION: u32 = 2;
/// Largest number of joints a message carries.
pub const MAX_JOINTS: usize = 2;
/// Knots per command slice. At 10 ms per knot a slice covers up to 320 ms.
pub const MAX_KNOTS: usize = 32;
/// The namespace used when none is given.
pub const DEFAULT_NAMESPACE: &str = "vic";
/// Slots for rejection counts by reason in [`Telemetry`] (see `board::Rejection`).
pub const REJECTION_REASONS: usize = 16;

/// The first sequence number of a publisher that starts now: its start time on the monotonic
/// clock. Receivers refuse sequence numbers that go backwards or repeat; starting from the clock
/// lets a restarted publisher (a planner after a crash, a second `vic inject`) continue upward
/// without any state shared between processes.
pub fn session_seq() -> u64 {
    monotonic_ns()
}

/// The current time on `CLOCK_MONOTONIC` in nanoseconds: the time base of every message, common
/// to all processes of the machine.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// What the board is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Mode {
    /// Plant frozen at its reset state, waiting for the trial start or a command.
    Idle = 0,
    /// Following a valid command.
    Running = 1,
    /// No valid command covers the present: holding the position with the safe stiffness.
    SafeHold = 2,
    /// The plant guard tripped (a joint or speed limit, or a state that is not finite): latched
    /// in a safe hold (or frozen) until an explicit reset.
    Fault = 3,
}

impl Mode {
    /// From the wire value (unknown values read as `Fault`).
    pub fn from_u32(v: u32) -> Mode {
        match v {
            0 => Mode::Idle,
            1 => Mode::Running,
            2 => Mode::SafeHold,
            _ => Mode::Fault,
        }
    }
    /// Lower-case name for reports.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Idle => "idle",
            Mode::Running => "running",
            Mode::SafeHold => "safe-hold",
            Mode::Fault => "fault",
        }
    }
}

/// The board's plant state, published every tick.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("vic::State/2")]
#[repr(C)]
pub struct StateMsg {
    pub version: u32,
    pub joints: u32,
    pub seq: u64,
    /// Publish time [ns, monotonic].
    pub time_ns: u64,
    /// Board tick counter.
    pub tick: u64,
    /// Trial the state belongs to (from the last reset).
    pub trial: u32,
    /// [`Mode`] as `u32`.
    pub mode: u32,
    /// Plant time since the trial start [ns] (0 while idle before the start).
    pub trial_time_ns: u64,
    /// Joint angles [rad], velocities [rad/s] and the joint torque applied [N m].
    pub q: [f64; MAX_JOINTS],
    pub qd: [f64; MAX_JOINTS],
    pub tau: [f64; MAX_JOINTS],
    /// External torque from disturbances in force [N m].
    pub tau_ext: [f64; MAX_JOINTS],
    /// Stiffness in use [N m/rad].
    pub stiffness: [f64; MAX_JOINTS],
    /// Sequence number of the command slice used (0: none).
    pub command_seq: u64,
    /// Sequence number of the last disturbance applied and the tick it was applied at.
    pub disturbance_seq: u64,
    pub disturbance_tick: u64,
    /// Trial time at which the watchdog expires unless a valid command covers the present
    /// [ns] (the last covered period + the watchdog timeout).
    pub watchdog_deadline_ns: u64,
    /// Sequence number of the reset that started this trial: a restarted planner numbers its
    /// trials from 0 again, and this tells its trial from the one before the restart.
    pub reset_seq: u64,
}

/// One knot of a command: the inputs of the impedance law (Eq. 4) at one time.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("vic::Knot/1")]
#[repr(C)]
pub struct Knot {
    /// Feedforward torque `τ_ff` [N m].
    pub tau_ff: [f64; MAX_JOINTS],
    /// Stiffness `K_P` [N m/rad] (the damping follows from the actuator's law).
    pub stiffness: [f64; MAX_JOINTS],
    /// Equilibrium `q_d` [rad] and `q_d'` [rad/s].
    pub q_d: [f64; MAX_JOINTS],
    pub qd_d: [f64; MAX_JOINTS],
}

/// How the board reads the knots between their times.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Interpolation {
    /// Zero-order hold: knot `i` holds over `[t_i, t_{i+1})` (the plan's discretisation).
    Hold = 0,
    /// Linear between knots.
    Linear = 1,
}

/// A slice of commands covering `[start, start + count · knot_dt)` of a trial's plant time.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("vic::CommandSlice/1")]
#[repr(C)]
pub struct CommandSlice {
    pub version: u32,
    pub joints: u32,
    pub seq: u64,
    /// Publish time [ns, monotonic].
    pub time_ns: u64,
    /// The trial the slice is for; slices for another trial are rejected.
    pub trial: u32,
    /// [`Interpolation`] as `u32`.
    pub interpolation: u32,
    /// Trial time of the first knot [ns].
    pub start_ns: u64,
    /// Time between knots [ns].
    pub knot_dt_ns: u64,
    /// Number of valid knots.
    pub count: u32,
    pub _pad: u32,
    pub knots: [Knot; MAX_KNOTS],
}

impl Default for CommandSlice {
    fn default() -> Self {
        CommandSlice {
            version: PROTOCOL_VERSION,
            joints: 0,
            seq: 0,
            time_ns: 0,
            trial: 0,
            interpolation: Interpolation::Hold as u32,
            start_ns: 0,
            knot_dt_ns: 0,
            count: 0,
            _pad: 0,
            knots: [Knot::default(); MAX_KNOTS],
        }
    }
}

impl CommandSlice {
    /// Trial time just after the last knot's interval [ns].
    pub fn end_ns(&self) -> u64 {
        self.start_ns + self.count as u64 * self.knot_dt_ns
    }
}

/// Kinds of disturbance.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum DisturbanceKind {
    /// `torque` for `duration_ns`.
    Pulse = 0,
    /// A steady `torque` until changed (zero removes it).
    Load = 1,
    /// Field on (`value` = β of a divergent field [N/m]) or off (`value` = 0).
    Field = 2,
    /// Noise level: the plant noise is multiplied by `value` (1: as configured, 0: none).
    Noise = 3,
}

impl DisturbanceKind {
    pub fn from_u32(v: u32) -> Option<Self> {
        Some(match v {
            0 => DisturbanceKind::Pulse,
            1 => DisturbanceKind::Load,
            2 => DisturbanceKind::Field,
            3 => DisturbanceKind::Noise,
            _ => return None,
        })
    }
}

/// A disturbance for the board to apply.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("vic::Disturbance/1")]
#[repr(C)]
pub struct Disturbance {
    pub version: u32,
    /// [`DisturbanceKind`] as `u32`.
    pub kind: u32,
    pub seq: u64,
    pub time_ns: u64,
    /// Joint torque [N m] (pulse, load).
    pub torque: [f64; MAX_JOINTS],
    /// Pulse duration [ns].
    pub duration_ns: u64,
    /// Field β [N/m] or noise factor.
    pub value: f64,
}

/// Control requests.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum ControlKind {
    /// Put the plant at `q0`, `qd0`, reseed the noise from `(seed, trial)`, wait for the trial to
    /// start at the board tick on or after `start_ns` (monotonic).
    Reset = 0,
    /// Stop the trial: freeze the plant (idle).
    Stop = 1,
}

/// A control request to the board.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("vic::Control/1")]
#[repr(C)]
pub struct Control {
    pub version: u32,
    /// [`ControlKind`] as `u32`.
    pub kind: u32,
    pub seq: u64,
    pub time_ns: u64,
    pub trial: u32,
    pub _pad: u32,
    pub seed: u64,
    /// Monotonic time at which the trial starts [ns].
    pub start_ns: u64,
    pub q0: [f64; MAX_JOINTS],
    pub qd0: [f64; MAX_JOINTS],
}

/// Percentiles of a histogram [µs].
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("vic::Percentiles/1")]
#[repr(C)]
pub struct Percentiles {
    pub p50: f64,
    pub p99: f64,
    pub p999: f64,
    pub max: f64,
    pub count: u64,
}

/// The board's telemetry, published at a lower rate than the state.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("vic::Telemetry/2")]
#[repr(C)]
pub struct Telemetry {
    pub version: u32,
    pub mode: u32,
    pub seq: u64,
    pub time_ns: u64,
    pub tick: u64,
    /// Tick rate measured over the last telemetry interval [Hz].
    pub tick_rate_hz: f64,
    /// Wake-up lateness, tick work time and age of the command used [µs].
    pub jitter_us: Percentiles,
    pub work_us: Percentiles,
    pub command_age_us: Percentiles,
    /// Ticks that woke more than one period late, and periods skipped.
    pub late_ticks: u64,
    pub missed_periods: u64,
    pub rejected_messages: u64,
    pub safe_hold_ticks: u64,
    /// Distance of the joint angles to the commanded equilibrium [rad] (Euclidean).
    pub tracking_error: f64,
    pub stiffness: [f64; MAX_JOINTS],
    pub tau_ext: [f64; MAX_JOINTS],
    pub field_beta: f64,
    pub noise_factor: f64,
    pub trial: u32,
    pub joints: u32,
    /// Rejected messages by reason (indexed by `board::Rejection as usize`).
    pub rejected_by_reason: [u64; REJECTION_REASONS],
    /// Why the board is in fault (`board::FaultReason as u32`, 0: none).
    pub fault_reason: u32,
    pub _pad: u32,
    /// Times the watchdog ramped the board to its safe hold.
    pub watchdog_trips: u64,
    /// Sequence number of the last disturbance applied and the tick it was applied at.
    pub disturbance_seq: u64,
    pub disturbance_tick: u64,
}

/// What a board's event wakes its listeners for (iceoryx2 event ids).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(usize)]
pub enum BoardEvent {
    /// New telemetry was published.
    Telemetry = 1,
    /// A disturbance or control request was applied (its acknowledgement is in the state).
    Applied = 2,
}

/// A transport failure, with the namespace and service it concerns.
#[derive(Debug, thiserror::Error)]
#[error("namespace \"{namespace}\": {what}")]
pub struct TransportError {
    pub namespace: String,
    pub what: String,
}

/// Checks a namespace: 1–32 characters of `[A-Za-z0-9_-]`.
pub fn validate_namespace(ns: &str) -> Result<(), String> {
    if ns.is_empty()
        || ns.len() > 32
        || !ns
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        return Err(format!(
            "namespace \"{ns}\": use 1 to 32 letters, digits, '_' or '-'"
        ));
    }
    Ok(())
}

/// The iceoryx2 file prefix of a namespace.
pub fn prefix(ns: &str) -> String {
    format!("vic_{ns}_")
}

/// The iceoryx2 configuration of a namespace: the defaults with the namespace's prefix (no config
/// file is looked up).
fn config(ns: &str) -> Result<Config, String> {
    validate_namespace(ns)?;
    let mut cfg = Config::default();
    cfg.global.prefix = FileName::new(prefix(ns).as_bytes()).map_err(|e| format!("{e:?}"))?;
    Ok(cfg)
}

/// Which side of the services a process is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// Publishes state and telemetry; receives commands, control and disturbances.
    Board,
    /// Publishes commands and control; receives state and telemetry.
    Planner,
    /// Publishes disturbances; receives state and telemetry (`vic inject`, `status`, `monitor`).
    Tool,
}

type Pub<T> = Publisher<ipc::Service, T, ()>;
type Sub<T> = Subscriber<ipc::Service, T, ()>;

/// One process's connection to the services of a namespace.
pub struct Endpoint {
    namespace: String,
    // Ports before the node: they are dropped first.
    state_pub: Option<Pub<StateMsg>>,
    telemetry_pub: Option<Pub<Telemetry>>,
    command_pub: Option<Pub<CommandSlice>>,
    control_pub: Option<Pub<Control>>,
    disturbance_pub: Option<Pub<Disturbance>>,
    state_sub: Option<Sub<StateMsg>>,
    telemetry_sub: Option<Sub<Telemetry>>,
    command_sub: Option<Sub<CommandSlice>>,
    control_sub: Option<Sub<Control>>,
    disturbance_sub: Option<Sub<Disturbance>>,
    notifier: Option<iceoryx2::port::notifier::Notifier<ipc::Service>>,
    /// Dead nodes of the namespace whose resources were removed when this endpoint opened.
    pub cleaned_dead_nodes: usize,
    listener: Option<iceoryx2::port::listener::Listener<ipc::Service>>,
    node: Option<Node<ipc::Service>>,
    config: Config,
}

impl Drop for Endpoint {
    /// Closes the ports and the node; the last process of a namespace to leave also removes the
    /// namespace's management file, so that a clean shutdown leaves nothing in `/dev/shm`.
    fn drop(&mut self) {
        self.state_pub = None;
        self.telemetry_pub = None;
        self.command_pub = None;
        self.control_pub = None;
        self.disturbance_pub = None;
        self.state_sub = None;
        self.telemetry_sub = None;
        self.command_sub = None;
        self.control_sub = None;
        self.disturbance_sub = None;
        self.notifier = None;
        self.listener = None;
        self.node = None;
        let mut others = false;
        let _ = Node::<ipc::Service>::list(&self.config, |state| {
            others |= matches!(state, NodeState::Alive(_));
            CallbackProgression::Continue
        });
        if !others {
            remove_namespace(&self.namespace);
        }
    }
}

/// The iceoryx2 node name of each role; the board's is how a second board finds the first.
fn node_name(role: Role) -> &'static str {
    match role {
        Role::Board => "vic-board",
        Role::Planner => "vic-planner",
        Role::Tool => "vic-tool",
    }
}

fn dead_nodes_in(cfg: &Config) -> usize {
    let mut n = 0;
    let _ = Node::<ipc::Service>::list(cfg, |state| {
        n += matches!(state, NodeState::Dead(_)) as usize;
        CallbackProgression::Continue
    });
    n
}

/// Nodes of killed processes whose resources nobody has removed yet, in namespace `ns`.
pub fn dead_nodes(ns: &str) -> usize {
    config(ns).map(|c| dead_nodes_in(&c)).unwrap_or(0)
}

/// Removes the resources of the namespace's dead nodes (processes killed without cleaning up) and
/// returns the process ids of the live nodes named `name` other than `own`.
fn live_nodes_named(
    cfg: &Config,
    name: &str,
    own: &iceoryx2::identifiers::UniqueNodeId,
) -> Result<(Vec<u32>, usize), String> {
    use iceoryx2::node::NodeView;
    let mut alive = Vec::new();
    let mut dead = Vec::new();
    Node::<ipc::Service>::list(cfg, |state| {
        match state {
            NodeState::Alive(view) => {
                if let Some(d) = view.details()
                    && view.id() != own
                    && d.name().as_str() == name
                {
                    alive.push(d.process_id().value() as u32);
                }
            }
            NodeState::Dead(view) => dead.push(view),
            _ => {}
        }
        CallbackProgression::Continue
    })
    .map_err(|e| format!("cannot list the nodes: {e:?}"))?;
    let mut cleaned = 0;
    for view in dead {
        if view.try_remove_stale_resources().is_ok() {
            cleaned += 1;
        }
    }
    Ok((alive, cleaned))
}

/// Subscriber buffer of the state service: a 50 Hz reader sees every 1 kHz state.
pub const STATE_BUFFER: usize = 128;

impl Endpoint {
    /// Connects to the namespace `ns` in the given role, creating the services if needed.
    pub fn open(ns: &str, role: Role) -> Result<Endpoint, TransportError> {
        set_log_level(LogLevel::Error);
        let err = |what: String| TransportError {
            namespace: ns.to_string(),
            what,
        };
        let cfg = config(ns).map_err(err)?;
        // Dead nodes (killed processes) are counted before our node's creation, which already
        // removes some of their resources.
        let dead_before = dead_nodes_in(&cfg);
        let name = NodeName::new(node_name(role)).map_err(|e| err(format!("{e:?}")))?;
        let node = NodeBuilder::new()
            .name(&name)
            .config(&cfg)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .map_err(|e| err(format!("cannot create a node: {e:?}")))?;
        let mut ep = Endpoint {
            namespace: ns.to_string(),
            state_pub: None,
            telemetry_pub: None,
            command_pub: None,
            control_pub: None,
            disturbance_pub: None,
            state_sub: None,
            telemetry_sub: None,
            command_sub: None,
            control_sub: None,
            disturbance_sub: None,
            cleaned_dead_nodes: 0,
            notifier: None,
            listener: None,
            node: Some(node),
            config: cfg.clone(),
        };
        // A board refuses to start beside a live one (two plants answering one planner); the
        // resources of a killed one are removed here so that the services open cleanly.
        let (alive, _) =
            live_nodes_named(&cfg, node_name(Role::Board), ep.node().id()).map_err(err)?;
        ep.cleaned_dead_nodes = dead_before.saturating_sub(dead_nodes_in(&cfg));
        restrict_namespace_files(ns);
        if role == Role::Board && !alive.is_empty() {
            return Err(err(format!(
                "a board is already running in this namespace (pid {}); stop it or use another \
                 --namespace",
                alive[0]
            )));
        }
        let node = ep.node.as_ref().expect("open");
        macro_rules! service {
            ($name:expr, $ty:ty, $buffer:expr, $history:expr) => {{
                let name = ServiceName::new($name).map_err(|e| err(format!("{e:?}")))?;
                node.service_builder(&name)
                    .publish_subscribe::<$ty>()
                    .max_publishers(4)
                    .max_subscribers(8)
                    .subscriber_max_buffer_size(STATE_BUFFER)
                    .history_size($history)
                    .enable_safe_overflow(true)
                    .open_or_create()
                    .map_err(|e| err(format!("service {}: {e:?}", $name)))
                    .map(|s| (s, $buffer))
            }};
        }
        let (state, _) = service!("vic/state", StateMsg, STATE_BUFFER, 1)?;
        let (telemetry, _) = service!("vic/telemetry", Telemetry, 1, 1)?;
        let (command, _) = service!("vic/command", CommandSlice, 8, 0)?;
        let (control, _) = service!("vic/control", Control, 8, 0)?;
        let (disturbance, _) = service!("vic/disturbance", Disturbance, 8, 0)?;
        let event_name = ServiceName::new("vic/board-event").map_err(|e| err(format!("{e:?}")))?;
        let event = node
            .service_builder(&event_name)
            .event()
            .max_notifiers(4)
            .max_listeners(16)
            .open_or_create()
            .map_err(|e| err(format!("service vic/board-event: {e:?}")))?;
        if role == Role::Board {
            ep.notifier = Some(
                event
                    .notifier_builder()
                    .create()
                    .map_err(|e| err(format!("event notifier: {e:?}")))?,
            );
        } else {
            ep.listener = Some(
                event
                    .listener_builder()
                    .create()
                    .map_err(|e| err(format!("event listener: {e:?}")))?,
            );
        }
        let p = |what: &str, e: &dyn std::fmt::Debug| err(format!("{what} publisher: {e:?}"));
        let s = |what: &str, e: &dyn std::fmt::Debug| err(format!("{what} subscriber: {e:?}"));
        match role {
            Role::Board => {
                ep.state_pub = Some(
                    state
                        .publisher_builder()
                        .create()
                        .map_err(|e| p("state", &e))?,
                );
                ep.telemetry_pub = Some(
                    telemetry
                        .publisher_builder()
                        .create()
                        .map_err(|e| p("telemetry", &e))?,
                );
                ep.command_sub = Some(
                    command
                        .subscriber_builder()
                        .buffer_size(8)
                        .create()
                        .map_err(|e| s("command", &e))?,
                );
                ep.control_sub = Some(
                    control
                        .subscriber_builder()
                        .buffer_size(8)
                        .create()
                        .map_err(|e| s("control", &e))?,
                );
                ep.disturbance_sub = Some(
                    disturbance
                        .subscriber_builder()
                        .buffer_size(8)
                        .create()
                        .map_err(|e| s("disturbance", &e))?,
                );
            }
            Role::Planner | Role::Tool => {
                ep.state_sub = Some(
                    state
                        .subscriber_builder()
                        .buffer_size(STATE_BUFFER)
                        .create()
                        .map_err(|e| s("state", &e))?,
                );
                ep.telemetry_sub = Some(
                    telemetry
                        .subscriber_builder()
                        .buffer_size(1)
                        .create()
                        .map_err(|e| s("telemetry", &e))?,
                );
                if role == Role::Planner {
                    ep.command_pub = Some(
                        command
                            .publisher_builder()
                            .create()
                            .map_err(|e| p("command", &e))?,
                    );
                    ep.control_pub = Some(
                        control
                            .publisher_builder()
                            .create()
                            .map_err(|e| p("control", &e))?,
                    );
                } else {
                    ep.disturbance_pub = Some(
                        disturbance
                            .publisher_builder()
                            .create()
                            .map_err(|e| p("disturbance", &e))?,
                    );
                }
            }
        }
        Ok(ep)
    }

    fn node(&self) -> &Node<ipc::Service> {
        self.node
            .as_ref()
            .expect("the node lives as long as the endpoint")
    }

    /// The namespace of this endpoint.
    pub fn namespace(&self) -> &str {
        &self.namespace
    }

    fn send<T: std::fmt::Debug + ZeroCopySend + Copy>(
        &self,
        port: &Option<Pub<T>>,
        what: &str,
        value: T,
    ) -> Result<(), TransportError> {
        let port = port.as_ref().ok_or_else(|| TransportError {
            namespace: self.namespace.clone(),
            what: format!("this endpoint does not publish {what}"),
        })?;
        port.send_copy(value)
            .map(|_| ())
            .map_err(|e| TransportError {
                namespace: self.namespace.clone(),
                what: format!("cannot send {what}: {e:?}"),
            })
    }

    /// Publishes the plant state (board).
    pub fn publish_state(&self, s: &StateMsg) -> Result<(), TransportError> {
        self.send(&self.state_pub, "state", *s)
    }
    /// Publishes telemetry (board).
    pub fn publish_telemetry(&self, t: &Telemetry) -> Result<(), TransportError> {
        self.send(&self.telemetry_pub, "telemetry", *t)
    }
    /// Publishes a command slice (planner).
    pub fn publish_command(&self, c: &CommandSlice) -> Result<(), TransportError> {
        self.send(&self.command_pub, "commands", *c)
    }
    /// Publishes a control request (planner).
    pub fn publish_control(&self, c: &Control) -> Result<(), TransportError> {
        self.send(&self.control_pub, "control", *c)
    }
    /// Publishes a disturbance (tools).
    pub fn publish_disturbance(&self, d: &Disturbance) -> Result<(), TransportError> {
        self.send(&self.disturbance_pub, "disturbances", *d)
    }

    /// Calls `f` on every message waiting on `port`, oldest first; returns how many there were.
    fn drain<T: std::fmt::Debug + ZeroCopySend + Copy>(
        port: &Option<Sub<T>>,
        mut f: impl FnMut(&T),
    ) -> usize {
        let Some(port) = port else { return 0 };
        let mut n = 0;
        while let Ok(Some(sample)) = port.receive() {
            f(&sample);
            n += 1;
        }
        n
    }

    /// Every state received since the last call, oldest first (planner, tools).
    pub fn drain_states(&self, f: impl FnMut(&StateMsg)) -> usize {
        Self::drain(&self.state_sub, f)
    }
    /// The newest state received since the last call, if any.
    pub fn latest_state(&self) -> Option<StateMsg> {
        let mut last = None;
        self.drain_states(|s| last = Some(*s));
        last
    }
    /// The newest telemetry received since the last call, if any.
    pub fn latest_telemetry(&self) -> Option<Telemetry> {
        let mut last = None;
        Self::drain(&self.telemetry_sub, |t| last = Some(*t));
        last
    }
    /// Every command slice received since the last call, oldest first (board).
    pub fn drain_commands(&self, f: impl FnMut(&CommandSlice)) -> usize {
        Self::drain(&self.command_sub, f)
    }
    /// The newest command slice received since the last call, if any (board).
    pub fn latest_command(&self) -> Option<CommandSlice> {
        let mut last = None;
        self.drain_commands(|c| last = Some(*c));
        last
    }
    /// Every control request received since the last call (board).
    pub fn drain_controls(&self, f: impl FnMut(&Control)) -> usize {
        Self::drain(&self.control_sub, f)
    }
    /// Every disturbance received since the last call (board).
    pub fn drain_disturbances(&self, f: impl FnMut(&Disturbance)) -> usize {
        Self::drain(&self.disturbance_sub, f)
    }

    /// Wakes the board's listeners (board). Without listeners this touches shared memory only.
    pub fn notify(&self, e: BoardEvent) {
        if let Some(n) = &self.notifier {
            let _ = n.notify_with_custom_event_id(EventId::new(e as usize));
        }
    }

    /// Blocks until the board signals an event or `timeout` passes (planner, tools): the
    /// iceoryx2 listener sleeps in the kernel, no polling. Returns whether an event came.
    pub fn wait_event(&self, timeout: std::time::Duration) -> bool {
        let Some(l) = &self.listener else {
            std::thread::sleep(timeout);
            return false;
        };
        let mut got = false;
        let _ = l.timed_wait(|_| got = true, timeout);
        // Drain what else is pending, so the next wait blocks again.
        let _ = l.try_wait(|_| got = true);
        got
    }
}

/// Waits up to `timeout` for telemetry from a board in the namespace of `ep` (woken by the
/// board's events, no polling). `None`: no board answered.
pub fn wait_for_telemetry(ep: &Endpoint, timeout: std::time::Duration) -> Option<Telemetry> {
    let deadline = std::time::Instant::now() + timeout;
    loop {
        if let Some(t) = ep.latest_telemetry() {
            return Some(t);
        }
        let left = deadline.saturating_duration_since(std::time::Instant::now());
        if left.is_zero() {
            return None;
        }
        ep.wait_event(left.min(std::time::Duration::from_millis(200)));
    }
}

/// Whether a board is alive in the namespace (it publishes telemetry within `timeout`). Cheap
/// enough to call from tools, not from a loop.
pub fn board_present(ns: &str, timeout: std::time::Duration) -> Result<bool, TransportError> {
    let ep = Endpoint::open(ns, Role::Tool)?;
    Ok(wait_for_telemetry(&ep, timeout).is_some())
}

/// Removes the shared-memory and node files a namespace left behind. Call it only when no
/// process of the namespace runs any more. Returns how many files were removed.
pub fn remove_namespace(ns: &str) -> usize {
    if validate_namespace(ns).is_err() {
        return 0;
    }
    let prefix = prefix(ns);
    let mut removed = 0;
    let mut dirs = vec![std::path::PathBuf::from("/dev/shm")];
    if let Ok(cfg) = config(ns) {
        dirs.push(std::path::PathBuf::from(cfg.global.root_path().to_string()));
    }
    while let Some(dir) = dirs.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.flatten() {
            let path = e.path();
            let name = e.file_name().to_string_lossy().to_string();
            let is_dir = e.file_type().map(|t| t.is_dir()).unwrap_or(false);
            if is_dir && dir != std::path::Path::new("/dev/shm") {
                dirs.push(path);
            } else if !is_dir && name.starts_with(&prefix) && std::fs::remove_file(&path).is_ok() {
                removed += 1;
            }
        }
    }
    removed
}

/// Makes the namespace's files in `/dev/shm` owner-only. iceoryx2 creates its data segments 0600
/// but its 16-byte `global_mgmt` file 0666; no other user may write any of them.
fn restrict_namespace_files(ns: &str) {
    use std::os::unix::fs::PermissionsExt;
    let prefix = prefix(ns);
    let Ok(dir) = std::fs::read_dir("/dev/shm") else {
        return;
    };
    for e in dir.flatten() {
        if e.file_name().to_string_lossy().starts_with(&prefix)
            && let Ok(m) = e.metadata()
            && m.permissions().mode() & 0o077 != 0
        {
            let _ = std::fs::set_permissions(e.path(), std::fs::Permissions::from_mode(0o600));
        }
    }
}

/// Files a namespace has in `/dev/shm` (for tests and `vic demo`'s final check).
pub fn namespace_files(ns: &str) -> Vec<String> {
    let prefix = prefix(ns);
    std::fs::read_dir("/dev/shm")
        .map(|d| {
            d.flatten()
                .map(|e| e.file_name().to_string_lossy().to_string())
                .filter(|n| n.starts_with(&prefix))
                .collect()
        })
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn state_and_commands_cross_two_nodes() {
        let ns = format!("t{}x{}", std::process::id(), monotonic_ns() % 100_000);
        {
            let board = Endpoint::open(&ns, Role::Board).unwrap();
            let planner = Endpoint::open(&ns, Role::Planner).unwrap();
            let s = StateMsg {
                version: PROTOCOL_VERSION,
                seq: 7,
                q: [0.5, 1.0],
                ..Default::default()
            };
            board.publish_state(&s).unwrap();
            let got = planner.latest_state().unwrap();
            assert_eq!(got.seq, 7);
            assert_eq!(got.q, [0.5, 1.0]);
            let mut c = CommandSlice {
                seq: 3,
                count: 2,
                ..Default::default()
            };
            c.knots[1].stiffness = [10.0, 20.0];
            planner.publish_command(&c).unwrap();
            let got = board.latest_command().unwrap();
            assert_eq!(got.seq, 3);
            assert_eq!(got.knots[1].stiffness, [10.0, 20.0]);
            assert!(board.latest_command().is_none());
            // A different namespace sees nothing.
            let other = format!("{ns}o");
            {
                let stranger = Endpoint::open(&other, Role::Planner).unwrap();
                board.publish_state(&s).unwrap();
                assert!(stranger.latest_state().is_none());
            }
            remove_namespace(&other);
            // Publishing on a port this role does not have is an error, not a panic.
            assert!(planner.publish_state(&s).is_err());
        }
        remove_namespace(&ns);
        assert!(
            namespace_files(&ns).is_empty(),
            "{:?}",
            namespace_files(&ns)
        );
    }

    #[test]
    fn namespaces_are_checked() {
        assert!(validate_namespace("vic").is_ok());
        assert!(validate_namespace("a/b").is_err());
        assert!(validate_namespace("").is_err());
    }
}
