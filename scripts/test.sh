#!/usr/bin/env bash
# Sets everything up, then builds and runs the whole test suite twice: an optimised build and an
# ASan+UBSan build. Warnings are errors here.
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
