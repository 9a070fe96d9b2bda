//! The chart of a sweep: relative MSE against seconds on log-log axes, one line per method, as SVG and as PNG
//! ([`draw_charts`]), drawn with plotters; the PNG's text with a font built into the binary.

use crate::curve::Curve;
use anyhow::{Context, Result};
use photon_coordinator::out::report::sig;
use std::path::Path;

/// Draws relMSE against seconds on log-log axes, one line per method, to `svg` and `png`, each with a title, axis
/// labels, tick labels and a legend. The PNG's text is rasterised with DejaVu Sans, built into the binary
/// (`tools/sweep/assets/`, its licence beside it), so no system font is needed.
pub fn draw_charts(curves: &[Curve], title: &str, svg: &Path, png: &Path) -> Result<()> {
    use plotters::prelude::*;
    let (w, h) = CHART_SIZE;
    {
        let root = SVGBackend::new(svg, (w, h)).into_drawing_area();
        draw(&root, curves, Some(title)).with_context(|| format!("drawing {}", svg.display()))?;
        root.present().with_context(|| format!("writing {}", svg.display()))?;
    }
    let buf = chart_pixels(curves, Some(title)).with_context(|| format!("drawing {}", png.display()))?;
    image::save_buffer(png, &buf, w, h, image::ExtendedColorType::Rgb8)
        .with_context(|| format!("writing {}", png.display()))?;
    Ok(())
}

/// Width and height of a chart in pixels.
const CHART_SIZE: (u32, u32) = (800, 560);

/// The chart as RGB8 pixels (row-major, `CHART_SIZE`), with its text when `title` is given.
fn chart_pixels(curves: &[Curve], title: Option<&str>) -> Result<Vec<u8>> {
    use plotters::prelude::*;
    register_font();
    let (w, h) = CHART_SIZE;
    let mut buf = vec![0u8; 3 * w as usize * h as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        draw(&root, curves, title)?;
        root.present()?;
    }
    Ok(buf)
}

/// Registers the built-in font as plotters' `sans-serif`, once.
fn register_font() {
    static FONT: std::sync::Once = std::sync::Once::new();
    FONT.call_once(|| {
        // DejaVu Sans (Bitstream Vera licence: tools/sweep/assets/DejaVuSans-LICENSE.txt).
        let bytes: &'static [u8] = include_bytes!("../assets/DejaVuSans.ttf");
        if plotters::style::register_font("sans-serif", plotters::style::FontStyle::Normal, bytes).is_err() {
            tracing::warn!("the built-in chart font does not load: PNG charts will lack their text");
        }
    });
}

/// The line colour of the `i`-th method (a colour-blind-safe palette, Wong 2011).
fn colour(i: usize) -> plotters::style::RGBColor {
    const WONG: [(u8, u8, u8); 7] =
        [(0, 114, 178), (213, 94, 0), (0, 158, 115), (204, 121, 167), (230, 159, 0), (86, 180, 233), (0, 0, 0)];
    let (r, g, b) = WONG[i % WONG.len()];
    plotters::style::RGBColor(r, g, b)
}

/// The axis range `[lo, hi]` of positive values, widened to whole powers of ten.
fn decade_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) =
        values.filter(|v| *v > 0.0 && v.is_finite()).fold((f64::INFINITY, 0.0f64), |(l, h), v| (l.min(v), h.max(v)));
    if lo > hi {
        return (0.1, 1.0);
    }
    let lo = 10f64.powf(lo.log10().floor());
    let hi = 10f64.powf(hi.log10().ceil());
    if hi > lo { (lo, hi) } else { (lo, lo * 10.0) }
}

/// The powers of ten from `lo` to `hi` (both powers of ten, as [`decade_range`] makes them).
fn decades((lo, hi): (f64, f64)) -> Vec<f64> {
    let (a, b) = (lo.log10().round() as i32, hi.log10().round() as i32);
    (a..=b).map(|e| 10f64.powi(e)).collect()
}

/// A tick label on a log axis: `0.01`, `1`, `100` between 10⁻³ and 10³, `1e-5` outside.
fn decade_label(v: f64) -> String {
    let e = v.log10().round();
    if (v / 10f64.powf(e) - 1.0).abs() > 1e-6 {
        return sig(v);
    }
    if (-3.0..=3.0).contains(&e) { format!("{}", 10f64.powf(e) as f32) } else { format!("1e{e}") }
}

/// The chart on one drawing area; `title` (and every other text) only when given.
fn draw<DB: plotters::prelude::DrawingBackend>(
    root: &plotters::prelude::DrawingArea<DB, plotters::coord::Shift>,
    curves: &[Curve],
    title: Option<&str>,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    use plotters::prelude::*;
    root.fill(&WHITE)?;
    let xr = decade_range(curves.iter().flat_map(|c| c.points.iter().map(|p| p.0)));
    let yr = decade_range(curves.iter().flat_map(|c| c.points.iter().map(|p| p.1)));
    register_font();
    let labels = title.is_some();
    let mut builder = ChartBuilder::on(root);
    builder.margin(20);
    if let Some(t) = title {
        builder.caption(t, ("sans-serif", 22)).x_label_area_size(50).y_label_area_size(70);
    } else {
        builder.x_label_area_size(0).y_label_area_size(0);
    }
    let mut chart = builder.build_cartesian_2d((xr.0..xr.1).log_scale(), (yr.0..yr.1).log_scale())?;
    if labels {
        chart
            .configure_mesh()
            .x_desc("wall seconds (prepare + render)")
            .y_desc("relative MSE")
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .x_label_formatter(&|v| decade_label(*v))
            .y_label_formatter(&|v| decade_label(*v))
            .draw()?;
    } else {
        // The mesh would draw tick labels; without a font, draw the decade grid and the frame by hand.
        let grey = RGBColor(200, 200, 200);
        for x in decades(xr) {
            chart.draw_series(LineSeries::new([(x, yr.0), (x, yr.1)], grey.stroke_width(1)))?;
        }
        for y in decades(yr) {
            chart.draw_series(LineSeries::new([(xr.0, y), (xr.1, y)], grey.stroke_width(1)))?;
        }
        chart.draw_series([Rectangle::new([(xr.0, yr.0), (xr.1, yr.1)], BLACK.stroke_width(1))])?;
    }
    for (i, c) in curves.iter().enumerate() {
        let col = colour(i);
        let series = chart.draw_series(LineSeries::new(c.points.iter().copied(), col.stroke_width(2)))?;
        if labels {
            series
                .label(c.method.name())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], col.stroke_width(2)));
        }
        chart.draw_series(c.points.iter().map(|&p| Circle::new(p, 4, col.filled())))?;
    }
    if labels {
        chart.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw()?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::curve;

    #[test]
    fn png_charts_carry_their_text() {
        let curves = [curve(&[(0.5, 0.2), (2.0, 0.05), (8.0, 0.01)])];
        let with = chart_pixels(&curves, Some("Cornell box: relMSE against time")).unwrap();
        let without = chart_pixels(&curves, None).unwrap();
        // Dark pixels (the text is black) in the title band above the plot and in the axis-label band below it,
        // away from the frame's sides: the same chart drawn without its text has none there (its grid is grey,
        // its line blue, its frame on the band's edges).
        let (w, h) = (CHART_SIZE.0 as usize, CHART_SIZE.1 as usize);
        let dark = |buf: &[u8], rows: std::ops::Range<usize>| {
            rows.flat_map(|y| (200..600).map(move |x| 3 * (y * w + x)))
                .filter(|&i| buf[i..i + 3].iter().all(|&c| c < 100))
                .count()
        };
        for band in [22..45, h - 45..h - 22] {
            assert_eq!(dark(&without, band.clone()), 0, "{band:?}");
            assert!(dark(&with, band.clone()) > 100, "{band:?}: {} dark pixels", dark(&with, band.clone()));
        }
    }
}
