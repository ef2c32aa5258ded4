//! What can go wrong when connecting to or talking over a namespace's services, told so that the
//! user can act on it.

/// A transport failure, with the namespace it concerns.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    /// The namespace is not a usable name (it becomes part of file names in `/dev/shm`).
    #[error("namespace \"{0}\": use 1 to 32 letters, digits, '_' or '-'")]
    InvalidNamespace(String),
    /// A second board would make two plants answer one planner.
    #[error(
        "namespace \"{namespace}\": a board is already running in this namespace (pid {pid}); \
         stop it or use another --namespace"
    )]
    BoardAlreadyRunning { namespace: String, pid: u32 },
    /// A second central process would send a second stream of commands to one board.
    #[error(
        "namespace \"{namespace}\": a central process (vic-planner) is already running in this \
         namespace (pid {pid}); stop it or use another --namespace"
    )]
    CentralAlreadyRunning { namespace: String, pid: u32 },
    /// The private iceoryx2 directory is not safe to use.
    #[error("iceoryx2 directory {path}: {reason}; {remedy}")]
    UnsafeRoot {
        path: String,
        reason: String,
        /// What the user can do about it (where the directory is decides).
        remedy: String,
    },
    /// Another user owns one of the namespace's files.
    #[error(
        "namespace \"{namespace}\": {path} belongs to uid {owner}, not to you; another user \
         holds this namespace (or made the file first, and only they or an administrator can \
         remove it from the sticky /dev/shm): use another --namespace"
    )]
    ForeignFile {
        namespace: String,
        path: String,
        owner: u32,
    },
    /// Nothing answered: no board publishes telemetry in the namespace.
    #[error("no board in namespace \"{namespace}\"")]
    NoBoard { namespace: String },
    /// A service has all the ports of one kind it was created for: which limit, the configured
    /// number, and who holds the slots.
    #[error(
        "namespace \"{namespace}\": {in_use} of {max} {} of service {service} in use, held by \
         {holders}; stop one of these processes or use another --namespace (`vic status \
         --namespace {namespace}` lists every process of the namespace)",
        kind.plural()
    )]
    TooManyPorts {
        namespace: String,
        service: &'static str,
        kind: PortKind,
        in_use: usize,
        max: usize,
        holders: String,
    },
    /// iceoryx2 refused something else (a node, a service, a port or a send).
    #[error("namespace \"{namespace}\": {what}: {reason}")]
    Ipc {
        namespace: String,
        what: String,
        reason: String,
    },
}

impl TransportError {
    /// An iceoryx2 failure while doing `what`.
    pub(crate) fn ipc(namespace: &str, what: impl Into<String>, e: impl std::fmt::Debug) -> Self {
        TransportError::Ipc {
            namespace: namespace.to_string(),
            what: what.into(),
            reason: format!("{e:?}"),
        }
    }
}

/// Which kind of port of a service is full.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PortKind {
    Publisher,
    Subscriber,
    Notifier,
    Listener,
    /// A process (node) attached to the service.
    Node,
}

impl PortKind {
    /// The plural the messages use.
    pub(crate) fn plural(self) -> &'static str {
        match self {
            PortKind::Publisher => "publishers",
            PortKind::Subscriber => "subscribers",
            PortKind::Notifier => "notifiers",
            PortKind::Listener => "listeners",
            PortKind::Node => "processes (nodes)",
        }
    }
}
