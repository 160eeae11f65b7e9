#!/usr/bin/env bash
# GPU time of previs builds on four workloads at 640×480, max depth 8 — the shader's own cost,
# without device creation, BVH build or pipeline compile (`previs render --timing`'s gpu_s):
#   bunny       bench_scenes.cpp's bunny under rooitou_park_1k.hdr, 16 spp in 16-sample dispatches
#   area        bench/scenes/area_lights_mirror.gltf (--photons off), 16 spp likewise
#   preview     the same scene as 16 one-sample dispatches (a checkpoint after every sample ends a
#               dispatch), as live preview frames and photon iterations dispatch
#   caustics    bench/scenes/caustics_glass.gltf, 16 photon iterations of 65536 photons (photon pass
#               shown apart)
# The builds alternate within each run, so slow drift of a noisy machine hits all alike; the
# medians over the runs are printed per workload and build, with the ratio to the first build.
#
#   bench/gpu_time.sh [--runs N] [--only WORKLOAD,...] PREVIS_BINARY...
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
runs=3
known=(bunny area preview caustics)
source "$root/bench/build_comparison.sh"
parse_build_comparison_options "$@"
source "$root/bench/scenes/bench_scene.sh"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
common=(--width 640 --height 480 --max-depth 8 --quiet --timing)
every_sample=$(seq -s, 1 16)

# One workload on one build: prints "gpu_s photon_gpu_s".
gpu_seconds() {  # binary workload seed
    local args
    case "$2" in
        bunny) bench_scene bunny; args=("$scene" --env "$env" --spp 16) ;;
        area) bench_scene area-lights; args=("$scene" "${previs_args[@]}" --spp 16) ;;
        preview) bench_scene area-lights
                 args=("$scene" "${previs_args[@]}" --spp 16 --checkpoints "$every_sample") ;;
        # The photon count pinned: builds with another default compare the same work.
        caustics) args=("$root/bench/scenes/caustics_glass.gltf" --photons 65536 --spp 16) ;;
    esac
    "$1" render "${args[@]}" "${common[@]}" --seed "$3" --out "$work/out.exr" 2>&1 |
        sed -n 's/.* gpu_s=\([0-9.]*\) photon_gpu_s=\([0-9.]*\).*/\1 \2/p'
}


echo "| workload | build | GPU s (median of $runs) | photon pass s | ratio to the first build |"
echo "|---|---|---|---|---|"
for workload in "${workloads[@]}"; do
    declare -A gpu=() photon=()
    for ((r = 1; r <= runs; ++r)); do
        for b in "${binaries[@]}"; do
            read -r g p < <(gpu_seconds "$b" "$workload" "$r")
            gpu[$b]+="$g "
            photon[$b]+="$p "
        done
    done
    first=""
    for b in "${binaries[@]}"; do
        g=$(tr ' ' '\n' <<<"${gpu[$b]}" | grep . | median)
        p=$(tr ' ' '\n' <<<"${photon[$b]}" | grep . | median)
        [[ -z $first ]] && first=$g
        printf '| %s | %s | %.2f | %.2f | %.2f |\n' "$workload" "$(basename "$b")" "$g" "$p" \
            "$(awk -v a="$g" -v b="$first" 'BEGIN { print a / b }')"
    done
    unset gpu photon
done
