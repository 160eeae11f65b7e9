#!/usr/bin/env bash
# A long fuzzing session of one target (docs/fuzzing.md), e.g. the 10 minutes each target ran
# before issue 11 closed. Corpus, crashes and the log go to build-fuzz/fuzz-long/TARGET/ (the
# seed corpus in fuzz/corpus/ is only read). Usage: fuzz/run_long.sh TARGET [SECONDS]  (600)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
target=$1 seconds=${2:-600}
work="$root/build-fuzz/fuzz-long/$target"
mkdir -p "$work/corpus" "$work/artifacts"
cd "$work"
export OPENCV_LOG_LEVEL=ERROR  # OpenCV logs every frame it cannot decode
nice -n 10 "$root/build-fuzz/fuzz/fuzz_$target" -max_total_time="$seconds" -timeout=10 \
    -rss_limit_mb=2048 -print_final_stats=1 -artifact_prefix="$work/artifacts/" \
    "$work/corpus" "$root/fuzz/corpus/fuzz_$target" > "$work/log.txt" 2>&1 || true
grep -E "^#[0-9]+.*(DONE|INITED)|^stat::|ERROR|runtime error|SUMMARY" "$work/log.txt" | head -20
echo "corpus: $(ls "$work/corpus" | wc -l) files, $(du -sh "$work/corpus" | cut -f1)"
echo "artifacts: $(ls "$work/artifacts" | wc -l)"
