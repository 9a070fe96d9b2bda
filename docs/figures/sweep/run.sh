#!/usr/bin/env bash
# The sweeps of docs/RESULTS.md ("Error against time"): two references, two sweeps, each sweep's folder (sweep.csv,
# sweep.svg, sweep.png, report.html and its images) kept as docs/figures/sweep/{cornell,caustic}/. About 6 minutes
# on 2 idle cores. PHOTON_BIN: the folder of a release build (default: target/release, built when missing).
set -euo pipefail
cd "$(dirname "$0")/../../.."
bin=${PHOTON_BIN:-target/release}
[ -x "$bin/photon-coordinator" ] || cargo build --release -p photon-coordinator -p photon-worker
pc="$bin/photon-coordinator"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
out=docs/figures/sweep
time "$pc" reference scenes/cornell.toml -o "$work/cornell-ref.exr" --spp 2048 --size 96x96
time "$pc" sweep scenes/cornell.toml --reference "$work/cornell-ref.exr" \
  --methods path,photon-map,final-gather,progressive --budget 1,2,4,8,16,32 --out "$work/cornell"
time "$pc" reference scenes/caustic-point.toml -o "$work/caustic-ref.exr" --passes 2048 --size 96x72
time "$pc" sweep scenes/caustic-point.toml --reference "$work/caustic-ref.exr" \
  --methods path,photon-map,final-gather,progressive --budget 1,2,4,8,16,32 --out "$work/caustic"
for s in cornell caustic; do
  rm -rf "${out:?}/$s"
  cp -r "$work/$s" "$out/$s"
done
