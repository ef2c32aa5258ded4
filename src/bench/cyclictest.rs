//! The wake-up baseline: `cyclictest` (Debian package `rt-tests`) at the board's interval, run
//! for the same duration as the board loop, its latency histogram parsed into a [`Dist`].

use super::Dist;
use super::error::{BenchError, HistogramError};
use std::path::{Path, PathBuf};

/// How to install the baseline, for messages.
pub(crate) const INSTALL_HINT: &str = "install it with `apt-get install rt-tests` (Debian/Ubuntu) or run scripts/bench.sh, \
     which installs it when missing";

/// Where `cyclictest` is on `PATH` (and in `/usr/sbin`, `/usr/bin`), if anywhere.
pub(crate) fn find() -> Option<PathBuf> {
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .chain(["/usr/sbin".into(), "/usr/bin".into(), "/sbin".into()])
        .map(|d| d.join("cyclictest"))
        .find(|p| p.is_file())
}

/// One cyclictest run.
#[derive(Debug, Clone)]
pub(crate) struct Options {
    /// Wake-up interval [µs] (`-i`).
    pub(crate) interval_us: u64,
    /// Duration [s] (`-D`).
    pub(crate) seconds: u64,
    /// `SCHED_FIFO` priority (`-p`), or the default scheduler.
    pub(crate) fifo_priority: Option<i32>,
    /// Pin the measuring thread to this CPU (`-a`).
    pub(crate) cpu: Option<usize>,
    /// Largest latency the histogram resolves [µs] (`-h`); later wake-ups count as overflows and
    /// only the maximum keeps their value.
    pub(crate) histogram_us: u64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            interval_us: 1000,
            seconds: 30,
            fifo_priority: None,
            cpu: None,
            histogram_us: 20_000,
        }
    }
}

impl Options {
    /// The command-line arguments (memory locked, quiet, histogram to `histfile`).
    pub(crate) fn args(&self, histfile: &Path) -> Vec<String> {
        let mut a = vec![
            "-m".to_string(),
            "-q".to_string(),
            format!("-i{}", self.interval_us),
            format!("-D{}s", self.seconds),
            format!("-h{}", self.histogram_us),
            format!("--histfile={}", histfile.display()),
        ];
        if let Some(p) = self.fifo_priority {
            a.push(format!("-p{p}"));
        }
        if let Some(c) = self.cpu {
            a.push(format!("-a{c}"));
        }
        a
    }
}

/// A parsed cyclictest histogram (one measuring thread; several columns are summed).
#[derive(Debug, Clone, PartialEq)]
pub struct Histogram {
    /// `counts[v]`: wake-ups `v` µs late.
    pub counts: Vec<u64>,
    /// Wake-ups beyond the histogram's range.
    pub overflows: u64,
    /// `# Total:` as printed (the samples in the buckets).
    pub total: u64,
    pub min_us: f64,
    pub(crate) avg_us: f64,
    pub max_us: f64,
}

impl Histogram {
    /// The distribution, p50/p99/p99.9 from the buckets and the true maximum.
    pub fn dist(&self) -> Dist {
        Dist::from_buckets(&self.counts, self.overflows, self.max_us)
    }
}

/// Parses the text cyclictest writes with `-h N --histfile=F`: lines `LATENCY COUNT…` then
/// `# Total:`, `# Min Latencies:`, `# Avg Latencies:`, `# Max Latencies:` and `# Histogram
/// Overflows:` (one column per thread; they are summed, the maximum is the largest).
pub fn parse(text: &str) -> Result<Histogram, HistogramError> {
    let mut counts: Vec<u64> = Vec::new();
    let (mut total, mut min, mut avg, mut max, mut overflows) = (None, None, None, None, None);
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        let nums = |rest: &str| -> Result<Vec<u64>, HistogramError> {
            rest.split_whitespace()
                .map(|t| {
                    t.parse::<u64>().map_err(|source| HistogramError::Number {
                        line: i + 1,
                        token: t.to_string(),
                        source,
                    })
                })
                .collect()
        };
        if let Some(rest) = line.strip_prefix('#') {
            let Some((key, value)) = rest.split_once(':') else {
                continue;
            };
            let key = key.trim();
            let v = || nums(value);
            match key {
                "Total" => total = Some(v()?.iter().sum::<u64>()),
                "Min Latencies" => min = v()?.into_iter().min(),
                "Avg Latencies" => avg = v()?.into_iter().max(),
                "Max Latencies" => max = v()?.into_iter().max(),
                "Histogram Overflows" => overflows = Some(v()?.iter().sum::<u64>()),
                _ => {}
            }
            continue;
        }
        if line.is_empty() {
            continue;
        }
        let v = nums(line)?;
        if v.len() < 2 {
            return Err(HistogramError::Row {
                line: i + 1,
                text: line.to_string(),
            });
        }
        let at = v[0] as usize;
        if at > 10_000_000 {
            return Err(HistogramError::Latency {
                line: i + 1,
                latency_us: at,
            });
        }
        if counts.len() <= at {
            counts.resize(at + 1, 0);
        }
        counts[at] += v[1..].iter().sum::<u64>();
    }
    let h = Histogram {
        total: total.ok_or(HistogramError::Missing("Total"))?,
        max_us: max.ok_or(HistogramError::Missing("Max Latencies"))? as f64,
        min_us: min.unwrap_or(0) as f64,
        avg_us: avg.unwrap_or(0) as f64,
        overflows: overflows.unwrap_or(0),
        counts,
    };
    let in_buckets: u64 = h.counts.iter().sum();
    if in_buckets != h.total {
        return Err(HistogramError::Total {
            in_buckets,
            total: h.total,
        });
    }
    Ok(h)
}

/// A finished cyclictest run.
#[derive(Debug, Clone)]
pub(crate) struct Run {
    pub(crate) histogram: Histogram,
    /// CPU time over wall time [%].
    pub(crate) cpu_percent: f64,
    pub(crate) command: String,
}

/// Runs cyclictest with `opts` and parses its histogram.
pub(crate) fn run(binary: &Path, opts: &Options) -> Result<Run, BenchError> {
    let histfile = std::env::temp_dir().join(format!(
        "vic-cyclictest-{}-{}.hist",
        std::process::id(),
        vic_rt::transport::monotonic_ns()
    ));
    let args = opts.args(&histfile);
    let command = format!("{} {}", binary.display(), args.join(" "));
    let cpu0 = vic_rt::sched::children_cpu_ns();
    let t0 = vic_rt::transport::monotonic_ns();
    let out = std::process::Command::new(binary)
        .args(&args)
        .stdin(std::process::Stdio::null())
        .output()
        .map_err(|e| BenchError::io(format!("cannot run {command}"), e))?;
    let wall = vic_rt::transport::monotonic_ns() - t0;
    let cpu = vic_rt::sched::children_cpu_ns().saturating_sub(cpu0);
    let text = std::fs::read_to_string(&histfile);
    let _ = std::fs::remove_file(&histfile);
    if !out.status.success() {
        return Err(BenchError::Failed {
            command,
            status: out.status,
            stderr: String::from_utf8_lossy(&out.stderr).trim().to_string(),
        });
    }
    let text = text.map_err(|e| BenchError::io(format!("{command} wrote no histogram"), e))?;
    Ok(Run {
        histogram: parse(&text)?,
        cpu_percent: 100.0 * cpu as f64 / wall.max(1) as f64,
        command,
    })
}
