//! How workers get the photon maps (`--photon-maps ship|trace|auto`): shipped from the coordinator or traced by
//! each worker from the deterministic photon streams, the image is the same, bit for bit; the summary says
//! which way was used, and the end table shows who traced what.

#![allow(clippy::unwrap_used)]

use photon_core::image_io::Image;
use photon_tests::{WorkerProcess, coordinator, run_with_timeout, scenes_dir, temp_dir};
use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

const LIMIT: Duration = Duration::from_secs(240);
const PATHS: u64 = 30_000;

fn render(out: &Path, method: &str, extra: &[&str]) -> Output {
    let mut cmd = Command::new(coordinator());
    cmd.arg("render").arg(scenes_dir().join("cornell.toml")).arg("-o").arg(out).arg("-q").arg("--no-cache");
    cmd.args(["--size", "48x40", "--spp", "1", "--integrator", method, "--photons", &PATHS.to_string()]);
    run_with_timeout(cmd.args(extra), LIMIT)
}

fn text(o: &Output) -> String {
    format!("stdout:\n{}\nstderr:\n{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

fn bits(path: &Path) -> Vec<u32> {
    Image::read(path).unwrap().pixels.iter().map(|v| v.to_bits()).collect()
}

/// A worker's row of the end table: (units it rendered, blob bytes shipped to it, photon paths it traced).
fn row(o: &Output, addr: &str) -> (u64, String, u64) {
    let stdout = String::from_utf8_lossy(&o.stdout);
    let line = stdout.lines().find(|l| l.starts_with(addr)).unwrap_or_else(|| panic!("{}", text(o)));
    // worker, platform (2 words), threads, units, busy s, Mpx/s, shipped (2 words), ship s, load s, photon paths
    let words: Vec<&str> = line.split_whitespace().collect();
    (words[4].parse().unwrap(), format!("{} {}", words[7], words[8]), words[11].parse().unwrap())
}

#[test]
fn shipped_traced_and_chosen_maps_give_the_same_bytes() {
    let dir = temp_dir("map-delivery", "modes");
    // final-gather on the Cornell box reads three maps: global, caustic (glass and mirror) and irradiance.
    for method in ["photon-map", "final-gather"] {
        let in_process = dir.join(format!("{method}-in-process.exr"));
        let o = render(&in_process, method, &[]);
        assert!(o.status.success(), "{}", text(&o));
        let want = bits(&in_process);
        assert!(want.iter().any(|&v| f32::from_bits(v) > 0.0), "{method}: a black image");
        for mode in ["ship", "trace", "auto"] {
            // Fresh workers for each mode: a worker keeps the maps it traced for the next render of the job.
            let ws: Vec<WorkerProcess> = (0..2).map(|_| WorkerProcess::start(&["--threads", "1"])).collect();
            let list = format!("{},{}", ws[0].addr, ws[1].addr);
            let out = dir.join(format!("{method}-{mode}.exr"));
            let o = render(&out, method, &["--workers", &list, "--photon-maps", mode]);
            assert!(o.status.success(), "{method} {mode}: {}", text(&o));
            assert!(bits(&out) == want, "{method}: --photon-maps {mode} changed pixels");
            let summary = String::from_utf8_lossy(&o.stdout);
            let traced = summary.contains("photon maps traced by each worker");
            match mode {
                "ship" => assert!(summary.contains("traced here and shipped (--photon-maps)"), "{}", text(&o)),
                "trace" => assert!(traced && summary.contains("(--photon-maps)"), "{}", text(&o)),
                // Auto names the model's two estimates, whichever it chose.
                _ => assert!(summary.contains("(modelled ") && summary.contains(" s shipped)"), "{}", text(&o)),
            }
            // Tracing workers trace every path of the maps themselves, once each, when they render anything (a
            // worker the others outran before its first strip traces nothing), and are shipped no photons.
            let caustic = u64::from(method == "final-gather");
            let mut tracers = 0;
            for w in &ws {
                let (units, shipped, paths) = row(&o, &w.addr);
                if traced {
                    let want = if units > 0 { PATHS * (1 + caustic) } else { 0 };
                    assert_eq!(paths, want, "{method} {mode}: {}", text(&o));
                    tracers += usize::from(units > 0);
                    assert!(shipped.ends_with(" B") || shipped.ends_with("KiB"), "{method} {mode}: {shipped}");
                } else {
                    assert_eq!(paths, 0, "{method} {mode}: {}", text(&o));
                    assert!(shipped.ends_with("MiB"), "{method} {mode}: {shipped}");
                }
            }
            assert!(!traced || tracers >= 1, "{method} {mode}: nobody traced: {}", text(&o));
            if traced {
                // Rendered again on the same workers, the job's maps are still held: nothing is traced again.
                let first = o;
                let o = render(&out, method, &["--workers", &list, "--photon-maps", mode]);
                assert!(o.status.success() && bits(&out) == want, "{method} {mode} again: {}", text(&o));
                // (A worker that rendered nothing the first time may trace now, for its first strip.)
                let first_units: Vec<u64> = ws.iter().map(|w| row(&first, &w.addr).0).collect();
                for (w, before) in ws.iter().zip(first_units) {
                    let (_, _, paths) = row(&o, &w.addr);
                    assert!(paths == 0 || before == 0, "{method} {mode} again: {}", text(&o));
                }
            }
        }
    }
}

#[test]
fn a_worker_refuses_maps_sent_both_ways_or_for_a_method_without_maps() {
    use photon_proto::pb;
    use photon_proto::pb::render_client::RenderClient;
    let rt = tokio::runtime::Runtime::new().unwrap();
    let w = WorkerProcess::start(&["--threads", "1"]);
    let scene_path = scenes_dir().join("cornell.toml");
    let scene = photon_core::scene::Scene::load(&scene_path).unwrap();
    let prep = photon_core::prepare::Prepared::new(&scene, &scene_path).unwrap();
    let blob = prep.encode_scene().unwrap();
    let id = photon_proto::blob_id(&blob);
    let frame_of = |method: photon_core::scene::Integrator| {
        let mut settings = prep.settings.clone();
        settings.integrator = method;
        photon_core::prepare::Prepared::encode_frame_of(&prep.camera, &settings).unwrap()
    };
    rt.block_on(async {
        let mut c = RenderClient::connect(format!("http://{}", w.addr)).await.unwrap();
        let header = pb::BlobHeader { id: id.clone(), size: blob.len() as u64 };
        let chunks = vec![pb::BlobChunk { header: Some(header), data: blob.clone() }];
        c.put_blob(tokio_stream::iter(chunks)).await.unwrap();
        let request = |frame, photons_blob: &str, trace_photons| pb::StripRequest {
            scene_blob: id.clone(),
            photons_blob: photons_blob.to_owned(),
            frame,
            row_start: 0,
            row_end: 1,
            trace_photons,
            ..Default::default()
        };
        let photon_map = frame_of(photon_core::scene::Integrator::PhotonMap);
        let cases = [
            (request(photon_map.clone(), &id, true), "trace_photons"),
            (request(frame_of(photon_core::scene::Integrator::Path), "", true), "needs no photon maps"),
            (request(photon_map.clone(), "", false), "needs photon maps"),
        ];
        for (r, needle) in cases {
            let e = c.render_strip(r).await.err().unwrap_or_else(|| panic!("accepted: {needle}"));
            assert_eq!(e.code(), tonic::Code::InvalidArgument, "{e:?}");
            assert!(e.message().contains(needle), "{e:?}");
        }
        // Asked to trace, it renders the strip from the scene blob alone.
        let mut stream = c.render_strip(request(photon_map, "", true)).await.unwrap().into_inner();
        let mut done = None;
        while let Some(event) = stream.message().await.unwrap() {
            if let Some(pb::strip_event::Event::Done(s)) = event.event {
                done = Some(s);
            }
        }
        let done = done.unwrap();
        assert_eq!(done.photon_paths, u64::from(prep.settings.photons.global), "{done:?}");
    });
}
