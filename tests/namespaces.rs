//! Namespaces with real processes (issue 14, items 1 and 2): `a` and `a_b` side by side, one
//! stopped, the other untouched and answering; no file of a namespace that another user could
//! write; a foreign or unsafe iceoryx2 directory refused.

use crate::common;

use common::daemons::{Daemons, unique_namespace};
use std::collections::BTreeSet;
use std::os::unix::fs::MetadataExt;
use std::time::Duration;
use vic_rt::transport::{ToolPorts, namespace_files, plain_global_file, root_dir};

fn files(ns: &str) -> BTreeSet<String> {
    namespace_files(ns).into_iter().collect()
}

fn answers(ns: &str) -> bool {
    ToolPorts::open(ns)
        .map(|t| t.wait_for_telemetry(Duration::from_secs(5)).is_some())
        .unwrap_or(false)
}

#[test]
fn stopping_a_namespace_leaves_the_one_whose_name_it_prefixes_intact() {
    let a = unique_namespace("ns");
    let ab = format!("{a}_b");
    let mut d = Daemons::default();
    let board_a = d.board(&a, &[]);
    let _board_ab = d.board(&ab, &[]);
    assert!(answers(&a) && answers(&ab), "both boards should answer");
    let before = files(&ab);
    assert!(!before.is_empty());
    // The namespaces share no file.
    assert!(files(&a).is_disjoint(&before), "{:?}", files(&a));
    // Every file of a namespace is its user's alone: no group or other access in /dev/shm,
    // and vic's global file lives in the private directory; the one in /dev/shm is the plain
    // `ipc` service's, made owner-only for the Python client.
    for f in before.iter().chain(files(&a).iter()) {
        // A file listed a moment ago may be gone (iceoryx2 removes its transient ones): there
        // is nothing left to check of it.
        let m = match std::fs::metadata(f) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
            m => m.unwrap(),
        };
        if f.starts_with("/dev/shm") {
            assert_eq!(m.mode() & 0o077, 0, "{f} mode {:o}", m.mode());
            let plain = [
                plain_global_file(&a).unwrap(),
                plain_global_file(&ab).unwrap(),
            ];
            assert!(
                !f.contains("global_mgmt") || plain.iter().any(|p| p.to_str() == Some(f)),
                "{f} in /dev/shm"
            );
        } else {
            assert!(f.starts_with(root_dir().to_str().unwrap()), "{f}");
        }
    }
    let root = std::fs::metadata(root_dir()).unwrap();
    assert_eq!(root.mode() & 0o777, 0o700);

    // Stop every process of `a` (the board is the last: it removes `a`'s files).
    let out = d.signal_and_wait(board_a, libc::SIGTERM);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(files(&a).is_empty(), "{:?}", files(&a));
    // `a_b` keeps every file and its board answers.
    let after = files(&ab);
    assert!(
        before.is_subset(&after),
        "lost: {:?}",
        before.difference(&after).collect::<Vec<_>>()
    );
    assert!(answers(&ab), "the board of {ab} no longer answers");
}

#[test]
fn a_namespace_file_of_another_user_is_refused_with_a_message() {
    let ns = unique_namespace("nf");
    // A file in the namespace's name that belongs to someone else (uid 65534, "nobody").
    let path = format!("/dev/shm/{}planted", vic_rt::transport::prefix(&ns));
    std::fs::write(&path, [0u8; 16]).unwrap();
    // SAFETY: chown(2) on a file this test created, with a valid NUL-terminated path.
    let c = std::ffi::CString::new(path.clone()).unwrap();
    let owned = unsafe { libc::chown(c.as_ptr(), 65534, 65534) } == 0;
    if !owned {
        // Without the right to give a file away the test cannot plant a foreign one.
        std::fs::remove_file(&path).unwrap();
        eprintln!("skipped: cannot chown (not root)");
        return;
    }
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_vic-board"))
        .args(["--config", common::daemons::CONFIG, "--namespace", &ns])
        .output()
        .unwrap();
    std::fs::remove_file(&path).unwrap();
    assert_eq!(out.status.code(), Some(1));
    let msg = String::from_utf8_lossy(&out.stderr);
    assert!(
        msg.contains("belongs to uid 65534") && msg.contains("another --namespace"),
        "{msg}"
    );
}

/// The node directories (`{root}/nodes/{id}`) holding files of namespace `ns`.
fn node_dirs(ns: &str) -> BTreeSet<std::path::PathBuf> {
    let nodes = root_dir().join("nodes");
    namespace_files(ns)
        .iter()
        .filter_map(|f| std::path::Path::new(f).parent().map(|p| p.to_path_buf()))
        .filter(|d| d.parent() == Some(nodes.as_path()))
        .collect()
}

#[test]
fn a_killed_boards_node_directory_goes_with_its_namespace() {
    let ns = unique_namespace("nd");
    let mut d = Daemons::default();
    let board = d.board(&ns, &[]);
    assert!(answers(&ns), "the board should answer");
    let dirs = node_dirs(&ns);
    assert!(!dirs.is_empty(), "no node directory of {ns}");
    // Killed: the board cannot remove its own node directory; removing the namespace (what
    // the last process of a namespace, the tests' guard and the soak script do) must.
    d.signal_and_wait(board, libc::SIGKILL);
    vic_rt::transport::remove_namespace(&ns);
    assert!(files(&ns).is_empty(), "{:?}", files(&ns));
    let left: Vec<_> = dirs.iter().filter(|d| d.exists()).collect();
    assert!(left.is_empty(), "node directories left: {left:?}");
}

#[test]
fn a_clean_exit_after_a_killed_observer_leaves_no_node_directory() {
    let ns = unique_namespace("nc");
    let mut d = Daemons::default();
    let board = d.board(&ns, &[]);
    assert!(answers(&ns), "the board should answer");
    // An observer killed while the board runs: its node is dead.
    let mut monitor = std::process::Command::new(env!("CARGO_BIN_EXE_vic"))
        .args(["monitor", "--namespace", &ns, "--interval-s", "0.1"])
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let t0 = std::time::Instant::now();
    while node_dirs(&ns).len() < 2 {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "the monitor has no node"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let dirs = node_dirs(&ns);
    monitor.kill().unwrap();
    monitor.wait().unwrap();
    // The board exits cleanly, the last of its namespace.
    let out = d.signal_and_wait(board, libc::SIGTERM);
    assert!(out.status.success());
    assert!(files(&ns).is_empty(), "{:?}", files(&ns));
    let left: Vec<_> = dirs.iter().filter(|d| d.exists()).collect();
    assert!(left.is_empty(), "node directories left: {left:?}");
}
