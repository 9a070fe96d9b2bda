//! TLS between coordinator and workers, with certificates from `deploy/tls/make-certs.sh`: a coordinator that
//! trusts the workers' authority and holds the token renders; one without the authority, with another authority,
//! with another name for the worker, with the wrong token or speaking TLS to a plaintext worker is refused with a
//! message that says why, and the worker keeps serving. A worker listening beyond loopback without TLS warns.

#![allow(clippy::unwrap_used)]

use photon_tests::{WorkerProcess, coordinator, run_with_timeout, scenes_dir, temp_dir};
use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

fn certs(dir: &Path, hosts: &[&str]) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/tls/make-certs.sh");
    let out = Command::new("bash").arg(script).arg(dir).args(hosts).output().unwrap();
    assert!(out.status.success(), "make-certs.sh failed: {}", String::from_utf8_lossy(&out.stderr));
}

fn render(dir: &Path, name: &str, extra: &[&str]) -> Output {
    let mut cmd = Command::new(coordinator());
    cmd.arg("render").arg(scenes_dir().join("cornell.toml")).arg("-o").arg(dir.join(name));
    cmd.args(["-q", "--no-cache", "--size", "32x24", "--integrator", "path", "--spp", "2"]).args(extra);
    run_with_timeout(&mut cmd, Duration::from_secs(120))
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn tls_and_token_refusals_are_clear_and_the_worker_keeps_serving() {
    let dir = temp_dir("tls", "refusals");
    let (good, other) = (dir.join("good"), dir.join("other"));
    certs(&good, &["127.0.0.1"]);
    certs(&other, &["127.0.0.1"]);
    let (token, wrong) = (dir.join("token"), dir.join("wrong"));
    std::fs::write(&token, "lab-secret\n").unwrap();
    std::fs::write(&wrong, "not-the-secret").unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_owned();
    let (cert, key, ca) = (s(&good.join("127.0.0.1.pem")), s(&good.join("127.0.0.1.key")), s(&good.join("ca.pem")));
    let w = WorkerProcess::start(&["--tls-cert", &cert, "--tls-key", &key, "--token-file", &s(&token)]);
    let port = w.addr.rsplit(':').next().unwrap().to_owned();
    let ok = |name: &str| render(&dir, name, &["--workers", &w.addr, "--tls-ca", &ca, "--token-file", &s(&token)]);

    let o = ok("a.exr");
    assert!(o.status.success(), "{}", stderr(&o));
    // The in-process render of the same job gives the same bytes: TLS changes the wire, not the pixels.
    let o = render(&dir, "b.exr", &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(std::fs::read(dir.join("a.exr")).unwrap(), std::fs::read(dir.join("b.exr")).unwrap());

    let refusals: [(&str, Vec<String>, &str); 4] = [
        ("plaintext", vec!["--token-file".into(), s(&token)], "give the coordinator --tls-ca"),
        (
            "other authority",
            vec!["--tls-ca".into(), s(&other.join("ca.pem")), "--token-file".into(), s(&token)],
            "invalid peer certificate",
        ),
        ("no token", vec!["--tls-ca".into(), ca.clone()], "requires a token"),
        ("wrong token", vec!["--tls-ca".into(), ca.clone(), "--token-file".into(), s(&wrong)], "wrong token"),
    ];
    for (case, args, expect) in refusals {
        let mut all = vec!["--workers".to_owned(), w.addr.clone()];
        all.extend(args);
        let all: Vec<&str> = all.iter().map(String::as_str).collect();
        let o = render(&dir, "x.exr", &all);
        assert!(!o.status.success(), "{case}: rendered");
        assert!(stderr(&o).contains(expect), "{case}: expected `{expect}` in:\n{}", stderr(&o));
    }
    // Another name for the same worker: its certificate names 127.0.0.1 only.
    let o = render(
        &dir,
        "y.exr",
        &["--workers", &format!("localhost:{port}"), "--tls-ca", &ca, "--token-file", &s(&token)],
    );
    assert!(!o.status.success());
    assert!(stderr(&o).contains("not valid for name"), "{}", stderr(&o));
    // Still serving.
    let o = ok("c.exr");
    assert!(o.status.success(), "{}", stderr(&o));

    // TLS towards a plaintext worker.
    let plain = WorkerProcess::start(&[]);
    let o = render(&dir, "z.exr", &["--workers", &plain.addr, "--tls-ca", &ca]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("drop --tls-ca"), "{}", stderr(&o));
}

#[test]
fn plaintext_beyond_loopback_warns() {
    let w = WorkerProcess::start_on("0.0.0.0:0", &[]);
    w.wait_for_log("TLS is off", 1, Duration::from_secs(20));
}

#[test]
fn workers_pass_photon_maps_to_each_other_over_tls() {
    let dir = temp_dir("tls", "peers");
    certs(&dir, &["127.0.0.1"]);
    let token = dir.join("token");
    std::fs::write(&token, "lab-secret\n").unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_owned();
    let (cert, key, ca) = (s(&dir.join("127.0.0.1.pem")), s(&dir.join("127.0.0.1.key")), s(&dir.join("ca.pem")));
    let tls = ["--tls-cert", &cert, "--tls-key", &key, "--token-file", &s(&token), "--threads", "1"];
    let ws = [WorkerProcess::start(&tls), WorkerProcess::start(&tls)];
    let maps = |name: &str, extra: &[&str]| {
        let mut cmd = Command::new(coordinator());
        cmd.arg("render").arg(scenes_dir().join("cornell.toml")).arg("-o").arg(dir.join(name));
        cmd.args(["-q", "--no-cache", "--size", "32x24", "--integrator", "photon-map", "--photons", "30000"]);
        run_with_timeout(cmd.args(extra), Duration::from_secs(120))
    };
    let list = format!("{},{}", ws[0].addr, ws[1].addr);
    let o =
        maps("peers.exr", &["--workers", &list, "--tls-ca", &ca, "--token-file", &s(&token), "--photon-maps", "peers"]);
    assert!(o.status.success(), "{}", stderr(&o));
    // One worker fetched the maps from the other, verifying its certificate with the farm's authority.
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("passed between workers"), "{stdout}\n{}", stderr(&o));
    let o = maps("here.exr", &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(std::fs::read(dir.join("peers.exr")).unwrap(), std::fs::read(dir.join("here.exr")).unwrap());
}

#[test]
fn a_tls_worker_fetches_from_peers_over_tls_only() {
    use photon_proto::pb;
    let dir = temp_dir("tls", "downgrade");
    certs(&dir, &["127.0.0.1"]);
    let s = |p: &Path| p.to_str().unwrap().to_owned();
    let w = WorkerProcess::start(&[
        "--tls-cert",
        &s(&dir.join("127.0.0.1.pem")),
        "--tls-key",
        &s(&dir.join("127.0.0.1.key")),
    ]);
    let ca = std::fs::read(dir.join("ca.pem")).unwrap();
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let endpoint = photon_proto::transport::tls_endpoint(&format!("https://{}", w.addr), &ca).unwrap();
        let mut c = pb::render_client::RenderClient::new(endpoint.connect().await.unwrap());
        // Asked to fetch without the farm's CA (in plaintext, which would send its token in the clear), it refuses.
        let blob = pb::BlobHeader { id: photon_proto::blob_id(b"x"), size: 1 };
        let plaintext = pb::FetchBlobRequest { blob: Some(blob), peer: "127.0.0.1:1".into(), tls_ca: Vec::new() };
        let e = c.fetch_blob(plaintext).await.unwrap_err();
        assert!(e.code() == tonic::Code::FailedPrecondition && e.message().contains("over TLS only"), "{e:?}");
    });
}
