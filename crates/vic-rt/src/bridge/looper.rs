//! The bridge's thread: one iceoryx2 wait set that wakes on the local publishers' relay
//! notifications, with a slow safety interval; no polling. (What arrives from the link is
//! published by the Zenoh callbacks themselves: see the module doc of [`super`].)

use super::trace::{self, Point};
use super::{BridgeError, BridgeStats, Side};
use crate::transport::relay::RelayListener;
use crate::transport::service::Service as Ipc;
use iceoryx2::prelude::{CallbackProgression, SignalHandlingMode, WaitSetBuilder};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// How often the thread looks at `stop` at the latest, whatever the safety interval.
const STOP_CHECK: Duration = Duration::from_millis(100);

/// The bridge's loop, the same on both sides.
pub(super) struct Looper<'a> {
    /// Which bridge this is (for the trace marks).
    pub side: Side,
    /// The longest the thread sleeps before draining the local side anyway (a notification
    /// missed, e.g. from a client that does not notify, waits at most this long).
    pub safety: Duration,
    pub stop: &'a AtomicBool,
}

impl Looper<'_> {
    /// Sleeps in a wait set until the local side notifies (`relay`) or the safety interval
    /// passes; then drains the local side onto the link (`drain`). Until `stop`.
    pub fn run(
        &self,
        relay: &RelayListener,
        mut drain: impl FnMut(&mut BridgeStats),
        stats: &mut BridgeStats,
    ) -> Result<(), BridgeError> {
        let wait = |e: &dyn std::fmt::Debug| BridgeError::Wait(format!("{e:?}"));
        // iceoryx2 must not install its own signal handlers: the command's handler owns them.
        let waitset = WaitSetBuilder::new()
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<Ipc>()
            .map_err(|e| wait(&e))?;
        let _local = waitset
            .attach_notification(relay.port())
            .map_err(|e| wait(&e))?;
        // The first pass drains at once (what was published before the bridge came up).
        let mut deadline = Instant::now();
        while !self.stop.load(Ordering::Relaxed) {
            let now = Instant::now();
            let mut woke = now >= deadline;
            if !woke {
                // Every wake-up does all the work below, which is cheap when there is nothing. A
                // timeout (the callback not called) that
                // is not the safety deadline only looks at `stop`; an interrupted wait (a
                // signal) does the same.
                let _ = waitset.wait_and_process_once_with_timeout(
                    |_| {
                        woke = true;
                        CallbackProgression::Continue
                    },
                    (deadline - now).min(STOP_CHECK),
                );
                woke |= Instant::now() >= deadline;
            }
            if !woke {
                continue;
            }
            // Consume the notifications *before* draining, so that a publish after the drain
            // rings again (consuming them after would lose it); a wait set whose listener is not
            // drained would also wake at once, forever.
            if relay.take() {
                trace::mark(self.side, Point::LocalWoke);
            }
            drain(stats);
            deadline = Instant::now() + self.safety;
        }
        Ok(())
    }
}
