#!/usr/bin/env bash
# The level-of-detail table of docs/RESULTS.md ("Level of detail (issue 13)"): the Stanford bunny (get-bunny.sh)
# rendered from 16, 64, 256 and 1024 units (its nearest point 12.2 to 1020 units away), with every triangle
# (bunny-full.toml, lod = 0) and with the default lod = 1 (bunny.toml), without the prepared cache, on one
# in-process worker. Per distance: triangles before and after (the coordinator's log), the bytes shipped to the
# worker (the scene blob, and the frame of a few hundred bytes), prepare and render seconds (the summary line),
# and the relMSE of the lod image against the full one (`compare`; same seed, so only the geometry differs),
# beside the render's own noise: the relMSE of the full mesh with another seed against the full mesh.
#
#   bash docs/figures/lod/run.sh          # PHOTON_BIN=target/debug for another build of photon-coordinator
#   LOD=0.25 bash docs/figures/lod/run.sh # another lod than bunny.toml's 1 (a copy of it beside it, removed after)
set -euo pipefail
cd "$(dirname "$0")/../../.."
bin="${PHOTON_BIN:-target/release}/photon-coordinator"
here=docs/figures/lod
[ -f "$here/bunny.obj" ] || bash "$here/get-bunny.sh"
lod_scene="$here/bunny.toml"
if [ -n "${LOD:-}" ]; then
  lod_scene="$here/bunny-lod-$LOD.toml"
  sed "s/^lod = 1.0\$/lod = $LOD/" "$here/bunny.toml" >"$lod_scene"
fi
rel_mse() { "$bin" compare "$1" "$2" | tr ' ' '\n' | sed -n 's/^rel_mse=//p' | xargs printf '%.2e'; }
out="$(mktemp -d)"
trap 'rm -rf "$out"; [ "$lod_scene" = "$here/bunny.toml" ] || rm -f "$lod_scene"' EXIT
l="lod ${LOD:-1}"
echo "| camera distance | triangles | → with $l | bytes shipped | → with $l | prepare s | → with $l | render s | → with $l | relMSE of $l | relMSE of seed 2 |"
echo "|---|---|---|---|---|---|---|---|---|---|---|"
for d in 16 64 256 1024; do
  row="| $d |"
  declare -A tri=() bytes=() prep=() rend=()
  for kind in full lod; do
    scene="$lod_scene"
    [ "$kind" = full ] && scene="$here/bunny-full.toml"
    RUST_LOG=photon_core=info "$bin" render "$scene" -o "$out/$kind-$d.exr" -q --no-cache \
      --set "camera.eye=[0.0, 4.8, $d.0]" >"$out/$kind-$d.txt" 2>"$out/$kind-$d.log"
    summary=$(tail -n 1 "$out/$kind-$d.txt")
    rend[$kind]=$(echo "$summary" | sed -E 's/.* ([0-9.]+) s render.*/\1/')
    prep[$kind]=$(echo "$summary" | sed -E 's/.*\(\+([0-9.]+) s prepare.*/\1/')
    bytes[$kind]=$(echo "$summary" | sed -E 's/.* ([0-9]+) blob bytes shipped.*/\1/')
  done
  line=$(grep -E 'mesh .*bunny.obj: [0-9]+ triangles' "$out/lod-$d.log" | tail -n 1)
  tri[full]=$(echo "$line" | sed -E 's/.*bunny.obj: ([0-9]+) triangles.*/\1/')
  tri[lod]=$(echo "$line" | sed -E 's/.*→ ([0-9]+) \(lod.*/\1/; t; s/.*/(all)/')
  "$bin" render "$here/bunny-full.toml" -o "$out/seed-$d.exr" -q --no-cache --seed 2 \
    --set "camera.eye=[0.0, 4.8, $d.0]" >/dev/null
  rel=$(rel_mse "$out/lod-$d.exr" "$out/full-$d.exr")
  noise=$(rel_mse "$out/seed-$d.exr" "$out/full-$d.exr")
  echo "$row ${tri[full]} | ${tri[lod]} | ${bytes[full]} | ${bytes[lod]} | ${prep[full]} | ${prep[lod]} | ${rend[full]} | ${rend[lod]} | $rel | $noise |"
  unset tri bytes prep rend
done
