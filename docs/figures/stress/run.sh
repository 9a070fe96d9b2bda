#!/usr/bin/env bash
# The stability suite (issue "speed against accuracy", item 4): every scene of scenes/stress/, the two
# scenes with participating media (scenes/fog.toml, scenes/volume-caustic.toml), the PLY mesh scene
# (scenes/ply-mesh.toml), the glTF scene (scenes/gltf-showcase.toml) and the sky (scenes/sky.toml), through all
# five methods at one modest budget, each compared with a high-sample
# reference of the same scene.
#
#   bash docs/figures/stress/run.sh            # from the repository root; about 8 minutes on 2 shared cores
#   SCENES="scenes/fog.toml" CSV=/tmp/fog.csv bash docs/figures/stress/run.sh   # some scenes, rows elsewhere
#
# Writes docs/figures/stress/results.csv and one 8-bit PNG per scene and method (plus the reference's).
# The linear EXRs live in a temporary directory and are deleted on exit: only the PNGs are kept.
#
# References: the path tracer at REF_SPP samples, except in the scenes whose only light is a point light
# seen through glass (point-caustic, light-in-glass, volume-caustic), where no camera path can reach the light
# through the glass, and in grazing-light, whose point light 1 mm above the floor makes the first bounce so bright that a
# 2048-spp path-traced reference is still fireflies; there the reference is `progressive` at REF_PASSES passes.
# References use another seed than the method renders, so a progressive render is not correlated with the
# progressive reference's first passes.
#
# Environment: SCENES (the scene files, default as above), METHODS (default: the five above; vcm and bdpt
# are known too, at 256 passes: `METHODS="vcm bdpt" CSV=docs/figures/stress/vcm.csv`), CSV (default docs/figures/stress/results.csv), PHOTON_BIN
# (default target/release/photon-coordinator, built here if absent), SIZE (96x96),
# THREADS (2), REF_SPP (2048), REF_PASSES (256), LIMIT (90: seconds before a render is stopped and recorded
# as a render-error; large-radius's radius-1 gathers take minutes each).
set -euo pipefail

root=$(cd "$(dirname "$0")/../../.." && pwd)
cd "$root"
out=docs/figures/stress
bin=${PHOTON_BIN:-target/release/photon-coordinator}
size=${SIZE:-96x96}
threads=${THREADS:-2}
ref_spp=${REF_SPP:-2048}
ref_passes=${REF_PASSES:-256}
limit=${LIMIT:-90}
ref_seed=1001
progressive_reference=" point-caustic light-in-glass grazing-light volume-caustic "

if [[ ! -x $bin ]]; then
    cargo build --release -p photon-coordinator
fi

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# The five methods at the budget under test. photon-map, final-gather and progressive use each scene's own
# photon settings (map sizes, k, radius, pass_photons); final-gather's gather rays are set to 16.
# vcm's rows (METHODS=vcm) are run at 256 passes, enough for its mean to be held against the reference's.
# shellcheck disable=SC2206  # the list is meant to split
methods=(${METHODS:-path direct photon-map final-gather progressive})
declare -A budget=(
    [path]="--spp 16"
    [direct]="--spp 16"
    [photon-map]="--spp 4"
    [final-gather]="--spp 2 --set render.photons.final_gather_rays=16"
    [progressive]="--passes 16"
    [vcm]="--passes 256"
    [bdpt]="--passes 256"
)

# render NAME ARGS...: renders to $tmp/NAME.exr; sets `prep` and `secs` from the summary line
# ("… 0.41 s render (+0.59 s prepare) …"), or returns 1 (failed, or stopped after $limit s) with the error,
# if any, in $tmp/NAME.err.
render() {
    local name=$1
    shift
    local line
    line=$(timeout "$limit" "$bin" render "$@" --size "$size" --threads "$threads" -o "$tmp/$name.exr" -q 2>"$tmp/$name.err") ||
        return 1
    secs=$(sed -E 's/.* ([0-9.]+) s render.*/\1/' <<<"$line")
    prep=$(sed -E 's/.*\(\+([0-9.]+) s prepare[,)].*/\1/' <<<"$line")
}

# check NAME: NaN/Inf/negative counts of $tmp/NAME.exr, as "nan,inf,neg"; writes $out/NAME.png from the EXR
# (the same bytes `render -o NAME.png` would write), so every image is rendered once.
check() {
    python3 "$out/exrcheck.py" "$tmp/$1.exr" "$out/$1.png" | sed -E 's/nan=([0-9]+) inf=([0-9]+) neg=([0-9]+).*/\1,\2,\3/'
}

csv=${CSV:-$out/results.csv}
echo "scene,method,budget,reference,prepare_s,render_s,total_s,rmse,rel_mse,rel_bias,nan,inf,neg,status" >"$csv"

# shellcheck disable=SC2206  # the list is meant to split and glob
scene_files=(${SCENES:-scenes/stress/*.toml scenes/fog.toml scenes/volume-caustic.toml scenes/ply-mesh.toml scenes/gltf-showcase.toml scenes/sky.toml})
for scene_file in "${scene_files[@]}"; do
    scene=$(basename "$scene_file" .toml)
    if [[ $progressive_reference == *" $scene "* ]]; then
        ref_method=progressive
        ref_args=(--integrator progressive --passes "$ref_passes")
        ref_budget="progressive $ref_passes passes"
    else
        ref_method=path
        ref_args=(--integrator path --spp "$ref_spp")
        ref_budget="path $ref_spp spp"
    fi
    echo "== $scene (reference: $ref_budget)" >&2
    if ! render "$scene-reference" "$scene_file" "${ref_args[@]}" --seed "$ref_seed"; then
        echo "$scene,reference,$ref_budget,$ref_method,,,,,,,,,,render-error: $(head -c 200 "$tmp/$scene-reference.err" | tr ',\n' ';;')" >>"$csv"
        continue
    fi
    total=$(awk "BEGIN { print $prep + $secs }")
    echo "$scene,reference,$ref_budget,$ref_method,$prep,$secs,$total,0,0,0,$(check "$scene-reference"),ok" >>"$csv"

    for m in "${methods[@]}"; do
        # shellcheck disable=SC2206  # the budget strings are meant to split into arguments
        args=(--integrator "$m" ${budget[$m]})
        name="$scene-$m"
        if ! render "$name" "$scene_file" "${args[@]}"; then
            echo "$scene,$m,${budget[$m]},$ref_method,,,,,,,,,,render-error (over ${limit} s or failed): $(head -c 200 "$tmp/$name.err" | tr ',\n' ';;')" >>"$csv"
            continue
        fi
        total=$(awk "BEGIN { print $prep + $secs }")
        counts=$(check "$name")
        # compare fails on a NaN or infinite pixel; the status column says so instead of stopping the suite.
        if metrics=$("$bin" compare "$tmp/$name.exr" "$tmp/$scene-reference.exr" 2>"$tmp/$name.cmp" | tail -n 1); then
            rmse=$(sed -E 's/.*rmse=([^ ]+) rel_mse.*/\1/' <<<"$metrics")
            rel_mse=$(sed -E 's/.*rel_mse=([^ ]+).*/\1/' <<<"$metrics")
            rel_bias=$(sed -E 's/.*rel_bias=([^ ]+).*/\1/' <<<"$metrics")
            status=ok
            [[ $counts == 0,0,0 ]] || status=negative-values
        else
            rmse="" rel_mse="" rel_bias=""
            status="compare-error: $(head -c 200 "$tmp/$name.cmp" | tr ',\n' ';;')"
        fi
        echo "$scene,$m,${budget[$m]},$ref_method,$prep,$secs,$total,$rmse,$rel_mse,$rel_bias,$counts,$status" >>"$csv"
        echo "   $m: ${total} s, rel_mse $rel_mse, $status" >&2
    done
done
echo "wrote $csv" >&2
