//! `vic bench loop`: the board's 1 kHz loop with its real work ([`vic_rt::board::live::board_tick`]
//! on a scenario's plant, a 50 Hz planner thread streaming hold commands over the real
//! transport), under each combination of the options real-time loops use, and `cyclictest` at
//! the same interval for the same duration in the same run (sequentially: the variants one after
//! the other, then the baselines).

mod measure;
mod variants;

pub use crate::daemons::launch::board_config;
pub use measure::hold_slice;
pub(crate) use variants::{HEADLINE, Variant, variants};

use super::{BenchError, Dist, cyclictest, ratio};
use serde::Serialize;
use std::path::PathBuf;
use vic_rt::sched;

/// The loop's period [ns]: 1 kHz, cyclictest's `-i1000`.
pub const PERIOD_NS: u64 = 1_000_000;
/// `SCHED_FIFO` priority of the real-time variants (cyclictest's `-p80`).
pub(crate) const FIFO_PRIORITY: i32 = 80;
/// Spin before each deadline in the spin variants [µs].
pub(crate) const SPIN_US: u64 = 100;

/// Options of `vic bench loop`.
#[derive(Debug, Clone)]
pub(crate) struct Options {
    /// Duration of each variant and of each cyclictest run [s].
    pub(crate) seconds: u64,
    /// Scenario whose plant the board integrates (impedance actuator).
    pub(crate) config: PathBuf,
    pub(crate) overrides: Vec<String>,
    /// Names of the variants to run (empty: all).
    pub(crate) variants: Vec<String>,
    /// Run cyclictest (when found).
    pub(crate) baseline: bool,
}

/// The figures of one variant.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct VariantResult {
    #[serde(flatten)]
    pub(crate) variant: Variant,
    /// Wake-up lateness (woke − deadline).
    pub(crate) jitter: Dist,
    /// Tick work: drain the transport, step the board, publish the state.
    pub(crate) work: Dist,
    /// CPU time of the loop thread over wall time [%].
    pub(crate) cpu_percent: f64,
    pub(crate) late_ticks: u64,
    pub(crate) missed_periods: u64,
    /// Options asked for that the system refused (the loop ran without them).
    pub(crate) refused: Vec<String>,
    /// The cyclictest run it is compared with (`cyclictest` or `cyclictest_fifo`).
    pub(crate) baseline: &'static str,
    pub(crate) ratio_p99: Option<f64>,
    pub(crate) ratio_p50: Option<f64>,
}

/// A cyclictest run's figures.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct BaselineResult {
    #[serde(flatten)]
    pub(crate) dist: Dist,
    pub(crate) cpu_percent: f64,
    pub(crate) command: String,
}

/// The summary in the documented shape: `{p50_us, p99_us, p999_us, max_us, cpu_percent}`.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Headline {
    #[serde(flatten)]
    pub(crate) dist: Dist,
    pub(crate) cpu_percent: f64,
    pub(crate) variant: String,
    /// Tick work of the same run.
    pub(crate) work: Dist,
}

/// The whole report of `vic bench loop`.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Report {
    pub(crate) interval_us: u64,
    pub(crate) seconds: u64,
    pub(crate) order: String,
    pub(crate) scenario: String,
    pub(crate) vic: Headline,
    pub(crate) baseline: Option<BaselineResult>,
    pub(crate) ratio_p99: Option<f64>,
    pub(crate) variants: Vec<VariantResult>,
    pub(crate) baselines: Baselines,
    /// Why there is no baseline, when there is none.
    pub(crate) baseline_note: Option<String>,
    pub(crate) fifo_permitted: bool,
    pub(crate) machine: super::Machine,
}

/// Both cyclictest runs.
#[derive(Debug, Clone, Serialize, Default)]
pub(crate) struct Baselines {
    pub(crate) cyclictest: Option<BaselineResult>,
    pub(crate) cyclictest_fifo: Option<BaselineResult>,
}

impl Baselines {
    /// The cyclictest run a variant is compared with (its `baseline` name).
    fn for_variant(&self, name: &str) -> &Option<BaselineResult> {
        if name == "cyclictest_fifo" {
            &self.cyclictest_fifo
        } else {
            &self.cyclictest
        }
    }
}

/// Runs the chosen variants then cyclictest (default scheduler, and `SCHED_FIFO` 80 when a FIFO
/// variant ran and FIFO is permitted), each for `opts.seconds`.
pub(crate) fn run(opts: &Options, mut progress: impl FnMut(&str)) -> Result<Report, BenchError> {
    let all = variants();
    for name in &opts.variants {
        if !all.iter().any(|v| v.name == name) {
            let names: Vec<_> = all.iter().map(|v| v.name).collect();
            return Err(BenchError::UnknownVariant {
                name: name.clone(),
                choices: names.join(", "),
            });
        }
    }
    let chosen: Vec<Variant> = all
        .into_iter()
        .filter(|v| opts.variants.is_empty() || opts.variants.iter().any(|n| n == v.name))
        .collect();
    let plant = measure::load(opts)?;
    let machine = super::Machine::detect();
    let fifo_permitted = sched::fifo_permitted();
    let mut results = Vec::new();
    for v in &chosen {
        progress(&format!(
            "{} ({} s): {}",
            v.name, opts.seconds, v.description
        ));
        results.push(measure::run_variant(&plant, v, opts.seconds)?);
    }
    let with_fifo = fifo_permitted && chosen.iter().any(|v| v.fifo.is_some());
    let (baselines, note) = if opts.baseline {
        run_baselines(opts.seconds, with_fifo, &mut progress)?
    } else {
        (
            Baselines::default(),
            Some("baseline not requested (--no-baseline)".into()),
        )
    };
    for r in &mut results {
        let b = baselines.for_variant(r.baseline);
        r.ratio_p99 = ratio(r.jitter.p99_us, b.as_ref().map(|b| b.dist.p99_us));
        r.ratio_p50 = ratio(r.jitter.p50_us, b.as_ref().map(|b| b.dist.p50_us));
    }
    let head = results
        .iter()
        .find(|r| r.variant.name == HEADLINE)
        .or_else(|| results.first())
        .ok_or(BenchError::NoVariant)?;
    let baseline = baselines.for_variant(head.baseline).clone();
    let names: Vec<_> = chosen.iter().map(|v| v.name).collect();
    Ok(Report {
        interval_us: PERIOD_NS / 1000,
        seconds: opts.seconds,
        order: format!(
            "sequential, {} s each: {}, then cyclictest",
            opts.seconds,
            names.join(", ")
        ),
        scenario: opts.config.display().to_string(),
        vic: Headline {
            dist: head.jitter,
            cpu_percent: head.cpu_percent,
            variant: head.variant.name.to_string(),
            work: head.work,
        },
        ratio_p99: head.ratio_p99,
        baseline,
        variants: results,
        baselines,
        baseline_note: note,
        fifo_permitted,
        machine,
    })
}

/// cyclictest for `seconds` under the default scheduler, then under `SCHED_FIFO` 80 when
/// `with_fifo`; or why there is none (not installed).
fn run_baselines(
    seconds: u64,
    with_fifo: bool,
    progress: &mut impl FnMut(&str),
) -> Result<(Baselines, Option<String>), BenchError> {
    let mut baselines = Baselines::default();
    let Some(bin) = cyclictest::find() else {
        let note = format!("cyclictest not found: {}", cyclictest::INSTALL_HINT);
        return Ok((baselines, Some(note)));
    };
    let mut o = cyclictest::Options {
        seconds,
        interval_us: PERIOD_NS / 1000,
        ..Default::default()
    };
    let result = |r: cyclictest::Run| BaselineResult {
        dist: r.histogram.dist(),
        cpu_percent: r.cpu_percent,
        command: r.command,
    };
    progress(&format!("cyclictest ({seconds} s), default scheduler"));
    baselines.cyclictest = Some(result(cyclictest::run(&bin, &o)?));
    if with_fifo {
        o.fifo_priority = Some(FIFO_PRIORITY);
        progress(&format!("cyclictest ({seconds} s), SCHED_FIFO 80"));
        baselines.cyclictest_fifo = Some(result(cyclictest::run(&bin, &o)?));
    }
    Ok((baselines, None))
}

/// The report as a table.
pub(crate) fn print(r: &Report) {
    println!(
        "board loop at {} µs, {} s per run ({}); scenario {}",
        r.interval_us, r.seconds, r.order, r.scenario
    );
    println!("machine: {}", r.machine.line());
    println!(
        "{:<16} {:>8} {:>8} {:>8} {:>9} {:>6} {:>9} {:>9} {:>5}  refused",
        "wake-up [µs]", "p50", "p99", "p99.9", "max", "cpu%", "work p50", "work p99", "late"
    );
    for v in &r.variants {
        println!(
            "{:<16} {:>8.1} {:>8.1} {:>8.1} {:>9.1} {:>6.1} {:>9.2} {:>9.2} {:>5}  {}   ratio p99 {} vs {}",
            v.variant.name,
            v.jitter.p50_us,
            v.jitter.p99_us,
            v.jitter.p999_us,
            v.jitter.max_us,
            v.cpu_percent,
            v.work.p50_us,
            v.work.p99_us,
            v.late_ticks,
            if v.refused.is_empty() {
                "-".to_string()
            } else {
                v.refused.join("; ")
            },
            super::ratio_text(v.ratio_p99),
            v.baseline
        );
    }
    for (name, b) in [
        ("cyclictest", &r.baselines.cyclictest),
        ("cyclictest-fifo", &r.baselines.cyclictest_fifo),
    ] {
        if let Some(b) = b {
            println!(
                "{:<16} {:>8.1} {:>8.1} {:>8.1} {:>9.1} {:>6.1}",
                name, b.dist.p50_us, b.dist.p99_us, b.dist.p999_us, b.dist.max_us, b.cpu_percent
            );
        }
    }
    if let Some(n) = &r.baseline_note {
        println!("baseline: {n}");
    }
    println!(
        "headline: {} p99 {:.1} µs vs cyclictest p99 {} µs: ratio {} (target ≤ 1.5×); tick work p99 {:.2} µs (target < 5 µs)",
        r.vic.variant,
        r.vic.dist.p99_us,
        r.baseline
            .as_ref()
            .map_or("–".into(), |b| format!("{:.1}", b.dist.p99_us)),
        super::ratio_text(r.ratio_p99),
        r.vic.work.p99_us
    );
}
