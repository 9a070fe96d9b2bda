//! A worker refuses bad requests with a clear status and keeps serving: oversized, truncated, overlong and
//! wrongly hashed uploads, unknown blobs, rows outside the image, another protocol version.

#![allow(clippy::unwrap_used)]

use photon_core::method::Method;
use photon_proto::pb::{self, render_client::RenderClient};
use photon_tests::WorkerProcess;
use tonic::Code;
use tonic::transport::Channel;

async fn client(w: &WorkerProcess) -> RenderClient<Channel> {
    let channel = photon_proto::transport::endpoint(&format!("http://{}", w.addr)).unwrap().connect().await.unwrap();
    RenderClient::new(channel)
}

fn chunks(id: &str, size: u64, parts: &[&[u8]]) -> Vec<pb::BlobChunk> {
    let mut header = Some(pb::BlobHeader { id: id.into(), size });
    parts.iter().map(|p| pb::BlobChunk { header: header.take(), data: p.to_vec() }).collect()
}

async fn put(c: &mut RenderClient<Channel>, msgs: Vec<pb::BlobChunk>) -> Result<u64, tonic::Status> {
    c.put_blob(tokio_stream::iter(msgs)).await.map(|r| r.into_inner().stored)
}

async fn hello(c: &mut RenderClient<Channel>, protocol_version: u32) -> Result<pb::HelloReply, tonic::Status> {
    let req = pb::HelloRequest {
        protocol_version,
        build_id: photon_proto::BUILD_ID.into(),
        crate_version: photon_proto::CRATE_VERSION.into(),
        probe: Vec::new(),
    };
    c.hello(req).await.map(|r| r.into_inner())
}

#[tokio::test]
async fn bad_requests_are_refused_and_the_worker_keeps_serving() {
    let w = WorkerProcess::start(&["--max-blob-mib", "1"]);
    let mut c = client(&w).await;

    let e = hello(&mut c, photon_proto::PROTOCOL_VERSION + 1).await.unwrap_err();
    assert_eq!(e.code(), Code::FailedPrecondition);
    assert!(e.message().contains("protocol version"), "{}", e.message());
    let info = hello(&mut c, photon_proto::PROTOCOL_VERSION).await.unwrap();
    assert_eq!(info.max_blob_bytes, 1 << 20);
    assert!(info.threads >= 1 && !info.arch.is_empty());

    let blob = vec![7u8; 3000];
    let id = photon_proto::blob_id(&blob);

    // Larger than the worker's limit: refused from the header, before any byte is kept.
    let e = put(&mut c, chunks(&id, 2 << 20, &[&blob])).await.unwrap_err();
    assert_eq!(e.code(), Code::ResourceExhausted, "{e:?}");
    assert!(e.message().contains("exceeds this worker's limit"), "{}", e.message());
    // Truncated: fewer bytes than announced.
    let e = put(&mut c, chunks(&id, 3000, &[&blob[..1000], &blob[1000..2000]])).await.unwrap_err();
    assert_eq!(e.code(), Code::InvalidArgument);
    assert!(e.message().contains("truncated"), "{}", e.message());
    // Overlong: more bytes than announced.
    let e = put(&mut c, chunks(&id, 2000, &[&blob])).await.unwrap_err();
    assert_eq!(e.code(), Code::InvalidArgument);
    assert!(e.message().contains("sent more"), "{}", e.message());
    // Wrongly hashed: the bytes are not the id's.
    let mut other = blob.clone();
    other[10] = 8;
    let e = put(&mut c, chunks(&id, 3000, &[&other])).await.unwrap_err();
    assert_eq!(e.code(), Code::DataLoss);
    assert!(e.message().contains("hash to"), "{}", e.message());
    // Not an id at all, and a header without data first.
    let e = put(&mut c, chunks("../../etc/passwd", 3000, &[&blob])).await.unwrap_err();
    assert_eq!(e.code(), Code::InvalidArgument);
    let e = put(&mut c, vec![pb::BlobChunk { header: None, data: blob.clone() }]).await.unwrap_err();
    assert_eq!(e.code(), Code::InvalidArgument);

    // None of those was kept; a good upload is, once.
    let missing = c.missing_blobs(pb::MissingBlobsRequest { ids: vec![id.clone()] }).await.unwrap().into_inner();
    assert_eq!(missing.missing, vec![id.clone()]);
    assert_eq!(put(&mut c, chunks(&id, 3000, &[&blob[..1500], &blob[1500..]])).await.unwrap(), 3000);
    assert_eq!(put(&mut c, chunks(&id, 3000, &[&blob])).await.unwrap(), 0);
    let missing = c.missing_blobs(pb::MissingBlobsRequest { ids: vec![id.clone()] }).await.unwrap().into_inner();
    assert!(missing.missing.is_empty());

    // A strip of an unknown blob, and a blob that is not a scene.
    let strip = |scene: &str, rows: (u32, u32)| pb::StripRequest {
        scene_blob: scene.into(),
        photons_blob: String::new(),
        frame: Vec::new(),
        row_start: rows.0,
        row_end: rows.1,
        strip: 0,
        attempt: 1,
        ..Default::default()
    };
    let unknown = photon_proto::blob_id(b"never sent");
    let e = c.render_strip(strip(&unknown, (0, 1))).await.unwrap_err();
    assert_eq!(e.code(), Code::NotFound);
    let e = c.render_strip(strip(&id, (5, 2))).await.unwrap_err();
    assert_eq!(e.code(), Code::OutOfRange);
    let e = c.render_strip(strip(&id, (0, 1))).await.unwrap_err();
    assert_eq!(e.code(), Code::InvalidArgument);
    assert!(e.message().contains("the frame does not decode"), "{}", e.message());

    // Still serving.
    hello(&mut c, photon_proto::PROTOCOL_VERSION).await.unwrap();
}

#[tokio::test]
async fn the_standard_health_service_says_serving() {
    use tonic_health::pb::{HealthCheckRequest, health_check_response::ServingStatus, health_client::HealthClient};
    let w = WorkerProcess::start(&[]);
    let channel = photon_proto::transport::endpoint(&format!("http://{}", w.addr)).unwrap().connect().await.unwrap();
    let mut health = HealthClient::new(channel);
    for service in ["", "photon.v1.Render"] {
        let r = health.check(HealthCheckRequest { service: service.into() }).await.unwrap().into_inner();
        assert_eq!(r.status(), ServingStatus::Serving, "service `{service}`");
    }
}

#[tokio::test]
async fn rows_outside_the_image_are_refused() {
    // A real job: the scene's blobs, then a strip beyond its last row.
    let path = photon_tests::scenes_dir().join("cornell.toml");
    let mut scene = photon_core::scene::Scene::load(&path).unwrap();
    scene.camera.width = 8;
    scene.camera.height = 4;
    scene.render.integrator = Method::Path; // a strip of rows, not a block of passes
    let prep = photon_core::prepare::Prepared::new(&scene, &path).unwrap().with_photon_maps(&path).unwrap();
    let blob = prep.encode_scene().unwrap();
    let id = photon_proto::blob_id(&blob);
    let w = WorkerProcess::start(&[]);
    let mut c = client(&w).await;
    assert!(put(&mut c, chunks(&id, blob.len() as u64, &[&blob])).await.unwrap() > 0);
    let req = |rows: (u32, u32)| pb::StripRequest {
        scene_blob: id.clone(),
        photons_blob: String::new(),
        frame: prep.encode_frame().unwrap(),
        row_start: rows.0,
        row_end: rows.1,
        strip: 0,
        attempt: 1,
        unit_start: 0,
        unit_end: prep.settings.units(),
        ..Default::default()
    };
    let e = c.render_strip(req((2, 9))).await.unwrap_err();
    assert_eq!(e.code(), Code::OutOfRange);
    assert!(e.message().contains("outside the image's 4 rows"), "{}", e.message());
    // The valid rows render: 8 pixels × 3 sums × 8 bytes per row.
    let mut stream = c.render_strip(req((0, 4))).await.unwrap().into_inner();
    let mut bytes = 0;
    while let Some(ev) = stream.message().await.unwrap() {
        if let Some(pb::strip_event::Event::Sums(r)) = ev.event {
            bytes += r.data.len();
        }
    }
    assert_eq!(bytes, 4 * 8 * 24);
}

#[tokio::test]
async fn pass_blocks_are_checked_against_the_job() {
    let path = photon_tests::scenes_dir().join("cornell.toml");
    let mut scene = photon_core::scene::Scene::load(&path).unwrap();
    scene.camera.width = 8;
    scene.camera.height = 4;
    scene.render.photons.passes = 5;
    scene.render.photons.pass_photons = 500;
    let w = WorkerProcess::start(&[]);
    let mut c = client(&w).await;
    for integrator in [Method::Progressive, Method::Vcm, Method::Bdpt, Method::Lt, Method::Path] {
        scene.render.integrator = integrator;
        let prep = photon_core::prepare::Prepared::new(&scene, &path).unwrap();
        let blob = prep.encode_scene().unwrap();
        let id = photon_proto::blob_id(&blob);
        put(&mut c, chunks(&id, blob.len() as u64, &[&blob])).await.unwrap();
        let req = |passes: (u32, u32)| pb::StripRequest {
            scene_blob: id.clone(),
            frame: prep.encode_frame().unwrap(),
            row_start: 0,
            row_end: 4,
            unit_start: passes.0,
            unit_end: passes.1,
            ..Default::default()
        };
        if integrator.renders_passes() {
            for bad in [(0, 0), (3, 2), (4, 6)] {
                let e = c.render_strip(req(bad)).await.unwrap_err();
                assert_eq!(e.code(), Code::OutOfRange, "{bad:?}");
                assert!(e.message().contains("within the job's 5 passes"), "{}", e.message());
            }
            // A valid block: i64 sums, 8 bytes per value.
            let mut stream = c.render_strip(req((1, 3))).await.unwrap().into_inner();
            let mut bytes = 0;
            while let Some(ev) = stream.message().await.unwrap() {
                if let Some(pb::strip_event::Event::Sums(r)) = ev.event {
                    bytes += r.data.len();
                }
            }
            assert_eq!(bytes, 4 * 8 * 24);
        } else {
            // The other methods take blocks of sample indices within the frame's samples per pixel.
            let spp = prep.settings.spp;
            for bad in [(0, 0), (3, 2), (spp, spp + 1)] {
                let e = c.render_strip(req(bad)).await.unwrap_err();
                assert_eq!(e.code(), Code::OutOfRange, "{bad:?}");
                assert!(e.message().contains(&format!("within the job's {spp} samples per pixel")), "{}", e.message());
            }
        }
    }
}
