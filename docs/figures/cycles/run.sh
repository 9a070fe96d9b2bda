#!/usr/bin/env bash
# photon against Blender's Cycles on four simple scenes (docs/figures/cycles/compare.py says which and how the
# material models map). Usage: bash docs/figures/cycles/run.sh   (from the repository root)
# Needs Debian's blender (installed here if missing; a benchmark peer, never a dependency of photon). Writes the
# images and scenes to target/cycles/ and the table to docs/figures/cycles/summary.md, which docs/RESULTS.md
# quotes.
set -euo pipefail
here=docs/figures/cycles
if ! command -v blender > /dev/null; then
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends blender
fi
cargo build --release -q -p photon-coordinator
out=target/cycles
mkdir -p "$out"
blender -b --factory-startup -P "$here/compare.py" -- "$PWD/$out" "$PWD/target/release/photon-coordinator" \
    | tee "$out/log.txt"
grep '^|' "$out/log.txt" > "$here/summary.md"
cat "$here/summary.md"
