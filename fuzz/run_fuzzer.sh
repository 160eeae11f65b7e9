#!/usr/bin/env bash
# Runs one fuzz target for a few seconds on its checked-in seed corpus (the CTest fuzz tests;
# docs/fuzzing.md). New inputs go to a scratch folder in the build tree, never the source tree.
# Usage: run_fuzzer.sh FUZZER SEED_CORPUS WORK_DIR SECONDS
set -euo pipefail
fuzzer=$1 seeds=$2 work=$3 seconds=$4
# OpenCV logs every frame it cannot decode; the fuzzer output should show findings only.
export OPENCV_LOG_LEVEL=ERROR
# Crash inputs of earlier runs are kept (artifacts/) for a look after a failure.
rm -rf "$work/corpus"
mkdir -p "$work/corpus" "$work/artifacts"
exec "$fuzzer" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 \
    -artifact_prefix="$work/artifacts/" "$work/corpus" "$seeds"
