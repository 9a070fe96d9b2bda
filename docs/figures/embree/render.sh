#!/usr/bin/env bash
# Whole renders before and after a change of the ray casting: the path tracer's samples per second on
# scenes/mesh.toml, on the same room with its gold torus replaced by the bumpy icosphere of 1 310 720 triangles
# (`lod = 0`, so every triangle is kept), and on three scenes of spheres and rectangles or small meshes (cornell,
# textured, the Mitsuba room of boxes), rendered by two coordinator builds alternated in the same run.
# Usage: bash docs/figures/embree/render.sh OLD_COORDINATOR NEW_COORDINATOR [ROUNDS]   (from the repository root;
# default 3 rounds). Prints each render's summary line and, per scene and build, the median render seconds and
# samples per second (pixels × spp / render seconds; the render phase includes each worker's decoding of the
# scene and its BVH build), on 1 thread and on all.
set -euo pipefail
old=$1
new=$2
rounds=${3:-3}
cargo build --release -q -p photon-core --example raycast
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
target/release/examples/raycast obj "$dir/big.obj" 8
cp -r scenes/meshes "$dir/meshes"
python3 - "$dir" <<'PY'
import sys
d = sys.argv[1]
s = open("scenes/mesh.toml").read()
old = 'file = "meshes/torus.obj"\nmaterial = "gold"\ntransform = { translate = [-0.3, 0.55, -0.3], rotate = [60.0, 20.0, 0.0], scale = 0.75 }'
assert old in s, "scenes/mesh.toml's torus object changed: update this script"
s = s.replace(old, 'file = "big.obj"\nmaterial = "gold"\nlod = 0.0\ntransform = { translate = [-0.35, 0.4, -0.3], scale = 0.4 }')
open(f"{d}/big.toml", "w").write(s)
PY
raw="$dir/raw.txt"
for round in $(seq 1 "$rounds"); do
    for scene in scenes/mesh.toml "$dir/big.toml" scenes/cornell.toml scenes/textured.toml \
        scenes/rooms/cornell-boxes.toml; do
        for threads in 1 "$(nproc)"; do
            if (( round % 2 )); then order="old new"; else order="new old"; fi
            for build in $order; do
                bin=$old
                [ "$build" = new ] && bin=$new
                line=$("$bin" render "$scene" -o "$dir/out.exr" --size 128x128 --spp 16 --integrator path \
                    --threads "$threads" -q --no-cache 2>&1 | tail -1)
                echo "$build $(basename "$scene") $threads $line" | tee -a "$raw"
            done
        done
    done
done
python3 - "$raw" <<'PY'
import collections, re, statistics, sys
secs = collections.defaultdict(list)
for line in open(sys.argv[1]):
    build, scene, threads = line.split()[:3]
    m = re.search(r"([0-9.]+) s render", line)
    secs[(scene, threads, build)].append(float(m.group(1)))
samples = 128 * 128 * 16
print("| scene | threads | before s | after s | before samples/s | after samples/s | after / before |")
print("|---|---:|---:|---:|---:|---:|---:|")
for (scene, threads) in sorted({k[:2] for k in secs}):
    b, a = statistics.median(secs[(scene, threads, "old")]), statistics.median(secs[(scene, threads, "new")])
    name = {"big.toml": "mesh.toml, 1.31M-triangle icosphere"}.get(scene, scene)
    print(f"| {name} | {threads} | {b:.2f} | {a:.2f} | {samples / b / 1e6:.3f} M | {samples / a / 1e6:.3f} M | {b / a:.2f} |")
PY
