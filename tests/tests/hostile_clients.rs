//! A worker under a hostile or careless client: doctored frames (a width of 0xFFFFFFFF, a width of 0, a method
//! without its photons), an overlong build id, uploads that drip a byte at a time or stall next to a normal one,
//! and a strip that panics. Each is refused with a status that names what was wrong, and afterwards the same
//! worker renders a strip byte-identical to the one rendered here, its peak memory still small.

#![allow(clippy::unwrap_used)]

use photon_core::camera::Camera;
use photon_core::method::Method;
use photon_core::prepare::Prepared;
use photon_core::scene::{RenderSettings, Scene};
use photon_proto::pb::{self, render_client::RenderClient};
use photon_tests::WorkerProcess;
use std::time::{Duration, Instant};
use tonic::Code;
use tonic::transport::Channel;

async fn client(w: &WorkerProcess) -> RenderClient<Channel> {
    let channel = photon_proto::transport::endpoint(&format!("http://{}", w.addr)).unwrap().connect().await.unwrap();
    RenderClient::new(channel)
}

/// A small real job: the Cornell box at 8 × 4 pixels, path traced at 4 samples.
fn job() -> Prepared {
    let path = photon_tests::scenes_dir().join("cornell.toml");
    let mut scene = Scene::load(&path).unwrap();
    scene.camera.width = 8;
    scene.camera.height = 4;
    scene.render.spp = 4;
    scene.render.integrator = Method::Path;
    Prepared::new(&scene, &path).unwrap()
}

fn chunks(id: &str, bytes: &[u8]) -> Vec<pb::BlobChunk> {
    let mut header = Some(pb::BlobHeader { id: id.into(), size: bytes.len() as u64 });
    bytes.chunks(1 << 16).map(|p| pb::BlobChunk { header: header.take(), data: p.to_vec() }).collect()
}

fn request(scene_blob: &str, frame: Vec<u8>, rows: (u32, u32)) -> pb::StripRequest {
    pb::StripRequest {
        scene_blob: scene_blob.into(),
        photons_blob: String::new(),
        frame,
        row_start: rows.0,
        row_end: rows.1,
        strip: 0,
        attempt: 1,
        // One unit (a sample, or a pass): a block within every job.
        unit_start: 0,
        unit_end: 1,
        ..Default::default()
    }
}

/// The strip's pixel bytes, or the status that ended it.
async fn render(c: &mut RenderClient<Channel>, req: pb::StripRequest) -> Result<Vec<u8>, tonic::Status> {
    let mut stream = c.render_strip(req).await?.into_inner();
    let mut bytes = Vec::new();
    while let Some(ev) = stream.message().await? {
        match ev.event {
            Some(pb::strip_event::Event::Sums(r)) => bytes.extend_from_slice(&r.data),
            Some(pb::strip_event::Event::Done(d)) => assert_eq!(d.checksum, photon_proto::checksum(&bytes).to_vec()),
            _ => {}
        }
    }
    Ok(bytes)
}

/// An upload that sends its header and then one byte every `every` (announcing `size` bytes), or nothing more
/// when `every` is `None`: the status it ends with.
fn drip(mut c: RenderClient<Channel>, size: u64, every: Option<Duration>) -> tokio::task::JoinHandle<tonic::Status> {
    tokio::spawn(async move {
        let bytes = vec![1u8; size as usize];
        let id = photon_proto::blob_id(&bytes);
        let (tx, rx) = tokio::sync::mpsc::channel(4);
        let header = pb::BlobHeader { id, size };
        tx.send(pb::BlobChunk { header: Some(header), data: vec![1] }).await.unwrap();
        tokio::spawn(async move {
            let Some(every) = every else {
                // Stalled: keep the stream open, send nothing.
                tokio::time::sleep(Duration::from_secs(30)).await;
                drop(tx);
                return;
            };
            for _ in 1..size {
                tokio::time::sleep(every).await;
                if tx.send(pb::BlobChunk { header: None, data: vec![1] }).await.is_err() {
                    return;
                }
            }
        });
        c.put_blob(tokio_stream::wrappers::ReceiverStream::new(rx)).await.unwrap_err()
    })
}

/// One peer may hold `--max-calls-per-peer` calls at once over all its connections: the next is refused with
/// RESOURCE_EXHAUSTED naming the cap, and once the held calls end the peer is served again.
#[tokio::test]
async fn calls_over_the_per_peer_cap_are_refused_naming_it() {
    let w = WorkerProcess::start(&["--max-calls-per-peer", "2", "--upload-idle-s", "10"]);
    let hello = || pb::HelloRequest {
        protocol_version: photon_proto::PROTOCOL_VERSION,
        build_id: photon_proto::BUILD_ID.into(),
        crate_version: photon_proto::CRATE_VERSION.into(),
        probe: Vec::new(),
    };
    let mut c = client(&w).await;
    c.hello(hello()).await.unwrap();
    // Two stalled uploads, on two connections, hold both calls until the idle timeout (10 s) cuts them.
    let stalls = [drip(client(&w).await, 100, None), drip(client(&w).await, 100, None)];
    // Poll until both are admitted: then a third call, on a third connection, is refused.
    let end = Instant::now() + Duration::from_secs(8);
    let refused = loop {
        match c.hello(hello()).await {
            Err(e) => break e,
            Ok(_) if Instant::now() < end => tokio::time::sleep(Duration::from_millis(20)).await,
            Ok(_) => panic!("a third call was admitted while two uploads were held"),
        }
    };
    assert_eq!(refused.code(), Code::ResourceExhausted, "{refused:?}");
    assert!(refused.message().contains("2 calls") && refused.message().contains("--max-calls-per-peer"), "{refused:?}");
    for s in stalls {
        assert_eq!(s.await.unwrap().code(), Code::DeadlineExceeded);
    }
    // The held calls ended: the peer is served again.
    c.hello(hello()).await.unwrap();
}

#[tokio::test]
async fn hostile_requests_are_refused_and_the_worker_then_renders_a_correct_strip() {
    let w = WorkerProcess::start(&["--upload-idle-s", "1", "--test-panic-strips", "1"]);
    let mut c = client(&w).await;
    let prep = job();

    // A 1 MB build id: refused with a status that quotes a short prefix of it, not a transport error.
    let hello = pb::HelloRequest {
        protocol_version: photon_proto::PROTOCOL_VERSION,
        build_id: "x".repeat(1 << 20),
        crate_version: photon_proto::CRATE_VERSION.into(),
        probe: Vec::new(),
    };
    let e = c.hello(hello).await.unwrap_err();
    assert_eq!(e.code(), Code::FailedPrecondition, "{e:?}");
    assert!(e.message().len() < 1024 && e.message().contains("more bytes"), "{}", e.message());

    // Uploads: three that drip a byte every 300 ms and one that stalls, next to a normal 5 KB one, which is
    // stored at once; the drips are cut by the deadline (1 s idle + size at the minimum rate), the stall by the
    // idle timeout.
    let t0 = Instant::now();
    let drips: Vec<_> = (0..3).map(|_| drip(c.clone(), 100, Some(Duration::from_millis(300)))).collect();
    let stall = drip(c.clone(), 100, None);
    tokio::time::sleep(Duration::from_millis(200)).await;
    let normal = vec![7u8; 5000];
    let id = photon_proto::blob_id(&normal);
    let stored = c.put_blob(tokio_stream::iter(chunks(&id, &normal))).await.unwrap().into_inner().stored;
    assert_eq!(stored, 5000);
    assert!(t0.elapsed() < Duration::from_secs(1), "the normal upload waited {:?}", t0.elapsed());
    for d in drips {
        let e = d.await.unwrap();
        assert_eq!(e.code(), Code::DeadlineExceeded, "{e:?}");
        assert!(e.message().contains("too slow"), "{}", e.message());
    }
    let e = stall.await.unwrap();
    assert_eq!(e.code(), Code::DeadlineExceeded, "{e:?}");
    assert!(e.message().contains("no chunk of the upload for 1 s"), "{}", e.message());
    assert!(t0.elapsed() < Duration::from_secs(5), "the slow uploads were cut after {:?}", t0.elapsed());

    let scene = prep.encode_scene().unwrap();
    let scene_id = photon_proto::blob_id(&scene);
    assert!(c.put_blob(tokio_stream::iter(chunks(&scene_id, &scene))).await.unwrap().into_inner().stored > 0);

    // Doctored frames, refused before anything is allocated from them, naming the field.
    let frame = |camera: Camera, settings: &RenderSettings| Prepared::encode_frame_of(&camera, settings).unwrap();
    let settings = prep.settings.clone();
    for (width, rows) in [(u32::MAX, (0, 1)), (0, (0, 1))] {
        let mut camera = prep.camera;
        camera.width = width;
        let e = c.render_strip(request(&scene_id, frame(camera, &settings), rows)).await.unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument, "width {width}: {e:?}");
        assert!(e.message().contains("camera.width"), "{}", e.message());
    }
    let k = RenderSettings {
        photons: photon_core::scene::PhotonSettings { k: u32::MAX, ..settings.photons.clone() },
        ..settings.clone()
    };
    let e = c.render_strip(request(&scene_id, frame(prep.camera, &k), (0, 1))).await.unwrap_err();
    assert!(e.message().contains("render.photons.k"), "{}", e.message());
    let photon_map = RenderSettings { integrator: Method::PhotonMap, ..settings.clone() };
    let e = c.render_strip(request(&scene_id, frame(prep.camera, &photon_map), (0, 1))).await.unwrap_err();
    assert_eq!(e.code(), Code::InvalidArgument, "{e:?}");
    assert!(e.message().contains("photons_blob") && e.message().contains("needs photon maps"), "{}", e.message());
    let garbage = request(&"z".repeat(10_000), prep.encode_frame().unwrap(), (0, 1));
    let e = c.render_strip(garbage).await.unwrap_err();
    assert!(e.message().len() < 300 && e.message().contains("scene_blob"), "{}", e.message());
    // A blob that is not a scene, with a valid frame: it fails to decode on the render thread.
    let e = render(&mut c, request(&id, prep.encode_frame().unwrap(), (0, 1))).await.unwrap_err();
    assert_eq!(e.code(), Code::InvalidArgument, "{e:?}");
    assert!(e.message().contains("do not decode"), "{}", e.message());

    // The first real strip panics (fault injection): that strip fails, the worker does not.
    let e = render(&mut c, request(&scene_id, prep.encode_frame().unwrap(), (0, 4))).await.unwrap_err();
    assert_eq!(e.code(), Code::Internal, "{e:?}");
    assert!(e.message().contains("panicked"), "{}", e.message());

    // And the next is the strip this process renders.
    let got = render(&mut c, request(&scene_id, prep.encode_frame().unwrap(), (0, 4))).await.unwrap();
    let block = photon_core::render::Block { rows: 0..4, units: 0..1 };
    let expected =
        photon_core::render::render_block(&prep, &block, &|_| {}, &photon_core::run::Guard::unbounded()).unwrap();
    assert_eq!(got, photon_proto::sums_to_bytes(&expected.sums));

    // Nothing was allocated from the doctored sizes: the worker's peak resident memory stays small (a width of
    // 0xFFFFFFFF once asked for 51 GB).
    if let Ok(status) = std::fs::read_to_string(format!("/proc/{}/status", w.pid())) {
        let kib: u64 = status
            .lines()
            .find_map(|l| l.strip_prefix("VmHWM:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
            .unwrap();
        assert!(kib < 1 << 20, "the worker's peak resident memory is {kib} KiB");
        eprintln!("worker peak resident memory: {kib} KiB");
    }
}
