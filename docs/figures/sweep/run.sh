#!/usr/bin/env bash
# The sweeps of docs/RESULTS.md ("Error against time", "Participating media"): for each scene a reference and a
# sweep, each sweep's folder (sweep.csv, sweep.svg, sweep.png, report.html and its images) kept as
# docs/figures/sweep/NAME/. About 6 minutes on 2 idle cores for cornell and caustic, 12 for fog and
# volume-caustic. PHOTON_BIN: the folder of a release build (default: target/release, built when missing).
#
#   bash docs/figures/sweep/run.sh                         # all four
#   bash docs/figures/sweep/run.sh fog volume-caustic      # some of them
#   bash docs/figures/sweep/run.sh rooms-boxes rooms-spheres   # the Mitsuba rooms (not in the default four)
set -euo pipefail
cd "$(dirname "$0")/../../.."
bin=${PHOTON_BIN:-target/release}
[ -x "$bin/photon-coordinator" ] && [ -x "$bin/photon-sweep" ] ||
  cargo build --release -p photon-coordinator -p photon-worker -p photon-sweep
pc="$bin/photon-coordinator"
sweep_bin="$bin/photon-sweep"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
out=docs/figures/sweep
methods=path,photon-map,final-gather,progressive

# sweep NAME SCENE SIZE REFERENCE-ARGS... -- SWEEP-ARGS... (budgets 1,2,4,8,16,32 unless BUDGET is set)
sweep() {
  local name=$1 scene=$2 size=$3
  shift 3
  local ref=()
  while [ "$1" != "--" ]; do ref+=("$1"); shift; done
  shift
  time "$pc" reference "$scene" -o "$work/$name-ref.exr" --size "$size" "${ref[@]}"
  time "$sweep_bin" "$scene" --reference "$work/$name-ref.exr" --budget "${BUDGET:-1,2,4,8,16,32}" --out "$work/$name" "$@"
  rm -rf "${out:?}/$name"
  cp -r "$work/$name" "$out/$name"
}

for s in "${@:-cornell caustic fog volume-caustic}"; do
  for name in $s; do
    case $name in
      cornell) sweep cornell scenes/cornell.toml 96x96 --spp 2048 -- --methods "$methods" ;;
      caustic) sweep caustic scenes/caustic-point.toml 96x72 --passes 2048 -- --methods "$methods" ;;
      # Fog: the path tracer's reference (no caustic: the lamp is seen through no glass); direct light only is
      # swept too, to show what multiple scattering adds.
      fog) sweep fog scenes/fog.toml 96x96 --spp 4096 -- --methods "path,direct,photon-map,final-gather,progressive" ;;
      # The volume caustic: only photon methods render it, so the reference is progressive photon mapping.
      volume-caustic) sweep volume-caustic scenes/volume-caustic.toml 96x72 --passes 1024 -- --methods "$methods" ;;
      # The Mitsuba rooms at their own 256×256 with vcm beside the others, budgets from under 1 s to about 30 s
      # for the path tracer (b = 256) and a few minutes for vcm (1024 passes); the references are the path
      # tracer's (an area light: every path can be found from the camera), about 5 minutes each. About 20
      # minutes a room on 2 idle cores.
      rooms-boxes) BUDGET=1,2,4,8,16,32,64,128,256 sweep rooms-boxes scenes/rooms/cornell-boxes.toml 256x256 \
        --spp 8192 -- --methods path,final-gather,progressive,vcm ;;
      rooms-spheres) BUDGET=1,2,4,8,16,32,64,128,256 sweep rooms-spheres scenes/rooms/cornell-spheres.toml 256x256 \
        --spp 8192 -- --methods path,final-gather,progressive,vcm ;;
      *) echo "unknown sweep $name" >&2; exit 2 ;;
    esac
  done
done
