#!/usr/bin/env bash
# `--integrator auto` against each single method at its default settings, at equal wall time (all cores of this
# machine): the relative MSE of each image against the scene's own reference, and what auto chose. Rows go to
# docs/figures/auto/results.csv (or CSV); the images and each render's output stay in WORK (a temporary folder
# unless set), where a second run reuses the references. About 12 minutes a room on 2 cores at the default times,
# 7 for fog and volume-caustic, plus 1 to 5 minutes for each reference (20 for the volume caustic's two).
#
#   bash docs/figures/auto/run.sh                                # the rooms and the two media scenes, 5 20 40 s
#   TIMES="20" SCENES="cornell-spheres" bash docs/figures/auto/run.sh
#   METHODS="" bash docs/figures/auto/run.sh                    # auto alone (the single methods' rows do not change
#                                                                # with auto's model)
set -euo pipefail
cd "$(dirname "$0")/../../.."
bin=${PHOTON_BIN:-target/release}
[ -x "$bin/photon-coordinator" ] || cargo build --release -p photon-coordinator -p photon-worker
pc=$bin/photon-coordinator
work=${WORK:-$(mktemp -d)}
out=${CSV:-docs/figures/auto/results.csv}
echo "scene,seconds,method,chosen,passes,rel_mse" > "$out"
for name in ${SCENES:-cornell-boxes cornell-spheres fog volume-caustic}; do
  # The scene, its size, its reference's method and budget (the path tracer where every path can be found from
  # the camera; progressive photon mapping for the volume caustic, which only photon methods render), and the
  # single methods compared (vcm and bdpt fall back to the path tracer in a scene with media).
  #
  # The volume caustic's reference is biased: progressive photon mapping blurs the caustic's rims by its radius.
  # One started at the scene's own radius (0.24, 2 % of its diagonal) favours the renders that share its radius
  # sequence: they carry the same blur. So it starts at a quarter of it, 0.06, and runs 2048 passes, and there
  # are two of them, of different seeds: an image's error is the mean of its relative MSE against each, less
  # half the references' relative MSE against each other (each reference's own noise, which would otherwise add
  # to every method's error alike). docs/RESULTS.md, "Choosing the method, third part".
  seeds="7"
  case $name in
    cornell-boxes|cornell-spheres) scene=scenes/rooms/$name.toml size=256x256 ref=(--spp 4096) methods="path progressive vcm bdpt" ;;
    fog) scene=scenes/fog.toml size=96x96 ref=(--spp 4096) methods="path progressive" ;;
    volume-caustic) scene=scenes/volume-caustic.toml size=96x72 methods="progressive" seeds="8 9"
      ref=(--passes 2048 --set render.photons.radius=0.06) ;;
    *) echo "unknown scene $name" >&2; exit 2 ;;
  esac
  references=()
  for seed in $seeds; do
    reference=$work/$name-ref-$seed.exr
    [ -f "$reference" ] || "$pc" reference "$scene" -o "$reference" --size "$size" "${ref[@]}" --seed "$seed" >/dev/null
    references+=("$reference")
  done
  rel_mse() { "$pc" compare "$1" "$2" | grep -o 'rel_mse=[^ ]*' | cut -d= -f2; }
  # Half the references' error against each other: each one's own noise (0 with one reference).
  noise=0
  case ${#references[@]} in
    1) ;;
    2) mutual=$(rel_mse "${references[0]}" "${references[1]}")
       noise=$(awk -v e="$mutual" 'BEGIN { print e / 2 }') ;;
    *) echo "$name: one or two references, not ${#references[@]}" >&2; exit 2 ;;
  esac
  for t in ${TIMES:-5 20 40}; do
    for m in auto ${METHODS-$methods}; do
      img=$work/$name-$m-$t.exr
      "$pc" render "$scene" -o "$img" --size "$size" --integrator "$m" --time "${t}s" -q --no-cache > "$work/$name-$m-$t.txt"
      summary=$(tail -n 1 "$work/$name-$m-$t.txt")
      # The method that rendered (auto's choice) and its passes or samples, from the summary line.
      chosen=$(sed -E 's/.*stopped [^,]*, ([a-z-]+), .*/\1/' <<<"$summary")
      passes=$(sed -E 's/^[^,]*, ([0-9]+) (spp|passes).*/\1/' <<<"$summary")
      errors=()
      for r in "${references[@]}"; do errors+=("$(rel_mse "$img" "$r")"); done
      e=$(printf '%s\n' "${errors[@]}" | awk -v noise="$noise" -v want=${#references[@]} '
        /^[0-9.eE+-]+$/ { s += $1; n++ } END { if (n != want) exit 1; printf "%.6g\n", s / n - noise }')
      echo "$name,$t,$m,$chosen,$passes,$e" | tee -a "$out"
    done
  done
done
