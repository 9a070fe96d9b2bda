#!/usr/bin/env bash
# Ray casting: photon's BVH against Embree 3, tinybvh and obvhs on the same meshes and rays, interleaved in one run.
# Usage: bash docs/figures/embree/run.sh [ROUNDS]   (from the repository root; default 3 rounds)
# tinybvh (BVH8_CPU, through the tinybvh-rs crate) and obvhs (CWBVH) are timed by bench/anchors, a crate of its own
# outside photon's workspace and dependency tree (its src/main.rs says what each is given and how it is counted).
# With BEFORE=path/to/raycast (the example built from an earlier commit), that build is timed too, in the same
# rounds, and the summary gains its column.
# Needs Debian's libembree-dev (installed here if missing; benchmark only, never a dependency of photon), gcc with
# OpenMP, g++, and cargo. Writes docs/figures/embree/raw.txt (every measurement) and summary.md (medians over rounds
# and photon's share of each anchor's rate), which docs/RESULTS.md quotes.
set -euo pipefail
rounds=${1:-3}
here=docs/figures/embree
if [ ! -f /usr/include/embree3/rtcore.h ]; then
    apt-get update -qq && apt-get install -y -qq libembree-dev
fi
cargo build --release -q -p photon-core --example raycast
gcc -O3 -march=native -fopenmp -o target/embree_rays "$here/embree_rays.c" -lembree3 -lm
# From its folder, so that its .cargo/config.toml applies: target/anchors (never the main target dir's locks) and
# -C target-cpu=native, as embree_rays has -march=native.
(cd bench/anchors && cargo build --release -q --locked)
data=$(mktemp -d)
trap 'rm -rf "$data"' EXIT
target/release/examples/raycast write "$data"
threads_all=$(nproc)
: > "$here/raw.txt"
for round in $(seq 1 "$rounds"); do
    for mesh in ico4 ico6 ico8; do
        for threads in 1 "$threads_all"; do
            # Alternate which goes first, so a slow spell of this shared machine hits all alike.
            if (( round % 2 )); then
                order="photon embree tinybvh obvhs ${BEFORE:+before}"
            else
                order="${BEFORE:+before} obvhs tinybvh embree photon"
            fi
            for tool in $order; do
                if [ "$tool" = photon ]; then
                    target/release/examples/raycast time "$data" "$mesh" "$threads" >> "$here/raw.txt"
                elif [ "$tool" = before ]; then
                    "$BEFORE" time "$data" "$mesh" "$threads" | sed 's/^photon /before /' >> "$here/raw.txt"
                elif [ "$tool" != embree ]; then
                    target/anchors/release/anchors "$tool" "$data" "$mesh" "$threads" >> "$here/raw.txt"
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
anchors = ["tinybvh", "obvhs"]
head = ["mesh", "threads", "measure"] + (["before"] if before else []) + ["photon", "Embree"] + anchors
head += ["photon / Embree"] + [f"photon / {a}" for a in anchors]
out = ["| " + " | ".join(head) + " |", "|---|---:|---|" + "---:|" * (len(head) - 3)]


def med(tool, mesh, threads, r):
    v = vals.get((tool, mesh, threads, r))
    return statistics.median(v) if v else None


for mesh in ["ico4", "ico6", "ico8"]:
    for threads in sorted({k[2] for k in vals}, key=int):
        for r in rows:
            p, e = med("photon", mesh, threads, r), med("embree", mesh, threads, r)
            if not p or not e:
                continue
            unit = "" if r in ("build s", "bytes/tri") else " Mrays/s"
            x = [med(a, mesh, threads, r) for a in anchors]
            cells = [names[mesh], threads, r + unit] + ([med("before", mesh, threads, r)] if before else [])
            cells += [p, e] + x + [f"{p / e:.2f}"] + [f"{p / v:.2f}" if v else None for v in x]
            out.append("| " + " | ".join("–" if c is None else f"{c:.3g}" if isinstance(c, float) else c
                                         for c in cells) + " |")
out.append("")
for (tool, mesh, key), ph in sorted(hits.items()):
    if tool != "photon":
        continue
    em = hits.get(("embree", mesh, key), set())
    bf = hits.get(("before", mesh, key))
    out.append(f"- {names[mesh]} {key}: hits photon {sorted(ph)}, Embree {sorted(em)}"
               + "".join(f", {a} {sorted(hits.get((a, mesh, key), set()))}" for a in anchors)
               + (f", before {sorted(bf)}" if bf else ""))
open(sys.argv[2], "w").write("\n".join(out) + "\n")
print("\n".join(out))
PY
