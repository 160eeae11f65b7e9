#!/usr/bin/env bash
# Issue 9's caustics benchmark on bench/scenes/caustics_glass.gltf (a virtual glass ball and cube
# on a real table, one 4 cm lamp; make_scenes.py says more), 640×480, max depth 8:
#   1. the cost of one iteration: photon pass (trace + sort into the grid) and gather, at preview
#      settings (PREVIEW photons, the radius fixed) and refinement settings (65536 photons,
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
# --extrapolate removes that bias too (docs/caustics.md, "Measuring against a biased
# reference"): two more references at the first radius over √2, whose bias (∝ r², the
# kernel's second moment) is half as large, give R = 2B̄ − Ā, bias-free to first order. The
# photon curve's error against R is reported beside the other, with R's noise (B̄'s four times,
# Ā's once) subtracted the same way. The MSE against R comes from pairwise MSEs only:
# ‖Σ cᵢ Yᵢ‖² = −Σ_{i<j} cᵢ cⱼ ‖Yᵢ − Yⱼ‖² when Σ cᵢ = 0, here c = (x: 1, B: −1 each, A: ½ each).
#
# --references-only stops once the references are cached; --score FILE... scores existing renders
# of the scene (previs render's EXRs, same size and region) against them instead of running the
# benchmark, one line per file (with --extrapolate, against R as well).
#
#   bench/caustics.sh [--quick] [--ref-iterations N] [--previs BINARY] [--extrapolate]
#                     [--references-only | --score FILE...]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
previs=$root/build/cli/previs
ref_iterations=512
photon_spp=256
path_spp=1024
preview_photons=16384
photons=65536  # per iteration, the default (render/photon_map.h), references included
extrapolate=0
references_only=0
score=()
while [[ $# -gt 0 ]]; do
    case "$1" in
        --quick) ref_iterations=128; photon_spp=64; path_spp=128; shift ;;
        --ref-iterations) ref_iterations=$2; shift 2 ;;
        --previs) previs=$2; shift 2 ;;
        --extrapolate) extrapolate=1; shift ;;
        --references-only) references_only=1; shift ;;
        --score) shift; score=("$@"); break ;;
        *) echo "usage: $0 [--quick] [--ref-iterations N] [--previs BINARY] [--extrapolate] [--references-only | --score FILE...]" >&2; exit 2 ;;
    esac
done
scene=$root/bench/scenes/caustics_glass.gltf
region=290,255,460,345
out=$root/build/caustics
mkdir -p "$out"
common=(--width 640 --height 480 --max-depth 8 --quiet)

# The references depend on the renderer too: keyed by the binary and the photon count, so a
# changed estimator renders them again.
key=$({ cat "$scene" "$previs"; echo "$ref_iterations $photons"; } | sha256sum | cut -c1-16)
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
if ((extrapolate)); then
    # The first radius, as the progress line prints it with the radius held (alpha 1).
    r0=$("$previs" render "$scene" --width 64 --height 48 --max-depth 8 --photons "$photons" \
        --photon-alpha 1 --spp 1 --out "$out/radius.exr" 2>&1 |
        sed -n 's/.*radius \([0-9.e-]*\) m.*/\1/p' | head -1)
    half=$(awk -v r="$r0" 'BEGIN { printf "%.6g", r / sqrt(2) }')
    halfRefs=("$out/ref-$key-half-a.exr" "$out/ref-$key-half-b.exr")
    for i in 0 1; do
        if [[ ! -f ${halfRefs[$i]} ]]; then
            echo "rendering reference $((i + 1))/2 at radius $half m (first radius $r0 m over √2)" >&2
            "$previs" render "$scene" "${common[@]}" --photons "$photons" --spp "$ref_iterations" \
                --seed $((9100 + i)) --photon-radius "$half" --out "${halfRefs[$i]}"
        fi
    done
    A1=${refs[0]} A2=${refs[1]} B1=${halfRefs[0]} B2=${halfRefs[1]}
    dA=$(mse "$A1" "$A2") dB=$(mse "$B1" "$B2")
    # Ā–B̄ cross terms of the pairwise sum (coefficient +½ each), less B1–B2 and ¼ A1–A2.
    ext_const=$(awk -v a1b1="$(mse "$A1" "$B1")" -v a1b2="$(mse "$A1" "$B2")" \
        -v a2b1="$(mse "$A2" "$B1")" -v a2b2="$(mse "$A2" "$B2")" -v dA="$dA" -v dB="$dB" \
        'BEGIN { print 0.5 * (a1b1 + a1b2 + a2b1 + a2b2) - dB - 0.25 * dA }')
    ext_noise=$(awk -v dA="$dA" -v dB="$dB" 'BEGIN { print dB + dA / 4 }')  # var of 2B̄ − Ā
    half_mean=$("$previs" compare "$B1" "$B2" --region "$region" | awk '{print ($6 + $8) / 2}')
fi

ref_mean=$("$previs" compare "${refs[0]}" "${refs[1]}" --region "$region" |
    awk '{print ($6 + $8) / 2}')
((extrapolate)) && ext_mean=$(awk -v a="$ref_mean" -v b="$half_mean" 'BEGIN { print 2 * b - a }')
# "RMSE relative-RMSE [relative-RMSE-against-R]" of one render: the references' noise subtracted
# (see the top), floored at 0; the third only when $2 is 1.
score_file() {
    local file=$1 against_r=$2 xA1 xA2 rmse rel ext=""
    xA1=$(mse "$file" "${refs[0]}") xA2=$(mse "$file" "${refs[1]}")
    rmse=$(awk -v a="$xA1" -v b="$xA2" \
        -v r="$ref_mse" 'BEGIN { m = (a + b) / 2 - r; print (m > 0 ? sqrt(m) : 0) }')
    rel=$(awk -v r="$rmse" -v m="$ref_mean" 'BEGIN { print r / m }')
    if ((against_r)); then
        ext=$(awk -v xA1="$xA1" -v xA2="$xA2" \
            -v xB1="$(mse "$file" "$B1")" -v xB2="$(mse "$file" "$B2")" \
            -v c="$ext_const" -v n="$ext_noise" -v m="$ext_mean" \
            'BEGIN { v = xB1 + xB2 - 0.5 * (xA1 + xA2) + c - n; print (v > 0 ? sqrt(v) : 0) / m }')
    fi
    echo "$rmse $rel $ext"
}
((references_only)) && exit 0
if ((${#score[@]})); then
    for file in "${score[@]}"; do
        read -r rmse rel ext < <(score_file "$file" "$extrapolate")
        printf '%s  relative RMSE %.4f%s\n' "$file" "$rel" "${ext:+  against R: $ext}"
    done
    exit 0
fi

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
    # each), two sort pairs (8 each) and 256 digit counts per 512-record sort block (2), plus the
    # 1048492 bucket ranges (8 bytes each); render/photon_map.cpp's photonBufferBytes.
    awk -v n="$n" 'BEGIN { printf "photon map memory at %d photons: %.1f MiB\n", n, (4 * n * 82 + 1048492 * 8) / 1048576 }'
done
# The splat sums (Renderer::photonSplatBytes): per pixel three channels of 32.32 fixed point, one
# sum (mixed) as here without a plate, three (mixed, real, real unhidden) in a differential render.
awk 'BEGIN { printf "photon splat sums at 640x480: %.1f MiB (differential: %.1f MiB)\n", 640 * 480 * 24 / 1048576, 640 * 480 * 72 / 1048576 }'

echo
echo "## Caustic region against the reference"
csv=$out/curve.csv
echo "method,spp,seconds,rmse,rel_rmse,rel_rmse_extrapolated" >"$csv"
checkpoints() {  # up to N: 1,2,4,...,N
    local list=1 n=2
    while ((n <= $1)); do list+=",$n"; n=$((n * 2)); done
    echo "$list"
}
awk -v m="$ref_mse" -v mean="$ref_mean" 'BEGIN { printf "region mean %.4f; reference noise (relative RMSE of one reference) %.4f\n", mean, sqrt(m) / mean }'
if ((extrapolate)); then
    awk -v a="$ref_mean" -v b="$half_mean" -v e="$ext_mean" -v n="$ext_noise" -v dB="$dB" \
        'BEGIN { printf "extrapolated reference: region mean %.4f (radius r: %.4f, %+.2f %%; r/√2: %.4f, %+.2f %%); its noise %.4f of the mean; one r/√2 reference %.4f\n", e, a, 100 * (a - e) / e, b, 100 * (b - e) / e, sqrt(n) / e, sqrt(dB / 2) / b }'
fi
for method in photons paths; do
    if [[ $method == photons ]]; then spp=$photon_spp; mode=$photons; else spp=$path_spp; mode=off; fi
    "$previs" render "$scene" "${common[@]}" --photons "$mode" --spp "$spp" --seed 1 \
        --checkpoints "$(checkpoints "$spp")" --out "$out/$method.exr" |
        while read -r _ sppField secondsField fileField; do
            n=${sppField#spp=}
            seconds=${secondsField#total_s=}
            file=${fileField#file=}
            read -r rmse rel ext < <(score_file "$file" "$([[ $method == photons ]] && echo "$extrapolate" || echo 0)")
            echo "$method,$n,$seconds,$rmse,$rel,$ext" >>"$csv"
            printf '%-8s %5d spp  %8.2f s  relative RMSE %.4f%s\n' "$method" "$n" "$seconds" "$rel" \
                "${ext:+  (against the extrapolated reference: $(printf '%.4f' "$ext"))}"
        done
done
python3 - "$csv" <<'EOF'
import csv, math, sys
rows = {}
for r in csv.DictReader(open(sys.argv[1])):
    rows.setdefault(r["method"], []).append((float(r["seconds"]), max(float(r["rel_rmse"]), 1e-9)))
    if r.get("rel_rmse_extrapolated"):
        rows.setdefault(r["method"] + " (extrapolated reference)", []).append(
            (float(r["seconds"]), max(float(r["rel_rmse_extrapolated"]), 1e-9)))
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
