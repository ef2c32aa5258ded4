//! The Python client and the one file iceoryx2's plain `ipc` service would create
//! world-writable (issue 66, finding 2): the namespace's global management file in `/dev/shm`.
//! The client never creates it; vic's processes create it owner-only and the client only opens
//! such a file:
//! - with no board, the client refuses ("no board", naming the file) and leaves no file of the
//!   namespace; it refuses a file of that name with group or other access, or another user's,
//!   naming the file and its mode or owner;
//! - as root with two other uids: while a board runs as the *owner*, six Python clients connect
//!   as the owner (each receives states), and meanwhile a second user (`nobody`) tries to open
//!   every file of the namespace in `/dev/shm` for writing in a loop: it never gets a handle, and
//!   no file of the namespace is ever seen group- or other-writable (inotify and rescans, as in
//!   `other_user`), the global file included. Everything runs under umask 0, so a mode asked for
//!   is the mode seen.
//!
//! Without `VIC_PYTHON` the tests say why they skip (outside CI only); without root the second
//! one says why it skips.

use crate::common;
use crate::other_user::{
    OTHER, RootGuard, as_user, board_as, can_switch_users, namespace_files_of, owner_uid, root_of,
    watch,
};

use common::daemons::{Daemons, unique_namespace};
use std::os::unix::fs::PermissionsExt;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use vic_rt::transport::{namespace_files, plain_global_file, prefix};

/// The interpreter to use, or None (skip) outside CI.
fn python() -> Option<String> {
    match std::env::var("VIC_PYTHON") {
        Ok(p) => Some(p),
        Err(_) => {
            assert!(
                std::env::var_os("CI").is_none(),
                "CI must set VIC_PYTHON (a Python with iceoryx2==0.10.0 and numpy)"
            );
            eprintln!("VIC_PYTHON not set: the Python client's file test is skipped");
            None
        }
    }
}

/// `python -c script args…` with this checkout's client first on the path.
fn python_command(python: &str, script: &str) -> Command {
    let mut c = Command::new(python);
    c.args(["-c", script])
        .env(
            "PYTHONPATH",
            Path::new(env!("CARGO_MANIFEST_DIR")).join("python"),
        )
        .env("PYTHONDONTWRITEBYTECODE", "1");
    c
}

/// Connects once with `timeout` and prints the error, or `connected`.
const CONNECT_ONCE: &str = r#"
import sys, vic_client as vc
try:
    with vc.Board(sys.argv[1], timeout=float(sys.argv[2])):
        print("connected")
except vc.VicError as e:
    print("refused:", e)
"#;

fn connect_once(python: &str, ns: &str, timeout: &str) -> String {
    let out = python_command(python, CONNECT_ONCE)
        .args([ns, timeout])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).trim().to_string()
}

#[test]
fn the_client_never_creates_the_global_file_and_refuses_one_others_could_open() {
    let Some(py) = python() else { return };
    let ns = unique_namespace("pyown");
    let global = plain_global_file(&ns).unwrap();
    let name = global.display().to_string();

    // No board: refused, naming the missing file, and nothing of the namespace is left.
    let said = connect_once(&py, &ns, "0.3");
    assert!(said.starts_with("refused: no board"), "{said}");
    assert!(said.contains(&name), "{said}");
    assert!(
        namespace_files(&ns).is_empty(),
        "{:?}",
        namespace_files(&ns)
    );

    // A file of that name others may open (as the plain service leaves it): refused by mode.
    std::fs::write(&global, [0u8; 16]).unwrap();
    std::fs::set_permissions(&global, std::fs::Permissions::from_mode(0o666)).unwrap();
    let said = connect_once(&py, &ns, "0.3");
    assert!(
        said.starts_with("refused") && said.contains(&name) && said.contains("mode 666"),
        "{said}"
    );

    // Another user's file: refused by owner (giving it away needs root).
    // SAFETY: geteuid(2) has no preconditions.
    if unsafe { libc::geteuid() } == 0 {
        std::fs::set_permissions(&global, std::fs::Permissions::from_mode(0o600)).unwrap();
        std::os::unix::fs::chown(&global, Some(OTHER), Some(OTHER)).unwrap();
        let said = connect_once(&py, &ns, "0.3");
        assert!(
            said.starts_with("refused")
                && said.contains(&name)
                && said.contains(&format!("belongs to uid {OTHER}")),
            "{said}"
        );
    }
    std::fs::remove_file(&global).unwrap();
}

/// Tries to open every file of the namespace in /dev/shm for writing (never creating one) until
/// the file `argv[2]` exists; prints how many attempts, then every file it opened.
const PROBE: &str = r#"
import os, sys
prefix, stop = sys.argv[1], sys.argv[2]
tries, opened = 0, set()
while not os.path.exists(stop):
    for f in os.listdir("/dev/shm"):
        if f.startswith(prefix):
            tries += 1
            try:
                os.close(os.open("/dev/shm/" + f, os.O_RDWR))
                opened.add(f)
            except OSError:
                pass
print(tries)
for f in sorted(opened):
    print("opened", f)
"#;

/// Connects `argv[2]` times, each time until a state arrived; prints `connected N`.
const CONNECT_MANY: &str = r#"
import sys, vic_client as vc
n = 0
for _ in range(int(sys.argv[2])):
    with vc.Board(sys.argv[1], timeout=10) as b:
        b.wait_state(lambda s: True, timeout=5)
        n += 1
print("connected", n)
"#;

fn with_umask0(c: &mut Command) -> &mut Command {
    // SAFETY: umask(2) is async-signal-safe and cannot fail.
    unsafe {
        c.pre_exec(|| {
            libc::umask(0);
            Ok(())
        })
    }
}

fn text(out: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

#[test]
fn no_other_user_gets_a_writable_handle_while_python_clients_connect() {
    let Some(py) = python() else { return };
    if !can_switch_users() {
        return;
    }
    let owner = owner_uid(2);
    let root = root_of(owner);
    let _guard = RootGuard(root.clone());
    let _ = std::fs::remove_dir_all(&root);
    let ns = unique_namespace("pyou");
    let stop_watch = Arc::new(AtomicBool::new(false));
    let watcher = {
        let (ns, root, stop) = (ns.clone(), root.clone(), stop_watch.clone());
        std::thread::spawn(move || watch(ns, root, stop))
    };
    std::thread::sleep(Duration::from_millis(50));

    let mut d = Daemons::default();
    d.namespaces.push(ns.clone());
    let child = with_umask0(&mut board_as(owner, &ns))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    d.children.push(child);
    let global = plain_global_file(&ns).unwrap();
    // Until the board's services and shared memory exist.
    let t0 = Instant::now();
    loop {
        let f = namespace_files_of(&ns, &root);
        if f.iter().filter(|p| p.starts_with("/dev/shm")).count() >= 6 {
            break;
        }
        if let Some(status) = d.children[0].try_wait().unwrap() {
            panic!("the board ended: {status}");
        }
        assert!(t0.elapsed() < Duration::from_secs(20), "files: {f:?}");
        std::thread::sleep(Duration::from_millis(20));
    }

    // The other user probes from now until the clients are done.
    let stop_file = PathBuf::from(format!("/tmp/{ns}.stop"));
    let _ = std::fs::remove_file(&stop_file);
    let probe = as_user(OTHER, &py)
        .args(["-c", PROBE, &prefix(&ns)])
        .arg(&stop_file)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(200));
    let clients = with_umask0(
        as_user(owner, &py)
            .args(["-c", CONNECT_MANY, &ns, "6"])
            .env(
                "PYTHONPATH",
                Path::new(env!("CARGO_MANIFEST_DIR")).join("python"),
            )
            .env("PYTHONDONTWRITEBYTECODE", "1"),
    )
    .output()
    .unwrap();
    std::fs::write(&stop_file, b"").unwrap();
    let probed = probe.wait_with_output().unwrap();
    let _ = std::fs::remove_file(&stop_file);
    let board = d.signal_and_wait(0, libc::SIGTERM);
    stop_watch.store(true, Ordering::Relaxed);
    let seen = watcher.join().unwrap();

    assert!(
        text(&clients).contains("connected 6"),
        "the owner's clients: {}",
        text(&clients)
    );
    assert!(probed.status.success(), "{}", text(&probed));
    let report = String::from_utf8_lossy(&probed.stdout).to_string();
    let tries: usize = report.lines().next().unwrap_or("0").trim().parse().unwrap();
    eprintln!(
        "the other user tried {tries} opens; {} paths of the namespace seen in {} scans; global \
         file modes {:?}",
        seen.modes.len(),
        seen.scans,
        seen.modes.get(&global)
    );
    assert!(tries > 100, "the probe hardly ran: {report}");
    assert!(
        !report.contains("opened"),
        "the other user got a writable handle:\n{report}"
    );
    assert!(
        seen.modes.contains_key(&global),
        "the watcher never saw the global file"
    );
    assert!(seen.violations.is_empty(), "{:#?}", seen.violations);
    assert!(board.status.success(), "{}", text(&board));
    assert!(namespace_files_of(&ns, &root).is_empty());
}
