#!/usr/bin/python3
"""Figures and the Markdown table of the multirate study (scripts/multirate_study.sh).

usage: /usr/bin/python3 scripts/plot_multirate.py DIR [RAW]
Reads every RAW/NAME.json and DIR/NAME.csv written by palpate-bench-multirate --json --csv
(RAW defaults to data/verification/X for DIR docs/verification/X, else DIR/raw) and writes DIR/NAME.png (the pressing force over the path: the truth stepped at the haptic
rate, the multirate render and the zero-order hold; below, their errors against the
truth) and DIR/multirate.md (the error table of every run).
"""
import glob
import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def raw_default(out):
    """The runs' JSON for the output folder OUT: under data/ for a folder under docs/
    (docs/verification/X -> data/verification/X, data/README.md), else OUT/raw."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    parts = os.path.relpath(os.path.abspath(out), root).split(os.sep)
    if parts[0] == "docs" and len(parts) > 1:
        return os.path.join(root, "data", *parts[1:])
    return os.path.join(out, "raw")


def plot(name, data, table, folder):
    d = np.genfromtxt(os.path.join(folder, name + ".csv"), delimiter=",", names=True, dtype=None, encoding=None)
    t = d["t"]
    truth = np.c_[d["truth_x"], d["truth_y"], d["truth_z"]]
    multi = np.c_[d["multirate_x"], d["multirate_y"], d["multirate_z"]]
    hold = np.c_[d["hold_x"], d["hold_y"], d["hold_z"]]
    fig, (ax_f, ax_e) = plt.subplots(2, 1, figsize=(10, 6.4), sharex=True, gridspec_kw={"height_ratios": [3, 2]})
    ax_f.plot(t, truth[:, 2], "k-", lw=2.2, label=f"truth: the scene stepped at {1 / data['haptic_dt']:.0f} Hz")
    ax_f.plot(t, multi[:, 2], "C0-", lw=1.0,
              label=f"multirate: {1 / data['model_dt']:.0f} Hz model, local model rendered at "
                    f"{1 / data['haptic_dt']:.0f} Hz")
    ax_f.plot(t, hold[:, 2], "C3:", lw=1.0, label="zero-order hold of the model's force")
    ax_f.set_ylabel("F_z rendered (N)")
    ax_f.legend(loc="upper right", fontsize=8)
    ax_f.set_title(f"{data['scene']} ({data['particles']} particles): palpation path, force on the device")
    ax_e.semilogy(t, np.maximum(np.linalg.norm(hold - truth, axis=1), 1e-6), "C3-", lw=0.6, alpha=0.7,
                  label="|hold - truth|")
    ax_e.semilogy(t, np.maximum(np.linalg.norm(multi - truth, axis=1), 1e-6), "C0-", lw=0.6,
                  label="|multirate - truth|")
    ax_e.set_ylim(1e-3, max(1.0, 2 * data["peak_force"]))
    ax_e.set_ylabel("error (N)")
    ax_e.set_xlabel("t (s)")
    ax_e.legend(loc="upper right", fontsize=8)
    motions = d["motion"]
    start = 0
    for k in range(1, len(t) + 1):
        if k == len(t) or motions[k] != motions[start]:
            for ax in (ax_f, ax_e):
                ax.axvline(t[start], color="0.85", lw=0.5)
            ax_f.text(t[start], ax_f.get_ylim()[1] * 0.97, motions[start], fontsize=7, va="top", color="0.4")
            start = k
    fig.tight_layout()
    fig.savefig(os.path.join(folder, name + ".png"), dpi=110)
    plt.close(fig)

    peak = data["peak_force"]
    table.append(f"\n**{name}**: {data['scene']}, {data['particles']} particles, model step "
                 f"{1e3 * data['model_dt']:g} ms, rendered every {1e3 * data['haptic_dt']:g} ms, peak force "
                 f"{peak:.4g} N; wall time of the runs: truth {data['truth_wall_seconds']:.1f} s, coarse "
                 f"{data['coarse_wall_seconds']:.1f} s.\n")
    table.append("| motion | renders | local model p50 / p99 / max (N) | p99 % of peak | hold p50 / p99 / max (N) "
                 "| p99 % of peak |")
    table.append("|---|---:|---|---:|---|---:|")
    for motion, e in data["error"].items():
        a, b = e["local_model"], e["hold"]
        table.append(f"| {motion} | {e['samples']} | {a['median']:.3g} / {a['p99']:.3g} / {a['max']:.3g} | "
                     f"{100 * a['p99'] / peak:.2f} | {b['median']:.3g} / {b['p99']:.3g} / {b['max']:.3g} | "
                     f"{100 * b['p99'] / peak:.2f} |")
    if "error_by_model_age" in data:
        table.append("\n| model age (ms) | local model p50 / p99 (N) | hold p50 / p99 (N) |")
        table.append("|---:|---|---|")
        for e in data["error_by_model_age"]:
            a, b = e["local_model"], e["hold"]
            table.append(f"| {1e3 * e['age_s']:g} | {a['median']:.3g} / {a['p99']:.3g} | "
                         f"{b['median']:.3g} / {b['p99']:.3g} |")


def main(folder, raw):
    table = ["# Multirate haptics: force error along the palpation path (palpate-bench-multirate)"]
    names = [os.path.splitext(os.path.basename(p))[0] for p in sorted(glob.glob(os.path.join(raw, "*.json")))]
    names = [n for n in names if os.path.exists(os.path.join(folder, n + ".csv"))]
    if not names:
        sys.exit(f"plot_multirate.py: no palpate-bench-multirate JSON in {raw} with its CSV in {folder}")
    for name in names:
        with open(os.path.join(raw, name + ".json")) as f:
            plot(name, json.load(f), table, folder)
    with open(os.path.join(folder, "multirate.md"), "w") as f:
        f.write("\n".join(table) + "\n")


if __name__ == "__main__":
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2] if len(sys.argv) > 2 else raw_default(sys.argv[1]))
