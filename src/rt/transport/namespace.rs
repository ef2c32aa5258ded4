//! Namespaces: every service and node of one instance (and of one parallel test) lives under a
//! namespace, which becomes iceoryx2's `global.prefix`, so instances never see each other.
//! This module checks names, finds the namespace's files and nodes, and removes what killed
//! processes left behind.

use super::error::TransportError;
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

/// The iceoryx2 file prefix of a namespace.
pub fn prefix(ns: &str) -> String {
    format!("vic_{ns}_")
}

/// The iceoryx2 configuration of a namespace: the defaults with the namespace's prefix (no config
/// file is looked up).
pub fn config(ns: &str) -> Result<Config, TransportError> {
    validate_namespace(ns)?;
    let mut cfg = Config::default();
    cfg.global.prefix = FileName::new(prefix(ns).as_bytes())
        .map_err(|e| TransportError::ipc(ns, "file prefix", e))?;
    Ok(cfg)
}

/// Nodes of killed processes in the namespace of `cfg`.
pub(super) fn dead_nodes_in(cfg: &Config) -> usize {
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

/// Whether any node of the namespace is alive.
pub(super) fn any_node_alive(cfg: &Config) -> bool {
    let mut alive = false;
    let _ = Node::<ipc::Service>::list(cfg, |state| {
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
    .map_err(|e| TransportError::ipc(ns, "cannot list the nodes", e))?;
    let mut cleaned = 0;
    for view in dead {
        cleaned += view.try_remove_stale_resources().is_ok() as usize;
    }
    Ok((alive, cleaned))
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
    let Ok(cfg) = config(ns) else {
        return 0;
    };
    let prefix = prefix(ns);
    let shm = std::path::Path::new("/dev/shm");
    let mut removed = 0;
    let mut dirs = vec![
        shm.to_path_buf(),
        std::path::PathBuf::from(cfg.global.root_path().to_string()),
    ];
    while let Some(dir) = dirs.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.flatten() {
            let path = e.path();
            let name = e.file_name().to_string_lossy().to_string();
            let is_dir = e.file_type().map(|t| t.is_dir()).unwrap_or(false);
            if is_dir && dir != shm {
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

/// Files a namespace has in `/dev/shm` (for tests and `vic demo`'s final check).
pub fn namespace_files(ns: &str) -> Vec<String> {
    shm_files(ns)
        .map(|e| e.file_name().to_string_lossy().to_string())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn namespaces_are_checked() {
        assert!(validate_namespace("vic").is_ok());
        assert!(validate_namespace("a/b").is_err());
        assert!(validate_namespace("").is_err());
        assert!(validate_namespace(&"x".repeat(33)).is_err());
    }
}
