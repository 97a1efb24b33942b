#!/usr/bin/python3
"""Figures and the Markdown table of the sliding study (scripts/slide_study.sh).

usage: /usr/bin/python3 scripts/plot_slide.py DIR [RAW]
Reads every RAW/*.json written by palpate-slide --json (RAW defaults to data/verification/X
for DIR docs/verification/X, else DIR/raw) and writes DIR/sliding.png
(|mean F_x| / |mean F_z| and the depth error at the middle against the speed) and
DIR/sliding.md (the table).
"""
import glob
import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def raw_default(out):
    """The runs' JSON for the output folder OUT: under data/ for a folder under docs/
    (docs/verification/X -> data/verification/X, data/README.md), else OUT/raw."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    parts = os.path.relpath(os.path.abspath(out), root).split(os.sep)
    if parts[0] == "docs" and len(parts) > 1:
        return os.path.join(root, "data", *parts[1:])
    return os.path.join(out, "raw")


def main(folder, raw):
    runs = []
    for path in sorted(glob.glob(os.path.join(raw, "*.json"))):
        with open(path) as f:
            data = json.load(f)
        if "rows" in data and "static_depth" in data:
            runs.append((os.path.splitext(os.path.basename(path))[0], data))
    if not runs:
        sys.exit(f"plot_slide.py: no palpate-slide JSON in {raw}")

    fig, (ax_ratio, ax_depth) = plt.subplots(1, 2, figsize=(11, 4.2))
    lines = ["| scene | particles | v [m/s] | mean F_x [N] | mean F_z [N] | \\|F_x\\|/\\|F_z\\| | rms F_x/F_z "
             "| d_middle [mm] | d_static [mm] | depth error | steps | wall [s] |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, data in runs:
        rows = [r for r in data["rows"] if r["ratio"] is not None]
        v = [r["speed"] for r in rows]
        label = f'{data["scene"]} ({data["particles"]} particles, {data["integrator"]})'
        ax_ratio.loglog(v, [r["ratio"] for r in rows], "o-", label=label + ": |mean F_x| / |mean F_z|")
        ax_ratio.loglog(v, [r["rms_ratio"] for r in rows], "x:", color=ax_ratio.lines[-1].get_color(),
                        label=label + ": rms F_x / |mean F_z|")
        ax_depth.semilogx(v, [100 * r["depth_error"] for r in rows], "o-", label=label)
        for r in data["rows"]:
            def f(x, fmt):
                return "-" if x is None else fmt % x
            lines.append(f'| {data["scene"]} | {data["particles"]} | {r["speed"]:g} | {f(r["mean_fx"], "%.4g")} '
                         f'| {f(r["mean_fz"], "%.5g")} | {f(r["ratio"], "%.2e")} | {f(r["rms_ratio"], "%.2e")} '
                         f'| {f(None if r["depth_middle"] is None else 1e3 * r["depth_middle"], "%.4f")} '
                         f'| {1e3 * data["static_depth"]:.4f} | {f(None if r["depth_error"] is None else 100 * r["depth_error"], "%+.3f %%")} '
                         f'| {r["steps"]} | {r["wall_seconds"]:.1f} |')
    vmin = min(r["speed"] for _, d in runs for r in d["rows"])
    vmax = max(r["speed"] for _, d in runs for r in d["rows"])
    # The slope-1 guide through the smallest ratio at the slowest speed (a symmetric cloud,
    # whose quasi-static floor (4.5) is zero, follows it).
    slowest = [r for _, d in runs for r in d["rows"] if r["ratio"] is not None and r["speed"] == vmin]
    anchor = min(slowest, key=lambda r: r["ratio"]) if slowest else None
    if anchor:
        ax_ratio.loglog([vmin, vmax], [anchor["ratio"] * vmin / anchor["speed"], anchor["ratio"] * vmax / anchor["speed"]],
                        "k--", lw=0.8, label="slope 1 (linear drag)")
    force = runs[0][1]["force"]
    ax_ratio.set_xlabel("target speed v [m/s]")
    ax_ratio.set_ylabel("tangential / normal contact force on the tool")
    ax_ratio.set_title(f"Frictionless drag at F = {force:g} N, window x in [-{runs[0][1]['half_window']:g}, "
                       f"{runs[0][1]['half_window']:g}] m")
    ax_ratio.grid(True, which="both", alpha=0.3)
    ax_ratio.legend(fontsize=7, loc="upper left")
    ax_depth.axhline(0, color="k", lw=0.8)
    ax_depth.set_xlabel("target speed v [m/s]")
    ax_depth.set_ylabel("(d_middle - d_static) / d_static [%]")
    ax_depth.set_title("Depth as the tool crosses the middle")
    ax_depth.grid(True, which="both", alpha=0.3)
    ax_depth.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(folder, "sliding.png"), dpi=130)
    with open(os.path.join(folder, "sliding.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2] if len(sys.argv) > 2 else raw_default(sys.argv[1]))
