#!/usr/bin/python3
"""The lateral scan's tables and plot (scripts/lateral_scan_study.sh).

usage: plot_lateral_scan.py DIR DEPTH [RAW]

Reads RAW/<scene>_<x>.json (palpate-verify --json at the site (x, 0); RAW defaults to
data/verification/X for DIR docs/verification/X, else DIR/raw) and writes
DIR/lateral_scan.csv, DIR/lateral_scan.md and DIR/lateral_scan.png: the force at the
fixed depth DEPTH (m) across the sites, simulated and reference, with and without the lump.
The force at a depth is interpolated on log F against log d between the two rows of
the sweep that bracket it (a Hertz-like curve is a straight line there); a depth
outside a site's sweep gives no value.
"""
import glob
import json
import math
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


def force_at_depth(forces, depths, depth):
    pairs = sorted((d, f) for d, f in zip(depths, forces) if d is not None and d > 0 and math.isfinite(d))
    for (d0, f0), (d1, f1) in zip(pairs, pairs[1:]):
        if d0 <= depth <= d1 and d1 > d0:
            t = (math.log(depth) - math.log(d0)) / (math.log(d1) - math.log(d0))
            return math.exp(math.log(f0) + t * (math.log(f1) - math.log(f0)))
    return None


def main():
    out, depth = sys.argv[1], float(sys.argv[2])
    raw = sys.argv[3] if len(sys.argv) > 3 else raw_default(out)
    runs = {}
    for path in glob.glob(os.path.join(raw, "*.json")):
        scene, x = os.path.splitext(os.path.basename(path))[0].rsplit("_", 1)
        try:
            runs[(scene, float(x))] = json.load(open(path))
        except (ValueError, json.JSONDecodeError):
            print("plot_lateral_scan.py: %s is not a palpate-verify result; skipped" % path, file=sys.stderr)
    scenes = sorted({s for s, _ in runs}, key=lambda s: (not s.startswith("palpation_lump"), s))
    csv = ["scene,site_x_m,particles,force_N,d_sim_m,d_ref_m,d_ref_uncertainty_m,err_ref,status"]
    md = ["Errors in depth against the finite-block reference at each site (per cent, at the forces of the "
          "sweep), and the force at the fixed depth %g mm interpolated from each curve." % (1e3 * depth), "",
          "| scene | x [mm] | errors at F = sweep [%%] | worst | L2 | F(d = %g mm) sim [N] | reference [N] | "
          "error |" % (1e3 * depth),
          "|---|---:|---|---:|---:|---:|---:|---:|"]
    signal = {}
    for scene in scenes:
        for x in sorted(x for s, x in runs if s == scene):
            j = runs[(scene, x)]
            rows = j["rows"]
            for r in rows:
                csv.append(",".join(str(v) if v is not None else "" for v in (
                    scene, x, j["particles"], r["force"], r["d_sim"], r["d_reference"],
                    r["d_reference_uncertainty"], r["error_reference"], r["status"])))
            errors = [r["error_reference"] for r in rows]
            worst = max((abs(e) for e in errors if e is not None), default=None)
            forces = [r["force"] for r in rows]
            f_sim = force_at_depth(forces, [r["d_sim"] for r in rows], depth)
            f_ref = force_at_depth(forces, [r["d_reference"] for r in rows], depth)
            signal.setdefault(scene, []).append((x, f_sim, f_ref))

            def pc(v):
                return "-" if v is None else "%+.1f" % (100 * v)

            def num(v):
                return "-" if v is None else "%.4f" % v

            md.append("| %s | %g | %s | %s | %s | %s | %s | %s |" % (
                scene, 1e3 * x, " / ".join(pc(e) for e in errors),
                "-" if worst is None else "%.1f %%" % (100 * worst),
                "-" if j["l2_error_reference"] is None else "%.2f %%" % (100 * j["l2_error_reference"]),
                num(f_sim), num(f_ref),
                "-" if f_sim is None or f_ref is None else "%+.1f %%" % (100 * (f_sim / f_ref - 1))))
    # The signal: F with the lump / F without it at the fixed depth, simulated against the references',
    # once for each run without the lump (another scene's cloud, or the lump scene's own cloud).
    lump = next((s for s in scenes if s.startswith("palpation_lump")), None)
    for block in (s for s in scenes if s.startswith("palpation_block")) if lump else ():
        md += ["", "The signal F(with the lump) / F(without) at d = %g mm, per cent, without the lump from %s; "
               "difference in percentage points." % (1e3 * depth, block), "",
               "| x [mm] | simulated | reference | difference |", "|---:|---:|---:|---:|"]
        without = {x: (fs, fr) for x, fs, fr in signal[block]}
        for x, fs, fr in signal[lump]:
            if x not in without or None in (fs, fr) + without[x]:
                continue
            rs, rr = fs / without[x][0], fr / without[x][1]
            md.append("| %g | %.1f | %.1f | %+.1f |" % (1e3 * x, 100 * rs, 100 * rr, 100 * (rs - rr)))
    open(os.path.join(out, "lateral_scan.csv"), "w").write("\n".join(csv) + "\n")
    open(os.path.join(out, "lateral_scan.md"), "w").write("\n".join(md) + "\n")
    print("\n".join(md))

    fig, ax = plt.subplots(figsize=(7, 4.2))
    style = {"palpation_lump": ("C3", "with the lump"), "palpation_block": ("C0", "without (homogeneous)"),
             "palpation_block_lump_cloud": ("C2", "without, on the lump scene's cloud")}
    for scene, points in signal.items():
        colour, label = style.get(scene.replace("_follow", ""), ("C7", scene))
        xs = [1e3 * x for x, _, _ in points]
        ax.plot(xs, [f if f is not None else float("nan") for _, f, _ in points], "o-", color=colour,
                label="MLS, " + label)
        ax.plot(xs, [f if f is not None else float("nan") for _, _, f in points], "s--", color=colour,
                mfc="none", label="hex FEM reference, " + label)
    ax.axvspan(4, 16, color="C3", alpha=0.08, label="lump (x = 10 ± 6 mm)")
    ax.set_xlabel("tool position x [mm] (y = 0)")
    ax.set_ylabel("force at depth %g mm [N]" % (1e3 * depth))
    ax.set_title("The palpation signal: a lateral scan at fixed depth")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "lateral_scan.png"), dpi=120)


if __name__ == "__main__":
    main()
