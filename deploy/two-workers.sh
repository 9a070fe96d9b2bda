#!/usr/bin/env bash
# The two-worker local test: start two photon workers on loopback, render a scene on both, compare the image
# with the in-process render of the same scene (they must be identical), and stop the workers.
#
#   bash deploy/two-workers.sh [SCENE] [extra render options...]
#
# Default scene: scenes/cornell.toml at 256x256, path traced at 16 spp. Output in ./two-workers/.
set -euo pipefail
cd "$(dirname "$0")/.."
scene=${1:-scenes/cornell.toml}
shift || true
extra=("$@")
if [ ${#extra[@]} -eq 0 ]; then extra=(--size 256x256 --integrator path --spp 16); fi

cargo build --release -q -p photon-coordinator -p photon-worker
bin=target/release
out=two-workers
mkdir -p "$out"

pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; }
trap cleanup EXIT

addrs=()
for i in 1 2; do
  # Port 0: the kernel picks a free port; the worker prints it on its first line.
  coproc_out="$out/worker-$i.out"
  "$bin/photon-worker" --listen 127.0.0.1:0 --threads 1 >"$coproc_out" 2>"$out/worker-$i.log" &
  pids+=($!)
  for _ in $(seq 100); do
    if grep -q "listening on" "$coproc_out" 2>/dev/null; then break; fi
    sleep 0.1
  done
  addr=$(sed -n 's/^photon-worker listening on //p' "$coproc_out")
  [ -n "$addr" ] || { echo "worker $i did not start; see $out/worker-$i.log" >&2; exit 1; }
  echo "worker $i on $addr"
  addrs+=("$addr")
done

workers=$(IFS=,; echo "${addrs[*]}")
"$bin/photon-coordinator" render "$scene" "${extra[@]}" --workers "$workers" -o "$out/two-workers.exr"
"$bin/photon-coordinator" render "$scene" "${extra[@]}" -q -o "$out/in-process.exr"
if cmp -s "$out/two-workers.exr" "$out/in-process.exr"; then
  echo "OK: two workers and the in-process render gave identical images ($out/two-workers.exr)"
else
  echo "FAIL: the two-worker image differs from the in-process one" >&2
  exit 1
fi
