#!/usr/bin/env bash
# The fixed cost of a render — what a one-sample `previs render` spends before and after its
# sample (`--timing`: load_s, device_s, setup_s, readback_s, total_s) — of previs builds on the
# benchmark scenes at 640×480, max depth 8, 1 spp:
#   bunny       bench_scenes.cpp's bunny under rooitou_park_1k.hdr (69K triangles)
#   area        bench/scenes/area_lights_mirror.gltf (--photons off)
#   caustics    bench/scenes/caustics_glass.gltf (trace_paths, trace_photons and the grid passes)
# This is what separates previs from Cycles at low sample counts in bench/compare_blender.sh,
# which counts it as Cycles' scene sync is counted. The builds alternate within each run; the
# medians over the runs are printed per workload and build, with total_s's ratio to the first.
# Each build renders each workload once before the runs, so Mesa's shader cache and previs's
# specialised-SPIR-V cache (gpu/spirv_cache.h) are warm, as on a box that has rendered the scene
# before; PREVIS_SHADER_CACHE_DISABLE=1 in the environment measures the cold specialisation.
#
#   bench/start_time.sh [--runs N] [--only WORKLOAD,...] PREVIS_BINARY...
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
runs=5
known=(bunny area caustics)
source "$root/bench/build_comparison.sh"
parse_build_comparison_options "$@"
source "$root/bench/scenes/bench_scene.sh"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
fields=(load_s device_s setup_s readback_s total_s)

stages() {  # binary workload seed: prints the fields' values
    local args
    case "$2" in
        bunny) bench_scene bunny; args=("$scene" --env "$env") ;;
        area) bench_scene area-lights; args=("$scene" "${previs_args[@]}") ;;
        caustics) args=("$root/bench/scenes/caustics_glass.gltf" --photons 65536) ;;
    esac
    local line
    line=$("$1" render "${args[@]}" --width 640 --height 480 --max-depth 8 --spp 1 --no-meter \
        --quiet --timing --seed "$3" --out "$work/out.exr" 2>&1 | grep '^timing ')
    for f in "${fields[@]}"; do sed -n "s/.* $f=\([0-9.]*\).*/\1/p" <<<"$line"; done | tr '\n' ' '
    echo
}


echo "Seconds, medians of $runs runs:"
echo "| workload | build |$(printf ' %s |' "${fields[@]}") total_s to the first build |"
echo "|---|---|---|---|---|---|---|---|"
for workload in "${workloads[@]}"; do
    for b in "${binaries[@]}"; do stages "$b" "$workload" 0 >/dev/null; done  # warm the caches
    declare -A values=()
    for ((r = 1; r <= runs; ++r)); do
        for b in "${binaries[@]}"; do
            read -r -a v < <(stages "$b" "$workload" "$r")
            for i in "${!fields[@]}"; do values[$b,$i]+="${v[$i]} "; done
        done
    done
    first=""
    for b in "${binaries[@]}"; do
        row="| $workload | $b |"
        for i in "${!fields[@]}"; do
            m=$(tr ' ' '\n' <<<"${values[$b,$i]}" | grep . | median)
            row+=" $(printf '%.3f' "$m") |"
            [[ ${fields[$i]} == total_s ]] && total=$m
        done
        [[ -z $first ]] && first=$total
        row+=" $(awk -v a="$total" -v b="$first" 'BEGIN { printf "%.2f", a / b }') |"
        echo "$row"
    done
    unset values
done
