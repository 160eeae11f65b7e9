#!/usr/bin/env bash
# previsd's peak resident memory and thread count on a config, what the unit's MemoryMax= and
# TasksMax= are sized from (systemd/previsd.service.in, docs/systemd.md): starts previsd, lets it
# run (the dial's start-up, preview, the demo's refinement), then reads VmHWM and Threads from
# /proc. --size WxH renders at that size instead of the config's (the largest output previsd
# supports live is 1920x1080).
#   usage: bench/previsd_footprint.sh [--config FILE] [--size WxH] [--seconds N] [--build DIR]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
config=$root/examples/demo/previsd.toml
size=""
seconds=60
build=$root/build
while (($#)); do
    case $1 in
        --config) config=$2; shift 2 ;;
        --size) size=$2; shift 2 ;;
        --seconds) seconds=$2; shift 2 ;;
        --build) build=$2; shift 2 ;;
        *) echo "previsd_footprint: unknown option '$1' (see the script's header)" >&2; exit 2 ;;
    esac
done
work=$(mktemp -d)
pid=""
trap '[ -n "$pid" ] && kill "$pid" 2>/dev/null; wait 2>/dev/null || true; rm -rf "$work"' EXIT
export RUNTIME_DIRECTORY=$work
# Beside the config, so its relative paths stay valid; [render] gets the size when asked (a
# config that sets its own width and height: edit it instead).
run=$(dirname "$config")/.footprint_$$.toml
trap '[ -n "$pid" ] && kill "$pid" 2>/dev/null; wait 2>/dev/null || true; rm -rf "$work" "$run"' EXIT
if [ -n "$size" ]; then
    w=${size%x*} h=${size#*x}
    awk -v w="$w" -v h="$h" '{ print } /^\[render\]/ { print "width = " w; print "height = " h }' \
        "$config" >"$run"
else
    cp "$config" "$run"
fi
"$build/daemon/previsd" --config "$run" >"$work/previsd.log" 2>&1 &
pid=$!
sleep "$seconds"
kill -0 "$pid" 2>/dev/null || { cat "$work/previsd.log"; echo "previsd_footprint: previsd exited" >&2; exit 1; }
peak=$(awk '/^VmHWM/ { print $2 }' "/proc/$pid/status")
threads=$(awk '/^Threads/ { print $2 }' "/proc/$pid/status")
echo "config $config${size:+ at $size}: peak resident ${peak} kB ($((peak / 1024)) MiB), $threads threads, $(nproc) cores"
