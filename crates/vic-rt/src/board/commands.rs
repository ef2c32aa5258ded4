//! The command buffer: the last few valid command slices, and the knot that covers a time.

use crate::transport::{CommandSlice, Interpolation, Knot};

/// Slices kept: a new slice overlaps the previous ones, and the newest covering the present wins.
const SLICES: usize = 4;

/// The knot in force at a trial time, with where it came from.
#[derive(Debug, Clone, Copy)]
pub(super) struct Covering {
    pub knot: Knot,
    /// Publish time of the slice [ns, monotonic].
    pub(crate) sent_ns: u64,
    pub seq: u64,
}

/// A ring of the newest valid command slices (fixed size: nothing allocates).
#[derive(Debug, Clone)]
pub(super) struct CommandBuffer {
    slices: [CommandSlice; SLICES],
    valid: [bool; SLICES],
    /// Arrival order of each slice: the newest wins. (Not the sequence number: those of two
    /// sender sessions do not compare.)
    arrival: [u64; SLICES],
    arrivals: u64,
    next: usize,
}

impl CommandBuffer {
    pub fn new() -> Self {
        CommandBuffer {
            slices: [CommandSlice::default(); SLICES],
            valid: [false; SLICES],
            arrival: [0; SLICES],
            arrivals: 0,
            next: 0,
        }
    }

    /// Keeps a validated slice, replacing the oldest.
    pub fn insert(&mut self, c: &CommandSlice) {
        self.slices[self.next] = *c;
        self.valid[self.next] = true;
        self.arrivals += 1;
        self.arrival[self.next] = self.arrivals;
        self.next = (self.next + 1) % SLICES;
    }

    /// Forgets every slice (a reset, a stop, a fault).
    pub fn clear(&mut self) {
        self.valid = [false; SLICES];
    }

    /// The knot in force at trial time `t` from the newest valid slice that covers it (held or
    /// interpolated as the slice says).
    pub fn covering(&self, t: u64) -> Option<Covering> {
        let mut best: Option<usize> = None;
        for s in 0..SLICES {
            let c = &self.slices[s];
            if self.valid[s]
                && c.start_ns <= t
                && t < c.end_ns()
                && best.is_none_or(|b| self.arrival[b] < self.arrival[s])
            {
                best = Some(s);
            }
        }
        let c = &self.slices[best?];
        let offset = t - c.start_ns;
        let i = (offset / c.knot_dt_ns) as usize;
        let mut knot = c.knots[i];
        if c.interpolation == Interpolation::Linear as u32 && i + 1 < c.count as usize {
            let a = (offset - i as u64 * c.knot_dt_ns) as f64 / c.knot_dt_ns as f64;
            knot = knot.lerp(&c.knots[i + 1], a);
        }
        Some(Covering {
            knot,
            sent_ns: c.header.time_ns,
            seq: c.header.seq,
        })
    }
}
