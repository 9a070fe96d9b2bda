//! Speed against accuracy: render a scene with each method at growing budgets, measure every image against a
//! reference, and summarise the curves of relative MSE against wall time.
//!
//! The pieces here are the ones worth testing without a renderer: how a budget multiplier becomes a method's
//! setting ([`budget`], as `--set` pairs through [`crate::cli::overrides`]), how a reference method is chosen ([`choose_reference`]), log-log interpolation
//! for the equal-time and equal-error tables ([`error_at`], [`time_to`], [`summaries`]), the CSV, the chart
//! ([`draw_charts`]), each method's image and error map ([`write_images`]) and the HTML page that shows them all
//! ([`Report`]). Renders go through the workers, as `render`'s do ([`render_timed`]).

use crate::cli::overrides::Setting;
use anyhow::{Context, Result};
use photon_core::image_io::Image;
use photon_core::light::Light;
use photon_core::material::Material;
use photon_core::method::{BudgetSetting, Method};
use photon_core::metrics;
use photon_core::prepare::Prepared;
use photon_core::scene::Scene;
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

/// Samples per pixel of `path` and `direct` at budget 1.
pub const BASE_SPP: u32 = 4;
/// Global photon paths of `photon-map` and global and caustic photon paths of `final-gather` at budget 1.
pub const BASE_PHOTONS: u32 = 25_000;
/// Passes of `progressive`, `vcm`, `bdpt` and `lt` at budget 1.
pub const BASE_PASSES: u32 = 4;
/// Samples per pixel of the photon-map methods, fixed across budgets: they only anti-alias the first hit, so the
/// budget grows the photon count alone.
pub const PHOTON_METHOD_SPP: u32 = 2;

/// The method a reference is rendered with, and why.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ReferenceChoice {
    /// `path` or `progressive`.
    pub integrator: Method,
    /// One sentence for the user.
    pub reason: String,
}

/// The path tracer, unless the scene has a point light and a mirror or glass material: light from a point
/// through a delta surface onto a diffuse one (a point-light caustic) is a path that a camera path can only
/// complete by hitting the point, which has probability zero, so the path tracer converges to an image without
/// the caustic. Progressive photon mapping is consistent for those paths.
pub fn choose_reference(prep: &Prepared) -> ReferenceChoice {
    let point = prep.lights.lights.iter().any(|l| matches!(l, Light::Point { .. }));
    let specular = prep.materials.iter().any(Material::has_specular);
    if point && specular {
        ReferenceChoice {
            integrator: Method::Progressive,
            reason: "the scene has a point light and a mirror or glass material: the caustics it casts are paths \
                     a path tracer can never complete, so progressive photon mapping (consistent) renders the \
                     reference"
                .into(),
        }
    } else {
        let why = if point { "no mirror or glass material" } else { "no point light" };
        ReferenceChoice {
            integrator: Method::Path,
            reason: format!(
                "{why}: every light path can be found from the camera, so the unbiased path tracer renders the reference"
            ),
        }
    }
}

/// What a budget multiplier set: the setting's name and value, for the CSV.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Budget {
    /// The setting that grows with the budget: `spp`, `photons` or `passes`.
    pub parameter: &'static str,
    /// Its value.
    pub value: u64,
}

/// The settings that render with `method` at budget multiplier `b`: `path`/`direct` at `BASE_SPP·b` spp,
/// `photon-map` with `BASE_PHOTONS·b` global photons (k unchanged), `final-gather` with `BASE_PHOTONS·b` global
/// and caustic photons, `progressive`, `vcm`, `bdpt` and `lt` with `BASE_PASSES·b` passes. The photon-map
/// methods render [`PHOTON_METHOD_SPP`] samples per pixel at every budget. Fails when a value overflows `u32`.
pub fn budget(method: Method, b: u32) -> Result<(Vec<Setting>, Budget)> {
    let times = |base: u32| base.checked_mul(b).with_context(|| format!("budget {b} × {base} overflows for {method}"));
    let grown = |parameter, value: u32| Budget { parameter, value: u64::from(value) };
    let (settings, budget) = match method.budget_setting() {
        BudgetSetting::Spp => {
            let spp = times(BASE_SPP)?;
            (vec![Setting::Spp(spp)], grown("spp", spp))
        }
        BudgetSetting::Photons { caustic } => {
            let n = times(BASE_PHOTONS)?;
            let mut settings = vec![Setting::Spp(PHOTON_METHOD_SPP), Setting::GlobalPhotons(n)];
            if caustic {
                settings.push(Setting::CausticPhotons(n));
            }
            (settings, grown("photons", n))
        }
        BudgetSetting::Passes => {
            let passes = times(BASE_PASSES)?;
            (vec![Setting::Passes(passes)], grown("passes", passes))
        }
    };
    Ok(([vec![Setting::Integrator(method)], settings].concat(), budget))
}

/// An image and the wall time it took.
#[derive(Clone, Debug)]
pub struct Timed {
    /// The linear image.
    pub image: Image,
    /// Seconds to prepare (meshes, BVH, photon maps).
    pub prepare_s: f64,
    /// Seconds to render the pixels.
    pub render_s: f64,
    /// The relative MSE the render estimated of itself without a reference ([`crate::farm::bounded`]): every method
    /// but `photon-map` and `final-gather`.
    pub estimated_rel_mse: Option<f64>,
}

/// Prepares `scene` here (no prepared-blob cache: its time is part of the method's cost) and renders it on the
/// workers at `addrs`, as `render` does. The render time runs from the first connection to the last strip, so it
/// includes shipping the blobs (workers that already hold them are sent nothing).
///
/// Every method but `photon-map` and `final-gather` renders its samples (passes) in rounds of whole-image blocks
/// that estimate their own error ([`crate::farm::bounded`]); the image is the same, bit for bit, as in strips.
pub async fn render_timed(
    scene: &Scene,
    scene_path: &Path,
    addrs: &[crate::fleet::session::WorkerAddr],
    mut options: crate::farm::Options,
) -> Result<Timed> {
    let t0 = Instant::now();
    let prep = Prepared::new(scene, scene_path)?.with_photon_maps(scene_path)?;
    let (width, height) = (prep.camera.width, prep.camera.height);
    let (scene_blob, photons, frame) = (prep.encode_scene()?, prep.encode_photons()?, prep.encode_frame()?);
    let textures = prep.encode_textures()?;
    let mut job = crate::job::Job::new(scene_blob, photons, textures, frame, (width, height), &prep.settings);
    let r = &prep.settings;
    // The methods whose error more units lower estimate it; vcm's merge radius shrinks with α as progressive
    // photon mapping's gather radius does (both biased), bdpt, lt and the path tracer are unbiased.
    let estimated =
        r.integrator.error_falls_with_units().then(|| (r.units(), r.integrator.bias_alpha(r.photons.alpha)));
    if let Some((passes, bias_alpha)) = estimated {
        job.passes = Some(passes.max(1));
        let passes = Some(passes.max(1));
        options.bound = Some(crate::farm::bounded::Bound {
            deadline: None,
            target_error: None,
            bias_alpha,
            passes,
            estimate: true,
        });
    }
    drop(prep);
    let prepare_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let outcome = crate::farm::render(&job, addrs, options).await?;
    let render_s = t1.elapsed().as_secs_f64();
    // A render in rounds that stopped short (no worker left, a signal) must not pass for its budget.
    if let (Some(b), Some((passes, _))) = (&outcome.bounded, estimated)
        && (b.reason != crate::farm::bounded::StopReason::Cap || b.passes != passes.max(1))
    {
        anyhow::bail!("the render stopped {} after {} of its {} passes (samples)", b.reason, b.passes, passes.max(1));
    }
    let estimated_rel_mse = outcome.bounded.and_then(|b| b.rel_mse_estimate);
    Ok(Timed { image: Image { width, height, pixels: outcome.pixels }, prepare_s, render_s, estimated_rel_mse })
}

/// One measured render of the sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// The method.
    pub method: Method,
    /// The budget multiplier.
    pub budget: u32,
    /// What the multiplier set.
    pub setting: Budget,
    /// Wall seconds, prepare plus render.
    pub seconds: f64,
    /// RMSE against the reference.
    pub rmse: f64,
    /// Relative MSE against the reference.
    pub rel_mse: f64,
    /// The relative MSE the render estimated without the reference, for the methods that estimate it.
    pub estimated_rel_mse: Option<f64>,
}

/// The CSV header of [`csv`].
pub const CSV_HEADER: &str = "method,budget,parameter,value,seconds,rmse,rel_mse,estimated_rel_mse";

/// The rows as CSV with a header line.
pub fn csv(rows: &[Row]) -> String {
    let mut s = format!("{CSV_HEADER}\n");
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{:.6},{:.6e},{:.6e},{}",
            r.method,
            r.budget,
            r.setting.parameter,
            r.setting.value,
            r.seconds,
            r.rmse,
            r.rel_mse,
            r.estimated_rel_mse.map(|e| format!("{e:.6e}")).unwrap_or_default()
        );
    }
    s
}

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

/// Four significant digits, in scientific notation outside [0.001, 10 000).
pub fn sig(x: f64) -> String {
    let a = x.abs();
    if x == 0.0 || !x.is_finite() {
        format!("{x}")
    } else if (1e-3..1e4).contains(&a) {
        let decimals = (3 - a.log10().floor() as i32).max(0) as usize;
        format!("{x:.decimals$}")
    } else {
        format!("{x:.3e}")
    }
}

/// A table of the methods against a few columns: the equal-time and equal-error summaries, printed as Markdown
/// ([`Table::markdown`]) and shown in the report as HTML ([`Table::html`]).
#[derive(Clone, Debug, PartialEq)]
pub enum Table {
    /// Headings and one row of cells per method.
    Cells {
        /// `method`, then one heading per column.
        head: Vec<String>,
        /// Per method its name, then its cells.
        rows: Vec<Vec<String>>,
    },
    /// Why there is nothing to compare.
    Empty(&'static str),
}

impl Table {
    /// The methods of `curves` against `columns`, cells from `cell` (the curve and the column's index).
    fn new(curves: &[Curve], columns: Vec<String>, cell: impl Fn(&Curve, usize) -> String) -> Table {
        let rows = curves
            .iter()
            .map(|c| {
                std::iter::once(c.method.name().to_owned()).chain((0..columns.len()).map(|i| cell(c, i))).collect()
            })
            .collect();
        Table::Cells { head: [vec!["method".to_owned()], columns].concat(), rows }
    }

    /// The table in Markdown (numbers right-aligned), or its reason in parentheses.
    pub fn markdown(&self) -> String {
        match self {
            Table::Empty(why) => format!("({why})\n"),
            Table::Cells { head, rows } => {
                let line = |cells: &[String]| format!("| {} |\n", cells.join(" | "));
                let rule = format!("|---|{}\n", "---:|".repeat(head.len().saturating_sub(1)));
                [line(head), rule].into_iter().chain(rows.iter().map(|r| line(r))).collect()
            }
        }
    }

    /// The table as an HTML `<table>`, or its reason as a `<p class="note">`; every text escaped.
    pub fn html(&self) -> String {
        match self {
            Table::Empty(why) => format!("<p class=\"note\">{}</p>\n", escape(why)),
            Table::Cells { head, rows } => {
                let line = |tag: &str, cells: &[String]| {
                    let cells: String = cells.iter().map(|c| format!("<{tag}>{}</{tag}>", escape(c))).collect();
                    format!("<tr>{cells}</tr>\n")
                };
                let body: String = rows.iter().map(|r| line("td", r)).collect();
                format!("<table>\n{}{body}</table>\n", line("th", head))
            }
        }
    }
}

/// The equal-time table: each method's relMSE at times inside every method's range.
pub fn equal_time(curves: &[Curve]) -> Table {
    let times = common_times(curves, 4);
    if times.is_empty() {
        return Table::Empty("no time lies inside every method's measured range: widen --budget");
    }
    let columns = times.iter().map(|t| format!("relMSE at {} s", sig(*t))).collect();
    Table::new(curves, columns, |c, i| error_at(c, times[i]).map_or_else(|| "—".into(), sig))
}

/// The equal-error table: seconds each method needs to reach a few relMSE levels.
pub fn equal_error(curves: &[Curve]) -> Table {
    let levels = error_levels(curves, 4);
    if levels.is_empty() {
        return Table::Empty("all errors are equal: no levels to compare");
    }
    let columns = levels.iter().map(|e| format!("s to relMSE {}", sig(*e))).collect();
    Table::new(curves, columns, |c, i| time_to(c, levels[i]).map_or_else(|| "—".into(), sig))
}

/// The summaries of a sweep, each with its heading: [`equal_time`] and [`equal_error`].
pub fn summaries(curves: &[Curve]) -> [(&'static str, Table); 2] {
    [
        ("equal time (relMSE, log-log interpolation)", equal_time(curves)),
        ("equal error (seconds, log-log interpolation; — out of the measured range)", equal_error(curves)),
    ]
}

/// The reference, tone-mapped, in the sweep's folder.
pub const REFERENCE_PNG: &str = "reference.png";
/// The report page in the sweep's folder ([`Report::html`]).
pub const REPORT_HTML: &str = "report.html";

/// The files, in the sweep's folder, of `method`'s image at its largest budget and of its error map:
/// `METHOD.png` and `METHOD-error.png`.
pub fn image_files(method: Method) -> [String; 2] {
    [format!("{}.png", method.name()), format!("{}-error.png", method.name())]
}

/// Writes `image`, rendered with `method`, into `dir` under the names of [`image_files`]: tone-mapped with
/// `exposure` as `render` writes a PNG, and the false-colour map of its relative error against `reference`
/// ([`metrics::error_image`], as `compare --error-image` writes it).
pub fn write_images(dir: &Path, method: Method, image: &Image, reference: &Image, exposure: f32) -> Result<()> {
    let [picture, error] = image_files(method).map(|name| dir.join(name));
    let map = metrics::error_image(image, reference)
        .with_context(|| format!("mapping the error of {} against the reference", picture.display()))?;
    image.write(&picture, exposure)?;
    map.write(&error, 0.0)?;
    Ok(())
}

/// Each method's row at its largest budget, in the order the methods first appear.
pub fn largest_budgets(rows: &[Row]) -> Vec<&Row> {
    let mut out: Vec<&Row> = Vec::new();
    for r in rows {
        match out.iter_mut().find(|o| o.method == r.method) {
            Some(o) if o.budget < r.budget => *o = r,
            Some(_) => {}
            None => out.push(r),
        }
    }
    out
}

/// `text` safe inside HTML text and quoted attribute values: `&`, `<`, `>`, `"` and `'` as character references.
pub fn escape(text: &str) -> String {
    let mut s = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => s.push_str("&amp;"),
            '<' => s.push_str("&lt;"),
            '>' => s.push_str("&gt;"),
            '"' => s.push_str("&quot;"),
            '\'' => s.push_str("&#39;"),
            c => s.push(c),
        }
    }
    s
}

/// A sweep as one HTML page ([`Report::html`]), beside its charts and images.
#[derive(Clone, Copy, Debug)]
pub struct Report<'a> {
    /// The scene file, as given.
    pub scene: &'a Path,
    /// The reference image, as given.
    pub reference: &'a Path,
    /// Width and height of every image.
    pub size: (u32, u32),
    /// This machine's threads.
    pub threads: usize,
    /// The `--set` pairs of every render.
    pub set: &'a [String],
    /// The measured renders, in the order they ran.
    pub rows: &'a [Row],
}

/// The style of the report page.
const REPORT_CSS: &str = "body { font-family: sans-serif; margin: 2em; color: #222; max-width: 70em; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; }
th, td { border: 1px solid #bbb; padding: 0.2em 0.6em; }
td + td { text-align: right; font-variant-numeric: tabular-nums; }
.note { font-style: italic; }
.grid { display: flex; flex-wrap: wrap; gap: 1.5em; align-items: flex-start; }
figure { margin: 0; }
figure img { display: block; max-width: 100%; height: auto; image-rendering: pixelated; margin-bottom: 0.3em; }
figcaption { font-size: 0.9em; line-height: 1.4; }";

impl Report<'_> {
    /// The page: a title with the scene and size; the settings (reference, methods, budgets, `--set` pairs,
    /// threads; no date, so the same sweep gives the same page but for its measured times); the chart
    /// (`sweep.png`, linking `sweep.svg` and `sweep.csv`); the [`summaries`] as tables; the reference and each
    /// method's image at its largest budget ([`largest_budgets`]) over its error map ([`image_files`]). Inline CSS,
    /// no script, every image a file beside the page; all text from paths and settings is escaped.
    pub fn html(&self) -> String {
        let (w, h) = self.size;
        let scene = escape(&self.scene.display().to_string());
        let title = format!("Sweep of {scene} at {w}×{h}");
        let mut s = format!(
            "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{title}</title>\n\
             <style>\n{REPORT_CSS}\n</style>\n</head>\n<body>\n<h1>{title}</h1>\n<ul>\n"
        );
        let mut methods: Vec<&str> = self.rows.iter().map(|r| r.method.name()).collect();
        methods.dedup();
        let mut budgets: Vec<u32> = self.rows.iter().map(|r| r.budget).collect();
        budgets.sort_unstable();
        budgets.dedup();
        let budgets: Vec<String> = budgets.iter().map(u32::to_string).collect();
        let set = if self.set.is_empty() { "none".to_owned() } else { self.set.join(", ") };
        let settings = [
            ("reference", self.reference.display().to_string()),
            ("methods", methods.join(", ")),
            ("budget multipliers", budgets.join(", ")),
            ("settings (--set)", set),
            ("threads on this machine", self.threads.to_string()),
        ];
        for (label, value) in settings {
            let _ = writeln!(s, "<li>{label}: {}</li>", escape(&value));
        }
        s.push_str(
            "</ul>\n<h2>Relative MSE against wall time</h2>\n<p><img src=\"sweep.png\" alt=\"relative MSE against \
             wall seconds, one line per method\"></p>\n<p><a href=\"sweep.svg\">the chart as SVG</a> · \
             <a href=\"sweep.csv\">the measurements as CSV</a></p>\n",
        );
        for (heading, table) in summaries(&curves(self.rows)) {
            let _ = write!(s, "<h2>{}</h2>\n{}", escape(heading), table.html());
        }
        let _ = write!(
            s,
            "<h2>Images at each method's largest budget</h2>\n<p>Under each image, its relative error per pixel, \
             |x − r| / (|r| + {}) averaged over the channels: black is 0, pale yellow 1 or more.</p>\n\
             <div class=\"grid\">\n",
            metrics::EPSILON
        );
        // Small images are shown enlarged to about 256 pixels wide, by a whole factor (crisp pixels).
        let zoom = (256 / w.max(1)).max(1);
        let img = |file: &str| {
            let file = escape(file);
            format!("<img src=\"{file}\" alt=\"{file}\" width=\"{}\" height=\"{}\">", w * zoom, h * zoom)
        };
        let reference = escape(&self.reference.display().to_string());
        let _ = writeln!(s, "<figure>{}<figcaption>reference<br>{reference}</figcaption></figure>", img(REFERENCE_PNG));
        for r in largest_budgets(self.rows) {
            let [picture, error] = image_files(r.method);
            let _ = writeln!(
                s,
                "<figure>{}{}<figcaption>{}, budget {} ({} {})<br>{} s, relMSE {}{}</figcaption></figure>",
                img(&picture),
                img(&error),
                escape(r.method.name()),
                r.budget,
                r.setting.parameter,
                r.setting.value,
                sig(r.seconds),
                sig(r.rel_mse),
                r.estimated_rel_mse.map(|e| format!(" (estimated {})", sig(e))).unwrap_or_default()
            );
        }
        s.push_str("</div>\n</body>\n</html>\n");
        s
    }
}

/// Draws relMSE against seconds on log-log axes, one line per method, to `svg` and `png`, each with a title, axis
/// labels, tick labels and a legend. The PNG's text is rasterised with DejaVu Sans, built into the binary
/// (`coordinator/assets/`, its licence beside it), so no system font is needed.
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
        // DejaVu Sans (Bitstream Vera licence: coordinator/assets/DejaVuSans-LICENSE.txt).
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
    use photon_core::scene::RenderSettings;

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

    fn curve(points: &[(f64, f64)]) -> Curve {
        Curve { method: Method::Path, points: points.to_vec() }
    }

    /// A scene file with default render settings, loaded with the pairs of `method` at budget `b`.
    fn with_budget(dir: &Path, method: Method, b: u32) -> (RenderSettings, Budget) {
        let text = "[camera]\neye = [0.0, 1.0, 3.0]\nlook_at = [0.0, 1.0, 0.0]\nwidth = 8\nheight = 8\n\
                    [materials.white]\ntype = \"lambert\"\n\
                    [[objects]]\ntype = \"sphere\"\ncenter = [0.0, 1.0, 0.0]\nradius = 0.5\nmaterial = \"white\"\n\
                    [[lights]]\ntype = \"point\"\nposition = [0.0, 2.0, 0.0]\npower = [10.0, 10.0, 10.0]\n";
        std::fs::write(dir.join("s.toml"), text).unwrap();
        let (settings, budget) = super::budget(method, b).unwrap();
        let scene = Scene::load_with(&dir.join("s.toml"), &crate::cli::overrides::pairs(&[], &settings)).unwrap();
        (scene.render, budget)
    }

    #[test]
    fn budgets_grow_the_right_setting() {
        let dir = std::env::temp_dir().join(format!("photon-sweep-budget-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let k = RenderSettings::default().photons.k;
        let (s, b) = with_budget(&dir, Method::Path, 8);
        assert_eq!(b, Budget { parameter: "spp", value: 32 });
        assert_eq!(s.spp, 32);
        let (s, b) = with_budget(&dir, Method::PhotonMap, 4);
        assert_eq!((b.value, s.photons.global, s.photons.k, s.spp), (100_000, 100_000, k, PHOTON_METHOD_SPP));
        let (s, _) = with_budget(&dir, Method::FinalGather, 2);
        assert_eq!((s.photons.global, s.photons.caustic), (50_000, 50_000));
        let (s, b) = with_budget(&dir, Method::Progressive, 16);
        assert_eq!((b.value, s.photons.passes), (64, 64));
        assert_eq!(s.integrator, Method::Progressive);
        for method in [Method::Vcm, Method::Bdpt, Method::Lt] {
            let (s, b) = with_budget(&dir, method, 2);
            assert_eq!(b, Budget { parameter: "passes", value: 8 }, "{method}");
            assert_eq!((s.integrator, s.photons.passes), (method, 8));
        }
        assert!(super::budget(Method::Path, u32::MAX).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }

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

    #[test]
    fn equal_time_uses_only_the_common_range() {
        let a = curve(&[(1.0, 1.0), (10.0, 0.1)]);
        let b = curve(&[(2.0, 0.5), (20.0, 0.05)]);
        let t = common_times(&[a.clone(), b.clone()], 3);
        assert_eq!(t.len(), 3);
        assert!((t[0] - 2.0).abs() < 1e-12 && (t[2] - 10.0).abs() < 1e-9);
        assert!(common_times(&[a, curve(&[(11.0, 1.0), (12.0, 0.5)])], 3).is_empty());
        let table = equal_time(&[b]).markdown();
        assert_eq!(table.lines().count(), 3, "{table}");
    }

    #[test]
    fn csv_has_a_row_per_render() {
        let row = Row {
            method: Method::Progressive,
            budget: 2,
            setting: Budget { parameter: "passes", value: 8 },
            seconds: 1.5,
            rmse: 0.25,
            rel_mse: 0.125,
            estimated_rel_mse: Some(0.1),
        };
        let s = csv(&[row.clone(), row]);
        let lines: Vec<&str> = s.lines().collect();
        assert_eq!(lines[0], CSV_HEADER);
        assert_eq!(lines.len(), 3);
        assert!(lines[1].starts_with("progressive,2,passes,8,1.5"), "{}", lines[1]);
        assert!(lines[1].ends_with(",1.000000e-1"), "{}", lines[1]);
    }

    fn row(method: Method, budget: u32, seconds: f64, rel_mse: f64) -> Row {
        let setting = Budget { parameter: "spp", value: u64::from(4 * budget) };
        Row { method, budget, setting, seconds, rmse: rel_mse.sqrt(), rel_mse, estimated_rel_mse: None }
    }

    /// Two methods whose time ranges overlap, so that both summaries have columns; progressive's rows out of
    /// budget order.
    fn two_methods() -> Vec<Row> {
        vec![
            row(Method::Path, 1, 1.0, 0.1),
            row(Method::Path, 4, 4.0, 0.025),
            row(Method::Progressive, 4, 8.0, 0.01),
            row(Method::Progressive, 1, 2.0, 0.08),
        ]
    }

    #[test]
    fn the_largest_budget_is_found_whatever_the_order() {
        let rows = two_methods();
        let top: Vec<(Method, u32)> = largest_budgets(&rows).iter().map(|r| (r.method, r.budget)).collect();
        assert_eq!(top, [(Method::Path, 4), (Method::Progressive, 4)]);
    }

    #[test]
    fn html_tables_hold_the_cells_of_the_printed_ones() {
        for (heading, table) in summaries(&curves(&two_methods())) {
            let (md, html) = (table.markdown(), table.html());
            assert_eq!(html.matches("<table>").count(), 1, "{heading}: {html}");
            // Every cell of the Markdown table, headings and the method column included, is a cell of the HTML.
            let cells: Vec<&str> =
                md.lines().filter(|l| !l.starts_with("|---")).flat_map(|l| l.split('|')).map(str::trim).collect();
            let cells: Vec<&str> = cells.into_iter().filter(|c| !c.is_empty()).collect();
            assert_eq!(cells.len(), 3 * 5, "{heading}: {md}");
            for c in cells {
                assert!(html.contains(&format!(">{}</t", escape(c))), "{heading}: {c} missing from {html}");
            }
        }
        let empty = equal_time(&[curve(&[(1.0, 1.0), (2.0, 0.5)]), curve(&[(3.0, 1.0), (4.0, 0.5)])]);
        assert!(empty.markdown().starts_with("(no time"), "{}", empty.markdown());
        assert!(empty.html().starts_with("<p class=\"note\">no time") && !empty.html().contains("<table>"));
    }

    #[test]
    fn the_report_escapes_text_from_file_names() {
        let rows = two_methods();
        let set = ["camera.fov=<30>".to_owned()];
        let report = Report {
            scene: Path::new("scenes/<script>alert('x')</script>.toml"),
            reference: Path::new("refs/a&b\".exr"),
            size: (12, 8),
            threads: 2,
            set: &set,
            rows: &rows,
        };
        let html = report.html();
        assert!(!html.contains("<script") && !html.contains("alert('x')"), "{html}");
        assert!(html.contains("<title>Sweep of scenes/&lt;script&gt;alert(&#39;x&#39;)&lt;/script&gt;.toml at 12×8"));
        assert!(html.contains("refs/a&amp;b&quot;.exr") && html.contains("camera.fov=&lt;30&gt;"), "{html}");
        assert!(html.contains("<li>threads on this machine: 2</li>"), "{html}");
        assert_eq!(html.matches("<table>").count(), 2, "{html}");
        assert!(html.contains("<img src=\"sweep.png\"") && html.contains("href=\"sweep.svg\""), "{html}");
        // The reference first, then each method's image over its error map, at the largest budget; 12 pixels
        // wide shows 21 times larger.
        let srcs: Vec<&str> = html.split("<img src=\"").skip(2).filter_map(|s| s.split('"').next()).collect();
        assert_eq!(srcs, [REFERENCE_PNG, "path.png", "path-error.png", "progressive.png", "progressive-error.png"]);
        assert!(html.contains("width=\"252\" height=\"168\""), "{html}");
        assert!(html.contains("progressive, budget 4 (spp 16)<br>8.000 s, relMSE 0.01000"), "{html}");
        assert!(!html.contains("budget 1 "), "{html}");
    }

    #[test]
    fn images_and_error_maps_are_written_as_pngs() {
        let dir = std::env::temp_dir().join(format!("photon-sweep-images-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let reference = Image { width: 4, height: 3, pixels: (0..36).map(|i| i as f32 / 36.0).collect() };
        let mut image = reference.clone();
        image.pixels[5] += 0.3;
        write_images(&dir, Method::FinalGather, &image, &reference, 1.0).unwrap();
        let [picture, error] = image_files(Method::FinalGather);
        assert_eq!((picture.as_str(), error.as_str()), ("final-gather.png", "final-gather-error.png"));
        let read = |name: &str| image::open(dir.join(name)).unwrap().into_rgb8();
        let png = read(&picture);
        assert_eq!((png.width(), png.height(), png.into_raw()), (4, 3, image.to_srgb8(1.0)));
        let map = read(&error);
        assert_eq!(map.into_raw(), metrics::error_image(&image, &reference).unwrap().to_srgb8(0.0));
        let small = Image::new(2, 2);
        let e = write_images(&dir, Method::Path, &small, &reference, 0.0).unwrap_err();
        assert!(format!("{e:#}").contains("path.png") && format!("{e:#}").contains("2x2"), "{e:#}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
