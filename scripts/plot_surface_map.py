#!/usr/bin/python3
"""The map of the depth error over the palpable surface (scripts/surface_map_study.sh).

usage: plot_surface_map.py CSV SCENE PNG [--target PERCENT] [--dome RB]

Reads CSV (one row per site, written by surface_map_study.sh: x_m, y_m, err_<F>N per force,
worst_abs_err, l2_err, ...) and the scene (its box, indenter radius and, for a mesh cloud, the
mesh file) and draws PNG:
  left   the worst |depth error| over the forces at each site, a cell per site with its value,
         green below the target (default 2 %), red above; the top face's outline, the
         palpable region (1.5 R from the walls) and, for a mesh cloud, where the mesh is finer
         than on the rest of the top face (the mean distance of each top-face node to its six
         nearest top-face neighbours, contoured) with the top-face nodes as dots;
  right  the signed error at the smallest and the largest verification force against the
         site's distance from the centre of the face, the target band shaded.
With --dome RB (a hemisphere of radius RB, m, no box): the rim and the circles where the skin
slopes by 15, 30 and 45 degrees instead of the walls; distances from the pole.
"""
import csv
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import TwoSlopeNorm  # noqa: E402
from matplotlib.patches import Circle, Rectangle  # noqa: E402


def read_msh_nodes(path):
    """The node positions of a gmsh .msh file (4.1 or 2.2 ASCII)."""
    lines = open(path).read().split("\n")
    i = lines.index("$Nodes")
    if lines[lines.index("$MeshFormat") + 1].startswith("2"):
        n = int(lines[i + 1])
        return np.array([[float(v) for v in lines[i + 2 + k].split()[1:4]] for k in range(n)])
    blocks = int(lines[i + 1].split()[0])
    k, points = i + 2, []
    for _ in range(blocks):
        n = int(lines[k].split()[3])
        k += 1 + n  # the block header, then the tags
        points += [[float(v) for v in lines[k + j].split()[:3]] for j in range(n)]
        k += n
    return np.array(points)


def top_face_spacing(scene_file, scene):
    """(top-face nodes (n x 2), their mean distance to the 6 nearest) or None (not a mesh cloud)."""
    dist = scene.get("body", {}).get("distribution", {})
    if dist.get("type") != "mesh" or "box" not in scene.get("body", {}):
        return None
    path = os.path.join(os.path.dirname(scene_file), dist["file"])
    if not os.path.exists(path):
        return None
    X = read_msh_nodes(path)
    top = X[np.abs(X[:, 2] - scene["body"]["box"]["max"][2]) < 1e-9][:, :2]
    if len(top) < 8:
        return None
    d = np.sqrt(((top[:, None, :] - top[None, :, :]) ** 2).sum(-1))
    np.fill_diagonal(d, np.inf)
    return top, np.sort(d, axis=1)[:, :6].mean(axis=1)


def main():
    args = sys.argv[1:]
    target = 2.0
    if "--target" in args:
        k = args.index("--target")
        target = float(args[k + 1])
        del args[k:k + 2]
    dome = None
    if "--dome" in args:
        k = args.index("--dome")
        dome = float(args[k + 1])
        del args[k:k + 2]
    if len(args) != 3:
        sys.exit(__doc__)
    csv_file, scene_file, png = args
    scene = json.load(open(scene_file))
    rows = list(csv.DictReader(open(csv_file)))
    force_cols = [c for c in rows[0] if c.startswith("err_") and c.endswith("N")]
    forces = [float(c[4:-1]) for c in force_cols]
    mm = 1000.0
    x = np.array([float(r["x_m"]) for r in rows]) * mm
    y = np.array([float(r["y_m"]) for r in rows]) * mm
    num = lambda v: float(v) if v not in ("", None) else math.nan
    worst = np.array([num(r["worst_abs_err"]) for r in rows]) * 100
    ref_unc = np.array([num(r.get("ref_uncertainty_max")) for r in rows]) * 100
    err = np.array([[num(r[c]) for c in force_cols] for r in rows]) * 100
    R = scene["indenter"]["radius"] * mm
    ux, uy = np.unique(np.round(x, 9)), np.unique(np.round(y, 9))
    steps = [s for s in np.concatenate([np.diff(ux), np.diff(uy)]) if s > 1e-9]
    cell = min(steps) if steps else 2 * R
    if dome is not None:
        lo, hi = -np.array([dome, dome]) * mm, np.array([dome, dome]) * mm
    else:
        box = scene["body"]["box"]
        lo, hi = np.array(box["min"][:2]) * mm, np.array(box["max"][:2]) * mm
    centre = 0.5 * (lo + hi)

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(14.5, 6.6), gridspec_kw={"width_ratios": [1.12, 1]})
    vmax = max(np.nanmax(worst), 2 * target)
    norm = TwoSlopeNorm(vmin=0, vcenter=target, vmax=vmax)
    cmap = plt.get_cmap("RdYlGn_r")
    for xi, yi, w, u in zip(x, y, worst, ref_unc):
        colour = cmap(norm(w)) if math.isfinite(w) else (0.8, 0.8, 0.8, 1)
        ax.add_patch(Rectangle((xi - cell / 2, yi - cell / 2), cell, cell, facecolor=colour, edgecolor="white", lw=1.5,
                               zorder=1))
        light = sum(colour[:3]) / 3 > 0.55
        # the text on a patch of the cell's colour, so the outlines drawn over the cells do not cross it
        box = dict(facecolor=colour, edgecolor="none", pad=0.6)
        ax.text(xi, yi + 0.1 * cell, "–" if not math.isfinite(w) else "%.1f %%" % w, ha="center", va="center",
                fontsize=11, fontweight="bold", color="black" if light else "white", zorder=4, bbox=box)
        if math.isfinite(u):
            ax.text(xi, yi - 0.22 * cell, "ref ±%.1f" % u, ha="center", va="center", fontsize=7.5,
                    color="black" if light else "white", zorder=4, bbox=box)
    if dome is not None:
        ax.add_patch(Circle((0, 0), dome * mm, fill=False, edgecolor="black", lw=2, zorder=3))
        for degrees in (15, 30, 45):
            ax.add_patch(Circle((0, 0), dome * mm * math.sin(math.radians(degrees)), fill=False, edgecolor="black",
                                lw=0.8, ls="--", zorder=3))
        handles = [plt.Line2D([], [], color="black", lw=2, label="the dome's rim (fixed base)"),
                   plt.Line2D([], [], color="black", lw=0.8, ls="--", label="where the skin slopes by 15, 30, 45° (the sites: cell centres)")]
    else:
        ax.add_patch(Rectangle(lo, *(hi - lo), fill=False, edgecolor="black", lw=2, zorder=3))
        m = 1.5 * R
        ax.add_patch(Rectangle(lo + m, *(hi - lo - 2 * m), fill=False, edgecolor="black", lw=1, ls="--", zorder=3))
        handles = [plt.Line2D([], [], color="black", lw=2, label="top face (walls)"),
                   plt.Line2D([], [], color="black", lw=1, ls="--",
                              label="palpable surface: 1.5 R from the walls (the sites: cell centres)")]
    spacing = top_face_spacing(scene_file, scene)
    note = ""
    if spacing is not None:
        top, h = spacing
        ax.scatter(top[:, 0] * mm, top[:, 1] * mm, s=0.6, c="black", alpha=0.35, lw=0, zorder=2)
        median = np.median(h)
        level = 0.85 * median
        if h.min() < level:
            # the contour's closed curves, less the specks of single finer nodes (under 2 spacings across)
            cs = plt.figure().add_subplot().tricontour(top[:, 0], top[:, 1], h, levels=[level])
            for seg in cs.allsegs[0]:
                if np.ptp(seg, axis=0).max() > 2 * median:
                    ax.plot(seg[:, 0] * mm, seg[:, 1] * mm, color="blue", lw=1.8, zorder=3)
            plt.close(cs.axes.figure)
            handles.append(plt.Line2D([], [], color="blue", lw=1.8,
                                      label="mesh refined: top-face spacing < %.1f mm" % (level * mm)))
        note = "top-face mesh nodes as dots; spacing %.1f mm at the finest, %.1f mm (median) elsewhere" % (
            h.min() * mm, median * mm)
    if np.isfinite(ref_unc).any():
        note += ("\n" if note else "") + "ref ±: the reference's largest relative uncertainty over the forces (%)"
    ax.set_xlim(lo[0] - 2, hi[0] + 2)
    ax.set_ylim(lo[1] - 2, hi[1] + 2)
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    n_ok = int(np.sum(worst <= target))
    ax.set_title("Worst |depth error| over F = %g ... %g N, per site\n%d of %d sites within %g %%" % (
        min(forces), max(forces), n_ok, len(rows), target, ), fontsize=11)
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.09), ncol=2, fontsize=8.5, frameon=False)
    if note:
        ax.text(0.5, -0.19, note, va="top", transform=ax.transAxes, ha="center", fontsize=8, color="0.3")
    sm = plt.cm.ScalarMappable(norm=norm, cmap=cmap)
    bar = fig.colorbar(sm, ax=ax, fraction=0.046, pad=0.03)
    bar.set_label("worst |depth error| (%)")
    bar.ax.axhline(target, color="black", lw=2)
    ticks = sorted(set([0, target] + [t for t in bar.get_ticks() if 0 <= t <= vmax and abs(t - target) > 0.06 * vmax]))
    bar.set_ticks(ticks)
    bar.set_ticklabels(["%g (target)" % t if t == target else "%g" % t for t in ticks])

    r = np.hypot(x - centre[0], y - centre[1])
    # the reference's uncertainty at each site and force, as error bars (DIR/NAME_rows.csv, if there)
    bars = np.full_like(err, math.nan)
    rows_file = csv_file[:-4] + "_rows.csv"
    if os.path.exists(rows_file):
        index = {(round(float(r["x_m"]) * mm, 6), round(float(r["y_m"]) * mm, 6), float(r["force_N"])): r
                 for r in csv.DictReader(open(rows_file))}
        for i in range(len(rows)):
            for k, F in enumerate(forces):
                q = index.get((round(x[i], 6), round(y[i], 6), F))
                if q and q["d_ref_uncertainty_m"] and q["d_sim_m"]:
                    # e = d_sim / d_ref - 1: d_ref +- u moves it by about (1 + e) u / d_ref
                    bars[i, k] = 100 * float(q["d_sim_m"]) / float(q["d_ref_m"]) * float(q["d_ref_uncertainty_m"]) / \
                        float(q["d_ref_m"])
    k_lo, k_hi = int(np.argmin(forces)), int(np.argmax(forces))
    ax2.axhspan(-target, target, color="green", alpha=0.12, lw=0, label="within ±%g %%" % target)
    ax2.axhline(0, color="black", lw=0.8)
    jitter = 0.35
    for k, marker, colour in ((k_lo, "o", "tab:blue"), (k_hi, "s", "tab:red")):
        e = err[:, k]
        # sites at the same distance are spread a little sideways to be seen
        offset = np.zeros_like(r)
        for d in np.unique(np.round(r, 6)):
            idx = np.where(np.isclose(r, d, atol=1e-6))[0]
            offset[idx] = (np.arange(len(idx)) - (len(idx) - 1) / 2) * jitter
        ax2.errorbar(r + offset + (-0.6 if k == k_lo else 0.6), e, yerr=bars[:, k], fmt=marker, ms=5.5, color=colour,
                     alpha=0.85, elinewidth=0.9, capsize=1.5, zorder=3,
                     label="F = %g N (bar: the reference's uncertainty)" % forces[k])
        d_unique = np.unique(np.round(r, 6))
        mean = [np.nanmean(e[np.isclose(r, d, atol=1e-6)]) for d in d_unique]
        ax2.plot(d_unique, mean, color=colour, lw=1.2, alpha=0.7,
                 label="F = %g N, mean over the sites at that distance" % forces[k])
    ax2.set_xlabel("horizontal distance of the site from the %s (mm)" % ("pole" if dome else "centre of the top face"))
    ax2.set_ylabel("error in depth against the reference at the site (%)")
    ax2.set_title("Signed error at the smallest and the largest verification force", fontsize=11)
    ax2.grid(alpha=0.3)
    ax2.legend(fontsize=9, loc="upper left")
    fig.suptitle("%s: the MLS depth against the converged reference at each of %d sites" % (
        scene.get("name", os.path.basename(scene_file)), len(rows)), fontsize=12.5)
    fig.tight_layout(w_pad=4)
    fig.savefig(png, dpi=110)
    print("plot_surface_map.py: wrote %s" % png)


if __name__ == "__main__":
    main()
