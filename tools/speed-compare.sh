#!/usr/bin/env bash
# Interleaved wall-clock medians of two builds on the same renders: the README's render (scenes/cornell.toml, its
# own progressive settings), the same scene with vcm, and with the path tracer on 2 local workers (sums travel
# over loopback). Prints one line per render: the median seconds of each build over RUNS runs and their ratio, and
# the median cores kept busy (CPU seconds of the command and its workers over wall seconds) of each build.
#
#   bash tools/speed-compare.sh BEFORE_BIN_DIR AFTER_BIN_DIR [RUNS]
set -euo pipefail
before=${1:?usage: tools/speed-compare.sh BEFORE_BIN AFTER_BIN [RUNS]}
after=${2:?usage: tools/speed-compare.sh BEFORE_BIN AFTER_BIN [RUNS]}
runs=${3:-5}
cd "$(dirname "$0")/.."
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
renders=(
  "readme|scenes/cornell.toml"
  "vcm|scenes/cornell.toml --integrator vcm --passes 16 --size 256x256"
  "path-local2|scenes/cornell.toml --integrator path --spp 16 --local 2"
)
median() { sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
for r in "${renders[@]}"; do
  name=${r%%|*}
  args=${r#*|}
  : >"$out/$name.before"
  : >"$out/$name.after"
  : >"$out/$name.before.busy"
  : >"$out/$name.after.busy"
  for _ in $(seq "$runs"); do
    for which in before after; do
      bin=$before
      [ "$which" = after ] && bin=$after
      # shellcheck disable=SC2086
      /usr/bin/time -f "%e %U %S" -o "$out/time" \
        "$bin/photon-coordinator" render $args -o "$out/image.exr" -q --no-cache >/dev/null 2>&1
      read -r wall user sys <"$out/time"
      echo "$wall" >>"$out/$name.$which"
      echo "scale=3; ($user + $sys) / $wall" | bc >>"$out/$name.$which.busy"
    done
  done
  b=$(median <"$out/$name.before")
  a=$(median <"$out/$name.after")
  bb=$(median <"$out/$name.before.busy")
  ab=$(median <"$out/$name.after.busy")
  echo "$name before ${b}s after ${a}s ratio $(echo "scale=3; $a / $b" | bc) cores busy before $bb after $ab"
done
