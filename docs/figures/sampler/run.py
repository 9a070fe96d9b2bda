#!/usr/bin/env python3
"""Variance per sample and samples per second of the path tracer: the padded Owen-scrambled Sobol sampler
against the PCG sampler it replaced, on the two Mitsuba rooms (docs/RESULTS.md, "Sampler").

    python3 docs/figures/sampler/run.py OLD_BIN NEW_BIN [SIZE]

OLD_BIN and NEW_BIN are folders with a release photon-coordinator: OLD_BIN built from a commit before the Sobol
sampler (e39bad5), NEW_BIN from this one. Both render two-sided copies of scenes/rooms/*.toml (the old build
has no `two_sided`; sidedness changes the image, not the sampler's variance), so that only the sampler
differs. The reference of each room is NEW_BIN's path tracer at 8192 spp with its own seed; for each spp N
and seed, relMSE(N) ≈ relVar/N + the reference's own, which is at most N/8192 of it. The variance per
sample is N·relMSE(N); the table gives its median over seeds for each sampler, and their ratio. Renders
are interleaved old/new, and the speed is the median over the renders at the largest N of (pixels·N / render
seconds), whose times the coordinator prints to 10 ms.
About 10 minutes at 128x128 on 2 cores.
"""

import pathlib
import re
import statistics
import subprocess
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parents[3]
ROOMS = ["cornell-boxes", "cornell-spheres"]
SPP = [4, 16, 64]
SEEDS = [11, 12, 13, 14, 15]


def run(cmd):
    out = subprocess.run(cmd, check=True, capture_output=True, text=True)
    return out.stdout + out.stderr


def render_seconds(text):
    m = re.search(r"([0-9.]+) s render", text)
    if not m:
        sys.exit(f"no render time in: {text}")
    return float(m.group(1))


def rel_mse(pc, image, reference):
    text = run([pc, "compare", image, reference])
    m = re.search(r"relative MSE[^\n]*?\s([0-9.eE+-]+)\s*$", text, re.M)
    if not m:
        sys.exit(f"no relative MSE in: {text}")
    return float(m.group(1))


def main():
    if len(sys.argv) not in (3, 4):
        sys.exit(__doc__)
    old = str(pathlib.Path(sys.argv[1]) / "photon-coordinator")
    new = str(pathlib.Path(sys.argv[2]) / "photon-coordinator")
    size = sys.argv[3] if len(sys.argv) == 4 else "128x128"
    w, h = (int(v) for v in size.split("x"))
    work = pathlib.Path(tempfile.mkdtemp())
    print(f"| room | spp | relVar/sample, PCG | Sobol | ratio |")
    print(f"|---|---|---|---|---|")
    speed = {"old": [], "new": []}
    for room in ROOMS:
        text = (ROOT / "scenes" / "rooms" / f"{room}.toml").read_text()
        scene = work / f"{room}.toml"
        scene.write_text(text.replace("two_sided = false\n", ""))
        ref = work / f"{room}-ref.exr"
        run([new, "reference", str(scene), "-o", str(ref), "--spp", "8192", "--size", size, "--seed", "1000"])
        for n in SPP:
            per = {"old": [], "new": []}
            for seed in SEEDS:
                for name, pc in (("old", old), ("new", new)):
                    img = work / f"{room}-{name}-{n}-{seed}.exr"
                    out = run([pc, "render", str(scene), "-o", str(img), "--spp", str(n), "--seed", str(seed),
                               "--size", size, "--integrator", "path", "--quiet"])
                    if n == SPP[-1]:
                        speed[name].append(w * h * n / render_seconds(out))
                    per[name].append(n * rel_mse(pc, str(img), str(ref)))
            a, b = statistics.median(per["old"]), statistics.median(per["new"])
            print(f"| {room} | {n} | {a:.4g} | {b:.4g} | {a / b:.2f} |", flush=True)
    a, b = statistics.median(speed["old"]), statistics.median(speed["new"])
    print(f"\npath samples/s (median of {len(speed['old'])} renders each): PCG {a / 1e6:.3f} M, "
          f"Sobol {b / 1e6:.3f} M, ratio Sobol/PCG {b / a:.3f}")


if __name__ == "__main__":
    main()
