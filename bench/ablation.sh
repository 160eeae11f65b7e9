#!/usr/bin/env bash
# Ablation of issue 8's changes: time per sample, error per sample and their product, the time to
# equal error, for several previs builds on bench/compare_blender.sh's two scenes (640×480, max
# depth 8). Each build is a `previs` binary; build one per commit (cmake --build, copy
# build/cli/previs away) and pass them oldest first: ratios are against the first.
#
#   bench/ablation.sh [--spp N] [--seeds K] PREVIS_BINARY...
#
# Time per sample = (wall time at N spp − wall time at 1 spp) / (N − 1), so fixed costs (device,
# BVH, pipeline compile) cancel; the median over K seeds. Error per sample = RMSE·√N against the
# 512-spp previs reference of bench/compare_blender.sh (rendered first if it is not cached), the
# mean over the K seeds; every build renders the same scene, so every build is measured against
# the same reference. Time to equal error (many-sample limit) = time ratio × error ratio².
# Run it on a quiet machine: it alternates the builds per seed so slow drift hits all alike.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
spp=16
seeds=3
while [[ $# -gt 0 && $1 == --* ]]; do
    case "$1" in
        --spp) spp=$2; shift 2 ;;
        --seeds) seeds=$2; shift 2 ;;
        *) echo "usage: $0 [--spp N] [--seeds K] PREVIS_BINARY..." >&2; exit 2 ;;
    esac
done
(($# > 0)) || { echo "usage: $0 [--spp N] [--seeds K] PREVIS_BINARY..." >&2; exit 2; }
binaries=("$@")
source "$root/bench/scenes/bench_scene.sh"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

seconds_of() {  # binary scene env spp seed out -> wall seconds of the whole process
    local env_args=()
    [[ "$3" != none ]] && env_args=(--env "$3")
    local t0 t1
    t0=$(date +%s.%N)
    "$1" render "$2" "${env_args[@]}" "${previs_args[@]}" --width 640 --height 480 \
        --max-depth 8 --spp "$4" \
        --seed "$5" --out "$6" --quiet
    t1=$(date +%s.%N)
    awk -v a="$t0" -v b="$t1" 'BEGIN { print b - a }'
}

echo "| scene | build | time / sample (s) | RMSE·√spp | time ratio | error ratio | time to equal error |"
echo "|---|---|---|---|---|---|---|"
for name in bunny area-lights; do
    bench_scene "$name"
    # The reference compare_blender.sh caches (same key), else rendered here by the last build.
    key=$(bench_reference_key "$scene" "$env" 640 480 8 512)
    ref="$cache/$name-$key-previs-ref.exr"
    [[ -f "$ref" ]] || seconds_of "${binaries[-1]}" "$scene" "$env" 512 1000 "$ref" >/dev/null
    declare -A times=() errors=()
    for ((s = 1; s <= seeds; ++s)); do
        for b in "${binaries[@]}"; do
            t1=$(seconds_of "$b" "$scene" "$env" 1 "$s" "$work/one.exr")
            tn=$(seconds_of "$b" "$scene" "$env" "$spp" "$s" "$work/n.exr")
            rmse=$("${binaries[-1]}" compare "$work/n.exr" "$ref" | awk '{print $2}')
            times[$b]+="$(awk -v a="$t1" -v b="$tn" -v n="$spp" 'BEGIN { print (b - a) / (n - 1) }') "
            errors[$b]+="$(awk -v r="$rmse" -v n="$spp" 'BEGIN { print r * sqrt(n) }') "
        done
    done
    base_t=""
    base_e=""
    for b in "${binaries[@]}"; do
        t=$(echo ${times[$b]} | tr ' ' '\n' | sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}')
        e=$(echo ${errors[$b]} | tr ' ' '\n' | awk '{s+=$1} END {print s/NR}')
        [[ -z "$base_t" ]] && base_t=$t && base_e=$e
        awk -v n="$name" -v b="$b" -v t="$t" -v e="$e" -v bt="$base_t" -v be="$base_e" 'BEGIN {
            printf "| %s | %s | %.4f | %.4f | %.2f | %.2f | %.2f |\n", n, b, t, e, t / bt, e / be,
                (t / bt) * (e / be) * (e / be) }'
    done
    unset times errors
done
