//! The bridge's thread: one iceoryx2 wait set that wakes on the local publishers' relay
//! notifications and on the Zenoh callbacks' wake-up, with a slow safety interval; no polling.

use super::trace::{self, Point};
use super::{BridgeError, BridgeStats, Counts, Inbound, Side};
use crate::rt::bridge::wire::Malformed;
use crate::rt::transport::relay::RelayListener;
use crate::rt::transport::service::Service as Ipc;
use iceoryx2::prelude::{CallbackProgression, SignalHandlingMode, WaitSetBuilder};
use iceoryx2_bb_posix::file_descriptor::{FileDescriptor, FileDescriptorBased};
use iceoryx2_bb_posix::file_descriptor_set::SynchronousMultiplexing;
use std::io::ErrorKind;
use std::os::fd::AsRawFd;
use std::os::unix::net::UnixDatagram;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// How often the thread looks at `stop` at the latest, whatever the safety interval.
const STOP_CHECK: Duration = Duration::from_millis(100);

/// The Zenoh callbacks' wake-up of the bridge's thread: a Unix datagram socket pair (the
/// callbacks run on Zenoh's threads, and a socket is safe to write from any of them, where an
/// iceoryx2 notifier of this service type is not `Sync`). The thread's wait set watches the
/// reading end.
#[derive(Debug)]
pub(super) struct LinkWake {
    tx: UnixDatagram,
    rx: UnixDatagram,
    /// The reading end as iceoryx2 sees it (not owning: `rx` closes it).
    fd: FileDescriptor,
}

impl LinkWake {
    pub(super) fn new() -> Result<LinkWake, BridgeError> {
        let io = |e: std::io::Error| BridgeError::Wait(format!("the link's wake-up socket: {e}"));
        let (tx, rx) = UnixDatagram::pair().map_err(io)?;
        tx.set_nonblocking(true).map_err(io)?;
        rx.set_nonblocking(true).map_err(io)?;
        let fd = FileDescriptor::non_owning_new(rx.as_raw_fd())
            .ok_or_else(|| BridgeError::Wait("the link's wake-up socket is not valid".into()))?;
        Ok(LinkWake { tx, rx, fd })
    }

    /// Wakes the thread (from a Zenoh callback, after the message is in the channel). A full
    /// socket buffer means the thread has wake-ups pending already: nothing is lost.
    pub(super) fn wake(&self) {
        let _ = self.tx.send(&[1]);
    }

    /// Consumes the pending wake-ups; whether there was one.
    fn take(&self) -> bool {
        let mut buf = [0u8; 16];
        let mut got = false;
        loop {
            match self.rx.recv(&mut buf) {
                Ok(_) => got = true,
                Err(e) if e.kind() == ErrorKind::Interrupted => continue,
                Err(_) => return got,
            }
        }
    }
}

impl FileDescriptorBased for LinkWake {
    fn file_descriptor(&self) -> &FileDescriptor {
        &self.fd
    }
}

impl SynchronousMultiplexing for LinkWake {}

/// The bridge's loop, the same on both sides.
pub(super) struct Looper<'a> {
    /// Which bridge this is (for the trace marks).
    pub side: Side,
    /// The longest the thread sleeps before draining the local side anyway (a notification
    /// missed, e.g. from a client that does not notify, waits at most this long).
    pub safety: Duration,
    pub stop: &'a AtomicBool,
    /// What the link's callbacks decoded.
    pub rx: &'a mpsc::Receiver<Inbound>,
    /// Rung by the link's callbacks after each message.
    pub wake: &'a LinkWake,
}

impl Looper<'_> {
    /// Sleeps in one wait set until the local side notifies (`relay`), the link delivers, or the
    /// safety interval passes; then forwards what arrived from the link (`forward`: publishes it
    /// locally, counts it in the received counts, says whether the local publish worked) and
    /// drains the local side (`drain`). Until `stop`. What did not decode is counted here, once
    /// for both sides, and never forwarded.
    pub fn run(
        &self,
        relay: &RelayListener,
        mut forward: impl FnMut(Inbound, &mut Counts) -> bool,
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
        let _link = waitset
            .attach_notification(self.wake)
            .map_err(|e| wait(&e))?;
        let mut inbound = |m: Inbound, s: &mut BridgeStats| match m {
            Inbound::Malformed(Malformed::Size { .. }) => s.malformed_size += 1,
            Inbound::Malformed(Malformed::Version(_)) => s.malformed_version += 1,
            m => {
                s.local_errors += (!forward(m, &mut s.received)) as u64;
                trace::mark(self.side, Point::Published);
            }
        };
        // The first pass drains at once (what was published before the bridge came up).
        let mut deadline = Instant::now();
        while !self.stop.load(Ordering::Relaxed) {
            let now = Instant::now();
            let mut woke = now >= deadline;
            if !woke {
                // Which attachment fired does not matter: every wake-up does all the work below,
                // which is cheap when there is nothing. A timeout (the callback not called) that
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
            if self.wake.take() {
                trace::mark(self.side, Point::LinkWoke);
            }
            while let Ok(m) = self.rx.try_recv() {
                inbound(m, stats);
            }
            drain(stats);
            deadline = Instant::now() + self.safety;
        }
        Ok(())
    }
}
