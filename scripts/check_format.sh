#!/usr/bin/env bash
# Fails (listing the files) when a C++ source differs from what clang-format makes of it
# (.clang-format: Google base, 4 spaces, 100 columns). gpu/shaders/ is left out: its shared
# headers are GLSL as well as C++, and clang-format does not know GLSL. Fix: the same file list
# through `clang-format -i`.
set -euo pipefail
cd "$(dirname "$0")/.."
if [[ -d .git || -f .git ]]; then
    mapfile -t files < <(git ls-files '*.cpp' '*.h' | grep -v '^gpu/shaders/')
else
    mapfile -t files < <(find . -path ./gpu/shaders -prune -o -path './build*' -prune -o \
                         \( -name '*.cpp' -o -name '*.h' \) -print | sed 's#^\./##')
fi
bad=()
for f in "${files[@]}"; do
    clang-format --dry-run --Werror "$f" >/dev/null 2>&1 || bad+=("$f")
done
if ((${#bad[@]})); then
    echo "not clang-formatted (run: clang-format -i FILE): ${bad[*]}" >&2
    exit 1
fi
echo "${#files[@]} files clang-formatted"
