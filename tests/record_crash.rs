//! Recordings that survive what stops their writer, with real processes: a board recording to
//! MCAP and `vic record` each killed with SIGKILL leave a file that `vic convert` reads, less at
//! most 100 ms (measured on the clock the ticks are stamped with: from the last tick in the file
//! to the moment of the kill); a full disk (a 200 KiB tmpfs, as root) is named at once as
//! ENOSPC and the file stays readable, also by the strict reader that needs a closed file, and
//! the board runs on; `--out` / `--record` never replace an existing file without `--force` and
//! never write through a symbolic link.

use crate::common;

use common::cli::{text, vic, wait_for_board};
use common::daemons::{Daemons, unique_namespace};
use serde_json::Value;
use std::io::BufRead;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use vic_rt::record::{read_board_mcap, read_recording};
use vic_rt::transport::monotonic_ns;

/// The data a SIGKILL may cost, by the documented bound.
const MAX_LOSS_MS: f64 = 100.0;

fn tmp(name: &str) -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR")).join(name)
}

/// `vic convert FILE --csv CSV --json`: its summary, after checking it succeeded.
fn convert(file: &Path, csv: &Path) -> Value {
    let o = vic(&[
        "convert",
        file.to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "vic convert: {}", text(&o));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// Data rows of a CSV written by `vic convert` (comment and header lines apart).
fn csv_rows(csv: &Path) -> Vec<Vec<String>> {
    std::fs::read_to_string(csv)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .map(|l| l.split(',').map(String::from).collect())
        .collect()
}

#[test]
fn a_board_recording_killed_with_sigkill_converts_less_at_most_100_ms() {
    let ns = unique_namespace("rkill");
    let (file, csv) = (tmp(&format!("{ns}.mcap")), tmp(&format!("{ns}.csv")));
    let mut d = Daemons::default();
    let board = d.board(&ns, &["--record", file.to_str().unwrap()]);
    wait_for_board(&ns);
    std::thread::sleep(Duration::from_millis(1500));
    let killed_ns = monotonic_ns();
    let out = d.signal_and_wait(board, libc::SIGKILL);
    assert_eq!(out.status.code(), None, "killed by a signal");
    drop(d);

    let summary = convert(&file, &csv);
    eprintln!("vic convert: {summary}");
    assert_eq!(summary["kind"], "board");
    assert!(
        summary["truncated"].is_string(),
        "an unclosed file is reported as such"
    );
    let rec = read_board_mcap(&file).unwrap();
    let rows = csv_rows(&csv);
    assert_eq!(rows.len(), rec.samples.len());
    assert_eq!(summary["rows"].as_u64(), Some(rec.samples.len() as u64));
    // Every tick from the first on, none skipped (no gap marked either).
    assert!(rec.gaps.is_empty(), "{:?}", rec.gaps);
    for (i, s) in rec.samples.iter().enumerate() {
        assert_eq!(s.tick, i as u64 + 1);
    }
    let last = rec.samples.last().unwrap();
    let lost_ms = killed_ns.saturating_sub(last.deadline_ns) as f64 * 1e-6;
    let period_ms = 1e3 / rec.metadata["rate_hz"].parse::<f64>().unwrap();
    eprintln!(
        "board killed {lost_ms:.1} ms after the last recorded tick ({} ticks recorded, ≈{:.0} lost at {period_ms} ms)",
        rec.samples.len(),
        lost_ms / period_ms
    );
    assert!(rec.samples.len() > 1000, "1.5 s at 1 kHz recorded");
    assert!(lost_ms <= MAX_LOSS_MS, "{lost_ms:.1} ms lost");
    std::fs::remove_file(&file).unwrap();
    std::fs::remove_file(&csv).unwrap();
}

/// `vic record --out FILE` as a child (stdout and stderr piped).
fn recorder(d: &mut Daemons, ns: &str, out: &Path, extra: &[&str]) -> usize {
    let child = Command::new(env!("CARGO_BIN_EXE_vic"))
        .args([
            "record",
            "--namespace",
            ns,
            "--json",
            "--wait",
            "10",
            "--out",
        ])
        .arg(out)
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    d.children.push(child);
    d.children.len() - 1
}

/// Waits for `path` to appear (vic record names its file once the first state arrived).
fn wait_for_file(path: &Path) {
    let t0 = Instant::now();
    while !path.exists() {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "{} never appeared",
            path.display()
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn vic_record_killed_with_sigkill_converts_less_at_most_100_ms() {
    let ns = unique_namespace("xkill");
    let (file, csv) = (tmp(&format!("{ns}.mcap")), tmp(&format!("{ns}.csv")));
    let mut d = Daemons::default();
    d.board(&ns, &[]);
    wait_for_board(&ns);
    let rec = recorder(&mut d, &ns, &file, &[]);
    wait_for_file(&file);
    std::thread::sleep(Duration::from_millis(1500));
    let killed_ns = monotonic_ns();
    let out = d.signal_and_wait(rec, libc::SIGKILL);
    assert_eq!(out.status.code(), None, "killed by a signal");
    drop(d);

    let summary = convert(&file, &csv);
    eprintln!("vic convert: {summary}");
    assert_eq!(summary["kind"], "namespace");
    assert!(summary["truncated"].is_string());
    let rows = csv_rows(&csv);
    assert!(rows.len() > 1000, "{} states", rows.len());
    // The states' ticks, and the gaps the recorder marked: together every tick once.
    let recording = read_recording(&file).unwrap();
    let (mut states, mut last_state_ns) = (Vec::new(), 0);
    let mut missed = 0;
    for (topic, t, data) in &recording.messages {
        let v: Value = serde_json::from_slice(data).unwrap();
        match topic.as_str() {
            "/state" => {
                states.push(v["tick"].as_u64().unwrap());
                last_state_ns = *t;
            }
            "/gap" => missed += v["ticks"].as_u64().unwrap(),
            _ => {}
        }
    }
    let csv_ticks: Vec<u64> = rows.iter().map(|r| r[1].parse().unwrap()).collect();
    assert_eq!(csv_ticks, states);
    let span = states.last().unwrap() - states[0] + 1;
    assert_eq!(span, states.len() as u64 + missed, "ticks {states:?}");
    let lost_ms = killed_ns.saturating_sub(last_state_ns) as f64 * 1e-6;
    eprintln!(
        "vic record killed {lost_ms:.1} ms after the last recorded state ({} states, {missed} missed)",
        states.len()
    );
    assert!(lost_ms <= MAX_LOSS_MS, "{lost_ms:.1} ms lost");
    std::fs::remove_file(&file).unwrap();
    std::fs::remove_file(&csv).unwrap();
}

/// A small tmpfs mounted for the test, unmounted and removed on drop. `None` (with the reason
/// printed) when not root or the mount is refused.
struct SmallDisk(PathBuf);

impl SmallDisk {
    fn mount(tag: &str, size: &str) -> Option<SmallDisk> {
        // SAFETY: geteuid has no preconditions.
        if unsafe { libc::geteuid() } != 0 {
            eprintln!("SKIPPED: mounting a {size} tmpfs needs root (CI runs as root)");
            return None;
        }
        let dir = tmp(&unique_namespace(tag));
        std::fs::create_dir_all(&dir).unwrap();
        let o = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
            .arg(&dir)
            .output();
        match o {
            Ok(o) if o.status.success() => Some(SmallDisk(dir)),
            o => {
                let _ = std::fs::remove_dir(&dir);
                eprintln!("SKIPPED: mount -t tmpfs refused: {o:?}");
                None
            }
        }
    }
}

impl Drop for SmallDisk {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.0).status();
        let _ = std::fs::remove_dir(&self.0);
    }
}

#[test]
fn vic_record_on_a_full_disk_names_enospc_and_leaves_a_closed_file() {
    let Some(disk) = SmallDisk::mount("xfull", "200k") else {
        return;
    };
    let ns = unique_namespace("xfull");
    let (file, csv) = (disk.0.join("ext.mcap"), tmp(&format!("{ns}.csv")));
    let mut d = Daemons::default();
    d.board(&ns, &[]);
    wait_for_board(&ns);
    let rec = recorder(&mut d, &ns, &file, &["--duration", "60"]);
    let t0 = Instant::now();
    let out = loop {
        if let Some(_status) = d.children[rec].try_wait().unwrap() {
            break d.wait(rec);
        }
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "vic record did not stop on a full disk"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    eprintln!(
        "vic record after {:.1} s: {}",
        t0.elapsed().as_secs_f64(),
        text(&out)
    );
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        stderr.contains("no space left on device (ENOSPC)"),
        "{stderr}"
    );
    assert!(stderr.contains(&file.display().to_string()), "{stderr}");
    // Closed: the strict reader (end magic required) reads it.
    let bytes = std::fs::read(&file).unwrap();
    let strict = mcap::MessageStream::new(&bytes).unwrap().count();
    let summary = convert(&file, &csv);
    eprintln!("vic convert: {summary}");
    assert!(
        summary["truncated"].is_null(),
        "closed, not truncated: {summary}"
    );
    let rows = summary["rows"].as_u64().unwrap();
    assert!(rows > 100, "{rows} states kept");
    assert!(strict as u64 >= rows);
    // What the message says the file keeps is what it holds.
    assert!(stderr.contains(&format!("keeps {rows} states")), "{stderr}");
    drop(d);
    std::fs::remove_file(&csv).unwrap();
}

#[test]
fn a_board_recording_on_a_full_disk_reports_enospc_at_once_and_runs_on() {
    let Some(disk) = SmallDisk::mount("bfull", "200k") else {
        return;
    };
    let ns = unique_namespace("bfull");
    let (file, csv) = (disk.0.join("board.mcap"), tmp(&format!("{ns}.csv")));
    let mut d = Daemons::default();
    let board = d.board(&ns, &["--record", file.to_str().unwrap()]);
    let stderr = d.children[board].stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(stderr).lines() {
            let Ok(line) = line else { break };
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    wait_for_board(&ns);
    let t0 = Instant::now();
    let report = loop {
        let line = rx
            .recv_timeout(Duration::from_secs(60).saturating_sub(t0.elapsed()))
            .expect("no ENOSPC report within 60 s");
        if line.contains("ENOSPC") {
            break line;
        }
    };
    eprintln!("after {:.1} s: {report}", t0.elapsed().as_secs_f64());
    assert!(
        report.contains("no space left on device (ENOSPC)"),
        "{report}"
    );
    assert!(report.contains(&file.display().to_string()), "{report}");
    // At once: the board's tick when the report was read is within a second of the tick the
    // recording stopped at.
    let number_after = |text: &str, key: &str| -> u64 {
        let at = text.find(key).unwrap_or_else(|| panic!("{key} in {text}"));
        let rest = &text[at + key.len()..];
        rest.split(|c: char| !c.is_ascii_digit())
            .next()
            .unwrap()
            .parse()
            .unwrap()
    };
    let stopped_at = number_after(&report, "recording stopped at tick ");
    let kept = number_after(&report, "keeps ticks 1 to ");
    let o = common::cli::status(&ns);
    assert!(
        o.status.success(),
        "vic status after the full disk: {}",
        text(&o)
    );
    let now: Value = serde_json::from_slice(&o.stdout).unwrap();
    let tick = now["tick"].as_u64().unwrap();
    eprintln!("stopped at tick {stopped_at}, board at tick {tick} when the report was read");
    assert!(
        tick >= stopped_at && tick - stopped_at < 1000,
        "{tick} vs {stopped_at}"
    );
    // The board runs on.
    std::thread::sleep(Duration::from_millis(300));
    assert!(
        d.children[board].try_wait().unwrap().is_none(),
        "the board stopped"
    );
    let o = common::cli::status(&ns);
    assert!(o.status.success(), "vic status later: {}", text(&o));
    let later: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(later["tick"].as_u64().unwrap() >= tick + 200, "{later}");
    let out = d.signal_and_wait(board, libc::SIGTERM);
    let stats: Value = serde_json::from_slice(&out.stdout).unwrap_or(Value::Null);
    eprintln!("board exit {:?}: {stats}", out.status.code());
    drop(d);
    let bytes = std::fs::read(&file).unwrap();
    let strict = mcap::MessageStream::new(&bytes).unwrap().count();
    let summary = convert(&file, &csv);
    eprintln!("vic convert: {summary}");
    assert!(summary["truncated"].is_null(), "closed: {summary}");
    let rows = summary["rows"].as_u64().unwrap();
    assert!(
        rows > 100 && strict as u64 >= rows,
        "{rows} ticks, {strict} messages"
    );
    assert_eq!(
        rows, kept,
        "the file keeps ticks 1 to {kept}, as the report said"
    );
    std::fs::remove_file(&csv).unwrap();
}

#[test]
fn an_existing_out_or_a_link_is_never_replaced_without_force() {
    let ns = unique_namespace("clob");
    let dir = tmp(&ns);
    std::fs::create_dir_all(&dir).unwrap();
    let (existing, victim, link) = (dir.join("run.mcap"), dir.join("victim"), dir.join("l.mcap"));
    std::fs::write(&existing, b"precious").unwrap();
    std::fs::write(&victim, b"victim").unwrap();
    std::os::unix::fs::symlink(&victim, &link).unwrap();
    let entries = || {
        let mut v: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
            .collect();
        v.sort();
        v
    };
    let before = entries();
    for out in [&existing, &link] {
        // No board at all (a mistyped namespace), without and with --force.
        let o = vic(&[
            "record",
            "--namespace",
            &ns,
            "--wait",
            "0.3",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(o.status.code(), Some(2), "{}", text(&o));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains("is there already") && err.contains("--force"),
            "{err}"
        );
        let o = vic(&[
            "record",
            "--namespace",
            &ns,
            "--wait",
            "0.3",
            "--force",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(o.status.code(), Some(1), "no board: {}", text(&o));
        assert!(
            String::from_utf8_lossy(&o.stderr).contains("no board"),
            "{}",
            text(&o)
        );
        // The board's --record likewise.
        let o = Command::new(env!("CARGO_BIN_EXE_vic-board"))
            .args([
                "--config",
                common::daemons::CONFIG,
                "--namespace",
                &ns,
                "--duration-s",
                "0.2",
            ])
            .arg("--record")
            .arg(out)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "vic-board: {}", text(&o));
        assert!(
            String::from_utf8_lossy(&o.stderr).contains("--record-force"),
            "{}",
            text(&o)
        );
    }
    vic_rt::transport::remove_namespace(&ns);
    assert_eq!(std::fs::read(&existing).unwrap(), b"precious");
    assert_eq!(std::fs::read(&victim).unwrap(), b"victim");
    assert!(std::fs::symlink_metadata(&link).unwrap().is_symlink());
    assert_eq!(entries(), before, "no file left behind, none removed");

    // With a board and --force: the link itself is replaced by the recording, its target kept.
    let mut d = Daemons::default();
    d.board(&ns, &[]);
    wait_for_board(&ns);
    let o = vic(&[
        "record",
        "--namespace",
        &ns,
        "--duration",
        "0.3",
        "--force",
        "--out",
        link.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    drop(d);
    assert!(!std::fs::symlink_metadata(&link).unwrap().is_symlink());
    assert!(read_recording(&link).unwrap().messages.len() > 100);
    assert_eq!(std::fs::read(&victim).unwrap(), b"victim");
    assert_eq!(entries(), before, "the same names, no temporary file left");
    std::fs::remove_dir_all(&dir).unwrap();
}
