#!/usr/bin/env bash
# Fails if a function outside tests/, bench/ and fuzz/ is longer than a reader takes in at once
# (LIMIT lines, default 120: docs/architecture.md, "Where to start reading"). Lengths come from
# universal-ctags' end lines, C++ and GLSL alike. Usage: check_function_length.sh [LIMIT]
set -euo pipefail
cd "$(dirname "$0")/.."
limit=${1:-120}
if ! command -v ctags >/dev/null || ! ctags --version 2>/dev/null | grep -q Universal; then
    echo "check_function_length: needs universal-ctags (scripts/setup.sh packages installs it)" >&2
    exit 2
fi
if ! git rev-parse --git-dir >/dev/null 2>&1; then
    echo "check_function_length: not a git checkout; nothing to check"
    exit 0
fi
git ls-files '*.cpp' '*.h' '*.comp' '*.glsl' | grep -v '^tests/\|^bench/\|^fuzz/' |
    ctags -x --fields=+ne --_xformat='%N %F %n %e' --kinds-C++=f --language-force=C++ -L - |
    awk -v limit="$limit" '$4 != "" { n = $4 - $3 + 1; if (n > limit) print n, $2 ":" $3, $1 }' |
    sort -rn >"${TMPDIR:-/tmp}/previs_long_functions.$$"
trap 'rm -f "${TMPDIR:-/tmp}/previs_long_functions.$$"' EXIT
if [[ -s "${TMPDIR:-/tmp}/previs_long_functions.$$" ]]; then
    echo "functions over $limit lines (lines, where, name):"
    cat "${TMPDIR:-/tmp}/previs_long_functions.$$"
    echo "split them into steps a reader takes in at once" >&2
    exit 1
fi
echo "no function outside tests/, bench/ and fuzz/ is over $limit lines"
