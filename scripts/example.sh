#!/usr/bin/env bash
# Sets everything up, then plays the bundled demo take.
#   scripts/example.sh           through the service pipeline in lock step (previs replay:
#                                tracking, lighting, differential rendering, compositing, preview
#                                and refinement as the recorded button presses say), then says
#                                where the frames went
#   scripts/example.sh --live    previsd plays the take live, looping, with the monitor page at
#                                http://127.0.0.1:8080/ and its controls on: a token made once
#                                in out/live/credentials/web-token (kept, git-ignored) that the
#                                page asks for; takes go to out/live/takes; Ctrl-C stops it
#   scripts/example.sh --live --check   only checks that config, token and takes folder
# PREVIS_BUILD=DIR uses that build instead of scripts/setup.sh's; PREVIS_OUT=DIR writes there
# instead of out/.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${PREVIS_BUILD:-$("$root/scripts/setup.sh" release)}
out_root=${PREVIS_OUT:-$root/out}
config="$root/examples/demo/previsd.toml"

if [[ "${1:-}" == "--live" ]]; then
    live="$out_root/live"
    mkdir -p "$live/credentials"
    token="$live/credentials/web-token"
    # The token previsd reads as the unit's credential would be (docs/web-monitor.md): only the
    # demo gets it, the config stays as shipped.
    if [[ ! -s "$token" ]]; then
        (umask 077; od -An -tx1 -N24 /dev/urandom | tr -d ' \n' >"$token")
    fi
    cd "$live"  # previsd's default takes folder is takes/ where it starts
    export CREDENTIALS_DIRECTORY="$live/credentials"
    if [[ "${2:-}" == "--check" ]]; then
        exec "$build/daemon/previsd" --config "$config" --check
    fi
    echo "previs: the demo plays live at http://127.0.0.1:8080/; the page's controls take the" \
         "token $(cat "$token") (kept in $token); takes go to $live/takes; Ctrl-C stops" >&2
    exec "$build/daemon/previsd" --config "$config"
fi

out="$out_root/demo"
rm -rf "$out"
"$build/cli/previs" replay "$root/examples/demo/session" --config "$config" --out "$out"
echo "previs: wrote $(ls "$out"/frame_*.png | wc -l) composited frames to $out/frame_NNNNNN.png" \
     "and $out/frames.csv (mode, samples, tracked pose per frame)"
