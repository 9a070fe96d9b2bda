//! The command line of `photon-sweep` ([`SweepArgs`]) and the sweep it runs ([`run`]).

use crate::budget::{self, Row};
use crate::{chart, curve, report, table};
use anyhow::{Context, Result, bail};
use clap::Parser;
use photon_coordinator::cli::overrides::{self, Setting};
use photon_coordinator::cli::{FarmArgs, Resolved, commands};
use photon_coordinator::farm;
use photon_coordinator::fleet::{self, session::WorkerAddr};
use photon_coordinator::measure;
use photon_coordinator::out::report::sig;
use photon_core::image_io::Image;
use photon_core::method::Method;
use photon_core::metrics;
use photon_core::scene::Scene;
use std::path::PathBuf;

/// Render a scene with several methods at growing budgets, measure each image against a reference, and write
/// sweep.csv, sweep.svg and sweep.png with equal-time and equal-error tables, each method's image at its largest
/// budget with its error map, and report.html showing them all. Renders run one after another on workers as
/// `photon-coordinator render`'s do (in-process by default; `--workers`, `--hosts` or `--local` for others).
#[derive(Parser, Debug)]
#[command(name = "photon-sweep", version)]
pub struct SweepArgs {
    /// The scene file (TOML).
    pub scene: PathBuf,
    /// The reference image (EXR), e.g. from `photon-coordinator reference`.
    #[arg(long)]
    pub reference: PathBuf,
    /// Methods, comma-separated: `path`, `direct`, `photon-map`, `final-gather`, `progressive`, `vcm`, `bdpt`,
    /// `lt`.
    #[arg(long, value_delimiter = ',', default_value = "path,photon-map,final-gather,progressive")]
    pub methods: Vec<Method>,
    /// Budget multipliers b, comma-separated: path/direct render 4·b spp; photon-map traces 25 000·b global
    /// photons (k fixed, 2 spp); final-gather 25 000·b global and caustic photons (2 spp); progressive, vcm, bdpt
    /// and lt 4·b passes.
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8")]
    pub budget: Vec<u32>,
    /// Image width and height, e.g. `96x96`; must match the reference (default: the reference's size).
    #[arg(long, value_parser = photon_coordinator::cli::parse_size)]
    pub size: Option<(u32, u32)>,
    /// Folder for sweep.csv, sweep.svg, sweep.png, report.html and its images: reference.png, METHOD.png and
    /// METHOD-error.png (created when missing).
    #[arg(long, default_value = ".")]
    pub out: PathBuf,
    /// Override a scene setting for every render, e.g. `--set render.photons.pass_photons=20000`; repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Where to render: the farm flags of `photon-coordinator render`.
    #[command(flatten)]
    pub farm: FarmArgs,
}

/// Runs a sweep: every (method, budget) rendered and measured, then the CSV, the charts, the printed tables and the
/// report page written into `args.out`.
pub fn run(args: SweepArgs) -> Result<()> {
    if args.methods.is_empty() || args.budget.is_empty() {
        bail!("--methods and --budget need at least one value each");
    }
    if args.budget.contains(&0) {
        bail!("budget multipliers must be at least 1");
    }
    let reference = Image::read(&args.reference).with_context(|| format!("reading {}", args.reference.display()))?;
    let (width, height) = args.size.unwrap_or((reference.width, reference.height));
    if (width, height) != (reference.width, reference.height) {
        bail!(
            "--size {width}x{height} differs from the reference {} ({}x{})",
            args.reference.display(),
            reference.width,
            reference.height
        );
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let base = overrides::pairs(&args.set, &[Setting::Size(width, height)]);
    // Load once before starting workers, so that a broken scene fails at once.
    let exposure = Scene::load_with(&args.scene, &base)?.render.exposure;
    reference.write(&args.out.join(report::REFERENCE_PNG), exposure)?;
    let Resolved { spec, token, tls_ca, policy } = args.farm.resolve()?;
    let rows = commands::runtime()?.block_on(async {
        // One set of workers for the whole sweep: they keep the blobs of repeated scenes and photon maps.
        let fleet = fleet::Fleet::start(&spec).await?;
        let names: Vec<&str> = fleet.addrs.iter().map(|a| a.name.as_str()).collect();
        println!(
            "sweep of {} at {width}x{height} against {}: on {} ({} threads here)",
            args.scene.display(),
            args.reference.display(),
            names.join(", "),
            rayon::current_num_threads()
        );
        let options = farm::Options { token, tls_ca, policy, ..farm::Options::default() };
        let rows = sweep_rows(&args, &base, &reference, &fleet.addrs, options).await;
        fleet.stop().await;
        rows
    })?;
    let csv_path = args.out.join("sweep.csv");
    std::fs::write(&csv_path, budget::csv(&rows)).with_context(|| format!("writing {}", csv_path.display()))?;
    let curves = curve::curves(&rows);
    let name = args.scene.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let title = format!("{name} {width}x{height}: relative MSE against wall time");
    let (svg, png) = (args.out.join("sweep.svg"), args.out.join("sweep.png"));
    chart::draw_charts(&curves, &title, &svg, &png)?;
    println!();
    for (heading, table) in table::summaries(&curves) {
        println!("{heading}:\n{}", table.markdown());
    }
    let report = report::Report {
        scene: &args.scene,
        reference: &args.reference,
        size: (width, height),
        threads: rayon::current_num_threads(),
        set: &args.set,
        rows: &rows,
    };
    let html = args.out.join(report::REPORT_HTML);
    std::fs::write(&html, report.html()).with_context(|| format!("writing {}", html.display()))?;
    println!(
        "wrote {}, {} and {}, and each method's image at its largest budget",
        csv_path.display(),
        svg.display(),
        png.display()
    );
    println!("report: {}", html.display());
    Ok(())
}

/// Renders every (method, budget) of a sweep on the workers at `addrs` and measures it; writes each method's
/// image at the largest budget and its error map into the sweep's folder ([`report::write_images`]).
async fn sweep_rows(
    args: &SweepArgs,
    base: &[String],
    reference: &Image,
    addrs: &[WorkerAddr],
    options: farm::Options,
) -> Result<Vec<Row>> {
    let mut rows = Vec::new();
    let largest = args.budget.iter().copied().max().unwrap_or_default();
    for &method in &args.methods {
        for &b in &args.budget {
            let (settings, setting) = budget::budget(method, b)?;
            let scene = Scene::load_with(&args.scene, &overrides::pairs(base, &settings))?;
            let t = measure::render_timed(&scene, &args.scene, addrs, options.clone())
                .await
                .with_context(|| format!("rendering {method} at budget {b}"))?;
            let m = metrics::compare(&t.image, reference, None)
                .with_context(|| format!("measuring {method} at budget {b} against {}", args.reference.display()))?;
            if b == largest {
                report::write_images(&args.out, method, &t.image, reference, scene.render.exposure)?;
            }
            let row = Row {
                method,
                budget: b,
                setting,
                seconds: t.prepare_s + t.render_s,
                rmse: m.rmse,
                rel_mse: m.rel_mse,
                estimated_rel_mse: t.estimated_rel_mse,
            };
            println!(
                "  {:<13} b={:<4} {:<16} {:>8.3} s  rmse {:<10} relMSE {}{}",
                method.name(),
                b,
                format!("{}={}", row.setting.parameter, row.setting.value),
                row.seconds,
                sig(row.rmse),
                sig(row.rel_mse),
                row.estimated_rel_mse.map(|e| format!(" (estimated {})", sig(e))).unwrap_or_default()
            );
            rows.push(row);
        }
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_methods_in_passes_parse() {
        let sweep = ["photon-sweep", "s.toml", "--reference", "r.exr", "--methods", "vcm,bdpt,lt"];
        let args = SweepArgs::try_parse_from(sweep).unwrap();
        assert_eq!(args.methods, [Method::Vcm, Method::Bdpt, Method::Lt]);
        assert_eq!(args.budget, [1, 2, 4, 8]);
    }
}
