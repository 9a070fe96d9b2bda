#!/usr/bin/env bash
# Ray casting: photon's BVH against Embree 3 on the same meshes and rays, interleaved in one run.
# Usage: bash docs/figures/embree/run.sh [ROUNDS]   (from the repository root; default 3 rounds)
# With BEFORE=path/to/raycast (the example built from an earlier commit), that build is timed too, in the same
# rounds, and the summary gains its column.
# Needs Debian's libembree-dev (installed here if missing; benchmark only, never a dependency of photon), gcc with
# OpenMP, and cargo. Writes docs/figures/embree/raw.txt (every measurement) and summary.md (medians over rounds and
# photon's share of Embree's rate), which docs/RESULTS.md quotes.
set -euo pipefail
rounds=${1:-3}
here=docs/figures/embree
if [ ! -f /usr/include/embree3/rtcore.h ]; then
    apt-get update -qq && apt-get install -y -qq libembree-dev
fi
cargo build --release -q -p photon-core --example raycast
gcc -O3 -march=native -fopenmp -o target/embree_rays "$here/embree_rays.c" -lembree3 -lm
data=$(mktemp -d)
trap 'rm -rf "$data"' EXIT
target/release/examples/raycast write "$data"
threads_all=$(nproc)
: > "$here/raw.txt"
for round in $(seq 1 "$rounds"); do
    for mesh in ico4 ico6 ico8; do
        for threads in 1 "$threads_all"; do
            # Alternate which goes first, so a slow spell of this shared machine hits both alike.
            if (( round % 2 )); then
                order="photon embree ${BEFORE:+before}"
            else
                order="${BEFORE:+before} embree photon"
            fi
            for tool in $order; do
                if [ "$tool" = photon ]; then
                    target/release/examples/raycast time "$data" "$mesh" "$threads" >> "$here/raw.txt"
                elif [ "$tool" = before ]; then
                    "$BEFORE" time "$data" "$mesh" "$threads" | sed 's/^photon /before /' >> "$here/raw.txt"
                else
                    target/embree_rays "$data" "$mesh" "$threads" >> "$here/raw.txt"
                fi
            done
        done
    done
    echo "round $round done"
done
python3 - "$here/raw.txt" "$here/summary.md" <<'PY'
import collections, statistics, sys
vals = collections.defaultdict(list)
hits = {}
for line in open(sys.argv[1]):
    w = line.split()
    if w[3] == "build":
        vals[(w[0], w[1], w[2], "build s")].append(float(w[4]))
        vals[(w[0], w[1], w[2], "bytes/tri")].append(float(w[5]))
    else:
        key = f"{w[3]} {w[4]}"
        vals[(w[0], w[1], w[2], key)].append(float(w[5]))
        hits.setdefault((w[0], w[1], key), set()).add(int(w[6]))
names = {"ico4": "5k", "ico6": "82k", "ico8": "1.31M"}
rows = ["closest coherent", "closest incoherent", "any coherent", "any incoherent", "build s", "bytes/tri"]
before = any(k[0] == "before" for k in vals)
head = "| mesh | threads | measure | " + ("before | " if before else "") + "photon | Embree | photon / Embree |"
out = [head, "|---|---:|---|" + ("---:|" if before else "") + "---:|---:|---:|"]
for mesh in ["ico4", "ico6", "ico8"]:
    for threads in sorted({k[2] for k in vals}, key=int):
        for r in rows:
            p, e = vals.get(("photon", mesh, threads, r)), vals.get(("embree", mesh, threads, r))
            if not p or not e:
                continue
            p, e = statistics.median(p), statistics.median(e)
            unit = "" if r in ("build s", "bytes/tri") else " Mrays/s"
            b = vals.get(("before", mesh, threads, r))
            col = (f"{statistics.median(b):.3g} | " if b else "– | ") if before else ""
            out.append(f"| {names[mesh]} | {threads} | {r}{unit} | {col}{p:.3g} | {e:.3g} | {p / e:.2f} |")
out.append("")
for (tool, mesh, key), ph in sorted(hits.items()):
    if tool != "photon":
        continue
    em = hits.get(("embree", mesh, key), set())
    bf = hits.get(("before", mesh, key))
    out.append(f"- {names[mesh]} {key}: hits photon {sorted(ph)}, Embree {sorted(em)}"
               + (f", before {sorted(bf)}" if bf else ""))
open(sys.argv[2], "w").write("\n".join(out) + "\n")
print("\n".join(out))
PY
