#!/bin/sh
# Issue 8 sampler ablation (bench/results/benchmarks_2026-11-27.md, "Issue 8: sampler"): Sobol' vs independent (PCG) on
# one scene: RMSE against a long reference at equal samples, and render time per sample, from
# A/B-alternated runs over several seeds.
#   bench/sampler_ablation.sh [SCENE] [W] [H] [REF_SPP] [SEEDS]
# Writes one CSV line per run (sampler,spp,seed,seconds,rmse,relMse) to stdout.
set -eu
PREVIS=${PREVIS:-build/cli/previs}
SCENE=${1:-examples/cubes_spheres/previs.toml}
W=${2:-160}
H=${3:-120}
REF_SPP=${4:-2048}
SEEDS=${5:-4}
OUT=${OUT:-/tmp/previs_sampler_ablation}
mkdir -p "$OUT"
REF="$OUT/ref_${W}x${H}_${REF_SPP}.exr"
if [ ! -f "$REF" ]; then
    "$PREVIS" render "$SCENE" --width "$W" --height "$H" --spp "$REF_SPP" --sampler sobol \
        --seed 777 --quiet --out "$REF"
fi
echo "sampler,spp,seed,seconds,rmse,relMse"
for spp in 4 16 64; do
    seed=1
    while [ "$seed" -le "$SEEDS" ]; do
        # Alternate the order so a load change on the machine does not favour one sampler.
        if [ $((seed % 2)) -eq 1 ]; then order="sobol independent"; else order="independent sobol"; fi
        for s in $order; do
            img="$OUT/${s}_${spp}_${seed}.exr"
            t0=$(date +%s.%N)
            "$PREVIS" render "$SCENE" --width "$W" --height "$H" --spp "$spp" --sampler "$s" \
                --seed "$seed" --quiet --out "$img"
            t1=$(date +%s.%N)
            err=$("$PREVIS" compare "$img" "$REF")
            echo "$s,$spp,$seed,$(echo "$t1 - $t0" | bc),$(echo "$err" | awk '{print $2","$4}')"
        done
        seed=$((seed + 1))
    done
done
