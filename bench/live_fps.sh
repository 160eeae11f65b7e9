#!/usr/bin/env bash
# The live service's frame rate and latency, measured from outside the process: starts previsd on
# a config (default: the shipped demo, examples/demo/previsd.toml), waits until it shows frames,
# then reads its status once a second (bench/status_sampler.py: one reader, not a `previs ctl`
# per sample) and reports the frames shown per second of wall clock (framesShown's growth, not the
# service's own estimate), and the medians of the service's fps, latencyMs, renderMs and
# lightingMs fields over the window.
# --keep DIR keeps previsd's log (the dial's corrections) and the status samples there;
# --busy-after N busy-loops one core from N seconds into the window to its end (another process
# loading the box) and reports the frames shown/s before and after it started.
#   usage: bench/live_fps.sh [--config FILE] [--seconds N] [--warmup N] [--build DIR] [--keep DIR]
#                            [--busy-after N]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
config=$root/examples/demo/previsd.toml
seconds=30
warmup=20
build=$root/build
keep=
busyAfter=
while (($#)); do
    case $1 in
        --config) config=$2; shift 2 ;;
        --seconds) seconds=$2; shift 2 ;;
        --warmup) warmup=$2; shift 2 ;;
        --build) build=$2; shift 2 ;;
        --keep) keep=$2; shift 2 ;;
        --busy-after) busyAfter=$2; shift 2 ;;
        *) echo "live_fps: unknown option '$1' (see the script's header)" >&2; exit 2 ;;
    esac
done
work=$(mktemp -d)
# Each step may fail (previsd gone, no samples yet) without stopping the rest: the folder goes.
trap 'kill "$pid" 2>/dev/null || true; wait "$pid" 2>/dev/null || true
      if [[ -n $keep ]]; then
          mkdir -p "$keep" && cp "$work"/previsd.log "$work"/samples "$keep"/ 2>/dev/null || true
      fi
      rm -rf "$work"' EXIT
export RUNTIME_DIRECTORY=$work
"$build/daemon/previsd" --config "$config" >"$work/previsd.log" 2>&1 &
pid=$!
busyArgs=()
[[ -n $busyAfter ]] && busyArgs=(--busy-after "$busyAfter" "$work/busy")
python3 "$root/bench/status_sampler.py" "$work/previsd.sock" "$pid" "$warmup" "$seconds" \
    "$work/samples" ${busyArgs[@]+"${busyArgs[@]}"} ||
    { echo "live_fps: no frame shown (previsd stopped, or 600 s); log:" >&2; cat "$work/previsd.log" >&2; exit 1; }
python3 - "$work/samples" "$work/busy" <<'EOF'
import json, statistics, sys
rows = []
for line in open(sys.argv[1]):
    t, _, body = line.partition(" ")
    try:
        rows.append((float(t), json.loads(body)))
    except ValueError:
        pass
(t0, a), (t1, b) = rows[0], rows[-1]
shown = (b["framesShown"] - a["framesShown"]) / (t1 - t0)
med = lambda k: statistics.median(r[k] for _, r in rows)
print(f"frames shown/s {shown:.2f} over {t1 - t0:.0f} s; medians: fps {med('fps'):.2f}, "
      f"latencyMs {med('latencyMs'):.0f}, renderMs {med('renderMs'):.0f}, "
      f"lightingMs {med('lightingMs'):.0f}, "
      f"dropped {b['framesDropped'] - a['framesDropped']}, mode {b['mode']}, "
      f"history {b.get('previewHistoryFrames')}")
try:
    busy = float(open(sys.argv[2]).read())
except OSError:
    sys.exit(0)
def rate(w):
    return (w[-1][1]["framesShown"] - w[0][1]["framesShown"]) / (w[-1][0] - w[0][0])
quiet = [r for r in rows if r[0] <= busy]
loaded = [r for r in rows if r[0] >= busy]
if len(quiet) > 1 and len(loaded) > 1:
    print(f"frames shown/s before the busy loop {rate(quiet):.2f}, with it {rate(loaded):.2f}")
EOF
