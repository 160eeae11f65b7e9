#!/usr/bin/env python3
"""Time to equal error, previs against Blender Cycles, from bench/compare_blender.sh's CSV.

  time_to_equal_error.py RESULTS.csv
RESULTS.csv rows: scene,renderer,spp,seconds,rmse (renderer previs or cycles; rmse against that
renderer's own long reference). For each scene, each renderer's (time, RMSE) points are joined in
log-log space (piecewise linear, in order of sample count); at RMSE levels both curves reach, the
time each needs is read off and the ratio previs/Cycles printed (≤ 1: previs gets there first).
Also per sample: the time one more sample costs (slope between the fewest and most samples) and
the error per sample, RMSE·√spp at the most samples (equal for two renderers with the same noise
per sample; lower is better), and from the two the ratio in the limit of many samples, where
fixed costs (start-up, BVH, pipeline compile) no longer count: time per sample ratio × (RMSE·√spp
ratio)², since the samples needed for an error e are (RMSE·√spp / e)².
"""
import csv
import math
import sys
from collections import defaultdict


def time_for_error(points, target):
    """Seconds at which the curve through `points` [(spp, seconds, rmse)] reaches `target`, by
    log-log interpolation between the first pair that brackets it; None if it never does."""
    for (_, t0, e0), (_, t1, e1) in zip(points, points[1:]):
        if e0 >= target >= e1 and e0 > e1:
            f = (math.log(e0) - math.log(target)) / (math.log(e0) - math.log(e1))
            return math.exp(math.log(t0) + f * (math.log(t1) - math.log(t0)))
    if points and points[0][2] <= target:
        return points[0][1]
    return None


def main(path):
    rows = defaultdict(list)
    with open(path) as f:
        for r in csv.DictReader(f):
            rows[(r["scene"], r["renderer"])].append(
                (int(r["spp"]), float(r["seconds"]), float(r["rmse"])))
    scenes = sorted({s for s, _ in rows}, key=lambda s: [k[0] for k in rows].index(s))
    summary = []
    for scene in scenes:
        p = sorted(rows[(scene, "previs")])
        c = sorted(rows[(scene, "cycles")])
        if not p or not c:
            print(f"{scene}: missing a renderer's rows")
            continue
        print(f"### {scene}\n\n| spp | previs s | previs RMSE | Cycles s | Cycles RMSE |\n"
              "|---|---|---|---|---|")
        cmap = {n: (t, e) for n, t, e in c}
        for n, t, e in p:
            ct, ce = cmap.get(n, (float("nan"), float("nan")))
            print(f"| {n} | {t:.2f} | {e:.4g} | {ct:.2f} | {ce:.4g} |")
        # RMSE levels both reach: from the larger of the two final errors up to the smaller of
        # the two first ones, five log-spaced levels.
        lo = max(p[-1][2], c[-1][2])
        hi = min(p[0][2], c[0][2])
        print(f"\n| RMSE | previs s | Cycles s | previs / Cycles |\n|---|---|---|---|")
        ratios = []
        if lo < hi:
            for k in range(5):
                # The ends exactly: exp(log(lo)) may round below lo, which the renderer whose
                # last error is lo never reaches, and the lowest level would be lost.
                target = hi if k == 0 else lo if k == 4 else math.exp(
                    math.log(hi) + (math.log(lo) - math.log(hi)) * k / 4)
                tp, tc = time_for_error(p, target), time_for_error(c, target)
                if tp is None or tc is None:
                    continue
                ratios.append(tp / tc)
                print(f"| {target:.4g} | {tp:.2f} | {tc:.2f} | {tp / tc:.2f}× |")
        else:
            print("| (the two error ranges do not overlap) | | | |")
        per_sample = [(pts[-1][1] - pts[0][1]) / (pts[-1][0] - pts[0][0]) for pts in (p, c)]
        per_error = [pts[-1][2] * math.sqrt(pts[-1][0]) for pts in (p, c)]
        print(f"\nPer sample: previs {per_sample[0]:.3f} s, Cycles {per_sample[1]:.3f} s "
              f"({per_sample[0] / per_sample[1]:.2f}×); RMSE·√spp at {p[-1][0]} / {c[-1][0]} spp: "
              f"previs {per_error[0]:.4g}, Cycles {per_error[1]:.4g} "
              f"({per_error[0] / per_error[1]:.2f}×).")
        if ratios:
            geo = math.exp(sum(math.log(r) for r in ratios) / len(ratios))
            print(f"Time to equal error, previs / Cycles: {ratios[-1]:.2f}× at the lowest common "
                  f"RMSE, {geo:.2f}× geometric mean over the levels.")
            ts, es = per_sample[0] / per_sample[1], per_error[0] / per_error[1]
            print(f"In the limit of many samples: {ts:.2f} × {es:.2f}² = {ts * es * es:.2f}×.\n")
            summary.append((scene, ratios[-1], geo, ts, es))
        else:
            print()
    print("### Summary\n\n| scene | time to equal error, previs / Cycles (lowest common RMSE) | "
          "geometric mean over levels | time per sample ratio | RMSE·√spp ratio | many-sample "
          "limit |\n|---|---|---|---|---|---|")
    for scene, last, geo, ts, es in summary:
        print(f"| {scene} | **{last:.2f}×** | {geo:.2f}× | {ts:.2f}× | {es:.2f}× | "
              f"{ts * es * es:.2f}× |")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
