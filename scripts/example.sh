#!/usr/bin/env bash
# Sets everything up, then renders the bundled example scene and says where the image went.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=$("$root/scripts/setup.sh" release)
mkdir -p "$root/out"
"$build/cli/previs" render "$root/examples/cubes_spheres/scene.gltf" \
    --width 640 --height 480 --spp 32 --out "$root/out/example.png"
echo "previs: wrote $root/out/example.png"
