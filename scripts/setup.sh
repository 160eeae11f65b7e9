#!/usr/bin/env bash
# Installs the Debian packages previs needs (skipping those present), then configures and
# builds one configuration. Usage: scripts/setup.sh [release|asan|fuzz|packages] [TARGET]
# (default release, every target; TARGET builds only that one and what it needs; packages: only
# the install; PREVIS_BUILD_JOBS: how many compile jobs, default one a core)
# fuzz: clang-14 with libFuzzer+ASan+UBSan in build-fuzz, only the fuzz targets (docs/fuzzing.md).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
config=${1:-release}

missing=()
while read -r pkg; do
    [[ -z "$pkg" || "$pkg" == \#* ]] && continue
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done < "$root/scripts/packages.txt"
if ((${#missing[@]})); then
    echo "setup: installing ${missing[*]}" >&2
    sudo_cmd=()
    [[ $(id -u) -ne 0 ]] && sudo_cmd=(sudo)
    "${sudo_cmd[@]}" apt-get update -qq
    DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends \
        "${missing[@]}" >&2
fi
[[ $config == packages ]] && exit 0

# Debug info as line tables only (-g1): backtraces, ASan reports and perf keep file:line, and a
# heavy translation unit compiles faster than with full -g (tests/daemon/previsd_test.cpp: 16 s
# against 23 s, one noisy run); pass -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O2 -g -DNDEBUG" for gdb.
# The sanitized build stays -O0 (its warnings are what CI has always passed with -Werror).
case "$config" in
    release) build="$root/build"
             flags=(-DCMAKE_BUILD_TYPE=RelWithDebInfo
                    "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O2 -g1 -DNDEBUG"
                    "-DCMAKE_C_FLAGS_RELWITHDEBINFO=-O2 -g1 -DNDEBUG") ;;
    asan) build="$root/build-asan"
          flags=(-DCMAKE_BUILD_TYPE=Debug -DPREVIS_SANITIZE=ON "-DCMAKE_CXX_FLAGS_DEBUG=-g1"
                 "-DCMAKE_C_FLAGS_DEBUG=-g1") ;;
    fuzz) build="$root/build-fuzz"
          flags=(-DCMAKE_BUILD_TYPE=RelWithDebInfo -DPREVIS_FUZZ=ON -DCMAKE_C_COMPILER=clang-14
                 -DCMAKE_CXX_COMPILER=clang++-14) ;;
    *) echo "setup: unknown configuration '$config' (use release, asan, fuzz or packages)" >&2; exit 2 ;;
esac
# Unity build: CMake compiles each target's sources in batches of 16 as one translation unit, so
# the CLI11/nlohmann-json/fmt/GoogleTest templates are parsed and instantiated once per batch
# instead of once per file (bench/results/benchmarks_2026-12-05.md, "CI's run with unity
# builds"). A fresh release or asan build folder (CI's) is configured with it on; an existing one
# keeps its setting, so a developer's folder configured with -DCMAKE_UNITY_BUILD=OFF (an edited
# file then recompiles alone, not with its batch) stays so. PREVIS_UNITY=ON or OFF sets it either
# way. The fuzz build (clang) stays per file: as unity it took 113 s against 110 (same section).
unity=(-DCMAKE_UNITY_BUILD_BATCH_SIZE=16)
if [[ -n ${PREVIS_UNITY:-} ]]; then
    unity+=(-DCMAKE_UNITY_BUILD="$PREVIS_UNITY")
elif [[ ! -f $build/CMakeCache.txt && $config != fuzz ]]; then
    unity+=(-DCMAKE_UNITY_BUILD=ON)
fi
# Links with lld (package lld) where it is installed: an ASan test's link took 2.4 CPU-s against
# bfd's 6.9 (test_compare), an optimised one 0.33 against 1.13 (test_previsd); the sanitized
# build links 50 executables, the optimised 74.
linker=()
if command -v ld.lld >/dev/null; then
    for kind in EXE SHARED MODULE; do linker+=("-DCMAKE_${kind}_LINKER_FLAGS=-fuse-ld=lld"); done
fi
cmake -S "$root" -B "$build" -G Ninja -DPREVIS_WERROR=${PREVIS_WERROR:-OFF} "${unity[@]}" \
    "${linker[@]}" "${flags[@]}" >&2
targets=()
[[ $config == fuzz ]] && targets=(--target previs_fuzzers)
[[ -n ${2:-} ]] && targets=(--target "$2")
cmake --build "$build" -j"${PREVIS_BUILD_JOBS:-$(nproc)}" "${targets[@]}" >&2
echo "$build"
