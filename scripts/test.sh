#!/usr/bin/env bash
# Sets everything up, then builds and runs the whole test suite twice: an optimised build and an
# ASan+UBSan build; then every fuzz target for a few seconds on its seed corpus (a clang build of
# the parsers only; docs/fuzzing.md). Warnings are errors here.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
export PREVIS_WERROR=ON
stage() { echo "== $1: $(($(date +%s) - started)) s since the start ==" >&2; }
started=$(date +%s)
for config in release asan; do
    # The sanitized run builds and runs the host tests, the VM tests of single devices and the
    # GPU tests labelled gpu-sanitized (tests/CMakeLists.txt, previs_sanitized_tests): the other GPU
    # tests spend their time in the driver, which is not instrumented, and the VM tests of whole
    # services (vm-release) take minutes under an emulated CPU with ASan; the host code both
    # exercise runs sanitized in the host tests. A single device's VM test (vm) runs only there:
    # one VM boot per test in the whole run. Likewise the GPU tests labelled gpu-sanitized
    # (previsd's service cases end to end, the Vulkan wrappers, the film's upsampling) run once,
    # sanitized: the optimised previsd still runs end to end in the release stage's VM test
    # (previsd_vm); the preview and replay cases whose time is renders run in the release stage.
    target=() select=(-LE '^(vm|gpu-sanitized)$')
    if [[ $config == asan ]]; then
        target=(previs_sanitized_tests)
        select=(-L '^(unit|vm|gpu-sanitized)$')
    fi
    stage "build ($config)"
    build=$("$root/scripts/setup.sh" "$config" "${target[@]}")
    stage "tests ($config)"
    ctest --test-dir "$build" --output-on-failure -j"$(nproc)" --timeout 600 "${select[@]}"
done
stage "build (fuzz)"
build=$("$root/scripts/setup.sh" fuzz)
stage "fuzz targets on their seed corpora"
# Each target runs PREVIS_FUZZ_SECONDS (fuzz/CMakeLists.txt) on one core.
ctest --test-dir "$build" --output-on-failure -j"$(nproc)" -L fuzz
stage "done"
