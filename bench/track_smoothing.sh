#!/usr/bin/env bash
# The take's camera track, raw and smoothed (vision/track_smoother.h), against the ground truth a
# take holds (poses.csv "truth" lines: the bundled demo take by default): position and rotation
# error per frame (median, 90th percentile, max), and the jitter on the still stretch (frames
# 20-44: the standard deviation of the error about its own mean, per axis, which a constant
# bias does not enter). Needs numpy (Debian python3-numpy).
#   usage: bench/track_smoothing.sh [TAKE] [--build DIR]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
take=$root/examples/demo/session
build=$root/build
while (($#)); do
    case $1 in
        --build) build=$2; shift 2 ;;
        *) take=$1; shift ;;
    esac
done
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$build/cli/previs" export-track "$take" --out "$work/raw.jsonl" 2>/dev/null
"$build/cli/previs" export-track "$take" --out "$work/smoothed.jsonl" --smoothed 2>/dev/null
/usr/bin/python3 - "$take" "$work/raw.jsonl" "$work/smoothed.jsonl" <<'PY'
import json, sys
import numpy as np
take = sys.argv[1]
truth = {}
for line in open(take + "/poses.csv"):
    if line.startswith("#"):
        continue
    f = line.strip().split(",")
    if f[2] == "truth":
        truth[int(f[1])] = np.array([float(x) for x in f[3:19]]).reshape(4, 4)
sequences = [int(l.split(",")[0]) for l in open(take + "/cameras/scene/index.csv")
             if not l.startswith("#")]
print("| track | frames | position error mm: median / p90 / max | rotation error °: median / p90 / max | still jitter mm (x, y, z) | still jitter ° |")
print("|---|---|---|---|---|---|")
for name, path in (("raw (tracked on each frame)", sys.argv[2]), ("smoothed (RTS)", sys.argv[3])):
    poses = {j["frame"]: np.array(j["worldFromCamera"]).reshape(4, 4) for j in map(json.loads, open(path))}
    pos, rot, still_d, still_r = [], [], [], []
    for k, m in sorted(poses.items()):
        t = truth.get(sequences[k])
        if t is None:
            continue
        d = m[:3, 3] - t[:3, 3]
        r = t[:3, :3].T @ m[:3, :3]
        angle = np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1)))
        pos.append(np.linalg.norm(d) * 1e3)
        rot.append(angle)
        if 20 <= k <= 44:
            still_d.append(d * 1e3)
            still_r.append(angle)
    pos, rot = np.array(pos), np.array(rot)
    jd = np.std(np.array(still_d), axis=0) if still_d else [float("nan")] * 3
    jr = np.std(still_r) if still_r else float("nan")
    print(f"| {name} | {len(pos)} | {np.median(pos):.3f} / {np.percentile(pos, 90):.3f} / {pos.max():.3f} "
          f"| {np.median(rot):.4f} / {np.percentile(rot, 90):.4f} / {rot.max():.4f} "
          f"| {jd[0]:.3f}, {jd[1]:.3f}, {jd[2]:.3f} | {jr:.4f} |")
PY
