//! A second real user against a namespace (issue 14, finding 2). The board runs as one uid (the
//! *owner*, not root) and `nobody` (65534) plays the other local user, both through `setpriv`:
//! - another user's root directory (`/tmp/vic-{uid}`), a root directory others may write into,
//!   and a namespace file another user planted in `/dev/shm` are refused: exit 1, a message
//!   naming the path and its owner or mode;
//! - while the board runs, the other user can open none of the namespace's files (in the root
//!   directory or `/dev/shm`), and no file or directory of the namespace is ever seen group- or
//!   other-writable, from the root directory's creation on: a thread watches `/dev/shm` and the
//!   root directory with inotify (each new or changed entry is checked at once) and rescans both
//!   between events, while the board starts under umask 0 (so a mode it asks for shows as is).
//!
//! Giving files away and switching users needs root: not root, the tests say why and skip. The
//! owners' uids are unused ones derived from this process's pid, so parallel runs do not meet, and
//! their root directories are removed at the end (never the uid running the tests: other tests
//! share it).

use crate::common;

use common::daemons::{CONFIG, Daemons, unique_namespace};
use std::collections::{BTreeMap, BTreeSet};
use std::ffi::CString;
use std::os::unix::fs::MetadataExt;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use vic_rt::transport::prefix;

/// `nobody`: the other local user.
pub(crate) const OTHER: u32 = 65534;

/// Whether the test can switch users; says why not when it cannot.
pub(crate) fn can_switch_users() -> bool {
    // SAFETY: geteuid(2) has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        eprintln!("skipped: not root (switching users needs root; CI runs this as root)");
        return false;
    }
    if Command::new("setpriv").arg("--version").output().is_err() {
        eprintln!("skipped: setpriv (util-linux) is not installed");
        return false;
    }
    true
}

/// An unused uid for test `k` (0 to 3) of this process (not in /etc/passwd: no one else's files).
pub(crate) fn owner_uid(k: u32) -> u32 {
    61_000 + (std::process::id() % 1000) * 4 + k
}

pub(crate) fn root_of(uid: u32) -> PathBuf {
    PathBuf::from(format!("/tmp/vic-{uid}"))
}

/// `program` run as `uid` (group `uid`, no supplementary groups).
pub(crate) fn as_user(uid: u32, program: &str) -> Command {
    let mut c = Command::new("setpriv");
    c.args([
        format!("--reuid={uid}"),
        format!("--regid={uid}"),
        "--clear-groups".to_string(),
        program.to_string(),
    ]);
    c
}

pub(crate) fn board_as(uid: u32, ns: &str) -> Command {
    let mut c = as_user(uid, env!("CARGO_BIN_EXE_vic-board"));
    c.args(["--config", CONFIG, "--namespace", ns, "--json"]);
    c
}

/// Removes the owner's root directory whatever happens.
pub(crate) struct RootGuard(pub(crate) PathBuf);
impl Drop for RootGuard {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn refused(out: &Output, needles: &[&str]) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    for n in needles {
        assert!(err.contains(n), "missing {n:?} in: {err}");
    }
}

#[test]
fn another_users_root_directory_or_namespace_file_is_refused_by_name() {
    if !can_switch_users() {
        return;
    }
    let owner = owner_uid(0);
    let root = root_of(owner);
    let _guard = RootGuard(root.clone());
    let _ = std::fs::remove_dir_all(&root);
    let ns = unique_namespace("ou");
    let root_name = root.display().to_string();

    // The other user creates the owner's root directory first.
    let made = as_user(OTHER, "mkdir")
        .args(["-m", "0700"])
        .arg(&root)
        .status()
        .unwrap();
    assert!(made.success());
    let out = board_as(owner, &ns).output().unwrap();
    refused(&out, &[&root_name, &format!("belongs to uid {OTHER}")]);
    std::fs::remove_dir(&root).unwrap();

    // The owner's own directory, but others may write into it.
    std::fs::create_dir(&root).unwrap();
    let c = CString::new(root_name.clone()).unwrap();
    // SAFETY: chown(2)/chmod(2) on a directory this test created, valid C string.
    unsafe {
        assert_eq!(libc::chown(c.as_ptr(), owner, owner), 0);
        assert_eq!(libc::chmod(c.as_ptr(), 0o777), 0);
    }
    let out = board_as(owner, &ns).output().unwrap();
    refused(&out, &[&root_name, "mode is 777"]);
    std::fs::remove_dir(&root).unwrap();

    // The other user plants a file in the namespace's name in /dev/shm (world-writable).
    let planted = format!("/dev/shm/{}planted", prefix(&ns));
    let made = as_user(OTHER, "touch").arg(&planted).status().unwrap();
    assert!(made.success());
    let out = board_as(owner, &ns).output().unwrap();
    let _ = std::fs::remove_file(&planted);
    refused(
        &out,
        &[
            &planted,
            &format!("belongs to uid {OTHER}"),
            "another --namespace",
        ],
    );
}

/// What the watcher saw: every path of the namespace with the modes it was seen with, and every
/// sighting of a group- or other-writable one.
#[derive(Default)]
pub(crate) struct Seen {
    pub(crate) modes: BTreeMap<PathBuf, BTreeSet<u32>>,
    pub(crate) violations: Vec<String>,
    pub(crate) scans: usize,
}

impl Seen {
    fn check(&mut self, path: &Path, is_root: bool) {
        let Ok(m) = std::fs::symlink_metadata(path) else {
            return; // already gone
        };
        let mode = m.mode() & 0o7777;
        // The root directory is private (0700); nothing in it or of the namespace in /dev/shm
        // may be group- or other-writable.
        let bad = if is_root {
            mode & 0o077 != 0
        } else {
            mode & 0o022 != 0
        };
        if bad {
            self.violations
                .push(format!("{} mode {mode:o}", path.display()));
        }
        self.modes
            .entry(path.to_path_buf())
            .or_default()
            .insert(mode);
    }
}

/// inotify on `/dev/shm`, `/tmp` (for the root directory's creation) and every directory under
/// the root directory as it appears; every event's path checked at once, and full rescans
/// between events, until `stop`.
pub(crate) fn watch(ns: String, root: PathBuf, stop: Arc<AtomicBool>) -> Seen {
    let prefix = prefix(&ns);
    let mut seen = Seen::default();
    // SAFETY: inotify_init1(2) with valid flags; the descriptor is closed below.
    let fd = unsafe { libc::inotify_init1(libc::IN_NONBLOCK | libc::IN_CLOEXEC) };
    assert!(fd >= 0, "inotify_init1");
    let mut dirs: BTreeMap<i32, PathBuf> = BTreeMap::new();
    let add = |dirs: &mut BTreeMap<i32, PathBuf>, p: &Path| {
        if dirs.values().any(|d| d == p) {
            return;
        }
        let c = CString::new(p.as_os_str().as_encoded_bytes()).unwrap();
        let mask = libc::IN_CREATE | libc::IN_ATTRIB | libc::IN_MOVED_TO | libc::IN_MODIFY;
        // SAFETY: a valid descriptor and C string.
        let wd = unsafe { libc::inotify_add_watch(fd, c.as_ptr(), mask) };
        if wd >= 0 {
            dirs.insert(wd, p.to_path_buf());
        }
    };
    add(&mut dirs, Path::new("/dev/shm"));
    add(&mut dirs, Path::new("/tmp"));
    let mut buf = [0u8; 16384];
    let mut last_event = Instant::now();
    while !stop.load(Ordering::Relaxed) || last_event.elapsed() < Duration::from_millis(20) {
        // Events first: the path of each, checked as soon as it is reported.
        // SAFETY: reading into a buffer we own, of its length.
        let n = unsafe { libc::read(fd, buf.as_mut_ptr().cast(), buf.len()) };
        let mut off = 0usize;
        while n > 0 && off + 16 <= n as usize {
            let wd = i32::from_ne_bytes(buf[off..off + 4].try_into().unwrap());
            let len = u32::from_ne_bytes(buf[off + 12..off + 16].try_into().unwrap()) as usize;
            let name = &buf[off + 16..off + 16 + len];
            let name = String::from_utf8_lossy(name)
                .trim_end_matches('\0')
                .to_string();
            off += 16 + len;
            let Some(dir) = dirs.get(&wd).cloned() else {
                continue;
            };
            let path = dir.join(&name);
            last_event = Instant::now();
            if path == root {
                seen.check(&path, true);
                add(&mut dirs, &path);
            } else if dir.starts_with(&root) {
                seen.check(&path, false);
                if path.is_dir() {
                    add(&mut dirs, &path);
                }
            } else if dir == Path::new("/dev/shm") && name.starts_with(&prefix) {
                seen.check(&path, false);
            }
        }
        // Then a full scan (catches what appeared before its directory was watched).
        seen.scans += 1;
        if let Ok(shm) = std::fs::read_dir("/dev/shm") {
            for e in shm.flatten() {
                if e.file_name().to_string_lossy().starts_with(&prefix) {
                    seen.check(&e.path(), false);
                }
            }
        }
        if root.exists() {
            seen.check(&root, true);
            add(&mut dirs, &root);
            let mut stack = vec![root.clone()];
            while let Some(d) = stack.pop() {
                for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
                    let p = e.path();
                    seen.check(&p, false);
                    if p.is_dir() {
                        add(&mut dirs, &p);
                        stack.push(p);
                    }
                }
            }
        }
    }
    // SAFETY: closing the descriptor opened above.
    unsafe { libc::close(fd) };
    seen
}

/// The namespace's files now (in the owner's root directory and /dev/shm).
pub(crate) fn namespace_files_of(ns: &str, root: &Path) -> Vec<PathBuf> {
    let prefix = prefix(ns);
    let mut out: Vec<PathBuf> = std::fs::read_dir("/dev/shm")
        .into_iter()
        .flatten()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(&prefix))
        .map(|e| e.path())
        .collect();
    let mut stack = vec![root.to_path_buf()];
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
fn no_other_user_can_open_a_running_namespace_nor_ever_write_to_it() {
    if !can_switch_users() {
        return;
    }
    let owner = owner_uid(1);
    let root = root_of(owner);
    let _guard = RootGuard(root.clone());
    let _ = std::fs::remove_dir_all(&root);
    let ns = unique_namespace("ow");
    let stop = Arc::new(AtomicBool::new(false));
    let watcher = {
        let (ns, root, stop) = (ns.clone(), root.clone(), stop.clone());
        std::thread::spawn(move || watch(ns, root, stop))
    };
    std::thread::sleep(Duration::from_millis(50));

    // The board, as the owner, under umask 0: a mode iceoryx2 or vic asks for is the mode seen.
    let mut d = Daemons::default();
    d.namespaces.push(ns.clone());
    let mut cmd = board_as(owner, &ns);
    // SAFETY: umask(2) is async-signal-safe and cannot fail.
    unsafe {
        cmd.pre_exec(|| {
            libc::umask(0);
            Ok(())
        });
    }
    let child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    d.children.push(child);
    // Until its global file, its services and shared memory exist.
    let t0 = Instant::now();
    let files = loop {
        let f = namespace_files_of(&ns, &root);
        let shm = f.iter().filter(|p| p.starts_with("/dev/shm")).count();
        let global = f
            .iter()
            .any(|p| p.to_string_lossy().ends_with("global_mgmt"));
        if shm >= 6 && global && f.len() >= 20 {
            break f;
        }
        if let Some(status) = d.children[0].try_wait().unwrap() {
            panic!("the board ended: {status}");
        }
        assert!(t0.elapsed() < Duration::from_secs(20), "files: {f:?}");
        std::thread::sleep(Duration::from_millis(50));
    };
    std::thread::sleep(Duration::from_millis(300));

    // The other user tries every file: open for reading, open for writing, list the directory.
    let script = r#"for f in "$@"; do
        if cat "$f" >/dev/null 2>&1; then echo "read $f"; fi
        if (exec 3>>"$f") 2>/dev/null; then echo "write $f"; fi
    done
    if ls "$ROOT" >/dev/null 2>&1; then echo "list $ROOT"; fi"#;
    let out = as_user(OTHER, "sh")
        .env("ROOT", &root)
        .args(["-c", script, "sh"])
        .args(&files)
        .output()
        .unwrap();
    let opened = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{out:?}");
    assert!(opened.trim().is_empty(), "the other user got in:\n{opened}");

    let board = d.signal_and_wait(0, libc::SIGTERM);
    assert!(
        board.status.success(),
        "{}",
        String::from_utf8_lossy(&board.stderr)
    );
    stop.store(true, Ordering::Relaxed);
    let seen = watcher.join().unwrap();
    let global: Vec<_> = seen
        .modes
        .iter()
        .filter(|(p, _)| p.to_string_lossy().ends_with("global_mgmt"))
        .collect();
    eprintln!(
        "{} paths of the namespace seen in {} scans (+ inotify events); global file modes {:?}",
        seen.modes.len(),
        seen.scans,
        global
    );
    assert!(
        seen.modes.len() >= files.len(),
        "the watcher saw too little"
    );
    assert!(!global.is_empty(), "the watcher never saw the global file");
    assert!(seen.violations.is_empty(), "{:#?}", seen.violations);
    // A clean exit leaves nothing of the namespace.
    assert!(namespace_files_of(&ns, &root).is_empty());
}
