#!/usr/bin/env bash
# Issue 9's caustics benchmark on bench/scenes/caustics_glass.gltf (a virtual glass ball and cube
# on a real table, one 4 cm lamp; make_scenes.py says more), 640×480, max depth 8:
#   1. the cost of one iteration: photon pass (trace + sort into the grid) and gather, at preview
#      settings (PREVIEW photons, the radius fixed) and refinement settings (32768 photons,
#      α = 2/3) — GPU times from `previs render --timing` over 16 iterations, median of 3 runs —
#      and the photon map's device memory;
#   2. convergence of the caustic region (pixels x 290–460, y 255–345: the ball's caustic and
#      shadow on the table) against a long photon-mapped reference: photon mapping and pure path
#      tracing (--photons off), each one run with checkpoints; relative RMSE = region RMSE over the
#      reference region's mean (all channels); the time (from process start: device, BVH and
#      compile count) to reach 5 %.
# The reference is progressive photon mapping itself, two independent renders of REF iterations
# each (cached in build/caustics/): path tracing cannot converge this scene in any time available
# here, and PPM is consistent (its bias shrinks with the radius), so the path tracer's curve is
# measured against it too. The references' own noise is not negligible at 5 % (light the caustic
# throws on the table reaches other surfaces through diffuse bounces: path-traced, noisy), so it
# is subtracted: with A and B the two references, MSE(x) ≈ ½[MSE(x, A) + MSE(x, B)] − ½·MSE(A, B),
# the noise of x and of either reference being independent. What remains is the references'
# shared bias (their radius after REF iterations), which is not subtracted.
#
#   bench/caustics.sh [--quick] [--ref-iterations N] [--previs BINARY]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
previs=$root/build/cli/previs
ref_iterations=512
photon_spp=256
path_spp=1024
preview_photons=16384
photons=32768  # per iteration, the default (render/photon_map.h), references included
while [[ $# -gt 0 ]]; do
    case "$1" in
        --quick) ref_iterations=128; photon_spp=64; path_spp=128; shift ;;
        --ref-iterations) ref_iterations=$2; shift 2 ;;
        --previs) previs=$2; shift 2 ;;
        *) echo "usage: $0 [--quick] [--ref-iterations N] [--previs BINARY]" >&2; exit 2 ;;
    esac
done
scene=$root/bench/scenes/caustics_glass.gltf
region=290,255,460,345
out=$root/build/caustics
mkdir -p "$out"
common=(--width 640 --height 480 --max-depth 8 --quiet)

# The references depend on the renderer too: keyed by the binary, so a changed estimator renders
# them again.
key=$({ cat "$scene" "$previs"; echo "$ref_iterations"; } | sha256sum | cut -c1-16)
refs=("$out/ref-$key-a.exr" "$out/ref-$key-b.exr")
for i in 0 1; do
    if [[ ! -f ${refs[$i]} ]]; then
        echo "rendering reference $((i + 1))/2: $ref_iterations photon iterations (cached: ${refs[$i]#"$root"/})" >&2
        "$previs" render "$scene" "${common[@]}" --photons "$photons" --spp "$ref_iterations" \
            --seed $((9000 + i)) --out "${refs[$i]}"
    fi
done
mse() { "$previs" compare "$1" "$2" --region "$region" | awk '{print $2 * $2}'; }
ref_mse=$(awk -v d="$(mse "${refs[0]}" "${refs[1]}")" 'BEGIN { print d / 2 }')

echo "## Cost per iteration (GPU time, median of 3 runs of 16 iterations)"
echo "| settings | photons | photon pass (ms) | trace + gather (ms) | path tracing alone (ms) |"
echo "|---|---|---|---|---|"
median() { sort -g | awk '{v[NR] = $1} END {print v[int((NR + 1) / 2)]}'; }
per_iteration() {  # label photons extra-args...
    local label=$1 photons=$2
    shift 2
    local pass=() trace=() alone=()
    for run in 1 2 3; do
        line=$("$previs" render "$scene" "${common[@]}" --spp 16 --seed "$run" --timing \
            --photons "$photons" "$@" --out "$out/timing.exr")
        gpu=$(sed -n 's/.* gpu_s=\([0-9.]*\).*/\1/p' <<<"$line")
        photon=$(sed -n 's/.*photon_gpu_s=\([0-9.]*\).*/\1/p' <<<"$line")
        pass+=("$(awk -v p="$photon" 'BEGIN { print p / 16 * 1000 }')")
        trace+=("$(awk -v g="$gpu" -v p="$photon" 'BEGIN { print (g - p) / 16 * 1000 }')")
        line=$("$previs" render "$scene" "${common[@]}" --spp 16 --seed "$run" --timing \
            --photons off --out "$out/timing.exr")
        gpu=$(sed -n 's/.* gpu_s=\([0-9.]*\).*/\1/p' <<<"$line")
        alone+=("$(awk -v g="$gpu" 'BEGIN { print g / 16 * 1000 }')")
    done
    printf '| %s | %s | %.1f | %.1f | %.1f |\n' "$label" "$photons" \
        "$(printf '%s\n' "${pass[@]}" | median)" "$(printf '%s\n' "${trace[@]}" | median)" \
        "$(printf '%s\n' "${alone[@]}" | median)"
}
per_iteration "preview (radius fixed)" "$preview_photons" --photon-alpha 1
per_iteration "refinement (alpha 2/3)" "$photons"
for n in "$preview_photons" "$photons"; do
    # Four records per photon (two solutions, two levels) in trace order and sorted (32 bytes
    # each), two sort pairs (8 each) and 256 digit counts per 64-record sort block (16), plus the
    # 1048568 bucket ranges (8 bytes each); render/photon_map.cpp's photonBufferBytes.
    awk -v n="$n" 'BEGIN { printf "photon map memory at %d photons: %.1f MiB\n", n, (4 * n * 96 + 1048568 * 8) / 1048576 }'
done

echo
echo "## Caustic region against the reference"
csv=$out/curve.csv
echo "method,spp,seconds,rmse,rel_rmse" >"$csv"
checkpoints() {  # up to N: 1,2,4,...,N
    local list=1 n=2
    while ((n <= $1)); do list+=",$n"; n=$((n * 2)); done
    echo "$list"
}
ref_mean=$("$previs" compare "${refs[0]}" "${refs[1]}" --region "$region" |
    awk '{print ($6 + $8) / 2}')
awk -v m="$ref_mse" -v mean="$ref_mean" 'BEGIN { printf "region mean %.4f; reference noise (relative RMSE of one reference) %.4f\n", mean, sqrt(m) / mean }'
for method in photons paths; do
    if [[ $method == photons ]]; then spp=$photon_spp; mode=$photons; else spp=$path_spp; mode=off; fi
    "$previs" render "$scene" "${common[@]}" --photons "$mode" --spp "$spp" --seed 1 \
        --checkpoints "$(checkpoints "$spp")" --out "$out/$method.exr" |
        while read -r _ sppField secondsField fileField; do
            n=${sppField#spp=}
            seconds=${secondsField#total_s=}
            file=${fileField#file=}
            # The references' noise subtracted (see the top); floored at 0.
            rmse=$(awk -v a="$(mse "$file" "${refs[0]}")" -v b="$(mse "$file" "${refs[1]}")" \
                -v r="$ref_mse" 'BEGIN { m = (a + b) / 2 - r; print (m > 0 ? sqrt(m) : 0) }')
            rel=$(awk -v r="$rmse" -v m="$ref_mean" 'BEGIN { print r / m }')
            echo "$method,$n,$seconds,$rmse,$rel" >>"$csv"
            printf '%-8s %5d spp  %8.2f s  relative RMSE %.4f\n' "$method" "$n" "$seconds" "$rel"
        done
done
python3 - "$csv" <<'EOF'
import csv, math, sys
rows = {}
for r in csv.DictReader(open(sys.argv[1])):
    rows.setdefault(r["method"], []).append((float(r["seconds"]), max(float(r["rel_rmse"]), 1e-9)))
for method, points in rows.items():
    target = 0.05
    found = None
    for (t0, e0), (t1, e1) in zip(points, points[1:]):
        if e0 >= target >= e1 and e0 > e1:
            f = (math.log(e0) - math.log(target)) / (math.log(e0) - math.log(e1))
            found = math.exp(math.log(t0) + f * (math.log(t1) - math.log(t0)))
            break
    if points[0][1] <= target:
        found = points[0][0]
    last = points[-1]
    if found is None:
        # Not reached: extrapolate the last doubling's slope (stated as such).
        (t0, e0), (t1, e1) = points[-2], points[-1]
        slope = math.log(e1 / e0) / math.log(t1 / t0)
        est = t1 * (target / e1) ** (1 / slope) if slope < 0 else float("inf")
        print(f"{method}: 5 % not reached in {last[0]:.1f} s (relative RMSE {last[1]:.4f}); "
              f"extrapolated from the last doubling (error ~ time^{slope:.2f}): {est:.0f} s")
    else:
        print(f"{method}: relative RMSE 5 % after {found:.1f} s")
EOF
echo "curve: ${csv#"$root"/}"  # relative to the checkout: results are committed
