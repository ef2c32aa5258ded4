//! Clipped drawing: plotters does not clip series to the plotting area, so lines, dashes and
//! polygons are clipped here against the view.

use super::*;

/// Draws a polyline, broken at non-finite points and clipped to `view`.
pub(super) fn lines<'c, DB: DrawingBackend + 'c>(
    chart: &mut Chart<'c, DB>,
    view: &View,
    points: impl IntoIterator<Item = (f64, f64)>,
    style: ShapeStyle,
) -> DrawResult<(), DB> {
    for run in clip_polyline(thin_out(points.into_iter().collect()), view) {
        chart.draw_series(LineSeries::new(run, style))?;
    }
    Ok(())
}

pub(super) fn dashed<'c, DB: DrawingBackend + 'c>(
    chart: &mut Chart<'c, DB>,
    view: &View,
    points: &[(f64, f64)],
    style: ShapeStyle,
) -> DrawResult<(), DB> {
    for run in clip_polyline(thin_out(points.to_vec()), view) {
        chart.draw_series(DashedLineSeries::new(run, 7, 5, style))?;
    }
    Ok(())
}

/// Fills a polygon clipped to `view`.
pub(super) fn fill<'c, DB: DrawingBackend + 'c>(
    chart: &mut Chart<'c, DB>,
    view: &View,
    polygon: &[(f64, f64)],
    colour: RGBAColor,
) -> DrawResult<(), DB> {
    let clipped = clip_polygon(&thin_out(polygon.to_vec()), view);
    if clipped.len() >= 3 {
        chart.draw_series(std::iter::once(Polygon::new(clipped, colour.filled())))?;
    }
    Ok(())
}

/// Keeps at most about `MAX_POINTS` points (every k-th, and the last).
pub(super) fn thin_out(points: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    if points.len() <= MAX_POINTS {
        return points;
    }
    let stride = points.len().div_ceil(MAX_POINTS);
    let last = points.len() - 1;
    points
        .into_iter()
        .enumerate()
        .filter(|(i, _)| i % stride == 0 || *i == last)
        .map(|(_, p)| p)
        .collect()
}

/// Polygons between an upper and a lower edge (same length), one per run of knots where both
/// edges are finite.
pub(super) fn band_polygons(
    upper: Vec<(f64, f64)>,
    lower: Vec<(f64, f64)>,
) -> Vec<Vec<(f64, f64)>> {
    let mut polygons = Vec::new();
    let mut start = 0;
    let n = upper.len().min(lower.len());
    while start < n {
        let ok = |k: usize| is_finite(upper[k]) && is_finite(lower[k]);
        if !ok(start) {
            start += 1;
            continue;
        }
        let mut end = start;
        while end < n && ok(end) {
            end += 1;
        }
        if end - start >= 2 {
            let mut polygon: Vec<(f64, f64)> = upper[start..end].to_vec();
            polygon.extend(lower[start..end].iter().rev());
            polygons.push(polygon);
        }
        start = end;
    }
    polygons
}

/// A rectangle in data coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct View {
    pub(super) x0: f64,
    pub(super) x1: f64,
    pub(super) y0: f64,
    pub(super) y1: f64,
}

impl View {
    pub(super) fn of<'c, DB: DrawingBackend + 'c>(chart: &Chart<'c, DB>) -> View {
        let (x, y) = (chart.x_range(), chart.y_range());
        View {
            x0: x.start,
            x1: x.end,
            y0: y.start,
            y1: y.end,
        }
    }

    pub(super) fn contains(&self, p: (f64, f64)) -> bool {
        (self.x0..=self.x1).contains(&p.0) && (self.y0..=self.y1).contains(&p.1)
    }
}

pub(super) fn is_finite(p: (f64, f64)) -> bool {
    p.0.is_finite() && p.1.is_finite()
}

/// Bounds huge values so that differences cannot overflow (far outside any view anyway).
pub(super) fn tame(p: (f64, f64)) -> (f64, f64) {
    const BIG: f64 = 1e12;
    (p.0.clamp(-BIG, BIG), p.1.clamp(-BIG, BIG))
}

/// Liang–Barsky: the part of segment a–b inside `v`, if any.
pub(super) fn clip_segment(
    a: (f64, f64),
    b: (f64, f64),
    v: &View,
) -> Option<((f64, f64), (f64, f64))> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0_f64, 1.0_f64);
    for (p, q) in [
        (-dx, a.0 - v.x0),
        (dx, v.x1 - a.0),
        (-dy, a.1 - v.y0),
        (dy, v.y1 - a.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
            continue;
        }
        let r = q / p;
        if p < 0.0 {
            t0 = t0.max(r);
        } else {
            t1 = t1.min(r);
        }
        if t0 > t1 {
            return None;
        }
    }
    let at = |t: f64| {
        if t == 0.0 {
            a
        } else if t == 1.0 {
            b
        } else {
            (a.0 + t * dx, a.1 + t * dy)
        }
    };
    Some((at(t0), at(t1)))
}

/// The pieces of a polyline inside `v`; non-finite points break the line.
pub(super) fn clip_polyline(points: Vec<(f64, f64)>, v: &View) -> Vec<Vec<(f64, f64)>> {
    pub(super) fn flush(runs: &mut Vec<Vec<(f64, f64)>>, run: &mut Vec<(f64, f64)>) {
        if run.len() >= 2 {
            runs.push(std::mem::take(run));
        } else {
            run.clear();
        }
    }
    let mut runs = Vec::new();
    let mut run: Vec<(f64, f64)> = Vec::new();
    let mut previous: Option<(f64, f64)> = None;
    for p in points {
        if !is_finite(p) {
            flush(&mut runs, &mut run);
            previous = None;
            continue;
        }
        let p = tame(p);
        if let Some(a) = previous {
            match clip_segment(a, p, v) {
                Some((s, e)) => {
                    if run.last() != Some(&s) {
                        flush(&mut runs, &mut run);
                        run.push(s);
                    }
                    run.push(e);
                }
                None => flush(&mut runs, &mut run),
            }
        }
        previous = Some(p);
    }
    flush(&mut runs, &mut run);
    runs
}

/// Sutherland–Hodgman: `polygon` clipped to `v` (non-finite vertices are dropped).
pub(super) fn clip_polygon(polygon: &[(f64, f64)], v: &View) -> Vec<(f64, f64)> {
    let mut poly: Vec<(f64, f64)> = polygon
        .iter()
        .copied()
        .filter(|p| is_finite(*p))
        .map(tame)
        .collect();
    for edge in 0..4 {
        let Some(&last) = poly.last() else {
            break;
        };
        let inside = |p: (f64, f64)| match edge {
            0 => p.0 >= v.x0,
            1 => p.0 <= v.x1,
            2 => p.1 >= v.y0,
            _ => p.1 <= v.y1,
        };
        let cross = |a: (f64, f64), b: (f64, f64)| match edge {
            0 | 1 => {
                let x = if edge == 0 { v.x0 } else { v.x1 };
                (x, a.1 + (x - a.0) / (b.0 - a.0) * (b.1 - a.1))
            }
            _ => {
                let y = if edge == 2 { v.y0 } else { v.y1 };
                (a.0 + (y - a.1) / (b.1 - a.1) * (b.0 - a.0), y)
            }
        };
        let input = std::mem::take(&mut poly);
        let mut previous = last;
        for current in input {
            match (inside(previous), inside(current)) {
                (true, true) => poly.push(current),
                (true, false) => poly.push(cross(previous, current)),
                (false, true) => {
                    poly.push(cross(previous, current));
                    poly.push(current);
                }
                (false, false) => {}
            }
            previous = current;
        }
    }
    poly.retain(|p| is_finite(*p));
    poly
}
