#!/usr/bin/env bash
# Renders every shipped scene with every method, in-process and on 2 local workers, at a small size and budget,
# and prints one line per render: the scene, the method, where it rendered, and the SHA-256 of its EXR (or the
# exit status when the render was refused). Two builds that print the same lines render the same bits.
#
#   bash tools/same-bits.sh target/release > after.txt      # BIN_DIR holds photon-coordinator and photon-worker
#   diff before.txt after.txt
#
# The size and budgets keep the whole run to a few minutes on 2 cores; SAME_BITS_ARGS replaces them.
set -uo pipefail
bin=${1:?usage: tools/same-bits.sh BIN_DIR}
cd "$(dirname "$0")/.."
args=${SAME_BITS_ARGS:---size 20x16 --spp 2 --passes 3 --photons 3000}
methods="path direct photon-map final-gather progressive vcm bdpt lt"
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
for scene in scenes/*.toml scenes/rooms/*.toml scenes/stress/*.toml scenes/regressions/*.toml; do
  for m in $methods; do
    for where in in-process local2; do
      farm=()
      [ "$where" = local2 ] && farm=(--local 2)
      exr="$out/image.exr"
      rm -f "$exr"
      # shellcheck disable=SC2086
      if "$bin/photon-coordinator" render "$scene" -o "$exr" -q --no-cache --integrator "$m" $args \
          --threads 2 "${farm[@]}" >/dev/null 2>"$out/err"; then
        echo "$scene $m $where $(sha256sum "$exr" | cut -c1-16)"
      else
        echo "$scene $m $where refused ($?)"
      fi
    done
  done
done
