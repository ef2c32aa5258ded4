//! Messages between the board, the planner and the command-line tools, and the iceoryx2 services
//! that carry them.
//!
//! - [`protocol`]: the wire types, each led by one [`Header`] (version, sequence number, publish
//!   time), and the reasons the board rejects a message;
//! - [`wire_enum`]: the macro that declares an enum sent as an integer (modes, kinds, reasons)
//!   with its wire values and names once;
//! - [`clock`]: the monotonic time base every process of the machine shares;
//! - [`namespace`]: names, files and dead nodes of a namespace (iceoryx2's `global.prefix`, so
//!   instances and parallel tests never see each other);
//! - [`service`]: iceoryx2's `ipc` service with its global file in the private directory;
//! - [`limits`]: the port and node limits of every service, in one place, and the "too many"
//!   error that names the limit and who holds the slots;
//! - [`session`]: one process's node and the services it opens;
//! - [`relay`]: the event services that wake a relay (the Zenoh bridge) when there is something
//!   to forward, free for the publishers while no relay listens;
//! - [`link_ports`]: the bridge's publishers of what arrives over its link, of the thread-safe
//!   service type, used from Zenoh's callbacks;
//! - [`ports`]: one type per role ([`BoardPorts`], [`CentralPorts`], [`ToolPorts`],
//!   [`ObserverPorts`], [`RecorderPorts`]) with plain `publish_*`, `latest_*` and `drain_*`
//!   methods; no caller touches an iceoryx2 builder.

pub mod clock;
pub mod error;
pub mod limits;
#[cfg(feature = "zenoh")]
pub mod link_ports;
pub mod namespace;
pub mod ports;
pub mod protocol;
pub mod recycled;
pub mod relay;
pub mod service;
pub(crate) mod session;
pub mod wire_enum;

pub use clock::{monotonic_ns, process_session, session_seq};
pub use error::PortKind;
pub use error::TransportError;
pub use namespace::{
    DEFAULT_NAMESPACE, MAX_ROOT_PATH, NodeInfo, NodeLiveness, RUNTIME_DIR_VAR,
    check_namespace_owner, dead_nodes, ensure_root_dir, list_nodes, namespace_files,
    plain_global_file, prefix, remove_namespace, root_dir, validate_namespace,
};
pub use ports::{
    BoardObserver, BoardPorts, BoardWatch, CENTRAL_NODE, CentralPorts, MonitorPorts, ObserverPorts,
    RawPorts, RecorderPorts, STATE_BUFFER, ToolPorts, board_present,
};
pub use protocol::*;
