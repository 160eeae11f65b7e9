#!/usr/bin/env bash
# The set's network (issue 39) measured from outside the process: starts previsd on the shipped
# demo (examples/demo/previsd.toml) with [freed] and [opentrackio] sending to an independent
# receiver on 127.0.0.1 (bench/network_live.py: counts datagrams, checks FreeD's size and
# checksum and OpenTrackIO's header and checksum, and times each OpenTrackIO sample from its
# timing.sampleTimestamp to its receipt), the web monitor on a free port (max_viewers = 8) and
# `[session] events = false` (the take's button presses not replayed: the preview throughout, as
# bench/live_fps.sh measures it). After the first frame and a warm-up it runs each case (0, 1
# and 5 viewers of /stream.mjpeg, Python clients counting the stream's parts) for a window,
# reading `previs ctl status --json` once a second; per case it reports frames shown and tracked
# per second, packets sent and received per second, the capture->packet delay (status's
# trackingOut.delayMs and the receiver's own), and the stream's rate per viewer with the web
# status's encodes. Each run starts a fresh previsd; the second run takes the cases in reverse.
#   usage: bench/network_live.sh [--runs N] [--seconds N] [--warmup N] [--settle N]
#                                [--viewers "0 1 5"] [--build DIR] [--keep DIR]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
demo=$root/examples/demo
runs=2
seconds=30
warmup=20
settle=5
viewers="0 1 5"
build=$root/build
keep=
while (($#)); do
    case $1 in
        --runs) runs=$2; shift 2 ;;
        --seconds) seconds=$2; shift 2 ;;
        --warmup) warmup=$2; shift 2 ;;
        --settle) settle=$2; shift 2 ;;
        --viewers) viewers=$2; shift 2 ;;
        --build) build=$2; shift 2 ;;
        --keep) keep=$2; shift 2 ;;
        *) echo "network_live: unknown option '$1' (see the script's header)" >&2; exit 2 ;;
    esac
done
py=/usr/bin/python3
helper=$root/bench/network_live.py
work=$(mktemp -d)
pids=()
cleanup() {
    for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
    for p in "${pids[@]}"; do wait "$p" 2>/dev/null || true; done
    if [[ -n $keep ]]; then mkdir -p "$keep" && cp -r "$work"/. "$keep"/; fi
    rm -rf "$work"
}
trap cleanup EXIT

run_once() {  # run_once INDEX CASES...
    local n=$1; shift
    local d=$work/run$n
    mkdir -p "$d/demo"
    echo "run $n: $(uptime)"
    # The demo's folder as symlinks, so the config's relative paths resolve beside the copy.
    for f in "$demo"/*; do ln -s "$f" "$d/demo/$(basename "$f")"; done
    rm "$d/demo/previsd.toml"
    "$py" "$helper" receive "$d/ports" "$d/udp.log" &
    local rx=$!; pids+=("$rx")
    for _ in $(seq 100); do [[ -s $d/ports ]] && break; sleep 0.1; done
    read -r freed_port otio_port <"$d/ports"
    local web_port; web_port=$("$py" "$helper" freeport)
    "$py" - "$demo/previsd.toml" "$d/demo/previsd.toml" "$freed_port" "$otio_port" "$web_port" <<'EOF'
import re, sys
src, dst, freed, otio, web = sys.argv[1:]
text = open(src).read()
text, n = re.subn(r'(?m)^listen = "127\.0\.0\.1:8080"$', f'listen = "127.0.0.1:{web}"\nmax_viewers = 8', text)
assert n == 1, "the demo config's [web] listen line changed: update bench/network_live.sh"
text += (f'\n[session]\nevents = false\n\n[freed]\nout = "127.0.0.1:{freed}"\n\n'
         f'[opentrackio]\nout = "127.0.0.1:{otio}"\n')
open(dst, "w").write(text)
EOF
    export RUNTIME_DIRECTORY=$d
    "$build/daemon/previsd" --config "$d/demo/previsd.toml" >"$d/previsd.log" 2>&1 &
    local pid=$!; pids+=("$pid")
    status() { timeout 10 "$build/cli/previs" ctl --socket "$d/previsd.sock" status --json 2>/dev/null; }
    local shown=0
    for _ in $(seq 600); do
        shown=$(status | "$py" -c 'import json,sys; print(json.load(sys.stdin)["framesShown"])' \
                2>/dev/null || echo 0)
        ((shown > 0)) && break
        sleep 1
    done
    ((shown > 0)) || { echo "network_live: no frame shown in 600 s; log:" >&2; cat "$d/previsd.log" >&2; exit 1; }
    sleep "$warmup"
    for v in "$@"; do
        local vp=()
        for ((i = 0; i < v; i++)); do
            "$py" "$helper" viewer "http://127.0.0.1:$web_port/stream.mjpeg" "$d/viewer-v$v-$i.log" &
            vp+=($!); pids+=($!)
        done
        sleep "$settle"
        local t0; t0=$(date +%s.%N)
        for _ in $(seq 0 "$seconds"); do
            local before body; before=$(date +%s.%N); body=$(status | tr -d '\n') || body=  # a failed call: a line the analysis skips
            echo "$before $(date +%s.%N) $body" >>"$d/samples"
            sleep 1
        done
        echo "v$v $v $t0 $(date +%s.%N)" >>"$d/cases"
        for p in "${vp[@]}"; do kill "$p" 2>/dev/null || true; wait "$p" 2>/dev/null || true; done
        pids=("$rx" "$pid")
        for ((i = 0; i < v; i++)); do
            head -1 "$d/viewer-v$v-$i.log" | grep -q ' 200' ||
                echo "network_live: viewer $i of $v: $(head -1 "$d/viewer-v$v-$i.log")" >&2
        done
    done
    kill "$pid" "$rx"; wait "$pid" 2>/dev/null || true; wait "$rx" 2>/dev/null || true
    pids=()
    "$py" "$helper" analyse "$d"
}

read -ra cases <<<"$viewers"
for ((r = 1; r <= runs; r++)); do
    if ((r % 2)); then run_once "$r" "${cases[@]}"
    else
        rev=(); for ((k = ${#cases[@]} - 1; k >= 0; k--)); do rev+=("${cases[k]}"); done
        run_once "$r" "${rev[@]}"
    fi
done
# Medians over the runs, per case, with the runs' range.
"$py" - "$work" <<'EOF'
import glob, json, os, statistics, sys
rows = [r for f in sorted(glob.glob(os.path.join(sys.argv[1], "run*", "result.json")))
        for r in json.load(open(f))]
keys = [("shown", "frames shown/s"), ("tracked", "tracked/s"), ("rxFreed", "FreeD rx/s"),
        ("rxOtio", "OpenTrackIO rx/s"), ("delayMed", "rx delay median ms"),
        ("delayP95", "rx delay p95 ms"), ("statusLastMed", "status delayMs.last median"),
        ("statusMax", "status delayMs.max"), ("encodedPerS", "web encodes/s"),
        ("sentPerEncode", "sent per encode")]
print("\nsummary: median [min, max] over runs")
for case in sorted({r["case"] for r in rows}, key=lambda c: int(c[1:])):
    rs = [r for r in rows if r["case"] == case]
    parts = [f"{label} {statistics.median(r[k] for r in rs):.2f} "
             f"[{min(r[k] for r in rs):.2f}, {max(r[k] for r in rs):.2f}]" for k, label in keys]
    vr = [x for r in rs for x in r["viewerRates"]]
    if vr:
        parts.append(f"per-viewer stream fps median {statistics.median(vr):.2f} "
                     f"[{min(vr):.2f}, {max(vr):.2f}]")
    print(f"{case} ({len(rs)} runs): " + "; ".join(parts))
EOF
