//! Every numeric flag of every binary, found in the binaries' own `--help` (so a new flag cannot
//! escape), run with NaN, ±inf, 1e300, -1, 0, 2^64, the largest i64 and the ends of the range its
//! help states (`[range: MIN to MAX]`): a value outside the range exits 2 with a message naming
//! the flag, the value and the range; a value inside is accepted. Never exit 101, a signal or a
//! hang (issue 66, item 8: five flags panicked on 1e300).
//!
//! Each case is `BIN [SUBCOMMAND…] --flag=VALUE --help`: clap checks a value when it reads it, so
//! a refused value ends the run exactly as without `--help`, while an accepted one prints the help
//! and exits 0 instead of starting a board, a planner or a recording.

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Every binary of `bins/`, by file stem.
const BINARIES: [(&str, &str); 3] = [
    ("vic", env!("CARGO_BIN_EXE_vic")),
    ("vic-board", env!("CARGO_BIN_EXE_vic-board")),
    ("vic-planner", env!("CARGO_BIN_EXE_vic-planner")),
];

/// Flags that take a value that is not a number (files, names, choices, lists of names).
const NOT_NUMERIC: &[&str] = &[
    "--config",
    "--set",
    "--namespace",
    "--out",
    "--plan",
    "--csv",
    "--plot",
    "--method",
    "--policy",
    "--config-dir",
    "--out-dir",
    "--plans-dir",
    "--stiffness-plan",
    "--feedback-plan",
    "--only",
    "--side",
    "--listen",
    "--connect",
    "--link-name",
    "--stamps",
    "--scenario",
    "--log",
    "--variant",
    "--strategies",
    "--strategy",
    "--record",
    "--log-level",
    "--trajectories",
];

/// The values every numeric flag is tried with (its range's ends are added).
const VALUES: [&str; 10] = [
    "NaN",
    "nan",
    "inf",
    "-inf",
    "1e300",
    "-1",
    "0",
    "18446744073709551616",
    "9223372036854775807",
    "-9223372036854775808",
];

/// A numeric flag of one command and the range its help states.
#[derive(Debug, Clone)]
struct Flag {
    command: Vec<String>,
    name: String,
    min: String,
    max: String,
}

fn help(bin: &str, path: &[String]) -> String {
    let out = Command::new(bin).args(path).arg("--help").output().unwrap();
    assert!(out.status.success(), "{bin} {path:?} --help failed");
    String::from_utf8(out.stdout).unwrap()
}

/// The subcommands a help lists under `Commands:` (without `help`).
fn subcommands(help: &str) -> Vec<String> {
    help.lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|w| *w != "help")
        .map(str::to_string)
        .collect()
}

/// The options of a help, each with the text of its block: its line and its description.
fn option_blocks(help: &str) -> Vec<(String, String)> {
    let mut blocks: Vec<(String, String)> = Vec::new();
    for line in help.lines() {
        let indent = line.len() - line.trim_start().len();
        let t = line.trim_start();
        if (1..=6).contains(&indent) && t.starts_with('-') {
            let name = t
                .split([' ', ','])
                .find(|w| w.starts_with("--"))
                .unwrap_or("")
                .to_string();
            blocks.push((name, line.to_string()));
        } else if indent == 0 && !line.is_empty() {
            blocks.push((String::new(), String::new()));
        } else if let Some(b) = blocks.last_mut() {
            b.1.push(' ');
            b.1.push_str(t);
        }
    }
    blocks.retain(|(name, _)| !name.is_empty());
    blocks
}

/// `[range: MIN to MAX]` of a block.
fn range(block: &str) -> Option<(String, String)> {
    let rest = &block[block.find("[range: ")? + 8..];
    let (min, rest) = rest.split_once(" to ")?;
    Some((min.to_string(), rest[..rest.find(']')?].to_string()))
}

/// Every numeric flag of every command of every binary, and the value flags that are neither
/// numeric with a stated range nor known to be non-numeric.
fn numeric_flags() -> (Vec<(&'static str, Flag)>, Vec<String>) {
    let (mut found, mut unknown) = (Vec::new(), Vec::new());
    for (name, bin) in BINARIES {
        let mut todo: Vec<Vec<String>> = vec![vec![]];
        while let Some(path) = todo.pop() {
            let text = help(bin, &path);
            for sub in subcommands(&text) {
                let mut p = path.clone();
                p.push(sub);
                todo.push(p);
            }
            for (flag, block) in option_blocks(&text) {
                let first_line = block.lines().next().unwrap_or("");
                let takes_value = first_line.split("  ").next().unwrap_or("").contains('<');
                match range(&block) {
                    Some((min, max)) => found.push((
                        bin,
                        Flag {
                            command: path.clone(),
                            name: flag,
                            min,
                            max,
                        },
                    )),
                    None if takes_value && !NOT_NUMERIC.contains(&flag.as_str()) => {
                        unknown.push(format!("{name} {} {flag}", path.join(" ")))
                    }
                    None => {}
                }
            }
        }
    }
    (found, unknown)
}

/// Whether `value` lies in `[min, max]`: as whole numbers when all three are, else as reals
/// (NaN and infinities never do).
fn inside(value: &str, min: &str, max: &str) -> bool {
    if let (Ok(v), Ok(lo), Ok(hi)) = (
        value.parse::<i128>(),
        min.parse::<i128>(),
        max.parse::<i128>(),
    ) {
        return lo <= v && v <= hi;
    }
    match (value.parse::<f64>(), min.parse::<f64>(), max.parse::<f64>()) {
        (Ok(v), Ok(lo), Ok(hi)) => v.is_finite() && lo <= v && v <= hi,
        _ => false,
    }
}

/// Runs `bin args`, killing it (by its pid) after `timeout`: the exit code, or why there is none.
fn run(bin: &str, args: &[String], timeout: Duration) -> Result<(i32, String), String> {
    let mut child = Command::new(bin)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let mut stderr = String::new();
            use std::io::Read;
            child
                .stderr
                .take()
                .unwrap()
                .read_to_string(&mut stderr)
                .unwrap();
            return match status.code() {
                Some(code) => Ok((code, stderr)),
                None => Err(format!("killed by a signal ({status}): {stderr}")),
            };
        }
        if t0.elapsed() > timeout {
            let _ = child.kill();
            let _ = child.wait();
            return Err(format!("still running after {timeout:?} (killed)"));
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

#[test]
fn the_test_covers_every_binary() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("bins");
    let mut stems: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| {
            let p = e.unwrap().path();
            (p.extension()? == "rs").then(|| p.file_stem().unwrap().to_string_lossy().into())
        })
        .collect();
    stems.sort();
    let mut listed: Vec<&str> = BINARIES.iter().map(|(n, _)| *n).collect();
    listed.sort();
    assert_eq!(stems, listed, "a binary of bins/ is missing from BINARIES");
}

#[test]
fn every_numeric_flag_refuses_values_outside_its_stated_range_with_exit_2() {
    let t0 = Instant::now();
    let (flags, unknown) = numeric_flags();
    assert!(
        unknown.is_empty(),
        "flags taking a value with no [range: MIN to MAX] in their help (state the range, or \
         list them in NOT_NUMERIC when they are not numbers): {unknown:?}"
    );
    // vic-board, vic-planner and most subcommands of vic have several.
    assert!(
        flags.len() >= 50,
        "only {} numeric flags found",
        flags.len()
    );
    let cases: Vec<(&str, &Flag, String)> = flags
        .iter()
        .flat_map(|(bin, f)| {
            VALUES
                .iter()
                .map(|v| v.to_string())
                .chain([f.min.clone(), f.max.clone()])
                .map(move |v| (*bin, f, v))
        })
        .collect();
    let failures = std::sync::Mutex::new(Vec::new());
    let next = std::sync::atomic::AtomicUsize::new(0);
    std::thread::scope(|s| {
        for _ in 0..2 {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    let Some((bin, f, value)) = cases.get(i) else {
                        break;
                    };
                    let mut args = f.command.clone();
                    args.push(format!("{}={value}", f.name));
                    args.push("--help".into());
                    let what = format!("{} {}", bin.rsplit('/').next().unwrap(), args.join(" "));
                    let expect_ok = inside(value, &f.min, &f.max);
                    let problem = match run(bin, &args, Duration::from_secs(10)) {
                        Err(e) => Some(e),
                        Ok((0, _)) if expect_ok => None,
                        Ok((2, stderr)) if !expect_ok => {
                            let range = format!("{} to {}", f.min, f.max);
                            let named = stderr.contains(&f.name)
                                && stderr.contains(value.as_str())
                                && stderr.contains(&range);
                            (!named).then(|| format!("message does not name {range}: {stderr}"))
                        }
                        Ok((code, stderr)) => Some(format!(
                            "exit {code}, expected {}: {stderr}",
                            if expect_ok { 0 } else { 2 }
                        )),
                    };
                    if let Some(p) = problem {
                        failures.lock().unwrap().push(format!("{what}: {p}"));
                    }
                }
            });
        }
    });
    let failures = failures.into_inner().unwrap();
    assert!(
        failures.is_empty(),
        "{} of {} cases failed:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
    eprintln!(
        "{} numeric flags, {} cases in {:.1} s",
        flags.len(),
        cases.len(),
        t0.elapsed().as_secs_f64()
    );
}
