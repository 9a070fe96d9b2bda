#!/usr/bin/env bash
# The numbers of docs/RESULTS.md, "Textures, bump and normal maps (issue 13)": what surface detail costs.
#   bash docs/figures/textures/run.sh [BIN]   (BIN: the folder of photon-coordinator; default target/release)
# 1. scenes/textured.toml against the same scene with every texture replaced by its mean constant and no bump or
#    normal map, path tracing, 3 interleaved runs each, median render seconds;
# 2. the texture blobs' sizes (what a worker receives once per image);
# 3. the image of textured.toml rendered in-process and on two --local workers: identical bytes.
set -euo pipefail
cd "$(dirname "$0")/../../.."
BIN=${1:-target/release}
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
# The untextured twin: constants for the checker (its cells' mean), the wood (its texels' mean), no bump, no
# normal map. Written next to the scene so its relative paths still resolve.
FLAT=scenes/.textured-flat.toml
trap 'rm -rf "$OUT" "$FLAT"' EXIT
sed -e 's|^albedo = { checker = .*|albedo = [0.46, 0.45, 0.43]|' \
    -e 's|^albedo = { image = "textures/wood.png" }|albedo = [0.33, 0.18, 0.08]|' \
    -e '/^bump = /d' -e '/^normal_map = /d' scenes/textured.toml > "$FLAT"
secs() { sed -n 's/.*, \([0-9.]*\) s render .*/\1/p' | head -1; }
median() { sort -g | sed -n 2p; }
run() { "$BIN/photon-coordinator" render "$1" -o "$OUT/x.exr" --size 256x256 --spp 32 --integrator path --no-cache | secs; }
: > "$OUT/t"; : > "$OUT/f"
for i in 1 2 3; do
  run scenes/textured.toml >> "$OUT/t"
  run "$FLAT" >> "$OUT/f"
done
t=$(median < "$OUT/t"); f=$(median < "$OUT/f")
echo "render seconds, 256x256, 32 spp, path, median of 3: textured $t, untextured $f, ratio $(python3 -c "print(round($t/$f, 3))")"
python3 - <<'PY'
import struct, zlib
for name in ["wood", "bricks", "ridges-normal"]:
    data = open(f"scenes/textures/{name}.png", "rb").read()
    w, h, depth, ctype = struct.unpack(">IIBB", data[16:26])
    ch = {0: 1, 2: 3}[ctype]
    print(f"{name}.png: {len(data)} B file, {w}x{h}x{ch} texels, blob {w*h*ch + 29} B")
PY
"$BIN/photon-coordinator" render scenes/textured.toml -o "$OUT/a.exr" --size 96x96 --spp 8 -q --no-cache
"$BIN/photon-coordinator" render scenes/textured.toml -o "$OUT/b.exr" --size 96x96 --spp 8 -q --no-cache --local 2 \
  | grep -o '[0-9]* blob bytes shipped' || true
cmp "$OUT/a.exr" "$OUT/b.exr" && echo "in-process and 2 local workers: identical bytes"
