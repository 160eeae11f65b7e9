#!/usr/bin/env bash
# The live rate through a long hold (issue 53, "the rate holds"): the demo session with the scene
# camera's frame 20 (the still view) repeated for --hold-seconds after the take's first 20 frames,
# previsd at --fps ([render] preview_fps), measured by bench/live_fps.sh; the other options go to
# it (e.g. --busy-after 20 --keep DIR: the dial's corrections are in the kept log).
#   usage: bench/live_fps_hold.sh [--hold-seconds N] [--fps F] [live_fps.sh options]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
demo=$root/examples/demo
hold=60
fps=15
args=()
while (($#)); do
    case $1 in
        --hold-seconds) hold=$2; shift 2 ;;
        --fps) fps=$2; shift 2 ;;
        *) args+=("$1"); shift ;;
    esac
done
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cp -r "$demo/session" "$work/session"
python3 - "$work" "$demo" "$hold" "$fps" <<'EOF'
import os, re, sys
work, demo, hold, fps = sys.argv[1], sys.argv[2], float(sys.argv[3]), sys.argv[4]
index = f"{work}/session/cameras/scene/index.csv"
lines = open(index).read().splitlines()
rows = [l.split(",") for l in lines[1:]]
period = (int(rows[1][1]) - int(rows[0][1])) / 1e9
# The take's first 20 frames move; then frame 20's picture (one pose) for the hold; then the rest.
files = [r[2] for r in rows[:20]] + [rows[20][2]] * int(hold / period) + [r[2] for r in rows[20:]]
out = [lines[0]]
for n, f in enumerate(files):
    out.append(f"{n},{int(rows[0][1]) + round(n * period * 1e9)},{f},{rows[0][3]},{rows[0][4]},,,")
open(index, "w").write("\n".join(out) + "\n")
# The demo's config with its relative paths made absolute (the session's to the copy), the frame
# rate asked, and no web monitor (its port may be taken).
config = []
for line in open(f"{demo}/previsd.toml"):
    m = re.match(r'^(scene|device|calibration|board) = "([^"]+)"', line)
    if m and m.group(2).startswith("session/"):
        line = f'{m.group(1)} = "{work}/{m.group(2)}"\n'
    elif m and os.path.exists(f"{demo}/{m.group(2)}"):
        line = f'{m.group(1)} = "{demo}/{m.group(2)}"\n'
    if line.startswith("preview_fps ="):
        line = f"preview_fps = {fps}\n"
    if line.startswith("[web]"):
        break
    config.append(line)
open(f"{work}/previsd.toml", "w").write("".join(config))
EOF
"$root/bench/live_fps.sh" --config "$work/previsd.toml" "${args[@]}"
