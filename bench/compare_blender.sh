#!/usr/bin/env bash
# Time to equal error, previs against Blender Cycles (CPU), on two scenes both renderers load from
# the same glTF (bench/scenes/make_scenes.py): "bunny" (bench_scenes.cpp's bunnyScene(), HDR
# environment rooitou_park_1k.hdr) and "area lights + mirror" (bench/scenes/area_lights_mirror.gltf,
# two 0.2 m emitters, a mirror sphere, no environment). 640×480, at most 8 bounces, in both.
#
#   bench/compare_blender.sh [--quick] [--ref-spp N] [--max-spp N] [--scenes bunny,area-lights]
#                            [--cycles-filter-glossy X]
#
# For each scene and renderer: a long reference (--ref-spp, default 512; --quick 128), rendered
# once with another seed and cached in build/compare_blender/ under a hash of the scene file and
# settings (delete the folder to render them again); then renders at 1, 2, 4, … --max-spp
# (default 32; --quick 8) samples per pixel, each image's RMSE (every pixel and channel of the
# linear EXR, `previs compare`) against its own renderer's reference — its own, so the error
# measures noise and not the small differences between the two renderers' models; the RMSE
# between the two references is printed too, so that bias is visible. The reference's own noise
# adds spp/ref_spp to each squared error (1/16 at the defaults: RMSE +3 %, both renderers alike).
#
# Times: previs = `previs render --timing`'s total: scene and map load, Vulkan device creation,
# renderer creation (BVH build, upload, pipeline compile), the samples and the readback (not the
# process start or the EXR write); Cycles = bpy.ops.render.render, which includes its scene sync
# and BVH build (not Blender's start, the glTF import or the EXR write). Cycles: CPU, threads =
# nproc, adaptive sampling, denoising and clamping off, 1-px box filter (previs jitters each
# sample uniformly in its pixel and weights all equally: a 1-px box), other settings at Blender's
# defaults, printed (sampling pattern, caustics, filter glossy, light threshold);
# --cycles-filter-glossy X sets Cycles' filter glossy (default 1.0: biased, less caustic noise;
# 0 = off, as previs).
# Needs Debian's blender and python3-numpy (its glTF importer imports numpy); installs both if
# missing.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
ref_spp=512
max_spp=32
scenes=bunny,area-lights
filter_glossy=default
while (($#)); do
    case "$1" in
        --quick) ref_spp=128; max_spp=8 ;;
        --ref-spp) ref_spp=$2; shift ;;
        --max-spp) max_spp=$2; shift ;;
        --scenes) scenes=$2; shift ;;
        --cycles-filter-glossy) filter_glossy=$2; shift ;;
        *) echo "usage: $0 [--quick] [--ref-spp N] [--max-spp N] [--scenes bunny,area-lights]" \
               "[--cycles-filter-glossy X]" >&2
           exit 2 ;;
    esac
    shift
done
width=640
height=480
depth=8
missing=()
command -v blender >/dev/null || missing+=(blender)
dpkg-query -W -f='${Status}' python3-numpy 2>/dev/null | grep -q "install ok installed" ||
    missing+=(python3-numpy)
if ((${#missing[@]})); then
    sudo_cmd=()
    [[ $(id -u) -ne 0 ]] && sudo_cmd=(sudo)
    "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" >&2
fi

build="$root/build"
[[ -f "$build/CMakeCache.txt" ]] ||
    cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo >&2
cmake --build "$build" --target previs -j"$(nproc)" >&2
previs="$build/cli/previs"
source "$root/bench/scenes/bench_scene.sh"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# previs render: prints the --timing total (seconds). One random sequence (--no-meter): the
# convergence meter's two interleaved sequences cost some stratification, and this compares
# renderers at their fastest.
previs_render() {  # scene env spp seed out
    local env_args=()
    [[ "$2" != none ]] && env_args=(--env "$2")
    "$previs" render "$1" "${env_args[@]}" "${previs_args[@]}" --width $width --height $height \
        --max-depth $depth \
        --spp "$3" --seed "$4" --out "$5" --no-meter --quiet --timing | sed -n 's/.*total_s=\([0-9.]*\).*/\1/p'
}

# Blender: renders every listed sample count in one session; prints "spp seconds" lines.
cycles_render() {  # scene env seed out_prefix spp...
    local scene=$1 env=$2 seed=$3 prefix=$4
    shift 4
    blender -b --factory-startup --python "$root/bench/blender_cycles_gltf.py" -- \
        "$scene" "$env" $width $height $depth "$seed" "$filter_glossy" "$prefix" "$@" >"$work/blender.log" 2>&1 || {
        tail -30 "$work/blender.log" >&2
        return 1
    }
    grep '^CYCLES_SETTINGS' "$work/blender.log" | sed 's/^CYCLES_SETTINGS/  Cycles:/' >&2
    sed -n 's/^CYCLES_RENDER spp=\([0-9]*\) seconds=\([0-9.]*\)/\1 \2/p' "$work/blender.log"
}

rmse() { "$previs" compare "$1" "$2" | awk '{print $2}'; }

counts=()
for ((n = 1; n <= max_spp; n *= 2)); do counts+=("$n"); done
csv="$work/results.csv"
echo "scene,renderer,spp,seconds,rmse" >"$csv"
echo "device: $(vulkaninfo --summary 2>/dev/null | sed -n 's/.*deviceName *= *//p' | head -1)," \
    "$(nproc) CPU threads; ${width}x${height}, max depth $depth; reference $ref_spp spp;" \
    "counts ${counts[*]}" >&2

for name in ${scenes//,/ }; do
    bench_scene "$name" || exit 2
    key=$(bench_reference_key "$scene" "$env" $width $height $depth "$ref_spp")
    ref_previs="$cache/$name-$key-previs-ref.exr"
    ref_cycles="$cache/$name-$key-cycles-filter-glossy-$filter_glossy-ref.exr"
    if [[ ! -f "$ref_previs" ]]; then
        echo "$name: previs reference, $ref_spp spp (once; cached)" >&2
        previs_render "$scene" "$env" "$ref_spp" 1000 "$ref_previs" >/dev/null
    fi
    if [[ ! -f "$ref_cycles" ]]; then
        echo "$name: Cycles reference, $ref_spp spp (once; cached)" >&2
        cycles_render "$scene" "$env" 1000 "$work/ref_" "$ref_spp" >/dev/null
        mv "$work/ref_$ref_spp.exr" "$ref_cycles"
    fi
    echo "$name: Cycles at ${counts[*]} spp" >&2
    while read -r n seconds; do
        echo "$name,cycles,$n,$seconds,$(rmse "$work/cycles_$n.exr" "$ref_cycles")" >>"$csv"
    done < <(cycles_render "$scene" "$env" 0 "$work/cycles_" "${counts[@]}")
    echo "$name: previs at ${counts[*]} spp" >&2
    for n in "${counts[@]}"; do
        seconds=$(previs_render "$scene" "$env" "$n" 0 "$work/previs_$n.exr")
        echo "$name,previs,$n,$seconds,$(rmse "$work/previs_$n.exr" "$ref_previs")" >>"$csv"
    done
    read -r _ bias _ _ _ mean_p _ mean_c _ < <("$previs" compare "$ref_previs" "$ref_cycles")
    echo "$name: references, previs against Cycles: RMSE $bias, means $mean_p / $mean_c" \
        "(both $ref_spp spp)" | tee -a "$work/bias.txt" >&2
done

echo
python3 "$root/bench/time_to_equal_error.py" "$csv"
echo
sed 's/^/- /' "$work/bias.txt"
cp "$csv" "$cache/last_results.csv"
# The two renderers' curves in one plot per scene (Debian's matplotlib; skipped without it).
if /usr/bin/python3 -c 'import matplotlib' 2>/dev/null; then
    /usr/bin/python3 "$root/bench/plot_trade.py" --blender "$csv" "$cache/compare_blender.png" &&
        echo "- plot: $cache/compare_blender.png"
fi
