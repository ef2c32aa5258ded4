//! The daemons' logs (`vic-board`, `vic-planner`) through `tracing`: formatted lines on stderr,
//! the level from `--log-level`, else `RUST_LOG`, else `info`. Never from inside the 1 kHz loop:
//! the board reports the loop's counters after it (its statistics), as before.

use crate::cli::input_error;
use std::io::IsTerminal;
use tracing::level_filters::LevelFilter;
use tracing_subscriber::filter::Targets;
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::util::SubscriberInitExt;

/// The level when neither `--log-level` nor `RUST_LOG` says.
pub(crate) const DEFAULT_LEVEL: &str = "info";

/// The filter of `flag` (the `--log-level` value), else of `RUST_LOG`, else [`DEFAULT_LEVEL`]: a
/// level (`error`, `warn`, `info`, `debug`, `trace`, `off`) or per-target levels
/// (`vic=debug,warn`). A bad value is the user's input (exit 2) and names where it came from.
pub(crate) fn filter(flag: Option<&str>, rust_log: Option<&str>) -> anyhow::Result<Targets> {
    let (spec, source) = match (flag, rust_log.filter(|s| !s.trim().is_empty())) {
        (Some(f), _) => (f, "--log-level"),
        (None, Some(env)) => (env, "RUST_LOG"),
        (None, None) => (DEFAULT_LEVEL, "the default"),
    };
    let bad = |why: String| {
        input_error(format!(
            "{source} {spec:?}: {why} (give a level: error, warn, info, debug, trace, off; or \
             per target: vic=debug,warn)"
        ))
    };
    // `Targets` would read a bare word as a target to enable at every level: a misspelt level
    // ("warning") would silently log everything of nothing. Every directive must end in a level.
    for directive in spec.split(',').map(str::trim).filter(|d| !d.is_empty()) {
        let level = directive.rsplit_once('=').map_or(directive, |(_, l)| l);
        if level.parse::<LevelFilter>().is_err() {
            return Err(bad(format!("{level:?} is not a level")));
        }
    }
    spec.parse::<Targets>().map_err(|e| bad(e.to_string()))
}

/// Sends this process's `tracing` events to stderr (colours only on a terminal). A second call
/// keeps the first subscriber.
pub(crate) fn init(flag: Option<&str>) -> anyhow::Result<()> {
    let filter = filter(flag, std::env::var("RUST_LOG").ok().as_deref())?;
    let fmt = tracing_subscriber::fmt::layer()
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .with_target(false);
    let _ = tracing_subscriber::registry()
        .with(fmt)
        .with(filter)
        .try_init();
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use tracing::Level;

    fn level(t: &Targets, target: &str) -> Option<Level> {
        [
            Level::TRACE,
            Level::DEBUG,
            Level::INFO,
            Level::WARN,
            Level::ERROR,
        ]
        .into_iter()
        .find(|l| t.would_enable(target, l))
    }

    #[test]
    fn the_flag_wins_over_rust_log_which_wins_over_info() {
        let t = filter(Some("warn"), Some("debug")).unwrap();
        assert_eq!(level(&t, "vic::demo"), Some(Level::WARN));
        let t = filter(None, Some("debug")).unwrap();
        assert_eq!(level(&t, "vic::demo"), Some(Level::DEBUG));
        for empty in [None, Some(""), Some("  ")] {
            let t = filter(None, empty).unwrap();
            assert_eq!(level(&t, "vic::demo"), Some(Level::INFO));
        }
        let t = filter(Some("vic=trace,error"), None).unwrap();
        assert_eq!(level(&t, "vic::daemons::board"), Some(Level::TRACE));
        assert_eq!(level(&t, "iceoryx2"), Some(Level::ERROR));
        assert_eq!(
            filter(Some("off"), None).unwrap().default_level(),
            Some(LevelFilter::OFF)
        );
    }

    #[test]
    fn a_bad_level_is_the_users_input_and_names_its_source() {
        let e = filter(Some("loud"), None).unwrap_err();
        assert_eq!(crate::cli::exit_code(&e), 2);
        assert!(e.to_string().contains("--log-level \"loud\""), "{e}");
        let e = filter(None, Some("vic=shouty")).unwrap_err();
        assert!(e.to_string().contains("RUST_LOG"), "{e}");
        assert!(filter(Some("warning"), None).is_err());
        assert!(filter(Some("info,vic"), None).is_err());
    }
}
