//! Gap accounting: the messages a sender numbered but the board never saw were overwritten in
//! the board's receive buffer (iceoryx2 keeps the newest `SUBSCRIBER_BUFFER` per publisher and
//! overwrites the oldest). They are counted from the sequence numbers, per sender session, so
//! that two senders interleaving on one service (a planner's slices between the messages of a
//! burst) do not hide each other's losses.
//!
//! It runs in the 1 kHz loop, once per message received: a fixed table, no allocation, no lock.

use crate::transport::Header;

/// Sender sessions tracked per kind of message. A board hears one central process, `vic inject`
/// and a few tools: 8 covers them with room for restarts.
pub const GAP_SESSIONS: usize = 8;

/// Largest gap counted as lost messages; a larger jump is a sender's renumbering (or junk), not
/// a loss the receive buffers could cause.
pub const MAX_COUNTED_GAP: u64 = 1 << 24;

/// The last message received from one session.
#[derive(Debug, Clone, Copy, Default)]
struct Slot {
    session: u32,
    seq: u64,
    /// When the session was last seen (the table's message count; 0: the slot is free).
    seen: u64,
}

/// Gap accounting of one kind of message, over every message received (valid or not): the
/// last sequence number of each of the `GAP_SESSIONS` sessions seen most recently.
///
/// Counted: within a tracked session, the numbers skipped between two messages received
/// (`seq - last - 1` when `seq > last`, up to [`MAX_COUNTED_GAP`]). Not counted: what a session
/// lost before its first message received, and, for a session evicted from the table (the
/// least recently seen goes when a new session arrives and the table is full), what it lost
/// between its last message before the eviction and its first after; it is a new session then.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct GapCounter {
    slots: [Slot; GAP_SESSIONS],
    /// Messages seen (the clock of `Slot::seen`).
    count: u64,
}

impl GapCounter {
    /// Messages missing before `h` in its session (0 for a session not in the table, a jump
    /// back or a jump of more than [`MAX_COUNTED_GAP`]); `h` becomes its session's last.
    pub(crate) fn missing_before(&mut self, h: &Header) -> u64 {
        self.count += 1;
        let seen = self.count;
        if let Some(slot) = self
            .slots
            .iter_mut()
            .find(|s| s.seen != 0 && s.session == h.session)
        {
            let gap = h.seq.saturating_sub(slot.seq).saturating_sub(1);
            slot.seq = h.seq;
            slot.seen = seen;
            return if gap <= MAX_COUNTED_GAP { gap } else { 0 };
        }
        // A new session (or one evicted before): it takes a free slot, else the least recently
        // seen session's. A free slot has `seen` 0, so it is the minimum.
        let slot = self
            .slots
            .iter_mut()
            .min_by_key(|s| s.seen)
            .expect("GAP_SESSIONS > 0");
        *slot = Slot {
            session: h.session,
            seq: h.seq,
            seen,
        };
        0
    }

    /// Sessions tracked now.
    #[cfg(test)]
    fn sessions(&self) -> usize {
        self.slots.iter().filter(|s| s.seen != 0).count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Total counted for messages `(session, seq)` in this order.
    fn count(messages: &[(u32, u64)]) -> u64 {
        let mut g = GapCounter::default();
        messages
            .iter()
            .map(|&(s, q)| g.missing_before(&Header::in_session(s, q, 0)))
            .sum()
    }

    #[test]
    fn two_interleaved_sessions_count_each_ones_gaps() {
        // Session 1 sends 1..=10 and the board receives 1, 2, 5, 9, 10 (lost: 3, 4, 6, 7, 8);
        // session 2 sends 100..=106 and the board receives 100, 101, 104, 106 (lost: 102, 103,
        // 105). Received interleaved as a board draining two publishers would: 5 + 3 = 8 lost.
        let got = count(&[
            (1, 1),
            (2, 100),
            (1, 2),
            (2, 101),
            (1, 5),
            (2, 104),
            (1, 9),
            (2, 106),
            (1, 10),
        ]);
        assert_eq!(got, 8);
        // A single tracker for the last session would see a new session at every switch and
        // count none of these losses. One switch in the middle of a session's gap still counts
        // the gap.
        assert_eq!(count(&[(1, 1), (2, 7), (2, 8), (1, 5)]), 3);
    }

    #[test]
    fn jumps_back_and_renumbering_are_not_losses_and_poison_nothing() {
        // u64::MAX then small numbers in session 1: no loss, and the session counts again from
        // its new number (5 → 8: 2 lost). Session 2 is untouched by session 1's jumps.
        assert_eq!(
            count(&[(1, 1), (2, 1), (1, u64::MAX), (1, 5), (2, 3), (1, 8)]),
            1 + 2
        );
        // A jump of more than 2^24 is a renumbering, not a loss; the next gap counts from it.
        let big = 1 + MAX_COUNTED_GAP + 1;
        assert_eq!(count(&[(1, 1), (1, big + 1), (1, big + 3)]), 1);
        assert_eq!(
            count(&[(1, 1), (1, 1 + MAX_COUNTED_GAP + 1)]),
            MAX_COUNTED_GAP
        );
    }

    #[test]
    fn more_sessions_than_slots_lose_only_the_evicted_ones_gaps() {
        let n = GAP_SESSIONS as u32;
        // n sessions fill the table; each then loses one message per round: all counted.
        let mut g = GapCounter::default();
        let mut lost = 0;
        for round in 0..3u64 {
            for s in 0..n {
                lost += g.missing_before(&Header::in_session(s, 2 * round + 1, 0));
            }
        }
        assert_eq!(lost, 2 * u64::from(n));
        assert_eq!(g.sessions(), GAP_SESSIONS);
        // One more session in the round (n + 1 in turn, each losing one per round): the least
        // recently seen is always the one that comes next, so each is evicted just before it
        // returns and nothing is counted. This is the table's limit: a session is tracked only
        // while fewer than GAP_SESSIONS other sessions came between two of its messages.
        let round_robin: Vec<(u32, u64)> = (0..3u64)
            .flat_map(|r| (0..=n).map(move |s| (s, 2 * r + 1)))
            .collect();
        assert_eq!(count(&round_robin), 0);
        // A steady sender between one-off sessions (one new session per message, like a sender
        // restarted every time): the steady one is seen every other message, never the least
        // recently seen, so its gaps are all counted (1 per message after the first: 9).
        let mixed: Vec<(u32, u64)> = (0..10u64)
            .flat_map(|i| [(7, 2 * i + 1), (1000 + i as u32, 1)])
            .collect();
        assert_eq!(count(&mixed), 9);
    }
}
