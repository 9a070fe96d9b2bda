#!/usr/bin/env bash
# What checkpoints cost: the README render without checkpoints, with the default (every 5 s) and every 1 s, in
# turn, RUNS times; prints each one's median wall time and its ratio to none.
#
#   bash tools/checkpoint-cost.sh BIN_DIR [RUNS]      # BIN_DIR holds a release photon-coordinator
set -euo pipefail
bin=${1:?usage: tools/checkpoint-cost.sh BIN_DIR [RUNS]}
runs=${2:-5}
cd "$(dirname "$0")/.."
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
for _ in $(seq "$runs"); do
  for v in none every-5s every-1s; do
    case $v in none) extra=(--no-checkpoint) ;; every-5s) extra=() ;; every-1s) extra=(--checkpoint-every 1s) ;; esac
    /usr/bin/time -f "$v %e" -a -o "$out/times" \
      "$bin/photon-coordinator" render scenes/cornell.toml -o "$out/image.exr" -q --no-cache "${extra[@]}" >/dev/null 2>&1
  done
done
python3 - "$out/times" <<'P'
import statistics, sys, collections
t = collections.defaultdict(list)
for line in open(sys.argv[1]):
    v, w = line.split()
    t[v].append(float(w))
none = statistics.median(t["none"])
for v in ("none", "every-5s", "every-1s"):
    m = statistics.median(t[v])
    print(f"{v}: median {m:.2f} s, ratio {m / none:.3f}")
P
