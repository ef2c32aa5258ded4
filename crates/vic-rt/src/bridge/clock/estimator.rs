//! The offset between two clocks from NTP-style probes (see [`super`]): the probe with the
//! smallest round trip of a window, and the drift across windows.

use std::collections::VecDeque;

/// Probes the offset is taken from (the one with the smallest round trip): 10 s of them.
pub const WINDOW: usize = 50;
/// Windows whose best probes give the drift: 12, two minutes.
pub const BLOCKS: usize = 12;
/// Smallest span of those best probes for a drift [ns]: with less, the drift is 0.
const MIN_DRIFT_SPAN_NS: u64 = 25_000_000_000;
/// Probes whose answer took longer than this are refused (a lost probe answered late).
const MAX_ROUND_TRIP_NS: u64 = 1_000_000_000;

/// One probe's four time stamps: `t0`, `t3` on the prober's (local) clock, `t1`, `t2` on the
/// responder's (remote) clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Probe {
    pub t0: u64,
    pub t1: u64,
    pub t2: u64,
    pub t3: u64,
}

/// What one probe measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sample {
    /// When the answer arrived (local clock) [ns].
    pub(crate) at_ns: u64,
    /// Local clock − remote clock [ns].
    pub offset_ns: i64,
    pub round_trip_ns: u64,
}

impl Probe {
    /// The probe's offset and round trip; `None` when its stamps cannot be (an answer before
    /// the question, a negative round trip, one longer than a second).
    pub fn sample(&self) -> Option<Sample> {
        let (t0, t1, t2, t3) = (
            self.t0 as i128,
            self.t1 as i128,
            self.t2 as i128,
            self.t3 as i128,
        );
        let round_trip = (t3 - t0) - (t2 - t1);
        if t3 < t0 || t2 < t1 || round_trip < 0 || round_trip > MAX_ROUND_TRIP_NS as i128 {
            return None;
        }
        let offset = ((t0 - t1) + (t3 - t2)).div_euclid(2);
        Some(Sample {
            at_ns: self.t3,
            offset_ns: i64::try_from(offset).ok()?,
            round_trip_ns: round_trip as u64,
        })
    }
}

/// The offset between the clocks: local time = remote time + [`Estimate::offset_at`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Estimate {
    /// Local clock − remote clock at `at_ns` [ns].
    pub offset_ns: i64,
    /// The local time of the probe it comes from [ns].
    pub(crate) at_ns: u64,
    /// That probe's round trip: the offset is exact within ± half of it [ns].
    pub round_trip_ns: u64,
    /// How fast the offset grows [ns per s of local time, i.e. parts per billion].
    pub drift_ppb: i64,
}

impl Estimate {
    /// The offset at local time `local_ns`, the drift applied from the probe's time on.
    pub(crate) fn offset_at(&self, local_ns: u64) -> i64 {
        let elapsed = local_ns as i128 - self.at_ns as i128;
        let drift = elapsed * self.drift_ppb as i128 / 1_000_000_000;
        (self.offset_ns as i128 + drift).clamp(i64::MIN as i128, i64::MAX as i128) as i64
    }

    /// Remote time `remote_ns` on the local clock, at local time `local_ns`.
    pub fn to_local(&self, remote_ns: u64, local_ns: u64) -> u64 {
        remote_ns.saturating_add_signed(self.offset_at(local_ns))
    }

    /// ± this much [ns]: half the round trip (the delays' asymmetry cannot be told apart).
    pub fn uncertainty_ns(&self) -> u64 {
        self.round_trip_ns.div_ceil(2)
    }
}

/// The offset from a stream of probes: the probe of smallest round trip among the last
/// [`WINDOW`], and the drift across the last [`BLOCKS`] windows. Allocates only in `new`.
#[derive(Debug, Clone)]
pub struct Estimator {
    window: VecDeque<Sample>,
    /// The best probe of the window being filled, and how many probes it has had.
    block: Option<Sample>,
    block_len: usize,
    /// The best probe of each finished window.
    blocks: VecDeque<Sample>,
}

impl Default for Estimator {
    fn default() -> Self {
        Estimator {
            window: VecDeque::with_capacity(WINDOW),
            block: None,
            block_len: 0,
            blocks: VecDeque::with_capacity(BLOCKS),
        }
    }
}

fn better(a: Option<Sample>, b: Sample) -> Sample {
    match a {
        Some(a) if a.round_trip_ns <= b.round_trip_ns => a,
        _ => b,
    }
}

impl Estimator {
    /// Takes a probe; false (and nothing learnt) when its stamps cannot be.
    pub fn add(&mut self, probe: &Probe) -> bool {
        let Some(s) = probe.sample() else {
            return false;
        };
        if self.window.len() == WINDOW {
            self.window.pop_front();
        }
        self.window.push_back(s);
        self.block = Some(better(self.block, s));
        self.block_len += 1;
        if self.block_len == WINDOW {
            if self.blocks.len() == BLOCKS {
                self.blocks.pop_front();
            }
            self.blocks.extend(self.block.take());
            self.block_len = 0;
        }
        true
    }

    /// The estimate, once a probe came back.
    pub fn estimate(&self) -> Option<Estimate> {
        let best = self
            .window
            .iter()
            .copied()
            .reduce(|a, b| better(Some(a), b))?;
        Some(Estimate {
            offset_ns: best.offset_ns,
            at_ns: best.at_ns,
            round_trip_ns: best.round_trip_ns,
            drift_ppb: self.drift_ppb(),
        })
    }

    /// The median round trip of the probes in the window [ns] (the link's typical latency,
    /// where the estimate takes the best).
    pub(crate) fn median_round_trip_ns(&self) -> Option<u64> {
        let mut rtt = [0u64; WINDOW];
        let n = self.window.len();
        for (r, s) in rtt.iter_mut().zip(&self.window) {
            *r = s.round_trip_ns;
        }
        rtt[..n].sort_unstable();
        (n > 0).then(|| rtt[n / 2])
    }

    /// The least-squares slope of offset over time through the finished windows' best probes
    /// [ppb]; 0 until they span [`MIN_DRIFT_SPAN_NS`].
    fn drift_ppb(&self) -> i64 {
        let (Some(first), Some(last)) = (self.blocks.front(), self.blocks.back()) else {
            return 0;
        };
        if self.blocks.len() < 3 || last.at_ns - first.at_ns < MIN_DRIFT_SPAN_NS {
            return 0;
        }
        // Relative to the first point, in s and ns, so that f64 keeps every digit.
        let n = self.blocks.len() as f64;
        let point = |s: &Sample| {
            (
                (s.at_ns - first.at_ns) as f64 * 1e-9,
                (s.offset_ns - first.offset_ns) as f64,
            )
        };
        let (sx, sy) = self
            .blocks
            .iter()
            .map(point)
            .fold((0.0, 0.0), |(a, b), (x, y)| (a + x, b + y));
        let (mx, my) = (sx / n, sy / n);
        let (sxy, sxx) = self
            .blocks
            .iter()
            .map(point)
            .fold((0.0, 0.0), |(a, b), (x, y)| {
                (a + (x - mx) * (y - my), b + (x - mx) * (x - mx))
            });
        (sxy / sxx).round() as i64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The probe a local clock that is `offset` ahead of the remote one sees, sent at local
    /// `t0`, with the one-way delays `out` and `back` and 10 µs spent answering.
    fn probe(t0: u64, offset: i64, out: u64, back: u64) -> Probe {
        let t1 = (t0 + out).saturating_add_signed(-offset);
        let t2 = t1 + 10_000;
        Probe {
            t0,
            t1,
            t2,
            t3: t0 + out + 10_000 + back,
        }
    }

    #[test]
    fn one_probe_gives_the_closed_form() {
        let offset = -5_000_000_000; // the remote clock 5 s ahead
        let (out, back) = (300_000, 100_000);
        let s = probe(1_000_000_000_000, offset, out, back)
            .sample()
            .unwrap();
        assert_eq!(s.round_trip_ns, out + back);
        // offset + (d_back − d_out) / 2: the asymmetry is the error, within ± round trip / 2.
        assert_eq!(s.offset_ns, offset + (back as i64 - out as i64) / 2);
        // Impossible stamps are refused.
        let mut bad = probe(1_000_000_000, 0, 10, 10);
        bad.t3 = bad.t0 - 1;
        assert_eq!(bad.sample(), None);
        bad = probe(1_000_000_000, 0, 10, 10);
        bad.t2 = bad.t1 - 1;
        assert_eq!(bad.sample(), None);
    }

    #[test]
    fn the_estimate_is_the_smallest_round_trip_and_ignores_a_delayed_probe() {
        let offset = 5_000_000_000_i64;
        let mut e = Estimator::default();
        assert_eq!(e.estimate(), None);
        let mut t0 = 10_000_000_000;
        // Asymmetric delays, 100–500 µs out and 50–250 µs back; the fastest is probe 7.
        let mut best = None;
        for i in 0..30u64 {
            let (out, back) = (
                100_000 + (i * 7919) % 400_000,
                50_000 + (i * 104_729) % 200_000,
            );
            let (out, back) = if i == 7 {
                (60_000, 40_000)
            } else {
                (out, back)
            };
            assert!(e.add(&probe(t0, offset, out, back)));
            if i == 7 {
                best = Some((
                    t0 + out + 10_000 + back,
                    offset + (back as i64 - out as i64) / 2,
                ));
            }
            t0 += 200_000_000;
        }
        // One probe held up 80 ms on the way out: its offset is 40 ms off, its round trip long.
        let outlier = probe(t0, offset, 80_000_000, 100_000).sample().unwrap();
        assert!((outlier.offset_ns - offset).abs() > 39_000_000);
        assert!(e.add(&probe(t0, offset, 80_000_000, 100_000)));
        let (at, expected) = best.unwrap();
        let est = e.estimate().unwrap();
        assert_eq!(est.offset_ns, expected);
        assert_eq!(est.at_ns, at);
        assert_eq!(est.round_trip_ns, 100_000);
        assert_eq!(est.uncertainty_ns(), 50_000);
        assert!((est.offset_ns - offset).unsigned_abs() <= est.uncertainty_ns());
        assert_eq!(est.drift_ppb, 0, "no drift from 6 s of probes");
        let mut rtts: Vec<u64> = e.window.iter().map(|s| s.round_trip_ns).collect();
        rtts.sort();
        assert_eq!(e.median_round_trip_ns(), Some(rtts[rtts.len() / 2]));
        // The mean of the same probes would be pulled off by the outlier.
        let w = &e.window;
        let mean = w.iter().map(|s| s.offset_ns as f64).sum::<f64>() / w.len() as f64;
        assert!((mean - offset as f64).abs() > 1_000_000.0);
        // A remote time translates by the offset.
        assert_eq!(est.to_local(1_000, at), (1_000 + expected) as u64);
    }

    #[test]
    fn the_best_probe_leaves_the_window() {
        let mut e = Estimator::default();
        let mut t0 = 1_000_000_000;
        assert!(e.add(&probe(t0, 0, 1_000, 1_000)));
        for _ in 0..WINDOW {
            t0 += 200_000_000;
            assert!(e.add(&probe(t0, 0, 50_000, 50_000)));
        }
        assert_eq!(e.estimate().unwrap().round_trip_ns, 100_000);
    }

    #[test]
    fn a_drifting_clock_is_followed() {
        // The local clock gains 40 ppm on the remote one, from a 2 s offset.
        let (offset0, ppm) = (2_000_000_000_i64, 40.0);
        let offset_at = |t: u64| offset0 + (t as f64 * ppm * 1e-6) as i64;
        let mut e = Estimator::default();
        let mut t0 = 100_000_000_000;
        for i in 0..(WINDOW * BLOCKS) as u64 {
            // Delays vary, with a fast probe now and then.
            let (out, back) = (80_000 + (i * 7919) % 300_000, 80_000 + (i * 6007) % 300_000);
            assert!(e.add(&probe(t0, offset_at(t0 + out), out, back)));
            t0 += 200_000_000;
        }
        let est = e.estimate().unwrap();
        let drift_ppm = est.drift_ppb as f64 / 1000.0;
        assert!((drift_ppm - ppm).abs() < 1.0, "drift {drift_ppm} ppm");
        // Extrapolated 10 s past the last probe, the offset stays within the uncertainty; an
        // estimate without the drift would be 400 µs off.
        let later = t0 + 10_000_000_000;
        let err = (est.offset_at(later) - offset_at(later)).unsigned_abs();
        assert!(err <= est.uncertainty_ns() + 40_000, "off by {err} ns");
        let without = (est.offset_ns - offset_at(later)).unsigned_abs();
        assert!(without > 400_000, "{without}");
    }
}
