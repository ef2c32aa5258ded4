//! Namespaces: every service and node of one instance (and of one parallel test) lives under a
//! namespace, which becomes iceoryx2's `global.prefix`, so instances never see each other.
//! This module checks names, finds the namespace's files and nodes, and removes what killed
//! processes left behind.
//!
//! Two namespaces can never share a file: the prefix `vic_{ns}.` ends with a `.`, which no
//! namespace contains, so `vic_a.` is not a prefix of `vic_a_b.`'s files. iceoryx2's own
//! directory (services, nodes, the global management file) is a per-user directory,
//! [`root_dir`], created 0700 and refused when another user owns it or can write into it.

use super::error::TransportError;
use super::service::Service as Ipc;
use iceoryx2::prelude::*;

/// The namespace used when none is given.
pub const DEFAULT_NAMESPACE: &str = "vic";

/// Checks a namespace: 1–32 characters of `[A-Za-z0-9_-]`.
pub fn validate_namespace(ns: &str) -> Result<(), TransportError> {
    let allowed = |c: char| c.is_ascii_alphanumeric() || c == '_' || c == '-';
    if ns.is_empty() || ns.len() > 32 || !ns.chars().all(allowed) {
        return Err(TransportError::InvalidNamespace(ns.to_string()));
    }
    Ok(())
}

/// The iceoryx2 file prefix of a namespace: `vic_{ns}.` (the `.` is the delimiter that no
/// namespace contains).
pub fn prefix(ns: &str) -> String {
    format!("vic_{ns}.")
}

/// The environment variable that names the private root directory instead of the default
/// place (for a user whose `/tmp/vic-{uid}` another user made first).
pub const RUNTIME_DIR_VAR: &str = "VIC_RUNTIME_DIR";

/// The longest root directory path [bytes], its final `/` included: iceoryx2's event sockets
/// live in it, named `{root}{prefix}{id}.event`, and a socket's path must fit the 108 bytes of
/// `sun_path`: 108 − 37 (the longest prefix) − 39 (a 128-bit id in decimal) − 6 = 26.
pub const MAX_ROOT_PATH: usize = 26;

/// Where the root directory is, and why there: what the error of an unusable one tells to do
/// depends on it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum RootPlace {
    /// `$VIC_RUNTIME_DIR/` as given.
    Given,
    /// `$XDG_RUNTIME_DIR/vic/`: the login session's own directory (e.g. `/run/user/{uid}`),
    /// which no other user can enter, so nobody can make `vic/` in it first.
    Session,
    /// `/tmp/vic-{uid}/`, when neither is set (or `$XDG_RUNTIME_DIR` is not a directory of this
    /// user that only they may enter). Another user can make it first: then every process of
    /// this user is refused, with what to do.
    Tmp,
}

/// `$XDG_RUNTIME_DIR` when it is an absolute path to a directory of this user that nobody else
/// may enter (what the XDG base directory specification promises of it), short enough for its
/// `vic/` to be a root directory ([`MAX_ROOT_PATH`]).
fn session_runtime_dir() -> Option<std::path::PathBuf> {
    use std::os::unix::fs::MetadataExt;
    let dir = std::path::PathBuf::from(std::env::var_os("XDG_RUNTIME_DIR")?);
    let m = std::fs::metadata(&dir).ok()?;
    // SAFETY: geteuid(2) has no preconditions and cannot fail.
    let uid = unsafe { libc::geteuid() };
    let fits = dir.join("vic/").as_os_str().len() <= MAX_ROOT_PATH;
    (dir.is_absolute() && fits && m.is_dir() && m.uid() == uid && m.mode() & 0o077 == 0)
        .then_some(dir)
}

fn root_place() -> (std::path::PathBuf, RootPlace) {
    if let Some(dir) = std::env::var_os(RUNTIME_DIR_VAR).filter(|d| !d.is_empty()) {
        let dir = dir.to_string_lossy();
        return (
            std::path::PathBuf::from(format!("{}/", dir.trim_end_matches('/'))),
            RootPlace::Given,
        );
    }
    if let Some(dir) = session_runtime_dir() {
        return (dir.join("vic/"), RootPlace::Session);
    }
    // SAFETY: geteuid(2) has no preconditions and cannot fail.
    let uid = unsafe { libc::geteuid() };
    (
        std::path::PathBuf::from(format!("/tmp/vic-{uid}/")),
        RootPlace::Tmp,
    )
}

/// The user's private iceoryx2 root directory: `$VIC_RUNTIME_DIR/` if set, else
/// `$XDG_RUNTIME_DIR/vic/` if that is the user's private directory, else `/tmp/vic-{uid}/`.
/// Every process and client of a namespace must see the same (they run with the same
/// environment).
pub fn root_dir() -> std::path::PathBuf {
    root_place().0
}

/// Creates the private root directory (0700) if it is missing and checks that it is safe: a
/// directory (not a link), owned by this user, that nobody else may enter or write into.
pub fn ensure_root_dir() -> Result<std::path::PathBuf, TransportError> {
    use std::os::unix::fs::{DirBuilderExt, MetadataExt};
    let (dir, place) = root_place();
    let path = dir.display().to_string();
    let elsewhere = format!(
        "set {RUNTIME_DIR_VAR} to a directory of yours that only you may enter (`mkdir -m 700 \
         DIR`, an absolute path of at most {MAX_ROOT_PATH} bytes), the same for every vic \
         process and Python client of the namespace"
    );
    let unsafe_root = |reason: String, remedy: String| TransportError::UnsafeRoot {
        path: path.clone(),
        reason,
        remedy,
    };
    if !dir.is_absolute() || path.len() > MAX_ROOT_PATH {
        return Err(unsafe_root(
            format!("{RUNTIME_DIR_VAR} must be an absolute path of at most {MAX_ROOT_PATH} bytes"),
            elsewhere,
        ));
    }
    match std::fs::DirBuilder::new().mode(0o700).create(&dir) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
        Err(e) => return Err(unsafe_root(format!("cannot create it: {e}"), elsewhere)),
    }
    let m = std::fs::symlink_metadata(&dir)
        .map_err(|e| unsafe_root(e.to_string(), elsewhere.clone()))?;
    // SAFETY: geteuid(2) has no preconditions and cannot fail.
    let uid = unsafe { libc::geteuid() };
    // What to do about a directory in the way: in sticky /tmp another user's can be removed
    // only by them or an administrator, so the remedy is a directory elsewhere.
    let in_the_way = |owner: u32| match (place, owner == uid) {
        (RootPlace::Tmp, false) => format!(
            "another user made it first and only they or an administrator can remove it (/tmp \
             is sticky); meanwhile {elsewhere}"
        ),
        _ => format!("remove it, or {elsewhere}"),
    };
    if !m.file_type().is_dir() {
        return Err(unsafe_root(
            "it is not a directory".into(),
            in_the_way(m.uid()),
        ));
    }
    if m.uid() != uid {
        return Err(unsafe_root(
            format!("it belongs to uid {}, not to you (uid {uid})", m.uid()),
            in_the_way(m.uid()),
        ));
    }
    if m.mode() & 0o077 != 0 {
        return Err(unsafe_root(
            format!(
                "its mode is {:o}: other users may enter it (it must be 700)",
                m.mode() & 0o777
            ),
            format!(
                "make it private (`chmod 700 {path}`) if nothing of another user is in it, or remove it"
            ),
        ));
    }
    Ok(dir)
}

/// The iceoryx2 configuration of a namespace: the defaults with the namespace's prefix and the
/// user's private root directory, made and checked first (no config file is looked up): iceoryx2
/// would otherwise create a missing root directory itself, open to the group (0750).
pub fn config(ns: &str) -> Result<Config, TransportError> {
    validate_namespace(ns)?;
    ensure_root_dir()?;
    let mut cfg = Config::default();
    cfg.global.prefix = FileName::new(prefix(ns).as_bytes())
        .map_err(|e| TransportError::ipc(ns, "file prefix", e))?;
    let root = root_dir();
    let root = Path::new(root.to_string_lossy().as_bytes())
        .map_err(|e| TransportError::ipc(ns, "root directory", e))?;
    cfg.global.set_root_path(&root);
    Ok(cfg)
}

/// The global management file of iceoryx2's plain `ipc` service for namespace `ns`, in
/// `/dev/shm`: every vic process of the namespace creates it owner-only
/// ([`super::service::create_plain_global_file`]) for the Python client, which only opens it.
pub fn plain_global_file(ns: &str) -> Result<std::path::PathBuf, TransportError> {
    validate_namespace(ns)?;
    let mut cfg = Config::default();
    cfg.global.prefix = FileName::new(prefix(ns).as_bytes())
        .map_err(|e| TransportError::ipc(ns, "file prefix", e))?;
    super::service::plain_global_file(&cfg).map_err(|e| TransportError::ipc(ns, "global file", e))
}

/// Refuses a namespace with a file another user owns (in `/dev/shm` or the root directory):
/// such a file could be read or written by that user, or block the namespace.
pub fn check_namespace_owner(ns: &str) -> Result<(), TransportError> {
    use std::os::unix::fs::MetadataExt;
    // SAFETY: geteuid(2) has no preconditions and cannot fail.
    let uid = unsafe { libc::geteuid() };
    for path in namespace_paths(ns) {
        if let Ok(m) = std::fs::symlink_metadata(&path)
            && m.uid() != uid
        {
            return Err(TransportError::ForeignFile {
                namespace: ns.to_string(),
                path: path.display().to_string(),
                owner: m.uid(),
            });
        }
    }
    Ok(())
}

/// Every file of the namespace in `/dev/shm` and (recursively) in the root directory.
fn namespace_paths(ns: &str) -> Vec<std::path::PathBuf> {
    let prefix = prefix(ns);
    let shm = std::path::Path::new("/dev/shm");
    let mut found = Vec::new();
    let mut dirs = vec![shm.to_path_buf(), root_dir()];
    while let Some(dir) = dirs.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().to_string();
            let is_dir = e.file_type().map(|t| t.is_dir()).unwrap_or(false);
            if is_dir && dir != shm {
                dirs.push(e.path());
            } else if !is_dir && name.starts_with(&prefix) {
                found.push(e.path());
            }
        }
    }
    found
}

/// Nodes of killed processes in the namespace of `cfg`.
pub(super) fn dead_nodes_in(cfg: &Config) -> usize {
    let mut n = 0;
    let _ = Node::<Ipc>::list(cfg, |state| {
        n += matches!(state, NodeState::Dead(_)) as usize;
        CallbackProgression::Continue
    });
    n
}

/// Nodes of killed processes whose resources nobody has removed yet, in namespace `ns`.
pub fn dead_nodes(ns: &str) -> usize {
    config(ns).map(|c| dead_nodes_in(&c)).unwrap_or(0)
}

/// Whether any node of the namespace is alive.
pub(super) fn any_node_alive(cfg: &Config) -> bool {
    let mut alive = false;
    let _ = Node::<Ipc>::list(cfg, |state| {
        alive |= matches!(state, NodeState::Alive(_));
        CallbackProgression::Continue
    });
    alive
}

/// Removes the resources of the namespace's dead nodes (processes killed without cleaning up) and
/// returns the process ids of the live nodes named `name` other than `own`, and how many dead
/// nodes were cleaned.
pub(super) fn live_nodes_named(
    ns: &str,
    cfg: &Config,
    name: &str,
    own: &iceoryx2::identifiers::UniqueNodeId,
) -> Result<(Vec<u32>, usize), TransportError> {
    use iceoryx2::node::NodeView;
    let mut alive = Vec::new();
    let mut dead = Vec::new();
    Node::<Ipc>::list(cfg, |state| {
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
    .map_err(|e| TransportError::ipc(ns, "cannot list the nodes", e))?;
    let mut cleaned = 0;
    for view in dead {
        let id = *view.id();
        cleaned += view.try_remove_stale_resources().is_ok() as usize;
        // The dead node was listed under this namespace's prefix: its directory is ours to
        // remove once iceoryx2 emptied it (`remove_dir` refuses a directory that is not empty).
        let _ = std::fs::remove_dir(node_dir(&id));
    }
    Ok((alive, cleaned))
}

/// iceoryx2's directory of one node's detail files: `{root}/nodes/{id}` (the default node
/// directory, which [`config`] keeps).
fn node_dir(id: &iceoryx2::identifiers::UniqueNodeId) -> std::path::PathBuf {
    root_dir().join("nodes").join(id.value().to_string())
}

/// Whether a node of a namespace is alive, and its process.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum NodeLiveness {
    Alive,
    /// Its process died without removing its resources (the next process cleans them).
    Dead,
    /// Another user's node, or one this process may not inspect.
    Inaccessible,
    /// Its files are incomplete (being created or removed).
    Undefined,
}

/// One node (process) of a namespace, as `vic status` lists it.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct NodeInfo {
    /// The node name, i.e. the role (`vic-board`, `vic-planner`, `vic-observer`, ...); empty
    /// when its details cannot be read.
    pub name: String,
    /// Its process id (0 when unknown).
    pub pid: u32,
    pub state: NodeLiveness,
    /// iceoryx2's node id (hexadecimal).
    pub id: String,
}

/// Every node of namespace `ns`, alive or not, sorted by role and pid. Needs no node of its own,
/// so it works when every port of a service is taken.
pub fn list_nodes(ns: &str) -> Result<Vec<NodeInfo>, TransportError> {
    use iceoryx2::node::NodeView;
    let cfg = config(ns)?;
    let mut nodes = Vec::new();
    let info = |view: &dyn NodeView, state| {
        let (name, pid) = view.details().as_ref().map_or((String::new(), 0), |d| {
            (d.name().as_str().to_string(), d.process_id().value() as u32)
        });
        NodeInfo {
            name,
            pid,
            state,
            id: view.id().to_string(),
        }
    };
    let listed = Node::<Ipc>::list(&cfg, |state| {
        nodes.push(match &state {
            NodeState::Alive(v) => info(v, NodeLiveness::Alive),
            NodeState::Dead(v) => info(v, NodeLiveness::Dead),
            NodeState::Inaccessible(id) => NodeInfo {
                name: String::new(),
                pid: 0,
                state: NodeLiveness::Inaccessible,
                id: id.to_string(),
            },
            NodeState::Undefined(id) => NodeInfo {
                name: String::new(),
                pid: 0,
                state: NodeLiveness::Undefined,
                id: id.to_string(),
            },
        });
        CallbackProgression::Continue
    });
    // A namespace nothing ever ran in has no node directory yet: no nodes.
    if let Err(e) = listed
        && std::fs::metadata(root_dir().join("nodes")).is_ok()
    {
        return Err(TransportError::ipc(ns, "cannot list the nodes", e));
    }
    nodes.sort_by(|a, b| (&a.name, a.pid, &a.id).cmp(&(&b.name, b.pid, &b.id)));
    Ok(nodes)
}

/// Names of the namespace's files in `/dev/shm`.
fn shm_files(ns: &str) -> impl Iterator<Item = std::fs::DirEntry> {
    let prefix = prefix(ns);
    std::fs::read_dir("/dev/shm")
        .into_iter()
        .flat_map(|d| d.flatten())
        .filter(move |e| e.file_name().to_string_lossy().starts_with(&prefix))
}

/// Removes the shared-memory and node files a namespace left behind. Call it only when no
/// process of the namespace runs any more. Returns how many files were removed.
pub fn remove_namespace(ns: &str) -> usize {
    if validate_namespace(ns).is_err() {
        return 0;
    }
    let paths = namespace_paths(ns);
    let removed = paths
        .iter()
        .filter(|p| std::fs::remove_file(p).is_ok())
        .count();
    remove_emptied_node_dirs(&paths);
    removed
}

/// Removes the node directories (`{root}/nodes/{id}`) that held files of the namespace and are
/// empty now: those of its nodes killed before they could remove their own (iceoryx2 removes the
/// directory of a node that exits cleanly, and of a dead node it cleans up, but not of one whose
/// files [`remove_namespace`] removed). A directory another namespace's node still uses keeps
/// its files, so `remove_dir` (empty directories only) leaves it.
fn remove_emptied_node_dirs(removed: &[std::path::PathBuf]) {
    let nodes = root_dir().join("nodes");
    let dirs: std::collections::BTreeSet<&std::path::Path> = removed
        .iter()
        .filter_map(|p| p.parent())
        .filter(|d| d.parent() == Some(nodes.as_path()))
        .collect();
    for d in dirs {
        let _ = std::fs::remove_dir(d);
    }
}

/// Makes the namespace's files in `/dev/shm` owner-only. iceoryx2 creates them 0600 (its global
/// file is an owner-only one in the private directory, [`super::service`]); this is a second line of
/// defence against a client of the plain `ipc` service that created its own there.
pub(super) fn restrict_namespace_files(ns: &str) {
    use std::os::unix::fs::PermissionsExt;
    for e in shm_files(ns) {
        if let Ok(m) = e.metadata()
            && m.permissions().mode() & 0o077 != 0
        {
            let _ = std::fs::set_permissions(e.path(), std::fs::Permissions::from_mode(0o600));
        }
    }
}

/// Files a namespace has in `/dev/shm` and in the private root directory (for tests and
/// `vic demo`'s final check).
pub fn namespace_files(ns: &str) -> Vec<String> {
    namespace_paths(ns)
        .iter()
        .map(|p| p.display().to_string())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_prefix_is_a_prefix_of_another_namespaces_files() {
        // The delimiter is not in the grammar: whatever two valid names, one's prefix never
        // starts another's file names.
        let names = ["a", "a_b", "a-b", "ab", "a_", "vic", "vic_x"];
        for a in names {
            for b in names {
                assert!(validate_namespace(a).is_ok() && validate_namespace(b).is_ok());
                let file = format!("{}iceoryx2_x.details", prefix(b));
                assert_eq!(file.starts_with(&prefix(a)), a == b, "{a} vs {b}");
            }
        }
    }

    #[test]
    fn namespaces_are_checked() {
        assert!(validate_namespace("vic").is_ok());
        assert!(validate_namespace("a/b").is_err());
        assert!(validate_namespace("").is_err());
        assert!(validate_namespace(&"x".repeat(33)).is_err());
    }
}
