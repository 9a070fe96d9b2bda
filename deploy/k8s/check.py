#!/usr/bin/env python3
"""Checks deploy/k8s and deploy/container without a cluster or a container engine.

    pip install kubernetes-validate     # schemas of the Kubernetes API, and PyYAML
    python3 deploy/k8s/check.py BIN_DIR   # BIN_DIR holds photon-worker and photon-coordinator (x86-64 build)

1. Every manifest is valid against the Kubernetes API schema (kubernetes-validate, strict: unknown fields fail).
2. The pieces fit: the Service selects the Deployment's pods, its target port is the container's named port, the
   probes ask for the worker's gRPC service by its name, the Job's `dns:` entry names the Service and its port,
   and every Secret and volume the pods mount is declared.
3. The commands run: the worker with the Deployment's arguments and the image's default command (its listen
   address moved to loopback, the token at a temporary path), and the coordinator with the Job's arguments
   against it (the scene path mapped to scenes/, the Service name to that worker, a small image size): the
   render must succeed and write its image.
"""
import json
import os
import re
import shlex
import subprocess
import sys
import tempfile

import kubernetes_validate
import yaml

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
K8S_VERSION = "1.30.0"


def fail(msg):
    print(f"deploy/k8s/check.py: {msg}", file=sys.stderr)
    sys.exit(1)


def load(name):
    path = os.path.join(ROOT, "deploy", "k8s", name)
    with open(path) as f:
        docs = [d for d in yaml.safe_load_all(f) if d]
    for d in docs:
        try:
            kubernetes_validate.validate(d, K8S_VERSION, strict=True)
        except kubernetes_validate.ValidationError as e:
            fail(f"{name}: {d['kind']} {d['metadata']['name']}: {e.message} at {'/'.join(map(str, e.path))}")
    print(f"{name}: {', '.join(d['kind'] for d in docs)} valid against Kubernetes {K8S_VERSION}")
    return {d["kind"]: d for d in docs}


def start_worker(bin_dir, args, token):
    args = [token if a == "/etc/photon/token" else a for a in args]
    args = ["127.0.0.1:0" if a.startswith("0.0.0.0:") else a for a in args]
    p = subprocess.Popen([os.path.join(bin_dir, "photon-worker"), *args], stdout=subprocess.PIPE,
                         stderr=subprocess.DEVNULL, text=True)
    line = p.stdout.readline().strip()
    if not line.startswith("photon-worker listening on "):
        p.kill()
        fail(f"the worker with {shlex.join(args)} did not start: {line!r}")
    return p, line.rsplit(" ", 1)[1]


def main():
    if len(sys.argv) != 2:
        fail("usage: check.py BIN_DIR")
    bin_dir = sys.argv[1]
    workers = load("workers.yaml")
    job_docs = load("render-job.yaml")
    svc, dep, job, pvc = workers["Service"], workers["Deployment"], job_docs["Job"], job_docs["PersistentVolumeClaim"]

    pod = dep["spec"]["template"]
    labels = pod["metadata"]["labels"]
    if svc["spec"].get("clusterIP") != "None":
        fail("the worker Service must be headless (clusterIP: None): its name must list every pod")
    if any(labels.get(k) != v for k, v in svc["spec"]["selector"].items()):
        fail("the Service's selector does not select the Deployment's pods")
    if dep["spec"]["selector"]["matchLabels"] != {k: labels[k] for k in dep["spec"]["selector"]["matchLabels"]}:
        fail("the Deployment's selector does not match its pod labels")
    worker = pod["spec"]["containers"][0]
    ports = {p["name"]: p["containerPort"] for p in worker["ports"]}
    svc_port = svc["spec"]["ports"][0]
    if svc_port["targetPort"] not in ports:
        fail(f"the Service targets port {svc_port['targetPort']!r}, which the worker container does not name")
    listen = worker["args"][worker["args"].index("--listen") + 1]
    if int(listen.rsplit(":", 1)[1]) != ports[svc_port["targetPort"]]:
        fail(f"the worker listens on {listen}, not on its container port {ports[svc_port['targetPort']]}")
    for probe in ("readinessProbe", "livenessProbe"):
        g = worker[probe]["grpc"]
        if g["port"] != ports[svc_port["targetPort"]] or g.get("service") not in ("", "photon.v1.Render"):
            fail(f"the {probe} must ask port {ports[svc_port['targetPort']]} for photon.v1.Render")
    coord = job["spec"]["template"]["spec"]["containers"][0]
    entry = coord["args"][coord["args"].index("--workers") + 1]
    m = re.fullmatch(r"dns:([^:]+):(\d+)", entry)
    if not m or m.group(1).split(".")[0] != svc["metadata"]["name"] or int(m.group(2)) != svc_port["port"]:
        fail(f"the Job's workers {entry!r} are not dns:{svc['metadata']['name']}:{svc_port['port']}")
    for spec in (pod["spec"], job["spec"]["template"]["spec"]):
        declared = {v["name"]: v for v in spec["volumes"]}
        for c in spec["containers"]:
            for mnt in c.get("volumeMounts", []):
                if mnt["name"] not in declared:
                    fail(f"{c['name']} mounts an undeclared volume {mnt['name']}")
        claims = [v["persistentVolumeClaim"]["claimName"] for v in spec["volumes"] if "persistentVolumeClaim" in v]
        if any(c != pvc["metadata"]["name"] for c in claims):
            fail(f"a claim in {claims} is not the PersistentVolumeClaim {pvc['metadata']['name']}")
    print("workers.yaml and render-job.yaml fit together")

    # The image's default command and the Deployment's, then the Job's render against the latter.
    with open(os.path.join(ROOT, "deploy", "container", "Containerfile")) as f:
        cmd = next(json.loads(l[4:]) for l in f if l.startswith("CMD "))
    with tempfile.TemporaryDirectory() as tmp:
        token = os.path.join(tmp, "token")
        with open(token, "w") as f:
            f.write("a-token-for-the-check\n")
        image_default, _ = start_worker(bin_dir, cmd, token)
        image_default.kill()
        w, addr = start_worker(bin_dir, worker["args"], token)
        try:
            args = []
            for a in coord["args"]:
                a = a.replace("/usr/share/photon/scenes", os.path.join(ROOT, "scenes"))
                a = a.replace("/etc/photon/token", token).replace("/out/", tmp + "/")
                args.append(f"dns:{addr}" if a == entry else a)
            env = dict(os.environ, **{e["name"]: e["value"].replace("/out", tmp) for e in coord.get("env", [])})
            out = args[args.index("-o") + 1]
            r = subprocess.run([os.path.join(bin_dir, "photon-coordinator"), *args, "--size", "48x36", "--spp", "2"],
                               env=env, capture_output=True, text=True, timeout=300)
            if r.returncode != 0 or not os.path.isfile(out):
                fail(f"the Job's render failed ({r.returncode}):\n{r.stdout}\n{r.stderr}")
            print(f"the Job's command rendered {os.path.basename(out)} on the Deployment's worker command: "
                  f"{r.stdout.strip().splitlines()[-1]}")
        finally:
            w.kill()


if __name__ == "__main__":
    main()
