#!/bin/sh
# Regenerates examples/demo/ — scene.gltf, scene.bin, board.png, the recorded session in
# examples/demo/session/ (the fisheye bracketed at 0, -5 and -10 stops) and the truth folder
# examples/demo/truth/ (linear mixed/real/mask renders for tests, outside the take) — with
# previs's own path tracer (bench/make_demo_session.cpp). Fixed seeds: the same build on the same
# device gives the same files. About 10-15 minutes on 2 CPU cores with lavapipe.
#
#   scripts/make_demo_session.sh [BUILD_DIR]      (default: build)
#
# PREVIS_BUILD_LOCK=FILE builds under flock FILE (a build folder shared with others).
set -eu
here=$(cd "$(dirname "$0")/.." && pwd)
build=${1:-$here/build}
# The shared data beside the checkout, else where PREVIS_DATA_DIR says.
data=${PREVIS_DATA_DIR:-${PREVIS_SHARED_DATA:-$here/../shared/data}}
env_map=$data/envmaps/polyhaven_1k_hdr/studio_small_03_1k.hdr
if [ ! -f "$env_map" ]; then
    echo "make_demo_session.sh: $env_map not found (set PREVIS_DATA_DIR to the shared data folder)" >&2
    exit 2
fi
if [ ! -f "$build/CMakeCache.txt" ]; then
    cmake -S "$here" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo
fi
if [ -n "${PREVIS_BUILD_LOCK:-}" ]; then
    flock "$PREVIS_BUILD_LOCK" cmake --build "$build" --target make_demo_session
else
    cmake --build "$build" --target make_demo_session
fi
"$build/bench/make_demo_session" --demo-dir "$here/examples/demo" --env "$env_map" \
    --env-scale 0.6 --moving-spp 12 --still-spp 96 --max-depth 3 \
    --bracket-stops 0,-5,-10 --truth-frames 10,32 --truth-spp 1024 \
    --env-name envmaps/polyhaven_1k_hdr/studio_small_03_1k.hdr
du -sh "$here/examples/demo"
