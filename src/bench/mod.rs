//! Benchmarks against the machine's own limits (`vic bench`): the board's 1 kHz loop against
//! `cyclictest` ([`loop_bench`], [`cyclictest`]) and the transport against a bare iceoryx2
//! ping-pong with the same payload ([`ipc`]), then the running board + planner pair ([`pair`]).
//! Each measures vic and its baseline in the same run and reports both distributions and their
//! ratio.

#[cfg(feature = "zenoh")]
pub(crate) mod bridge;
#[cfg(feature = "zenoh")]
pub(crate) mod bridge_hops;
pub mod cyclictest;
pub(crate) mod error;
pub(crate) mod ipc;
pub mod loop_bench;
pub(crate) mod pair;
pub mod sooc_scaling;

pub(crate) use error::BenchError;
pub use error::HistogramError;

use serde::{Deserialize, Serialize};
use vic_rt::realtime::LatencyHistogram;

/// A latency distribution [µs] as reported by every bench: p50, p99, p99.9, max, sample count.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Dist {
    pub p50_us: f64,
    pub p99_us: f64,
    pub p999_us: f64,
    pub max_us: f64,
    pub count: u64,
}

impl Dist {
    /// The distribution recorded in a [`LatencyHistogram`] (ns values).
    pub(crate) fn from_histogram(h: &LatencyHistogram) -> Dist {
        let p = h.percentiles();
        Dist {
            p50_us: p.p50,
            p99_us: p.p99,
            p999_us: p.p999,
            max_us: p.max,
            count: p.count,
        }
    }

    /// The distribution of a histogram of whole-µs buckets (`counts[v]` samples of `v` µs), with
    /// `overflow` samples beyond the last bucket and the true maximum `max_us` (cyclictest's
    /// histogram). A percentile that falls among the overflows reads as `max_us`.
    pub fn from_buckets(counts: &[u64], overflow: u64, max_us: f64) -> Dist {
        let total: u64 = counts.iter().sum::<u64>() + overflow;
        let q = |quantile: f64| percentile_of_buckets(counts, total, quantile).unwrap_or(max_us);
        Dist {
            p50_us: q(0.5),
            p99_us: q(0.99),
            p999_us: q(0.999),
            max_us,
            count: total,
        }
    }

    /// One line: `p50 … p99 … p99.9 … max …`.
    pub(crate) fn line(&self) -> String {
        format!(
            "p50 {:>8.2}  p99 {:>8.2}  p99.9 {:>8.2}  max {:>9.1} µs  (n = {})",
            self.p50_us, self.p99_us, self.p999_us, self.max_us, self.count
        )
    }
}

/// The smallest bucket value `v` with at least `ceil(quantile · total)` samples at or below it
/// (HdrHistogram's definition), or `None` when that rank lies beyond the buckets.
pub fn percentile_of_buckets(counts: &[u64], total: u64, quantile: f64) -> Option<f64> {
    if total == 0 {
        return Some(0.0);
    }
    let rank = ((quantile * total as f64).ceil() as u64).clamp(1, total);
    let mut seen = 0;
    for (v, c) in counts.iter().enumerate() {
        seen += c;
        if seen >= rank {
            return Some(v as f64);
        }
    }
    None
}

/// `vic / baseline`, or `None` when the baseline is missing or zero.
pub fn ratio(vic: f64, baseline: Option<f64>) -> Option<f64> {
    match baseline {
        Some(b) if b > 0.0 && vic.is_finite() => Some(vic / b),
        _ => None,
    }
}

/// A ratio for tables: `1.23×` or `–`.
pub(crate) fn ratio_text(r: Option<f64>) -> String {
    r.map_or("–".into(), |r| format!("{r:.2}×"))
}

/// A namespace no other process uses: `prefix`, the pid and a time-derived suffix.
pub fn unique_namespace(prefix: &str) -> String {
    format!(
        "{prefix}{}x{}",
        std::process::id(),
        vic_rt::transport::monotonic_ns() % 1_000_000
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bucket_percentiles_follow_the_rank_definition() {
        // 10 samples: 1,1,2,2,2,3,3,3,3,9.
        let mut counts = vec![0u64; 10];
        counts[1] = 2;
        counts[2] = 3;
        counts[3] = 4;
        counts[9] = 1;
        let d = Dist::from_buckets(&counts, 0, 9.0);
        assert_eq!(d.p50_us, 2.0); // rank 5
        assert_eq!(d.p99_us, 9.0); // rank 10
        assert_eq!(d.count, 10);
        // Overflows push the high percentiles to the maximum.
        let d = Dist::from_buckets(&counts[..5], 1, 120.0);
        assert_eq!(d.p99_us, 120.0);
        assert_eq!(ratio(3.0, Some(2.0)), Some(1.5));
        assert_eq!(ratio(3.0, None), None);
        assert_eq!(ratio(3.0, Some(0.0)), None);
    }
}

/// The machine a bench ran on.
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct Machine {
    pub(crate) cpus: usize,
    pub(crate) cpu_model: String,
    pub(crate) kernel: String,
    /// `hypervisor` when `/proc/cpuinfo` lists the flag (a virtual machine), else `bare metal?`.
    pub(crate) virtualization: String,
    /// `PREEMPT_RT` when the kernel says so in its version string.
    pub(crate) preempt: String,
    /// `/proc/loadavg`'s 1-minute figure when the bench started: other work competes for the CPUs.
    pub(crate) load_average_1min: f64,
}

impl Machine {
    /// Reads `/proc` (nothing is left empty: unknown fields read `unknown`).
    pub fn detect() -> Machine {
        let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
        let model = cpuinfo
            .lines()
            .find(|l| l.starts_with("model name"))
            .and_then(|l| l.split_once(':'))
            .map_or("unknown".to_string(), |(_, v)| v.trim().to_string());
        let version = std::fs::read_to_string("/proc/version").unwrap_or_default();
        let kernel = std::fs::read_to_string("/proc/sys/kernel/osrelease")
            .map_or("unknown".into(), |s| s.trim().to_string());
        let preempt = ["PREEMPT_RT", "PREEMPT_DYNAMIC", "PREEMPT"]
            .iter()
            .find(|p| version.contains(*p))
            .map_or("none".to_string(), |p| p.to_string());
        Machine {
            cpus: vic_rt::sched::cpu_count(),
            cpu_model: model,
            kernel,
            virtualization: if cpuinfo.contains(" hypervisor") {
                "hypervisor".into()
            } else {
                "bare metal?".into()
            },
            preempt,
            load_average_1min: std::fs::read_to_string("/proc/loadavg")
                .ok()
                .and_then(|s| s.split_whitespace().next()?.parse().ok())
                .unwrap_or(f64::NAN),
        }
    }
    /// One line for reports.
    pub fn line(&self) -> String {
        format!(
            "{} CPUs, {}, Linux {} ({}), {}, load average {:.2}",
            self.cpus,
            self.cpu_model,
            self.kernel,
            self.preempt,
            self.virtualization,
            self.load_average_1min
        )
    }
}
