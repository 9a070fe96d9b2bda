#!/usr/bin/env bash
# Images before and after a change of the BVH: renders every shipped scene (scenes/, scenes/rooms/, scenes/stress/,
# scenes/regressions/) with its own method at 64×64 with two coordinator builds, compares the EXR files byte for
# byte, and for those that differ prints how many pixels differ and by how much (core/examples/exr_diff.rs).
# Usage: bash docs/figures/bvh-images/run.sh OLD_COORDINATOR NEW_COORDINATOR (from the repository root).
set -euo pipefail
old=$1
new=$2
cargo build --release -q -p photon-core --example exr_diff
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
same=0
differ=0
for scene in scenes/*.toml scenes/rooms/*.toml scenes/stress/*.toml scenes/regressions/*.toml; do
    name=$(echo "$scene" | tr / _)
    # Small and quick: 4 spp, 4 passes, at most 20 000 photon paths per map or pass.
    args=(render "$scene" --size 64x64 --spp 4 --passes 4 --photons 20000 --threads 2 -q --no-cache)
    if ! "$old" "${args[@]}" -o "$out/$name.old.exr" > /dev/null 2>&1; then
        echo "skip $scene (the old build cannot render it)"
        continue
    fi
    "$new" "${args[@]}" -o "$out/$name.new.exr" > /dev/null
    if cmp -s "$out/$name.old.exr" "$out/$name.new.exr"; then
        same=$((same + 1))
        echo "same   $scene"
    else
        differ=$((differ + 1))
        # pixels, differing pixels, largest absolute and relative channel difference, the two means
        read -r px dpx dabs drel ma mb < <(target/release/examples/exr_diff "$out/$name.old.exr" "$out/$name.new.exr")
        echo "DIFFER $scene: $dpx of $px pixels, max |Δ| $dabs (relative $drel), mean $ma -> $mb"
    fi
done
echo "$same scenes byte-identical, $differ differ"
