//! Shared, robust axis ranges: a diverging column does not set the range of the others.

use super::*;

/// Bounding box of finite points.
#[derive(Clone, Copy, Debug)]
pub(super) struct Bounds {
    pub(super) x0: f64,
    pub(super) x1: f64,
    pub(super) y0: f64,
    pub(super) y1: f64,
}

impl Default for Bounds {
    fn default() -> Self {
        Bounds {
            x0: f64::INFINITY,
            x1: f64::NEG_INFINITY,
            y0: f64::INFINITY,
            y1: f64::NEG_INFINITY,
        }
    }
}

impl Bounds {
    pub(super) fn of(points: impl IntoIterator<Item = (f64, f64)>) -> Bounds {
        let mut b = Bounds::default();
        for p in points {
            b.add(p);
        }
        b
    }

    pub(super) fn add(&mut self, p: (f64, f64)) {
        if is_finite(p) {
            self.x0 = self.x0.min(p.0);
            self.x1 = self.x1.max(p.0);
            self.y0 = self.y0.min(p.1);
            self.y1 = self.y1.max(p.1);
        }
    }

    pub(super) fn extend(&mut self, other: &Bounds) {
        if !other.is_empty() {
            self.add((other.x0, other.y0));
            self.add((other.x1, other.y1));
        }
    }

    pub(super) fn is_empty(&self) -> bool {
        self.x0 > self.x1
    }

    /// The longer side, None when empty.
    pub(super) fn size(&self) -> Option<f64> {
        (!self.is_empty()).then(|| (self.x1 - self.x0).max(self.y1 - self.y0))
    }
}

/// The `tail` and `1 - tail` quantiles of the finite values.
pub(super) fn quantile_range(mut values: Vec<f64>, tail: f64) -> Option<(f64, f64)> {
    values.retain(|v| v.is_finite());
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let last = (values.len() - 1) as f64;
    let at = |q: f64| values[(last * q).round() as usize];
    Some((at(tail), at(1.0 - tail)))
}

/// Which columns to keep when fitting a shared range: those whose size is at most `factor` times
/// the (lower) median positive size, or `anchor` if larger.
pub(super) fn non_outliers(sizes: &[Option<f64>], factor: f64, anchor: f64) -> Vec<bool> {
    let mut positive: Vec<f64> = sizes
        .iter()
        .flatten()
        .copied()
        .filter(|s| *s > 0.0)
        .collect();
    positive.sort_by(f64::total_cmp);
    let cap = match positive.get(positive.len().saturating_sub(1) / 2) {
        Some(median) => factor * median.max(anchor),
        None => f64::INFINITY,
    };
    sizes
        .iter()
        .map(|s| matches!(s, Some(s) if *s <= cap))
        .collect()
}

/// A y range shared by all columns: the union of each column's central range, leaving out
/// columns that spread `OUTLIER_FACTOR` times more than the median one, plus `always`, padded.
pub(super) fn shared_range(
    per_column: Vec<Vec<f64>>,
    always: &[f64],
    include_zero: bool,
) -> (f64, f64) {
    let ranges: Vec<Option<(f64, f64)>> = per_column
        .into_iter()
        .map(|v| quantile_range(v, TAIL))
        .collect();
    let sizes: Vec<Option<f64>> = ranges.iter().map(|r| r.map(|(lo, hi)| hi - lo)).collect();
    let keep = non_outliers(&sizes, OUTLIER_FACTOR, 0.0);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (range, keep) in ranges.iter().zip(keep) {
        if let (Some((a, b)), true) = (range, keep) {
            lo = lo.min(*a);
            hi = hi.max(*b);
        }
    }
    for &v in always.iter().filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if include_zero {
        lo = lo.min(0.0);
        hi = hi.max(0.0);
    }
    pad(lo, hi)
}

/// `lo..hi` with 6 % margins; a default or widened range when empty or flat.
pub(super) fn pad(lo: f64, hi: f64) -> (f64, f64) {
    if !(lo.is_finite() && hi.is_finite()) {
        return (-1.0, 1.0);
    }
    let width = hi - lo;
    if width <= 1e-9 * lo.abs().max(hi.abs()).max(1e-300) {
        let half = (0.1 * lo.abs()).max(1.0);
        return (lo - half, hi + half);
    }
    (lo - 0.06 * width, hi + 0.06 * width)
}

/// Every column's reference joint angles [deg].
pub(super) fn reference_degrees(columns: &[ColumnPlot]) -> Vec<f64> {
    columns
        .iter()
        .flat_map(|c| c.reference_q.iter().flatten().map(|q| q * RAD_TO_DEG))
        .collect()
}

/// Each column's torque range, and the stiffness range shared by all columns when some column
/// has stiffness commands.
///
/// Torques differ between columns by orders of magnitude (a feedback law's corrections against
/// an open-loop plan's, a VSA's motor torques against a joint's): on one shared range the small
/// ones are flat lines at 0, and the large ones a barcode of clipped steps. So each column has
/// its own range, with 0 in it, from its trials that did not diverge. A column whose every
/// trial diverged takes the range of the others' (its blow-up leaves the frame, as it would on
/// the robot's torque limits), or its own when no column has a trial that did not diverge.
/// Stiffnesses share one range: their bounds are the same and their levels are what the
/// columns compare.
pub(super) fn command_ranges(columns: &[ColumnPlot]) -> (Vec<Span>, Option<Span>) {
    let own: Vec<Option<Span>> = command_values(columns, Commands::Torque)
        .into_iter()
        .map(|v| quantile_range(v, TAIL))
        .collect();
    let others = own
        .iter()
        .flatten()
        .fold(None, |acc: Option<Span>, &(lo, hi)| match acc {
            Some((a, b)) => Some((a.min(lo), b.max(hi))),
            None => Some((lo, hi)),
        });
    let everything = |c: &ColumnPlot| {
        let range = Commands::Torque.indices(c);
        let values = c.u.iter().flatten();
        quantile_range(
            values
                .flat_map(|step| step.get(range.clone()).unwrap_or_default().iter().copied())
                .collect(),
            TAIL,
        )
    };
    let torque = columns
        .iter()
        .zip(own)
        .map(|(c, own)| match own.or(others).or_else(|| everything(c)) {
            Some((lo, hi)) => pad(lo.min(0.0), hi.max(0.0)),
            None => pad(0.0, 0.0),
        })
        .collect();
    let stiffness = columns
        .iter()
        .any(|c| n_controls(c) > n_torques(c))
        .then(|| shared_range(command_values(columns, Commands::Stiffness), &[], true));
    (torque, stiffness)
}
