#!/usr/bin/env bash
# Sets everything up, then plays the bundled demo take through the service pipeline (previs
# replay: tracking, lighting, differential rendering, compositing, preview and refinement as the
# recorded button presses say) and says where the frames went.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=$("$root/scripts/setup.sh" release)
out="$root/out/demo"
rm -rf "$out"
"$build/cli/previs" replay "$root/examples/demo/session" --config "$root/examples/demo/previsd.toml" \
    --out "$out"
echo "previs: wrote $(ls "$out"/frame_*.png | wc -l) composited frames to $out/frame_NNNNNN.png" \
     "and $out/frames.csv (mode, samples, tracked pose per frame)"
