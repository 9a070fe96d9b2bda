//! Each method's curve of relative MSE against seconds ([`curves`]), and log-log interpolation along it: the error at a
//! time ([`error_at`]), the time to an error ([`time_to`]), and the times and levels the summaries compare at
//! ([`common_times`], [`error_levels`]).

use crate::budget::Row;
use photon_core::method::Method;

/// A method's curve: `(seconds, relMSE)` points, sorted by seconds.
#[derive(Clone, Debug, PartialEq)]
pub struct Curve {
    /// The method.
    pub method: Method,
    /// Points sorted by time.
    pub points: Vec<(f64, f64)>,
}

/// The rows grouped into one curve per method, in the order methods first appear.
pub fn curves(rows: &[Row]) -> Vec<Curve> {
    let mut out: Vec<Curve> = Vec::new();
    for r in rows {
        match out.iter_mut().find(|c| c.method == r.method) {
            Some(c) => c.points.push((r.seconds, r.rel_mse)),
            None => out.push(Curve { method: r.method, points: vec![(r.seconds, r.rel_mse)] }),
        }
    }
    for c in &mut out {
        c.points.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    out
}

/// Linear interpolation between `(x0, y0)` and `(x1, y1)` in log-log space at `x` (all positive).
fn lerp_log(x0: f64, y0: f64, x1: f64, y1: f64, x: f64) -> f64 {
    if x1 == x0 {
        return (y0 * y1).sqrt();
    }
    let t = (x.ln() - x0.ln()) / (x1.ln() - x0.ln());
    (y0.ln() + t * (y1.ln() - y0.ln())).exp()
}

/// The curve's relMSE at `seconds`, interpolated in log-log between the neighbouring points; `None` outside the
/// measured time range or where a value is not positive.
pub fn error_at(curve: &Curve, seconds: f64) -> Option<f64> {
    let p = &curve.points;
    let first = p.first()?;
    let last = p.last()?;
    if !(first.0..=last.0).contains(&seconds) || p.iter().any(|&(t, e)| t <= 0.0 || e <= 0.0) {
        return None;
    }
    let i = p.windows(2).position(|w| seconds <= w[1].0);
    match i {
        Some(i) => Some(lerp_log(p[i].0, p[i].1, p[i + 1].0, p[i + 1].1, seconds)),
        None => Some(first.1),
    }
}

/// Seconds the curve needs to reach relMSE `level`: the first segment, in time order, that falls from above
/// `level` to at or below it, interpolated in log-log. `None` when the first point is already at or below the
/// level (less time than measured would do) or no point reaches it.
pub fn time_to(curve: &Curve, level: f64) -> Option<f64> {
    let p = &curve.points;
    if level <= 0.0 || p.iter().any(|&(t, e)| t <= 0.0 || e <= 0.0) || p.first()?.1 <= level {
        return None;
    }
    p.windows(2).find(|w| w[0].1 > level && w[1].1 <= level).map(|w| {
        let (t0, e0, t1, e1) = (w[0].0, w[0].1, w[1].0, w[1].1);
        // Invert the log-log line: ln t = ln t0 + (ln level − ln e0) / (ln e1 − ln e0) · (ln t1 − ln t0).
        let s = (level.ln() - e0.ln()) / (e1.ln() - e0.ln());
        (t0.ln() + s * (t1.ln() - t0.ln())).exp()
    })
}

/// `n` values spaced evenly in log between `lo` and `hi` inclusive (one value, `lo`, when `n` is 1).
pub fn log_space(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    if n <= 1 {
        return vec![lo];
    }
    (0..n).map(|i| (lo.ln() + (hi.ln() - lo.ln()) * i as f64 / (n - 1) as f64).exp()).collect()
}

/// Rounds to two significant digits, so table headings read as chosen levels rather than computed ones.
fn round2(x: f64) -> f64 {
    if x <= 0.0 || !x.is_finite() {
        return x;
    }
    let scale = 10f64.powf(x.log10().floor() - 1.0);
    (x / scale).round() * scale
}

/// The times of the equal-time table: `n` log-spaced times inside every curve's measured range, or none when
/// the ranges do not overlap.
pub fn common_times(curves: &[Curve], n: usize) -> Vec<f64> {
    let lo = curves.iter().filter_map(|c| c.points.first().map(|p| p.0)).fold(0.0, f64::max);
    let hi = curves.iter().filter_map(|c| c.points.last().map(|p| p.0)).fold(f64::INFINITY, f64::min);
    if curves.is_empty() || lo <= 0.0 || lo > hi {
        return Vec::new();
    }
    log_space(lo, hi, n)
}

/// The levels of the equal-error table: `n` log-spaced relMSE values strictly inside the range of all measured
/// errors (from 15 % to 85 % of the way in log), rounded to two digits.
pub fn error_levels(curves: &[Curve], n: usize) -> Vec<f64> {
    let all = curves.iter().flat_map(|c| c.points.iter().map(|p| p.1)).filter(|e| *e > 0.0 && e.is_finite());
    let (lo, hi) = all.fold((f64::INFINITY, 0.0f64), |(lo, hi), e| (lo.min(e), hi.max(e)));
    if lo >= hi {
        return Vec::new();
    }
    let (a, b) = (lo.ln(), hi.ln());
    let mut levels: Vec<f64> =
        log_space((a + 0.85 * (b - a)).exp(), (a + 0.15 * (b - a)).exp(), n).into_iter().map(round2).collect();
    levels.dedup();
    levels
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::curve;

    #[test]
    fn a_power_law_interpolates_exactly_in_log_log() {
        // relMSE = 1 / t: a straight line of slope −1 in log-log.
        let c = curve(&[(1.0, 1.0), (4.0, 0.25), (16.0, 1.0 / 16.0)]);
        let e = error_at(&c, 2.0).unwrap();
        assert!((e - 0.5).abs() < 1e-12, "{e}");
        let t = time_to(&c, 0.1).unwrap();
        assert!((t - 10.0).abs() < 1e-9, "{t}");
        assert_eq!(error_at(&c, 0.5), None);
        assert_eq!(error_at(&c, 17.0), None);
        assert_eq!(time_to(&c, 0.01), None, "never reached");
        assert_eq!(time_to(&c, 2.0), None, "already below at the first point");
    }
}
