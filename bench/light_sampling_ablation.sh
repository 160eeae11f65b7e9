#!/bin/sh
# Issue 8 light-sampling ablation (bench/results/benchmarks_2026-11-27.md, "Issue 8: light sampling"): emissive triangles
# sampled by solid angle (--light-sampling solid-angle, the default) against by area, on one
# scene: RMSE against a long reference at equal samples, and user+sys CPU time of each render
# (/usr/bin/time; the device is lavapipe, so the render's CPU time is its cost), from
# A/B-alternated runs over several seeds.
#   [REF=image.exr] bench/light_sampling_ablation.sh [SCENE] [W] [H] [REF_SPP] [SEEDS]
# Writes one CSV line per run (lightSampling,spp,seed,cpuSeconds,rmse,relMse) to stdout.
set -eu
PREVIS=${PREVIS:-build/cli/previs}
SCENE=${1:-bench/scenes/area_lights_mirror.gltf}
W=${2:-640}
H=${3:-480}
REF_SPP=${4:-1024}
SEEDS=${5:-3}
DEPTH=${DEPTH:-8}
OUT=${OUT:-/tmp/previs_light_sampling_ablation}
mkdir -p "$OUT"
# REF: an existing reference image of the same settings (e.g. compare_blender.sh's cached one).
REF=${REF:-"$OUT/ref_${W}x${H}_d${DEPTH}_${REF_SPP}.exr"}
if [ ! -f "$REF" ]; then
    "$PREVIS" render "$SCENE" --width "$W" --height "$H" --max-depth "$DEPTH" --spp "$REF_SPP" \
        --seed 777 --quiet --out "$REF"
fi
echo "lightSampling,spp,seed,cpuSeconds,rmse,relMse"
for spp in 4 16 64; do
    seed=1
    while [ "$seed" -le "$SEEDS" ]; do
        # Alternate the order so a load change on the machine does not favour one strategy.
        if [ $((seed % 2)) -eq 1 ]; then order="solid-angle area"; else order="area solid-angle"; fi
        for ls in $order; do
            img="$OUT/${ls}_${spp}_${seed}.exr"
            cpu=$( { /usr/bin/time -f "%U %S" "$PREVIS" render "$SCENE" --width "$W" --height "$H" \
                --max-depth "$DEPTH" --spp "$spp" --light-sampling "$ls" --seed "$seed" --quiet \
                --out "$img" 2>&1 >/dev/null; } | tail -1 | awk '{print $1 + $2}')
            err=$("$PREVIS" compare "$img" "$REF")
            echo "$ls,$spp,$seed,$cpu,$(echo "$err" | awk '{print $2","$4}')"
        done
        seed=$((seed + 1))
    done
done
