//! `vic demo --distributed`: the demo with the board on one "host" and the planners on another.
//! The board runs in the demo's namespace with a board-side bridge beside it; the planners run in
//! a second namespace (a second iceoryx2 root: its own files, nothing shared with the first)
//! behind a central-side bridge; the two bridges meet over Zenoh TCP on loopback. The bridges run
//! as threads of the demo (each as `vic bridge` would), so their counts and the clock probes'
//! round trip come back with the results: the table shows the link's measured latency beside the
//! latency the delay lines inject.

use serde_json::Value;

/// The second "host"'s namespace for the demo's namespace `board_ns`.
#[cfg(feature = "zenoh")]
fn central_namespace(board_ns: &str) -> String {
    format!("{board_ns}c")
}

#[cfg(not(feature = "zenoh"))]
mod link {
    use super::*;
    use crate::cli::input_error;

    /// Without the `zenoh` feature there is no bridge, so no link is ever started.
    pub(crate) enum DistributedLink {}

    impl DistributedLink {
        /// Whether the demo can run distributed: not without the bridge (an input error that
        /// says how to build it).
        pub(crate) fn available() -> anyhow::Result<()> {
            Err(input_error(
                "--distributed needs the bridge: build vic with the zenoh feature \
                 (cargo build --release --features zenoh)",
            ))
        }

        pub(crate) fn start(_board_ns: &str) -> anyhow::Result<Self> {
            Err(Self::available().expect_err("no bridge without the zenoh feature"))
        }

        pub(crate) fn central_ns(&self) -> &str {
            match *self {}
        }

        pub(crate) fn stop(self) -> anyhow::Result<Value> {
            match self {}
        }
    }
}

#[cfg(feature = "zenoh")]
mod link {
    use super::*;
    use anyhow::anyhow;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::thread::JoinHandle;
    use vic_rt::bridge::{self, BridgeOptions, BridgeStats, Link, Side, Stamps};

    type Bridge = JoinHandle<Result<BridgeStats, bridge::BridgeError>>;

    /// The two bridges of a demo split across two namespaces.
    pub(crate) struct DistributedLink {
        stop: Arc<AtomicBool>,
        bridges: Vec<(Side, Bridge)>,
        central_ns: String,
        endpoint: String,
    }

    impl DistributedLink {
        pub(crate) fn available() -> anyhow::Result<()> {
            Ok(())
        }

        /// Starts both bridges: the board side listening on a free loopback port, the central
        /// side connecting to it. The board-side bridge translates stamps as across real hosts
        /// (the offset it measures is ~0 here, within ± half the round trip).
        pub(crate) fn start(board_ns: &str) -> anyhow::Result<Self> {
            let port = std::net::TcpListener::bind("127.0.0.1:0")
                .and_then(|l| l.local_addr())
                .map_err(|e| anyhow!("no free loopback port for the link: {e}"))?
                .port();
            let endpoint = format!("tcp/127.0.0.1:{port}");
            let central_ns = central_namespace(board_ns);
            let stop = Arc::new(AtomicBool::new(false));
            let spawn = |side, namespace: &str, link| {
                let options = BridgeOptions {
                    namespace: namespace.to_string(),
                    link_name: board_ns.to_string(),
                    side,
                    link,
                    security: bridge::Security::PlainLoopback,
                    safety_interval: bridge::DEFAULT_SAFETY_INTERVAL,
                    stamps: Stamps::Translate,
                    clock_skew_ns: 0,
                };
                let stop = stop.clone();
                (
                    side,
                    std::thread::spawn(move || bridge::run(&options, &stop, |_| {})),
                )
            };
            let bridges = vec![
                spawn(Side::Board, board_ns, Link::Listen(endpoint.clone())),
                spawn(Side::Central, &central_ns, Link::Connect(endpoint.clone())),
            ];
            Ok(DistributedLink {
                stop,
                bridges,
                central_ns,
                endpoint,
            })
        }

        /// The namespace the planners run in.
        pub(crate) fn central_ns(&self) -> &str {
            &self.central_ns
        }

        /// Stops both bridges and removes the second namespace; returns the link's figures.
        pub(crate) fn stop(mut self) -> anyhow::Result<Value> {
            let mut stats = serde_json::Map::new();
            for (side, b) in self.bridges.drain(..) {
                self.stop.store(true, Ordering::Relaxed);
                let s = b
                    .join()
                    .map_err(|_| anyhow!("the {side:?}-side bridge panicked"))?
                    .map_err(|e| anyhow!("the {side:?}-side bridge: {e}"))?;
                let key = format!("{side:?}_side").to_lowercase();
                stats.insert(key, serde_json::to_value(s)?);
            }
            let clock = &stats["board_side"]["clock"];
            let us = |key: &str| clock[key].as_f64().map(|ns| ns * 1e-3);
            Ok(serde_json::json!({
                "endpoint": self.endpoint,
                "central_namespace": self.central_ns,
                "round_trip_best_us": us("round_trip_ns"),
                "round_trip_median_us": us("round_trip_median_ns"),
                "clock_offset_us": us("offset_ns"),
                "clock_uncertainty_us": us("uncertainty_ns"),
                "leftover_shm_files": vic_rt::transport::namespace_files(&self.central_ns),
                "bridges": stats,
            }))
        }
    }

    impl Drop for DistributedLink {
        fn drop(&mut self) {
            self.stop.store(true, Ordering::Relaxed);
            for (_, b) in self.bridges.drain(..) {
                let _ = b.join();
            }
            vic_rt::transport::remove_namespace(&self.central_ns);
        }
    }
}

pub(crate) use link::DistributedLink;

/// The link's line under the table: its measured round trip beside the injected latency.
pub(crate) fn describe(link: &Value, latency_ms: f64) -> String {
    let f = |key: &str| link[key].as_f64().map_or("?".into(), |v| format!("{v:.0}"));
    format!(
        "link (Zenoh on {}): round trip {} µs median, {} µs best (clock probes), clock offset \
         {} ± {} µs; the delay lines inject {latency_ms} ms on top",
        link["endpoint"].as_str().unwrap_or("?"),
        f("round_trip_median_us"),
        f("round_trip_best_us"),
        f("clock_offset_us"),
        f("clock_uncertainty_us"),
    )
}
