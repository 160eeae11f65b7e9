#!/usr/bin/python3
"""Plots of the speed/accuracy trade (matplotlib, Debian's python3-matplotlib).

    plot_trade.py DIR                  the files `previs bench --only trade` wrote into DIR
    plot_trade.py --blender CSV OUT    bench/compare_blender.sh's curves: previs and Cycles

From DIR: trade.csv → trade_rmse.png and trade_relmse.png (error against wall time, log-log,
one line per setting), meter.png (the convergence meter's estimate against the true √relMSE);
figure2_NNNN.png → figure2.png (the paper's figure 2: the composite after 1, 10, 100, 1000
frames); resolution.csv → figure4.png (the paper's figure 4: time of a frame against pixels);
dial.csv → dial.png (every preview setting's time and error, the Pareto front, the choice).
"""
import csv
import glob
import math
import os
import sys
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")  # headless: files only
import matplotlib.image as mpimg  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402


def read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def curves(rows, key):
    """Rows grouped by `key`, in first-seen order."""
    out = defaultdict(list)
    for r in rows:
        out[r[key]].append(r)
    return out


def save(fig, path):
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def finish_axes(ax, xlabel, ylabel):
    """The log plots' labels, grid and legend."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)


def error_plot(rows, column, label, path, transform=lambda v: v):
    fig, ax = plt.subplots(figsize=(7, 5))
    for name, pts in curves(rows, "setting").items():
        style = "--" if pts[0]["mode"] == "preview" else "-"
        ax.loglog([float(p["seconds"]) for p in pts],
                  [transform(float(p[column])) for p in pts], style, marker="o", ms=3,
                  label=name)
    finish_axes(ax, "wall time (s)", label)
    ax.set_title(f"{label} against time ({rows[0]['width']}x{rows[0]['height']})")
    save(fig, path)


def meter_plot(rows, path):
    fig, ax = plt.subplots(figsize=(7, 5))
    for name, pts in curves(rows, "setting").items():
        pts = [p for p in pts if float(p["noise_estimate"]) >= 0]
        if not pts:
            continue
        spp = [int(p["spp"]) for p in pts]
        line, = ax.loglog(spp, [math.sqrt(float(p["relmse"])) for p in pts], "-", label=name)
        ax.loglog(spp, [float(p["noise_estimate"]) for p in pts], ":", marker="x", ms=4,
                  color=line.get_color())
    finish_axes(ax, "samples per pixel",
                "√relMSE: true (solid, includes depth bias) and estimated (dotted)")
    save(fig, path)


def figure2(directory, path):
    frames = sorted(glob.glob(os.path.join(directory, "figure2_*.png")))
    if not frames:
        return
    fig, axes = plt.subplots(1, len(frames), figsize=(3.2 * len(frames), 2.8))
    for ax, frame in zip(axes if len(frames) > 1 else [axes], frames):
        ax.imshow(mpimg.imread(frame))
        n = int(os.path.basename(frame)[len("figure2_"):-len(".png")])
        ax.set_title(f"{n} frame{'s' if n > 1 else ''}")
        ax.axis("off")
    fig.suptitle("Refinement: the composite after 1, 10, 100 and 1000 frames (1 spp each)")
    save(fig, path)


def figure4(rows, path):
    fig, ax = plt.subplots(figsize=(6, 4.5))
    pixels = [int(r["pixels"]) for r in rows]
    ms = [1e3 * float(r["seconds_per_frame"]) for r in rows]
    ax.loglog(pixels, ms, "-o")
    for r, x, y in zip(rows, pixels, ms):
        ax.annotate(r["resolution"], (x, y), textcoords="offset points", xytext=(4, -10),
                    fontsize=8)
    ax.set_xlabel("pixels")
    ax.set_ylabel("ms per 1-spp frame (median)")
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title("Time against resolution")
    save(fig, path)


def dial_plot(rows, path):
    """dial.csv: every preview setting's frame time against its error; the front and the choice."""
    fig, ax = plt.subplots(figsize=(7, 5))
    t = [1e3 * float(r["frame_seconds"]) for r in rows]
    e = [float(r["rmse"]) for r in rows]
    denoised = [r.get("denoise_levels", "0") != "0" for r in rows]
    ax.scatter([x for x, d in zip(t, denoised) if not d], [y for y, d in zip(e, denoised) if not d],
               s=14, color="0.6", label="grid points")
    if any(denoised):
        ax.scatter([x for x, d in zip(t, denoised) if d], [y for y, d in zip(e, denoised) if d],
                   s=14, marker="^", color="tab:green", label="grid points, denoised")
    front = sorted((x, y) for x, y, r in zip(t, e, rows) if r["pareto"] == "1")
    ax.plot([x for x, _ in front], [y for _, y in front], "-o", ms=4, label="Pareto front")
    for x, y, r in zip(t, e, rows):
        if r["chosen"] == "1":
            ax.scatter([x], [y], s=120, facecolors="none", edgecolors="red", linewidths=2,
                       label=f"chosen: 1/{1 / float(r['scale']):.3g} scale, {r['spp']} spp, "
                             f"depth {r['max_depth']}, denoise {r.get('denoise_levels', '0')}")
    ax.axvline(100.0, color="red", ls=":", label="10 fps budget")
    ax.set_xscale("log")
    ax.set_yscale("log")
    finish_axes(ax, "ms per preview frame (median)", "RMSE of one frame")
    ax.set_title("The dial: preview settings at 640x480")
    save(fig, path)


def blender(csv_path, path):
    """compare_blender.sh's last_results.csv: scene,renderer,spp,seconds,rmse."""
    rows = read_csv(csv_path)
    scenes = curves(rows, "scene")
    fig, axes = plt.subplots(1, len(scenes), figsize=(6 * len(scenes), 4.5), squeeze=False)
    for ax, (scene, pts) in zip(axes[0], scenes.items()):
        for renderer, rp in curves(pts, "renderer").items():
            ax.loglog([float(p["seconds"]) for p in rp], [float(p["rmse"]) for p in rp],
                      "-o", ms=3, label=renderer)
        ax.set_title(scene)
        ax.set_xlabel("wall time (s)")
        ax.set_ylabel("RMSE against the reference")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    save(fig, path)


def main(argv):
    if len(argv) == 4 and argv[1] == "--blender":
        blender(argv[2], argv[3])
        return 0
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    directory = argv[1]
    rows = read_csv(os.path.join(directory, "trade.csv"))
    error_plot(rows, "rmse", "RMSE", os.path.join(directory, "trade_rmse.png"))
    error_plot(rows, "relmse", "√relMSE", os.path.join(directory, "trade_relmse.png"),
               math.sqrt)
    meter_plot(rows, os.path.join(directory, "meter.png"))
    figure2(directory, os.path.join(directory, "figure2.png"))
    dial = os.path.join(directory, "dial.csv")
    if os.path.exists(dial):
        dial_plot(read_csv(dial), os.path.join(directory, "dial.png"))
    resolution = os.path.join(directory, "resolution.csv")
    if os.path.exists(resolution):
        figure4(read_csv(resolution), os.path.join(directory, "figure4.png"))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
