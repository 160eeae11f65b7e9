#!/bin/sh
# Issue 8 environment-sampling ablation (bench/results/benchmarks_2026-11-27.md, "Issue 8: environment sampling"): two
# previs builds (e.g. main's CDF inversion and this branch's alias table) × two samplers, on the
# env-lit bunny: RMSE and relMSE against a long reference at equal samples, and CPU time
# (user + sys of the whole command, /usr/bin/time) per run. Builds alternate run by run.
#   bench/env_sampling_ablation.sh NAME_A PREVIS_A NAME_B PREVIS_B SCENE ENV REF [SEEDS] [SPPS]
# REF: a long reference of the same scene and map (render it once, another seed). Writes one CSV
# line per run (build,sampler,spp,seed,cpuSeconds,rmse,relMse) to stdout.
set -eu
NAME_A=$1; PREVIS_A=$2; NAME_B=$3; PREVIS_B=$4; SCENE=$5; ENV=$6; REF=$7
SEEDS=${8:-4}
SPPS=${9:-"4 16 64"}
SAMPLERS=${SAMPLERS:-"sobol independent"}
OUT=${OUT:-/tmp/previs_env_ablation}
mkdir -p "$OUT"
echo "build,sampler,spp,seed,cpuSeconds,rmse,relMse"
run=0
for spp in $SPPS; do
    seed=1
    while [ "$seed" -le "$SEEDS" ]; do
        for s in $SAMPLERS; do
            # Alternate the order so a load change on the machine favours neither build.
            if [ $((run % 2)) -eq 0 ]; then order="A B"; else order="B A"; fi
            run=$((run + 1))
            for b in $order; do
                if [ "$b" = A ]; then name=$NAME_A; exe=$PREVIS_A; else name=$NAME_B; exe=$PREVIS_B; fi
                img="$OUT/${name}_${s}_${spp}_${seed}.exr"
                /usr/bin/time -f '%U %S' -o "$OUT/time" "$exe" render "$SCENE" --env "$ENV" \
                    --width 640 --height 480 --max-depth 8 --spp "$spp" --sampler "$s" \
                    --seed "$seed" --quiet --out "$img"
                cpu=$(awk '{print $1 + $2}' "$OUT/time")
                err=$("$exe" compare "$img" "$REF")
                echo "$name,$s,$spp,$seed,$cpu,$(echo "$err" | awk '{print $2","$4}')"
            done
        done
        seed=$((seed + 1))
    done
done
