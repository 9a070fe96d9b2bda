//! The files of a sweep's folder besides the CSV and the charts: the reference and each method's image at its largest
//! budget over its error map ([`write_images`]), and `report.html`, which shows them all ([`Report`]).

use crate::budget::Row;
use crate::curve::curves;
use crate::table::{escape, summaries};
use anyhow::{Context, Result};
use photon_coordinator::out::report::sig;
use photon_core::image_io::Image;
use photon_core::method::Method;
use photon_core::metrics;
use std::fmt::Write as _;
use std::path::Path;

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::two_methods;

    #[test]
    fn the_largest_budget_is_found_whatever_the_order() {
        let rows = two_methods();
        let top: Vec<(Method, u32)> = largest_budgets(&rows).iter().map(|r| (r.method, r.budget)).collect();
        assert_eq!(top, [(Method::Path, 4), (Method::Progressive, 4)]);
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
