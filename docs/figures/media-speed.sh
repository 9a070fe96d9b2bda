#!/usr/bin/env bash
# Same-run speed of scenes without media (docs/RESULTS.md, "Participating media"): two coordinator builds,
# BEFORE and AFTER, alternating job by job, 5 rounds, 2 threads; prints every render's seconds, then the medians
# and their ratio.
#
#   bash docs/figures/media-speed.sh BEFORE/photon-coordinator AFTER/photon-coordinator
set -euo pipefail
cd "$(dirname "$0")/../.."
before=$1 after=$2
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
jobs=(
  "scenes/cornell.toml --integrator path --size 256x256 --spp 32"
  "scenes/cornell.toml --integrator progressive --size 256x256 --passes 24"
  "scenes/cornell.toml --integrator final-gather --size 128x128 --spp 2 --photons 100000"
  "scenes/caustic-point.toml --integrator photon-map --size 256x192 --spp 16"
)
for round in 1 2 3 4 5; do
  for j in "${jobs[@]}"; do
    for build in before after; do
      bin=$before
      [ "$build" = after ] && bin=$after
      # shellcheck disable=SC2086  # the job is meant to split into arguments
      line=$("$bin" render $j -o "$out/speed.exr" -q --threads 2)
      echo "$round|$j|$build|$(sed -E 's/.* ([0-9.]+) s render.*/\1/' <<<"$line")"
    done
  done
done | tee "$out/times.txt"
python3 - "$out/times.txt" <<'PY'
import collections, statistics, sys
d = collections.defaultdict(list)
for line in open(sys.argv[1]):
    _, job, build, secs = line.strip().split("|")
    d[(job, build)].append(float(secs))
for job in dict.fromkeys(k[0] for k in d):
    b, a = statistics.median(d[(job, "before")]), statistics.median(d[(job, "after")])
    print(f"| `{job.removeprefix('scenes/')}` | {b:.3f} | {a:.3f} | {a / b:.3f} |")
PY
