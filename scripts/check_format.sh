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
# Batches of files on every core: one clang-format per file took half a minute of CI.
# Each violation is reported as "FILE:LINE:COL: error: ..."; the files are what it lists.
mapfile -t bad < <(printf '%s\0' "${files[@]}" |
    xargs -0 -n 40 -P "$(nproc)" clang-format --dry-run --Werror 2>&1 >/dev/null |
    grep -E '^[^ :]+:[0-9]+:[0-9]+: (error|warning)' | cut -d: -f1 | sort -u || true)
if ((${#bad[@]})); then
    echo "not clang-formatted (run: clang-format -i FILE): ${bad[*]}" >&2
    exit 1
fi
echo "${#files[@]} files clang-formatted"
