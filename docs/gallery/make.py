#!/usr/bin/env python3
"""Renders the gallery: every shipped scene (scenes/*.toml, scenes/stress/*.toml and scenes/rooms/*.toml) with its own settings.

    python3 docs/gallery/make.py            # the whole gallery and the README's picture (a few minutes on 2 cores)
    python3 docs/gallery/make.py --no-readme   # the gallery only

Builds the release coordinator (or uses $PHOTON_BIN), then for each scene:

* renders it at GALLERY_WIDTH pixels wide (its own aspect ratio) with the scene's own method and budget, to
  docs/gallery/NAME.png, and keeps the render and prepare seconds of the summary line;
* when scenes/references/NAME-32.exr exists, renders the same settings at the reference's 32x32 and measures the
  relative MSE (and RMSE) with `photon-coordinator compare`;

and writes docs/gallery/README.md with the images, commands, methods, times and errors. Unless --no-readme, it
also renders the README's picture: scenes/cornell.toml at its full size with its own settings (the README's first
command) and with `--integrator path` (the path tracer at the scene's 64 spp, the same time), measures both at
32x32 in the same way, and rewrites the block between the gallery markers of the top-level README.md.

Python 3.11 standard library only.
"""

import argparse
import datetime
import os
import re
import resource
import shlex
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
GALLERY = REPO / "docs" / "gallery"
REFERENCES = REPO / "scenes" / "references"
GALLERY_WIDTH = 192
README_BEGIN = "<!-- gallery:readme begin (written by docs/gallery/make.py) -->"
README_END = "<!-- gallery:readme end -->"
SUMMARY = re.compile(r": (\d+)x(\d+), (.*), ([a-z-]+), ([\d.]+) s render \(\+([\d.]+) s prepare")


def coordinator() -> Path:
    """The release coordinator: $PHOTON_BIN, or built here with cargo."""
    if "PHOTON_BIN" in os.environ:
        return Path(os.environ["PHOTON_BIN"])
    subprocess.run(["cargo", "build", "--release", "-q", "-p", "photon-coordinator", "--bins"], cwd=REPO, check=True)
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    return target / "release" / "photon-coordinator"


def scenes() -> list[Path]:
    """Every shipped scene, top level first, each folder sorted by name."""
    return (
        sorted((REPO / "scenes").glob("*.toml"))
        + sorted((REPO / "scenes" / "stress").glob("*.toml"))
        + sorted((REPO / "scenes" / "rooms").glob("*.toml"))
    )


def gallery_name(scene: Path) -> str:
    rel = scene.relative_to(REPO / "scenes").with_suffix("")
    return "-".join(rel.parts)


def reference_of(scene: Path) -> Path | None:
    """The small reference of a top-level scene, when scenes/references has one."""
    if scene.parent != REPO / "scenes":
        return None
    ref = REFERENCES / f"{scene.stem}-32.exr"
    return ref if ref.is_file() else None


def render(bin_: Path, args: list[str]) -> dict:
    """Runs `photon-coordinator render ARGS` in the repository and parses its summary line."""
    cmd = [str(bin_), "render", *args]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    out = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu_s = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    if out.returncode != 0:
        sys.exit(f"failed: {shlex.join(cmd)}\n{out.stderr}")
    line = out.stdout.strip().splitlines()[-1]
    m = SUMMARY.search(line)
    if not m:
        sys.exit(f"no summary line in the output of {shlex.join(cmd)}: {out.stdout}")
    samples = re.sub(r" \(\d+ paths traced on the workers\)", "", m.group(3))
    return {
        "size": f"{m.group(1)}x{m.group(2)}",
        "method": f"{m.group(4)}, {samples}",
        "render_s": float(m.group(5)),
        "prepare_s": float(m.group(6)),
        "cpu_s": cpu_s,
        "command": "photon-coordinator render " + shlex.join(args),
    }


def error(bin_: Path, scene_rel: str, reference: Path, extra: list[str], tmp: Path) -> dict:
    """Relative MSE and RMSE of the scene's settings (plus `extra`) rendered at 32x32, against `reference`."""
    exr = tmp / "measure.exr"
    render(bin_, [scene_rel, "-o", str(exr), "--size", "32x32", "-q", "--no-cache", *extra])
    out = subprocess.run(
        [str(bin_), "compare", str(exr), str(reference)], cwd=REPO, capture_output=True, text=True, check=True
    )
    kv = dict(p.split("=", 1) for p in out.stdout.splitlines()[-1].split())
    return {"rel_mse": float(kv["rel_mse"]), "rmse": float(kv["rmse"])}


def gallery_size(scene: Path) -> str:
    camera = tomllib.loads(scene.read_text()).get("camera", {})
    w, h = camera.get("width", 512), camera.get("height", 512)
    return f"{GALLERY_WIDTH}x{max(1, round(GALLERY_WIDTH * h / w))}"


def seconds(r: dict) -> str:
    return f"{r['render_s']:.2f} s (+{r['prepare_s']:.2f} s prepare); {r['cpu_s']:.1f} CPU s"


def sig(x: float) -> str:
    return f"{x:.3g}"


def readme_pair(bin_: Path, tmp: Path) -> str:
    """Renders the README's picture and returns its Markdown block. Each render runs twice, the two methods taking
    turns, and keeps its run of fewer CPU seconds: a shared machine's load then favours neither."""
    scene = "scenes/cornell.toml"
    ref = REFERENCES / "cornell-32.exr"
    pair = [("readme-default", []), ("readme-path", ["--integrator", "path"])]
    runs: list[dict] = [{}, {}]
    for attempt in range(2):
        for k, (name, extra) in enumerate(pair):
            png = f"docs/gallery/{name}.png"
            print(f"  {scene} {' '.join(extra) or '(its own settings)'}, run {attempt + 1} of 2", flush=True)
            r = render(bin_, [scene, "-o", png, "-q", "--no-cache", *extra])
            if not runs[k] or r["cpu_s"] < runs[k]["cpu_s"]:
                runs[k] = r
    for r, (name, extra) in zip(runs, pair):
        r.update(error(bin_, scene, ref, extra, tmp))
        r["png"] = f"docs/gallery/{name}.png"
    d, p = runs
    ratio = d["cpu_s"] / p["cpu_s"]
    if not 0.8 < ratio < 1.25:
        print(f"warning: the default takes {ratio:.2f}x the path tracer's CPU time", file=sys.stderr)
    cell = "| {} | {} |"
    return "\n".join(
        [
            cell.format(f"`{d['method']}` (the scene's own settings)", f"`{p['method']}` (`--integrator path`)"),
            "|---|---|",
            cell.format(f"![default render]({d['png']})", f"![path tracer]({p['png']})"),
            cell.format(seconds(d), seconds(p)),
            cell.format(*(f"relMSE {sig(r['rel_mse'])}, RMSE {sig(r['rmse'])}" for r in runs)),
            "",
            f"`{d['command']}` against `{p['command']}`, {d['size']}, on {os.cpu_count()} cores (load average"
            f" {os.getloadavg()[0]:.1f}); time: render seconds (+ prepare), then the CPU seconds of the whole command,"
            " the run of fewer CPU seconds of two each (on a shared machine they are the fairer measure of equal time);"
            " error: the same settings at 32×32 against `scenes/references/cornell-32.exr` (relative MSE with"
            " ε = 0.01, and RMSE).",
        ]
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-readme", action="store_true", help="do not render the README's picture")
    args = ap.parse_args()
    bin_ = coordinator()
    load = os.getloadavg()[0]
    started = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True)
    rows = []
    seen: dict[bytes, str] = {}
    with tempfile.TemporaryDirectory(prefix="photon-gallery-") as t:
        tmp = Path(t)
        if not args.no_readme:
            print("README picture", flush=True)
            block = readme_pair(bin_, tmp)
        for scene in scenes():
            rel = str(scene.relative_to(REPO))
            name = gallery_name(scene)
            print(f"  {rel}", flush=True)
            r = render(bin_, [rel, "-o", f"docs/gallery/{name}.png", "--size", gallery_size(scene), "-q", "--no-cache"])
            png = (GALLERY / f"{name}.png").read_bytes()
            same = seen.setdefault(png, rel)
            ref = reference_of(scene)
            if ref is not None:
                e = error(bin_, rel, ref, [], tmp)
                err = f"relMSE {sig(e['rel_mse'])}, RMSE {sig(e['rmse'])}"
            else:
                err = "no reference in scenes/references"
            method = r["method"]
            if same != rel:
                method += (
                    f" (the same image as `{same}`: the two scenes differ only in comments or in settings this"
                    " method does not read)"
                )
            rows.append(f"| ![{name}]({name}.png) | `{rel}` | {method} | {seconds(r)} | {err} | `{r['command']}` |")

    header = f"""# Gallery

Every shipped scene (`scenes/*.toml`, `scenes/stress/*.toml` and `scenes/rooms/*.toml`) rendered with its own method and budget at
{GALLERY_WIDTH} pixels wide, by `python3 docs/gallery/make.py` (this page and every image here are its output; run
it again to regenerate them). Made {started} at commit `{commit.stdout.strip()}` with the release build on
{os.cpu_count()} cores (load average {load:.1f} when it started).

**Time** is the summary line's render seconds (+ prepare: BVH, meshes, photon maps), then the CPU seconds of the
whole command (user + system, all threads; on a machine shared with other work a fairer measure than the
wall-clock seconds, which include waiting for a core). **Error** is measured
against the scene's 32×32 reference in `scenes/references/` (see its README): the same command at `--size 32x32`,
then `photon-coordinator compare`; relMSE is the relative MSE of docs/METRICS.md (ε = 0.01), RMSE its root mean
square error. The stress scenes have no reference there; docs/RESULTS.md ("Stress suite") measures them against
larger ones. `cargo test -p photon-core --test gallery_scenes` renders every scene here at 16×16 with its own
method and checks that each image is finite and not black, and that this page shows every shipped scene.

| image | scene | method | time | error | command |
|---|---|---|---|---|---|
"""
    (GALLERY / "README.md").write_text(header + "\n".join(rows) + "\n")
    if not args.no_readme:
        readme = REPO / "README.md"
        text = readme.read_text()
        begin, end = text.index(README_BEGIN) + len(README_BEGIN), text.index(README_END)
        readme.write_text(text[:begin] + "\n" + block + "\n" + text[end:])
    print("wrote docs/gallery/README.md" + ("" if args.no_readme else " and the picture of README.md"))


if __name__ == "__main__":
    main()
