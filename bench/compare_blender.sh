#!/usr/bin/env bash
# Renders the benchmark's bunny scene with Blender Cycles (CPU) and with previs at the same
# resolution, samples and bounce limit, and prints both times and their ratio.
#   bench/compare_blender.sh [SPP]        (default 16; installs Debian's blender if missing)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
spp=${1:-16}
# The shared data beside the checkout, else where PREVIS_SHARED_DATA says.
data=${PREVIS_SHARED_DATA:-$root/../shared/data}
env="$data/envmaps/polyhaven_1k_hdr/rooitou_park_1k.hdr"
mesh="$data/meshes/stanford_bunny.ply"
if ! command -v blender >/dev/null; then
    sudo_cmd=()
    [[ $(id -u) -ne 0 ]] && sudo_cmd=(sudo)
    "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends blender >&2
fi
build=$("$root/scripts/setup.sh" release)
out=$(mktemp -d)
cycles=$(blender -b --factory-startup --python "$root/bench/blender_cycles_bunny.py" -- \
    "$mesh" "$env" 640 480 "$spp" 8 "$out/cycles.png" 2>&1 | sed -n 's/^CYCLES_SECONDS \([0-9.]*\).*/\1/p')
# previs: median of 3 timed runs of SPP samples (BVH build and pipeline compile excluded, as
# reported separately by the throughput table).
ms=$("$build/cli/previs" bench --data "$data" --only throughput --spp "$spp" --repetitions 3 \
    2>/dev/null | awk -F'|' '/bunny on a plane/ {gsub(/ /, "", $6); print $6}')
previs=$(awk -v ms="$ms" -v spp="$spp" 'BEGIN { printf "%.3f", ms * spp / 1000 }')
ratio=$(awk -v a="$cycles" -v b="$previs" 'BEGIN { printf "%.2f", a / b }')
echo "bunny on a plane, 640x480, $spp spp, max bounces 8:"
echo "  Blender Cycles (CPU, $(nproc) threads): ${cycles} s"
echo "  previs ($(vulkaninfo --summary 2>/dev/null | sed -n 's/.*deviceName *= *//p' | head -1)): ${previs} s"
echo "  Cycles time / previs time: ${ratio}x"
rm -rf "$out"
