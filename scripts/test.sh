#!/usr/bin/env bash
# Sets everything up, then builds and runs the whole test suite twice: an optimised build and an
# ASan+UBSan build; then every fuzz target for a few seconds on its seed corpus (a clang build of
# the parsers only; docs/fuzzing.md). Warnings are errors here.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
export PREVIS_WERROR=ON
stage() { echo "== $1: $(($(date +%s) - started)) s since the start ==" >&2; }
started=$(date +%s)

# The next stage's build starts while a stage's tests run, one compile job at the lowest priority
# (nice 19): it takes only the CPU the tests leave idle (VM tests waiting on the emulated
# machine's timers, previsd's cases waiting on frames and signals) and barely slows them. When
# the tests are done it is stopped (ninja keeps every object it finished) and the stage's own
# build goes on from there on every core (and shows any error again, with its output).
early_pid="" early_log=""
start_early_build() {
    early_log=$(mktemp "${TMPDIR:-/tmp}/previs-early-build.XXXXXX")
    # Job control for this one job: its own process group, so stopping it reaches cmake and ninja.
    # Not setsid: a new session is a new autogroup, which the kernel shares the CPU with as an
    # equal, whatever its nice.
    set -m
    PREVIS_BUILD_JOBS=1 nice -n 19 "$root/scripts/setup.sh" "$@" </dev/null >/dev/null 2>"$early_log" &
    early_pid=$!
    set +m
}
stop_early_build() {
    [[ -n $early_pid ]] || return 0
    kill -TERM -- "-$early_pid" 2>/dev/null || true
    wait "$early_pid" 2>/dev/null || true
    # ninja ends its compilers before it exits: wait for the whole group to be gone.
    while kill -0 -- "-$early_pid" 2>/dev/null; do sleep 0.2; done
    echo "early build: $(grep -c '^\[' "$early_log" || true) steps done while the tests ran" >&2
    rm -f "$early_log"
    early_pid=""
}
trap stop_early_build EXIT

# The VM tests' cache (../shared/vmtest --prepare: the kernel's packages downloaded, vkms, gpio-sim
# and vimc built, the initramfs; 167 s, 76 CPU-s on a fresh cache here) is prepared beside the
# release build, at the lowest priority: its download and unpacking wait on the network and the
# disk, not on the build. The stage's tests wait for it (vmtest serialises on its cache's lock).
vmtest=$root/../shared/vmtest/vmtest
[[ -x $vmtest ]] || vmtest=${PREVIS_VMTEST_DIR:-$root/../shared/vmtest}/vmtest
prepare_pid="" prepare_log=""
start_vmtest_prepare() {
    [[ -x $vmtest ]] || return 0
    prepare_log=$(mktemp "${TMPDIR:-/tmp}/previs-vmtest-prepare.XXXXXX")
    nice -n 19 bash "$root/scripts/vmtest.sh" "$vmtest" --prepare </dev/null >"$prepare_log" 2>&1 &
    prepare_pid=$!
}
wait_vmtest_prepare() {
    [[ -n $prepare_pid ]] || return 0
    if ! wait "$prepare_pid"; then
        cat "$prepare_log" >&2
        echo "test.sh: vmtest --prepare failed; the vm tests will report it" >&2
    fi
    rm -f "$prepare_log"
    prepare_pid=""
}

# The Debian packages first (the VM's host tools among them), so the cache's preparation and
# the build do not both run apt.
stage packages
"$root/scripts/setup.sh" packages
start_vmtest_prepare

for config in release asan; do
    # Each test runs once. The sanitized run builds and runs the host tests (unit), the VM tests
    # of single devices (vm) and the GPU tests labelled gpu-sanitized (tests/CMakeLists.txt,
    # previs_sanitized_tests): previsd's service cases end to end, the Vulkan wrappers, the film's
    # upsampling. The release run takes the other GPU tests (gpu: their time is in the driver,
    # which is not instrumented; the preview and replay cases whose time is renders), the VM
    # tests of whole services (vm-release: minutes under an emulated CPU with ASan; the optimised
    # previsd runs end to end in previsd_vm) and the tree checks (lint). The host tests run only
    # sanitized: in both stages they took 189 CPU-s more (ctest -L unit, optimised, 2026-12-06).
    # The release build builds previs_release_stage: every target but the test binaries only
    # the sanitized stage runs (tests/CMakeLists.txt).
    target=(previs_release_stage) select=(-L '^(gpu|vm-release|lint)$')
    next=(asan previs_sanitized_tests)
    if [[ $config == asan ]]; then
        target=(previs_sanitized_tests)
        select=(-L '^(unit|vm|gpu-sanitized)$')
        next=(fuzz)
    fi
    stage "build ($config)"
    stop_early_build
    build=$("$root/scripts/setup.sh" "$config" "${target[@]}")
    wait_vmtest_prepare
    start_early_build "${next[@]}"
    stage "tests ($config)"
    ctest --test-dir "$build" --output-on-failure -j"$(nproc)" --timeout 600 "${select[@]}"
done
stage "build (fuzz)"
stop_early_build
build=$("$root/scripts/setup.sh" fuzz)
stage "fuzz targets on their seed corpora"
# Each target runs PREVIS_FUZZ_SECONDS (fuzz/CMakeLists.txt) on one core.
ctest --test-dir "$build" --output-on-failure -j"$(nproc)" -L fuzz
stage "done"
