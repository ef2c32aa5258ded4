//! The port and node limits of a namespace's services, and what a process is told when one is
//! reached: which limit, the configured number, and which processes hold the slots (node name and
//! pid), never a bare iceoryx2 error name.
//!
//! The limits are sized for one board, one central process, one recorder, `vic inject`, the
//! bridges and at least 32 read-only observers (`vic status`, `vic monitor`, Python clients that
//! only watch), with room to spare: observers take no publisher, so they cannot lock out a
//! sender, and 32 of them leave every subscriber and listener a sender or the board needs.
//! They are fixed when the first process of a namespace creates a service; a later process
//! (including a client of iceoryx2's own bindings) opens the service with the limits it has.

use super::error::{PortKind, TransportError};
use super::service::Service as Ipc;
use iceoryx2::identifiers::UniqueNodeId;
use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;
use std::collections::BTreeMap;

/// Publishers per message service: the board or the central process, `vic inject` (the
/// disturbance service) and a tool or a test's hostile sender.
pub const MAX_PUBLISHERS: usize = 4;
/// Subscribers per message service: board, central process, recorder, `vic inject`, a bridge
/// and 32 observers are 37; 48 leaves room for 11 more. (The cost is shared memory, not time:
/// a publisher's segment holds a buffer per possible subscriber, 48 × 128 states of 176 bytes,
/// about 1 MiB, for the state service.)
pub const MAX_SUBSCRIBERS: usize = 48;
/// Nodes (processes) per service: the subscribers' and the publishers' processes, with room.
pub const MAX_NODES: usize = 64;
/// Notifiers of the board's event service (the board; the rest is spare).
pub const MAX_NOTIFIERS: usize = 4;
/// Notifiers of each relay event service (`transport::relay`): every process that publishes
/// commands, controls or disturbances holds one (central process, `vic inject`, a raw sender, the
/// board-side bridge's two roles), with room to spare.
pub const MAX_RELAY_NOTIFIERS: usize = 8;
/// Listeners of the board's event service: the central process, `vic inject`, a bridge and every
/// observer (32 and more).
pub const MAX_LISTENERS: usize = 56;

/// The live nodes of a namespace by id: (node name, pid).
fn live_nodes(cfg: &Config) -> BTreeMap<UniqueNodeId, (String, u32)> {
    let mut nodes = BTreeMap::new();
    let _ = Node::<Ipc>::list(cfg, |state| {
        if let NodeState::Alive(view) = state
            && let Some(d) = view.details()
        {
            nodes.insert(
                *view.id(),
                (d.name().as_str().to_string(), d.process_id().value() as u32),
            );
        }
        CallbackProgression::Continue
    });
    nodes
}

/// "vic-observer pids 12, 13; vic-inject pid 14 ×2" for the nodes `ids` (all the namespace's live
/// nodes when `ids` is `None`); nodes that are not alive any more are counted as "gone".
pub(super) fn describe_holders(cfg: &Config, ids: Option<&[UniqueNodeId]>) -> String {
    let nodes = live_nodes(cfg);
    // Node name → pid → how many of the slots that process holds.
    let mut by_name: BTreeMap<String, BTreeMap<u32, usize>> = BTreeMap::new();
    let mut gone = 0;
    let all: Vec<UniqueNodeId>;
    let ids = match ids {
        Some(ids) => ids,
        None => {
            all = nodes.keys().copied().collect();
            &all
        }
    };
    for id in ids {
        match nodes.get(id) {
            Some((name, pid)) => {
                *by_name
                    .entry(name.clone())
                    .or_default()
                    .entry(*pid)
                    .or_default() += 1
            }
            None => gone += 1,
        }
    }
    let mut parts: Vec<String> = by_name
        .into_iter()
        .map(|(name, pids)| {
            let list: Vec<String> = pids
                .iter()
                .map(|(pid, n)| match n {
                    1 => pid.to_string(),
                    n => format!("{pid} ×{n}"),
                })
                .collect();
            let s = if pids.len() == 1 { "" } else { "s" };
            format!("{name} pid{s} {}", list.join(", "))
        })
        .collect();
    if gone > 0 {
        parts.push(format!("{gone} of a process that has just exited"));
    }
    if parts.is_empty() {
        "no live process".into()
    } else {
        parts.join("; ")
    }
}

/// The error of a full service: `in_use` of `max` ports of `kind` held by the nodes `holders`.
pub(super) fn too_many(
    namespace: &str,
    cfg: &Config,
    service: &'static str,
    kind: PortKind,
    max: usize,
    holders: Option<&[UniqueNodeId]>,
) -> TransportError {
    let in_use = holders.map_or(max, <[UniqueNodeId]>::len);
    TransportError::TooManyPorts {
        namespace: namespace.to_string(),
        service,
        kind,
        in_use,
        max,
        holders: describe_holders(cfg, holders),
    }
}
