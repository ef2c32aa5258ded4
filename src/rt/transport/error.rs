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
    /// The private iceoryx2 directory is not safe to use.
    #[error(
        "iceoryx2 directory {path}: {reason}; remove it (or fix its owner and mode 700) and \
         start again"
    )]
    UnsafeRoot { path: String, reason: String },
    /// Another user owns one of the namespace's files.
    #[error(
        "namespace \"{namespace}\": {path} belongs to uid {owner}, not to you; another user's \
         process holds this namespace: use another --namespace"
    )]
    ForeignFile {
        namespace: String,
        path: String,
        owner: u32,
    },
    /// Nothing answered: no board publishes telemetry in the namespace.
    #[error("no board in namespace \"{namespace}\"")]
    NoBoard { namespace: String },
    /// A service has all the ports it was created for (other processes hold them).
    #[error(
        "namespace \"{namespace}\": service {service} has no {port} slot left (too many \
         processes use it: stop some or use another --namespace)"
    )]
    TooManyPorts {
        namespace: String,
        service: &'static str,
        port: &'static str,
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
