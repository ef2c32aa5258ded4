//! Squatting (issue 66, finding 4): another local user who makes `/tmp/vic-{uid}` first can no
//! longer block a user for good. The root directory is `$VIC_RUNTIME_DIR/`, else
//! `$XDG_RUNTIME_DIR/vic/` (the login session's private directory, where nobody else can make
//! anything first), else `/tmp/vic-{uid}/`. As root, with `nobody` as the squatter and an unused
//! uid as the victim:
//! - the squatter makes `/tmp/vic-{victim}`: with neither variable set, the victim's board and
//!   Python client are refused (exit 1 / `VicError`), naming the directory, its owner, that
//!   only that user or an administrator can remove it, and `VIC_RUNTIME_DIR` as the way out;
//! - with `VIC_RUNTIME_DIR` (or `XDG_RUNTIME_DIR`) naming a private directory of the victim, the
//!   victim's board runs there, `vic status` finds it and a Python client receives its states;
//!   nothing lands in the squatted directory, and a clean exit leaves no file of the namespace.
//!
//! Without root it checks only that an unusable `VIC_RUNTIME_DIR` (relative, too long) is
//! refused by name.

use crate::common;
use crate::other_user::{OTHER, RootGuard, as_user, can_switch_users, owner_uid, root_of};

use common::daemons::{CONFIG, Daemons, unique_namespace};
use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};
use vic_rt::transport::{MAX_ROOT_PATH, RUNTIME_DIR_VAR, plain_global_file};

fn text(out: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// `command` with the root directory chosen by `runtime` (`VIC_RUNTIME_DIR`) and `xdg`
/// (`XDG_RUNTIME_DIR`) only.
fn with_dirs<'c>(
    command: &'c mut Command,
    runtime: Option<&Path>,
    xdg: Option<&Path>,
) -> &'c mut Command {
    command
        .env_remove(RUNTIME_DIR_VAR)
        .env_remove("XDG_RUNTIME_DIR");
    if let Some(d) = runtime {
        command.env(RUNTIME_DIR_VAR, d);
    }
    if let Some(d) = xdg {
        command.env("XDG_RUNTIME_DIR", d);
    }
    command
}

#[test]
fn the_longest_root_directory_and_namespace_still_work() {
    // A 32-character namespace in a root directory of MAX_ROOT_PATH bytes: the board runs and
    // `vic status` (a listener: an event socket in the root directory) finds it.
    let mut ns = unique_namespace("long");
    ns.extend(std::iter::repeat_n('z', 32 - ns.len()));
    let mut dir = format!("/tmp/vr{}", std::process::id());
    dir.extend(std::iter::repeat_n('d', MAX_ROOT_PATH - 1 - dir.len()));
    let dir = PathBuf::from(dir);
    // SAFETY: geteuid(2) has no preconditions.
    let _guard = private_dir(&dir, unsafe { libc::geteuid() });
    assert_eq!(format!("{}/", dir.display()).len(), MAX_ROOT_PATH);
    board_runs_as_me(&ns, &dir);
}

#[test]
fn an_unusable_runtime_dir_is_refused_by_name() {
    let ns = unique_namespace("rtdir");
    let long = format!("/tmp/{}", "d".repeat(MAX_ROOT_PATH));
    for (dir, needle) in [("relative/dir", "absolute path"), (long.as_str(), "bytes")] {
        let mut c = Command::new(env!("CARGO_BIN_EXE_vic-board"));
        c.args(["--config", CONFIG, "--namespace", &ns, "--duration-s", "1"]);
        let out = with_dirs(&mut c, Some(Path::new(dir)), None)
            .output()
            .unwrap();
        let err = text(&out);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(err.contains(dir) && err.contains(needle), "{err}");
        assert!(err.contains(RUNTIME_DIR_VAR), "{err}");
    }
    assert!(!Path::new("relative").exists());
}

/// A directory `path` of `uid`, mode 0700, removed at the end.
fn private_dir(path: &Path, uid: u32) -> RootGuard {
    let _ = std::fs::remove_dir_all(path);
    std::fs::create_dir(path).unwrap();
    std::os::unix::fs::chown(path, Some(uid), Some(uid)).unwrap();
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o700)).unwrap();
    RootGuard(path.to_path_buf())
}

/// Connects as `uid` and waits for a state; prints `connected` or the refusal.
const CONNECT: &str = r#"
import sys, vic_client as vc
try:
    with vc.Board(sys.argv[1], timeout=float(sys.argv[2])) as b:
        b.wait_state(lambda s: True, timeout=5)
        print("connected")
except vc.VicError as e:
    print("refused:", e)
"#;

fn python_as(uid: u32, py: &str, ns: &str, timeout: &str) -> Command {
    let mut c = as_user(uid, py);
    c.args(["-c", CONNECT, ns, timeout])
        .env(
            "PYTHONPATH",
            Path::new(env!("CARGO_MANIFEST_DIR")).join("python"),
        )
        .env("PYTHONDONTWRITEBYTECODE", "1");
    c
}

/// The board as `uid` in `ns`, its root directory chosen by `runtime`/`xdg`, until it answers
/// `vic status`; then a Python client (when there is an interpreter) receives its states.
fn board_runs(
    uid: u32,
    ns: &str,
    runtime: Option<&Path>,
    xdg: Option<&Path>,
    py: Option<&str>,
) -> Output {
    let mut d = Daemons::default();
    d.namespaces.push(ns.to_string());
    let mut board = as_user(uid, env!("CARGO_BIN_EXE_vic-board"));
    board.args(["--config", CONFIG, "--namespace", ns, "--json"]);
    let child = with_dirs(&mut board, runtime, xdg)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    d.children.push(child);
    let t0 = Instant::now();
    loop {
        let mut status = as_user(uid, env!("CARGO_BIN_EXE_vic"));
        status.args(["status", "--namespace", ns, "--timeout-s", "2"]);
        let out = with_dirs(&mut status, runtime, xdg).output().unwrap();
        if out.status.success() {
            break;
        }
        if let Some(s) = d.children[0].try_wait().unwrap() {
            let out = d.wait(0);
            panic!("the board ended ({s}): {}", text(&out));
        }
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "vic status: {}",
            text(&out)
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    if let Some(py) = py {
        let out = with_dirs(&mut python_as(uid, py, ns, "10"), runtime, xdg)
            .output()
            .unwrap();
        assert!(text(&out).contains("connected"), "{}", text(&out));
    }
    let out = d.signal_and_wait(0, libc::SIGTERM);
    assert!(out.status.success(), "{}", text(&out));
    out
}

/// [`board_runs`] as this user (no user switch, no Python).
fn board_runs_as_me(ns: &str, runtime: &Path) {
    let mut d = Daemons::default();
    d.namespaces.push(ns.to_string());
    let mut board = Command::new(env!("CARGO_BIN_EXE_vic-board"));
    board.args(["--config", CONFIG, "--namespace", ns, "--json", "--no-rt"]);
    let child = with_dirs(&mut board, Some(runtime), None)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    d.children.push(child);
    let t0 = Instant::now();
    loop {
        let mut status = Command::new(env!("CARGO_BIN_EXE_vic"));
        status.args(["status", "--namespace", ns, "--timeout-s", "2"]);
        let out = with_dirs(&mut status, Some(runtime), None)
            .output()
            .unwrap();
        if out.status.success() {
            break;
        }
        if d.children[0].try_wait().unwrap().is_some() {
            panic!("the board ended: {}", text(&d.wait(0)));
        }
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "vic status: {}",
            text(&out)
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let out = d.signal_and_wait(0, libc::SIGTERM);
    assert!(out.status.success(), "{}", text(&out));
}

/// Files under `dir`, recursively.
fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p);
            }
        }
    }
    out
}

#[test]
fn a_squatted_tmp_directory_is_named_with_what_to_do_and_a_private_one_works() {
    if !can_switch_users() {
        return;
    }
    let py = std::env::var("VIC_PYTHON").ok();
    let victim = owner_uid(3);
    let squatted = root_of(victim);
    let _squatted_guard = RootGuard(squatted.clone());
    let _ = std::fs::remove_dir_all(&squatted);
    let made = as_user(OTHER, "mkdir")
        .args(["-m", "0755"])
        .arg(&squatted)
        .status()
        .unwrap();
    assert!(made.success());
    let ns = unique_namespace("squat");

    // Nothing set: refused, naming the directory, its owner and the way out.
    let mut board = as_user(victim, env!("CARGO_BIN_EXE_vic-board"));
    board.args(["--config", CONFIG, "--namespace", &ns, "--duration-s", "1"]);
    let out = with_dirs(&mut board, None, None).output().unwrap();
    let err = text(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    let name = format!("{}/", squatted.display());
    for needle in [
        name.as_str(),
        &format!("belongs to uid {OTHER}"),
        "only they or an administrator can remove it",
        RUNTIME_DIR_VAR,
    ] {
        assert!(err.contains(needle), "missing {needle:?} in: {err}");
    }
    if let Some(py) = &py {
        let out = with_dirs(&mut python_as(victim, py, &ns, "0.5"), None, None)
            .output()
            .unwrap();
        let said = text(&out);
        for needle in [
            name.as_str(),
            &format!("belongs to uid {OTHER}"),
            "only they or an administrator can remove it",
            RUNTIME_DIR_VAR,
        ] {
            assert!(said.contains(needle), "missing {needle:?} in: {said}");
        }
    }

    // VIC_RUNTIME_DIR: a private directory of the victim's own.
    // Short paths: the root directory has at most MAX_ROOT_PATH bytes.
    let given = PathBuf::from(format!("/tmp/vg{}", std::process::id()));
    let _given_guard = private_dir(&given, victim);
    board_runs(victim, &ns, Some(&given), None, py.as_deref());

    // XDG_RUNTIME_DIR (a login session's directory): the root is its `vic/`, made 0700.
    let session = PathBuf::from(format!("/tmp/vx{}", std::process::id()));
    let _session_guard = private_dir(&session, victim);
    board_runs(victim, &ns, None, Some(&session), py.as_deref());
    let vic = std::fs::metadata(session.join("vic")).unwrap();
    assert_eq!((vic.uid(), vic.mode() & 0o777), (victim, 0o700));

    // Nothing went to the squatted directory; a clean exit left nothing of the namespace.
    assert!(
        files_under(&squatted).is_empty(),
        "{:?}",
        files_under(&squatted)
    );
    for dir in [&given, &session] {
        let left: Vec<_> = files_under(dir)
            .into_iter()
            .filter(|p| p.to_string_lossy().contains(&format!("vic_{ns}.")))
            .collect();
        assert!(left.is_empty(), "{left:?}");
    }
    assert!(!plain_global_file(&ns).unwrap().exists());
}
