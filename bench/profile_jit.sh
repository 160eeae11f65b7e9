#!/usr/bin/env bash
# Where llvmpipe spends a shader's time, by kind of machine code: perf samples the running
# command, gdb disassembles the JIT code they fall in (llvmpipe's code has no symbols), and
# bench/profile_jit.py sorts the samples into texel fetches, per-lane array stores, per-lane
# loops over uniform loads, integer divisions and the rest (with the hottest 128-byte chunks of
# the rest). Needs perf and gdb (root, or perf_event_paranoid ≤ 1).
#
#   bench/profile_jit.sh [--wait S] [--seconds S] COMMAND...
# e.g.
#   bench/profile_jit.sh build/cli/previs render bench/scenes/area_lights_mirror.gltf \
#       --photons off --spp 128 --width 640 --height 480 --quiet --out /tmp/profiled.exr
# COMMAND must run longer than --wait + --seconds (defaults 5 + 6): it is sampled after the
# pipeline compile, then stopped.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
wait_s=5
seconds=6
while [[ $# -gt 0 && $1 == --* ]]; do
    case "$1" in
        --wait) wait_s=$2; shift 2 ;;
        --seconds) seconds=$2; shift 2 ;;
        *) echo "usage: $0 [--wait S] [--seconds S] COMMAND..." >&2; exit 2 ;;
    esac
done
(($# > 0)) || { echo "usage: $0 [--wait S] [--seconds S] COMMAND..." >&2; exit 2; }
for tool in perf gdb; do
    command -v "$tool" >/dev/null || { echo "$0: needs $tool (apt-get install linux-perf gdb)" >&2; exit 1; }
done
work=$(mktemp -d)
"$@" >"$work/command.log" 2>&1 &
pid=$!
trap 'kill "$pid" 2>/dev/null || true; rm -rf "$work"' EXIT
sleep "$wait_s"
kill -0 "$pid" 2>/dev/null || { echo "$0: the command ended within $wait_s s:" >&2; cat "$work/command.log" >&2; exit 1; }
perf record -q -o "$work/perf.data" -p "$pid" -- sleep "$seconds" >/dev/null 2>&1
perf script -i "$work/perf.data" -F ip 2>/dev/null >"$work/ips.txt"
# The JIT code is the densest cluster of sampled addresses; disassemble from its first sampled
# instruction (an instruction boundary) on.
read -r first count < <(python3 "$root/bench/profile_jit.py" range "$work/ips.txt")
gdb -p "$pid" -batch -ex "x/${count}i 0x$first" >"$work/code.txt" 2>/dev/null
kill "$pid" 2>/dev/null || true
python3 "$root/bench/profile_jit.py" classify "$work/ips.txt" "$work/code.txt"
