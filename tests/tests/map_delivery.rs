//! How workers get the photon maps (`--photon-maps ship|peers|trace|auto`): shipped from the coordinator,
//! passed among the workers, or traced by each worker from the deterministic photon streams, the image is the
//! same, bit for bit; the summary says which way was used, and the end table shows who traced or sent what.

#![allow(clippy::unwrap_used)]

use photon_core::image_io::Image;
use photon_tests::{WorkerProcess, WorkerRow, coordinator, run_with_timeout, scenes_dir, temp_dir};
use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

const LIMIT: Duration = Duration::from_secs(240);
const PATHS: u64 = 30_000;

fn render(out: &Path, method: &str, extra: &[&str]) -> Output {
    render_spp(out, method, 1, extra)
}

fn render_spp(out: &Path, method: &str, spp: u32, extra: &[&str]) -> Output {
    let mut cmd = Command::new(coordinator());
    cmd.arg("render").arg(scenes_dir().join("cornell.toml")).arg("-o").arg(out).arg("-q").arg("--no-cache");
    cmd.args(["--size", "48x40", "--spp", &spp.to_string(), "--integrator", method]);
    run_with_timeout(cmd.args(["--photons", &PATHS.to_string()]).args(extra), LIMIT)
}

fn text(o: &Output) -> String {
    format!("stdout:\n{}\nstderr:\n{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

fn bits(path: &Path) -> Vec<u32> {
    Image::read(path).unwrap().pixels.iter().map(|v| v.to_bits()).collect()
}

/// A worker's row of the end table.
fn row(o: &Output, addr: &str) -> WorkerRow {
    WorkerRow::find(&String::from_utf8_lossy(&o.stdout), addr)
        .unwrap_or_else(|| panic!("no row for {addr}: {}", text(o)))
}

/// Whether a table's byte count is a megabyte or more (a photons blob), not a scene blob's kilobytes.
fn megabytes(bytes: &str) -> bool {
    bytes.ends_with("MiB")
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
        for mode in ["ship", "peers", "trace", "auto"] {
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
                "peers" => assert!(
                    summary.contains("passed among the workers (--photon-maps)")
                        && summary.contains("passed between workers"),
                    "{}",
                    text(&o)
                ),
                "trace" => assert!(traced && summary.contains("(--photon-maps)"), "{}", text(&o)),
                // Auto names the model's three estimates, whichever it chose.
                _ => assert!(summary.contains("(modelled ") && summary.contains(" s among peers)"), "{}", text(&o)),
            }
            if mode == "peers" {
                // The coordinator uploads the maps to one worker; the other fetches them from it.
                let rows: Vec<WorkerRow> = ws.iter().map(|w| row(&o, &w.addr)).collect();
                let from_here = rows.iter().filter(|r| megabytes(&r.shipped)).count();
                let from_peer = rows.iter().filter(|r| megabytes(&r.from_peers) && !megabytes(&r.shipped)).count();
                assert_eq!((from_here, from_peer), (1, 1), "{}", text(&o));
            }
            // Tracing workers trace every path of the maps themselves, once each, and report it with a finished
            // strip: one that rendered a strip reports them; one the others outran may have traced for a strip
            // that was cancelled (or rendered one whose copy lost) and reports all of them or none. They are
            // shipped no photons.
            let caustic = u64::from(method == "final-gather");
            let mut tracers = 0;
            for w in &ws {
                let WorkerRow { units, shipped, photon_paths: paths, .. } = row(&o, &w.addr);
                if traced {
                    let all = PATHS * (1 + caustic);
                    assert!(paths == all || (units == 0 && paths == 0), "{method} {mode}: {}", text(&o));
                    tracers += usize::from(units > 0);
                    assert!(shipped.ends_with(" B") || shipped.ends_with("KiB"), "{method} {mode}: {shipped}");
                } else {
                    assert_eq!(paths, 0, "{method} {mode}: {}", text(&o));
                    assert!(mode == "peers" || megabytes(&shipped), "{method} {mode}: {shipped}");
                }
            }
            assert!(!traced || tracers >= 1, "{method} {mode}: nobody traced: {}", text(&o));
            if traced {
                // Rendered again on the same workers, the job's maps are still held: nothing is traced again.
                let first = o;
                let o = render(&out, method, &["--workers", &list, "--photon-maps", mode]);
                assert!(o.status.success() && bits(&out) == want, "{method} {mode} again: {}", text(&o));
                // (A worker that rendered nothing the first time may trace now, for its first strip.)
                let first_units: Vec<u64> = ws.iter().map(|w| row(&first, &w.addr).units).collect();
                for (w, before) in ws.iter().zip(first_units) {
                    let paths = row(&o, &w.addr).photon_paths;
                    assert!(paths == 0 || before == 0, "{method} {mode} again: {}", text(&o));
                }
            }
        }
    }
}

#[test]
fn peers_pass_maps_on_with_the_token_and_a_corrupt_peer_loses_nothing() {
    let dir = temp_dir("map-delivery", "peers");
    let token = dir.join("token");
    std::fs::write(&token, "farm-token\n").unwrap();
    let token = token.to_str().unwrap();
    // 16 samples per pixel: the render outlasts the maps' passing on, so every worker is ready before the end.
    let in_process = dir.join("in-process.exr");
    assert!(render_spp(&in_process, "photon-map", 16, &[]).status.success());
    let want = bits(&in_process);
    // Three workers sharing a token: the maps reach each of them once. The coordinator uploads to one; then that
    // one sends to a second while the coordinator uploads to the third (or, if a worker asks late, a holder
    // sends to it).
    let ws: Vec<WorkerProcess> =
        (0..3).map(|_| WorkerProcess::start(&["--threads", "1", "--token-file", token])).collect();
    let list = ws.iter().map(|w| w.addr.as_str()).collect::<Vec<_>>().join(",");
    let out = dir.join("peers.exr");
    let o = render_spp(&out, "photon-map", 16, &["--workers", &list, "--photon-maps", "peers", "--token-file", token]);
    assert!(o.status.success() && bits(&out) == want, "{}", text(&o));
    let rows: Vec<WorkerRow> = ws.iter().map(|w| row(&o, &w.addr)).collect();
    assert!(rows.iter().all(|r| megabytes(&r.shipped) != megabytes(&r.from_peers)), "{}", text(&o));
    let fetched = rows.iter().filter(|r| megabytes(&r.from_peers)).count();
    assert!((1..=2).contains(&fetched), "{}", text(&o));
    // Workers that serve corrupted bytes: every fetch fails its hash check, and the coordinator uploads the maps
    // itself instead. The image is the same.
    let ws: Vec<WorkerProcess> =
        (0..2).map(|_| WorkerProcess::start(&["--threads", "1", "--test-corrupt-blobs"])).collect();
    let list = format!("{},{}", ws[0].addr, ws[1].addr);
    let out = dir.join("corrupt-peers.exr");
    let o = render_spp(&out, "photon-map", 16, &["--workers", &list, "--photon-maps", "peers"]);
    assert!(o.status.success() && bits(&out) == want, "{}", text(&o));
    // The second worker tried its peer first: the peer is blamed (ABORTED) and the next source taken.
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("fetch from peer") && stderr.contains("trying the next source"), "{}", text(&o));
    for w in &ws {
        let r = row(&o, &w.addr);
        assert!(megabytes(&r.shipped) && !megabytes(&r.from_peers), "{}", text(&o));
    }
    assert!(!String::from_utf8_lossy(&o.stdout).contains("passed between workers"), "{}", text(&o));
}

#[test]
fn a_worker_fetches_only_what_a_peer_holds_under_its_hash() {
    use photon_proto::pb;
    use photon_proto::pb::render_client::RenderClient;
    let rt = tokio::runtime::Runtime::new().unwrap();
    let (holder, receiver) = (WorkerProcess::start(&["--threads", "1"]), WorkerProcess::start(&["--threads", "1"]));
    let blob: Vec<u8> = (0..3 * photon_proto::MAX_CHUNK + 17).map(|i| (i * 7 % 251) as u8).collect();
    let id = photon_proto::blob_id(&blob);
    let header = pb::BlobHeader { id: id.clone(), size: blob.len() as u64 };
    rt.block_on(async {
        let mut h = RenderClient::connect(format!("http://{}", holder.addr)).await.unwrap();
        let chunks = photon_proto::blob_chunks(header.clone(), std::sync::Arc::new(blob.clone()));
        h.put_blob(tokio_stream::iter(chunks)).await.unwrap();
        let mut r = RenderClient::connect(format!("http://{}", receiver.addr)).await.unwrap();
        let fetch = |blob: pb::BlobHeader, peer: &str| pb::FetchBlobRequest {
            blob: Some(blob),
            peer: peer.to_owned(),
            tls_ca: Vec::new(),
        };
        // Refusals, each with its code: the peer's fault is ABORTED (a size that is not the blob's, a blob the
        // peer lacks, no peer there), the request's is INVALID_ARGUMENT (a bad id, not an http(s) peer); the
        // receiver still lacks the blob after them.
        let wrong_size = pb::BlobHeader { size: header.size + 1, ..header.clone() };
        let e = r.fetch_blob(fetch(wrong_size, &holder.addr)).await.unwrap_err();
        assert!(e.code() == tonic::Code::Aborted && e.message().contains("not the one asked for"), "{e:?}");
        let unknown = pb::BlobHeader { id: photon_proto::blob_id(b"other"), size: 5 };
        let e = r.fetch_blob(fetch(unknown, &holder.addr)).await.unwrap_err();
        assert!(e.code() == tonic::Code::Aborted && e.message().contains("refused (NotFound)"), "{e:?}");
        let e = r.fetch_blob(fetch(header.clone(), "127.0.0.1:1")).await.unwrap_err();
        assert!(e.code() == tonic::Code::Aborted && e.message().contains("cannot reach"), "{e:?}");
        let bad_id = pb::BlobHeader { id: "x".into(), size: 5 };
        let e = r.fetch_blob(fetch(bad_id, &holder.addr)).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::InvalidArgument, "{e:?}");
        let e = r.fetch_blob(fetch(header.clone(), "file:///etc/passwd")).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::InvalidArgument, "{e:?}");
        let missing = |r: &mut RenderClient<tonic::transport::Channel>| {
            let mut r = r.clone();
            let ids = vec![id.clone()];
            async move { r.missing_blobs(pb::MissingBlobsRequest { ids }).await.unwrap().into_inner().missing }
        };
        assert_eq!(missing(&mut r).await, vec![id.clone()]);
        // The right request: the receiver stores the blob's bytes (its GetBlob serves them back, equal).
        let stored = r.fetch_blob(fetch(header.clone(), &holder.addr)).await.unwrap().into_inner().stored;
        assert_eq!(stored, blob.len() as u64);
        assert!(missing(&mut r).await.is_empty());
        let mut served = r.get_blob(pb::GetBlobRequest { id: id.clone() }).await.unwrap().into_inner();
        let mut bytes = Vec::new();
        while let Some(chunk) = served.message().await.unwrap() {
            assert_eq!(chunk.header.is_some(), bytes.is_empty());
            bytes.extend(chunk.data);
        }
        assert!(bytes == blob);
    });
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
    let frame_of = |method: photon_core::method::Method| {
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
            unit_start: 0,
            unit_end: 1,
            trace_photons,
            ..Default::default()
        };
        let photon_map = frame_of(photon_core::method::Method::PhotonMap);
        let cases = [
            (request(photon_map.clone(), &id, true), "trace_photons"),
            (request(frame_of(photon_core::method::Method::Path), "", true), "needs no photon maps"),
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

#[test]
fn a_peer_that_stops_reading_frees_its_blob_and_slot_by_the_deadline() {
    use photon_proto::pb;
    use photon_proto::pb::render_client::RenderClient;
    let rt = tokio::runtime::Runtime::new().unwrap();
    // Serving allowance: 1 s idle + 40 MiB at 20 MiB/s = 3 s.
    let holder = WorkerProcess::start(&["--threads", "1", "--upload-idle-s", "1", "--upload-min-kib-s", "20480"]);
    let blob: Vec<u8> = (0..40usize << 20).map(|i| (i % 253) as u8).collect();
    let id = photon_proto::blob_id(&blob);
    rt.block_on(async {
        let mut h = RenderClient::connect(format!("http://{}", holder.addr)).await.unwrap();
        let header = pb::BlobHeader { id: id.clone(), size: blob.len() as u64 };
        h.put_blob(tokio_stream::iter(photon_proto::blob_chunks(header, std::sync::Arc::new(blob.clone()))))
            .await
            .unwrap();
        // Four readers that read nothing take every serving slot; a fifth call is refused.
        let mut stalled = Vec::new();
        for _ in 0..photon_proto::transport::SERVED_AT_ONCE {
            let mut c = RenderClient::connect(format!("http://{}", holder.addr)).await.unwrap();
            stalled.push(c.get_blob(pb::GetBlobRequest { id: id.clone() }).await.unwrap().into_inner());
        }
        let e = h.get_blob(pb::GetBlobRequest { id: id.clone() }).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::ResourceExhausted, "{e:?}");
        // Past the allowance the stalled calls end with DEADLINE_EXCEEDED after what was in flight, and the
        // slots are free: a reader that reads gets the whole blob.
        tokio::time::sleep(std::time::Duration::from_secs(5)).await;
        for mut s in stalled {
            let mut got = 0;
            let end = loop {
                match s.message().await {
                    Ok(Some(chunk)) => got += chunk.data.len(),
                    Ok(None) => break None,
                    Err(e) => break Some(e.code()),
                }
            };
            assert!(end == Some(tonic::Code::DeadlineExceeded) && got < blob.len(), "{end:?} after {got} bytes");
        }
        let mut served = h.get_blob(pb::GetBlobRequest { id }).await.unwrap().into_inner();
        let mut bytes = Vec::new();
        while let Some(chunk) = served.message().await.unwrap() {
            bytes.extend(chunk.data);
        }
        assert!(bytes == blob);
    });
}
