#!/usr/bin/env bash
# Sets everything up, then builds and runs the whole test suite twice: an optimised build and an
# ASan+UBSan build; then every fuzz target for a few seconds on its seed corpus (a clang build of
# the parsers only; docs/fuzzing.md). Warnings are errors here.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
export PREVIS_WERROR=ON
for config in release asan; do
    build=$("$root/scripts/setup.sh" "$config")
    echo "== tests ($config) ==" >&2
    # The sanitized run leaves out the VM tests of whole services (label vm-release: minutes under
    # an emulated CPU with ASan); their code runs sanitized in the host tests.
    exclude=()
    [[ $config == asan ]] && exclude=(-LE vm-release)
    ctest --test-dir "$build" --output-on-failure -j"$(nproc)" --timeout 600 "${exclude[@]}"
done
build=$("$root/scripts/setup.sh" fuzz)
echo "== fuzz targets on their seed corpora ==" >&2
# Each target runs PREVIS_FUZZ_SECONDS (fuzz/CMakeLists.txt) on one core.
ctest --test-dir "$build" --output-on-failure -j"$(nproc)" -L fuzz
