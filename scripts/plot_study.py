#!/usr/bin/python3
"""The accuracy-cost plot of a study (palpate-study merge calls it; docs/study.md).

    /usr/bin/python3 scripts/plot_study.py DIR

Reads DIR/study.csv and DIR/study_timing.csv (palpate-study merge) and writes
DIR/study.png: one point per case that ran (status ok), the L2 error of its sweep
against the finite-block reference (against Hertz when a case has no reference)
over its cost, the wall time per step of its sweep; one marker per scene, each
point labelled with its case index. Exit status 3 when matplotlib is missing, 4
when no case has results.
"""
import csv
import os
import sys

try:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
except ImportError:
    print("plot_study.py: python3-matplotlib is missing", file=sys.stderr)
    sys.exit(3)


def read(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def main(argv):
    if len(argv) != 1:
        sys.exit(__doc__)
    folder = argv[0]
    cases = {}  # case index -> scene, error, which error
    for row in read(os.path.join(folder, "study.csv")):
        if row["case_status"] != "ok":
            continue
        reference, hertz = row["l2_error_reference"], row["l2_error_hertz"]
        cases[row["case"]] = dict(scene=row["scene"], error=float(reference or hertz),
                                  against="reference" if reference else "Hertz")
    for row in read(os.path.join(folder, "study_timing.csv")):
        if row["case"] in cases and row["case_wall_per_step_s"]:
            cases[row["case"]]["cost"] = float(row["case_wall_per_step_s"])
    points = {k: c for k, c in cases.items() if "cost" in c}
    if not points:
        print("plot_study.py: no case of the study ran to the end", file=sys.stderr)
        sys.exit(4)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    markers = "osD^v<>ph*"
    for n, scene in enumerate(sorted({c["scene"] for c in points.values()})):
        for against, filled in (("reference", True), ("Hertz", False)):
            group = [(k, c) for k, c in points.items() if c["scene"] == scene and c["against"] == against]
            if not group:
                continue
            colour = "C%d" % (n % 10)
            ax.scatter([1e3 * c["cost"] for _, c in group], [100 * c["error"] for _, c in group],
                       marker=markers[n % len(markers)], facecolors=colour if filled else "none", edgecolors=colour,
                       label="%s (against %s)" % (os.path.basename(scene),
                                                  "the reference" if against == "reference" else "Hertz"))
            for k, c in group:
                ax.annotate(k, (1e3 * c["cost"], 100 * c["error"]), textcoords="offset points", xytext=(4, 3),
                            fontsize=8)
    ax.set_xlabel("wall time per step [ms]")
    ax.set_ylabel("L2 error of the sweep [%]")
    ax.set_title("%d cases (%s)" % (len(points), os.path.basename(os.path.abspath(folder))))
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(folder, "study.png"), dpi=120)


if __name__ == "__main__":
    main(sys.argv[1:])
