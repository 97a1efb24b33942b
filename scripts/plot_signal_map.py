#!/usr/bin/python3
"""The palpation signal over the palpable surface (issue #32, "The signal"): at each site of
two surface maps of the same grid (scripts/surface_map_study.sh), one of the tissue with the
lump and one without, the force at a fixed depth D, F(D), interpolated from each site's
force-depth curve (scripts/plot_lateral_scan.py's force_at_depth: log F against log d between
the two forces of the sweep that bracket D), and the signal F_lump(D) / F_without(D), simulated
and of the sites' converged references (the references' curves give the reference signal).

usage: plot_signal_map.py LUMP_ROWS WITHOUT_ROWS DEPTH OUT [--target POINTS] [--scene FILE]

LUMP_ROWS, WITHOUT_ROWS: the maps' DIR/NAME_rows.csv (x_m, y_m, force_N, d_sim_m, d_ref_m, ...).
Writes OUT.csv (a row per site: the four forces at D, both signals, their difference),
OUT.md (the table) and OUT.png (the reference's signal, the simulated one and their
difference in percentage points, a cell per site; the target, default 1 point, marked).
A site where D is outside either sweep (simulated or reference) has no value. --scene: the
lump's scene, whose inclusions are outlined on the maps.
"""
import csv
import json
import math
import os
import sys
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from plot_lateral_scan import force_at_depth  # noqa: E402


def signed(v):
    """%+.1f without a signed zero (a difference that rounds to 0.0 is 0.0)."""
    return "0.0" if abs(v) < 0.05 else "%+.1f" % v


def curves(rows_file):
    """{(x, y): (forces, simulated depths, reference depths)} of a map's rows, m and N."""
    by_site = defaultdict(list)
    for r in csv.DictReader(open(rows_file)):
        num = lambda v: float(v) if v not in ("", None) else None
        by_site[(float(r["x_m"]), float(r["y_m"]))].append(
            (float(r["force_N"]), num(r["d_sim_m"]) if r.get("status", "ok") == "ok" else None, num(r["d_ref_m"])))
    return {site: tuple(zip(*sorted(v))) for site, v in by_site.items()}


def main():
    args = sys.argv[1:]
    target = 1.0
    if "--target" in args:
        k = args.index("--target")
        target = float(args[k + 1])
        del args[k:k + 2]
    inclusions = []
    if "--scene" in args:
        k = args.index("--scene")
        scene = json.load(open(args[k + 1]))
        inclusions = [i["sphere"] for i in scene.get("material", {}).get("inclusions", []) if "sphere" in i]
        del args[k:k + 2]
    if len(args) != 4:
        sys.exit(__doc__)
    lump_rows, without_rows, depth, out = args[0], args[1], float(args[2]), args[3]
    lump, without = curves(lump_rows), curves(without_rows)
    sites = sorted(set(lump) & set(without), key=lambda s: (-s[1], s[0]))
    if not sites:
        sys.exit("plot_signal_map.py: the two maps have no site in common")
    table = []
    for site in sites:
        fl, dl_sim, dl_ref = lump[site]
        fw, dw_sim, dw_ref = without[site]
        forces = [force_at_depth(fl, dl_sim, depth), force_at_depth(fw, dw_sim, depth),
                  force_at_depth(fl, dl_ref, depth), force_at_depth(fw, dw_ref, depth)]
        if None in forces:
            table.append((site, forces, None, None))
            continue
        signal_sim, signal_ref = forces[0] / forces[1], forces[2] / forces[3]
        table.append((site, forces, signal_sim, signal_ref))

    head = ("x_m,y_m,F_lump_sim_N,F_without_sim_N,F_lump_ref_N,F_without_ref_N,signal_sim,signal_ref,"
            "difference_points")
    lines = [head]
    md = ["The signal F(with the lump) / F(without) at depth %g mm at each site, simulated and of the sites' "
          "converged references, per cent; difference in percentage points (target: within %g). "
          "Written by scripts/plot_signal_map.py from %s and %s." % (1e3 * depth, target, lump_rows, without_rows),
          "", "| x (mm) | y (mm) | F lump, sim (N) | F without, sim (N) | signal, sim | signal, reference | "
          "difference |", "|---:|---:|---:|---:|---:|---:|---:|"]
    for (x, y), f, s_sim, s_ref in table:
        diff = None if s_sim is None else 100 * (s_sim - s_ref)
        lines.append(",".join("" if v is None else repr(v) for v in (x, y, *f, s_sim, s_ref, diff)))
        if s_sim is None:
            md.append("| %g | %g | – | – | – | – | depth %g mm outside a sweep |" % (1e3 * x, 1e3 * y, 1e3 * depth))
            continue
        mark = "**" if abs(diff) > target else ""
        md.append("| %g | %g | %.4f | %.4f | %.1f | %.1f | %s%s%s |" % (
            1e3 * x, 1e3 * y, f[0], f[1], 100 * s_sim, 100 * s_ref, mark, signed(diff), mark))
    diffs = [100 * (s - r) for _, _, s, r in table if s is not None]
    within = sum(abs(d) <= target for d in diffs)
    md += ["", "%d of %d sites within %g point; the difference %s … %s points." % (
        within, len(table), target, signed(min(diffs)), signed(max(diffs)))]
    open(out + ".csv", "w").write("\n".join(lines) + "\n")
    open(out + ".md", "w").write("\n".join(md) + "\n")
    print("\n".join(md[2:]))

    mm = 1e3
    xs = np.array([s[0] for s, *_ in table]) * mm
    ys = np.array([s[1] for s, *_ in table]) * mm
    sim = np.array([math.nan if s is None else 100 * s for _, _, s, _ in table])
    ref = np.array([math.nan if r is None else 100 * r for _, _, _, r in table])
    steps = [s for s in np.concatenate([np.diff(np.unique(xs)), np.diff(np.unique(ys))]) if s > 1e-9]
    cell = min(steps) if steps else 10.0
    fig, axes = plt.subplots(1, 3, figsize=(16, 5.6))
    lo, hi = np.nanmin(np.concatenate([sim, ref])), np.nanmax(np.concatenate([sim, ref]))
    signal_norm = plt.Normalize(min(lo, 100), max(hi, 100.5))
    span = max(2 * target, np.nanmax(np.abs(sim - ref)))
    diff_norm = plt.Normalize(-span, span)
    panels = ((ref, signal_norm, "viridis", "reference: F(lump) / F(without), %"),
              (sim, signal_norm, "viridis", "MLS (cloud refined at each site): F(lump) / F(without), %"),
              (sim - ref, diff_norm, "RdBu_r", "difference, percentage points (target ±%g)" % target))
    for ax, (values, norm, cmap_name, title) in zip(axes, panels):
        cmap = plt.get_cmap(cmap_name)
        for xi, yi, v in zip(xs, ys, values):
            colour = cmap(norm(v)) if math.isfinite(v) else (0.85, 0.85, 0.85, 1)
            ax.add_patch(Rectangle((xi - cell / 2, yi - cell / 2), cell, cell, facecolor=colour, edgecolor="white",
                                   lw=1.5))
            light = sum(colour[:3]) / 3 > 0.5
            text = "–" if not math.isfinite(v) else (signed(v) if values is not ref and values is not sim else
                                                     "%.1f" % v)
            bold = values is not ref and values is not sim and math.isfinite(v) and abs(v) > target
            ax.text(xi, yi, text, ha="center", va="center", fontsize=10, color="black" if light else "white",
                    fontweight="bold" if bold else "normal")
        for sphere in inclusions:
            ax.add_patch(plt.Circle((sphere["center"][0] * mm, sphere["center"][1] * mm), sphere["radius"] * mm,
                                    fill=False, ls="--", color="red", lw=1.2))
        ax.set_xlim(xs.min() - cell * 0.6, xs.max() + cell * 0.6)
        ax.set_ylim(ys.min() - cell * 0.6, ys.max() + cell * 0.6)
        ax.set_aspect("equal")
        ax.set_xlabel("x (mm)")
        ax.set_title(title, fontsize=10)
        fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax, fraction=0.046, pad=0.03)
    axes[0].set_ylabel("y (mm)")
    fig.suptitle("The palpation signal at depth %g mm over the palpable surface (the lump's outline dashed): "
                 "%d of %d sites within %g point" % (1e3 * depth, within, len(table), target), fontsize=12)
    fig.tight_layout()
    fig.savefig(out + ".png", dpi=110)
    print("plot_signal_map.py: wrote %s.png" % out)


if __name__ == "__main__":
    main()
