#!/usr/bin/python3
"""Tables and plots of the verification study (scripts/verification_study.sh).

usage: /usr/bin/python3 scripts/plot_verification.py [OUT]   (default docs/verification)

Reads OUT/raw/runs.tsv and the JSON it lists (palpate-verify --json,
palpate-stable-dt --json) and writes into OUT:
  rows.csv                    every force of every sweep
  resolution_rows.csv         the resolution study, one row per force
  resolution.csv, volumes.csv, k_alpha.csv, hourglass.csv, integrators.csv
                              one row per run (sweep summary + stable time step)
  integrators_rows.csv        d of each integrator per force, and its difference from RK4 at 1 ms
  *.png                       the plots embedded in docs/verification.md
  tables.md                   the same numbers as Markdown tables
Needs Debian's python3-numpy and python3-matplotlib (hence /usr/bin/python3).
"""
import csv
import json
import math
import shlex
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
OUT = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs" / "verification"
SCENE = json.loads((ROOT / "scenes" / "hertz_cube.json").read_text())

# ---------------------------------------------------------------------------
# Hertz references (the same formulas as core/hertz.cpp, physics.md §3)
# ---------------------------------------------------------------------------
E = SCENE["material"]["young_modulus"]
NU = SCENE["material"]["poisson_ratio"]
R = SCENE["indenter"]["radius"]
BOX_MIN, BOX_MAX = SCENE["body"]["box"]["min"], SCENE["body"]["box"]["max"]
L = BOX_MAX[2] - BOX_MIN[2]
EDGE = BOX_MAX[0] - BOX_MIN[0]
E_STAR = E / (1 - NU * NU)


def hertz_depth(F, r=R):
    return (3 * F / (4 * E_STAR * math.sqrt(r))) ** (2 / 3)


def layer_factor(chi):
    a0 = -(1.2876 - 1.4678 * NU + 1.3442 * NU**2) / (1 - NU)
    b0 = (0.6387 - 1.0277 * NU + 1.5164 * NU**2) / (1 - NU)
    pi = math.pi
    return (1 - 2 * a0 / pi * chi + 4 * a0**2 / pi**2 * chi**2
            - 8 / pi**3 * (a0**3 + 4 * pi**2 * b0 / 15) * chi**3
            + 16 * a0 / pi**4 * (a0**3 + 3 * pi**2 * b0 / 5) * chi**4)


def layer_depth(F, r=R):
    lo, hi = 0.0, hertz_depth(F, r)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        f = 4 / 3 * E_STAR * math.sqrt(r) * mid**1.5 * layer_factor(math.sqrt(r * mid) / L)
        lo, hi = (mid, hi) if f < F else (lo, mid)
    return 0.5 * (lo + hi)


# ---------------------------------------------------------------------------
# Reading the runs
# ---------------------------------------------------------------------------
def parse_args(text):
    """Scene parameters of a run from its command-line arguments."""
    words = shlex.split(text)
    p = {}
    for i, w in enumerate(words):
        if w == "--per-edge":
            p["body.distribution.per_edge"] = words[i + 1]
        elif w == "--set":
            k, v = words[i + 1].split("=", 1)
            p[k] = v
        elif w == "--forces":
            p["forces"] = words[i + 1]
        elif w == "--force":
            p["force"] = words[i + 1]
    return p


def load_runs():
    runs = {}  # (study, label) -> {"verify": json, "stable": json, "params": {}, ...}
    with open(OUT / "raw" / "runs.tsv") as f:
        for r in csv.DictReader(f, delimiter="\t"):
            entry = runs.setdefault((r["study"], r["label"]), {"study": r["study"], "label": r["label"], "params": {}})
            try:
                data = json.loads((OUT / r["file"]).read_text())
            except (OSError, json.JSONDecodeError):
                data = None  # the run failed before printing (it is reported as missing)
            entry[r["kind"]] = data
            entry[r["kind"] + "_exit"] = int(r["exit"])
            entry[r["kind"] + "_wall"] = float(r["wall_s"])
            entry["params"].update(parse_args(r["args"]))
    return list(runs.values())


def radius(run):
    return float(run["params"].get("indenter.radius", R))


def check_references(run):
    """The Python Hertz formulas must reproduce the C++ ones."""
    r = radius(run)
    for row in run["verify"]["rows"]:
        assert abs(hertz_depth(row["force"], r) / row["d_hertz"] - 1) < 1e-9, row
        if row["d_finite_layer"] is not None:
            assert abs(layer_depth(row["force"], r) / row["d_finite_layer"] - 1) < 1e-6, row


def per_edge(run):
    n = run["params"].get("body.distribution.per_edge")
    return int(n) if n else round((run["verify"] or run["stable"])["particles"] ** (1 / 3))


def sinking(n):
    """Strain-free sinking of the centred sphere between the top particles of an n^3 lattice:
    the sphere first touches the particles nearest its axis (at s/sqrt(2) for even n, on the
    axis for odd n), R - sqrt(R^2 - r^2) below the height at which it would touch the flat face."""
    s = EDGE / (n - 1)
    r = s / math.sqrt(2) if n % 2 == 0 else 0.0
    return R - math.sqrt(R * R - r * r)


def fmt(x, spec):
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


def ms(x):
    return None if x is None else 1e3 * x


def body_dt(s):
    """The body's own stable step (100 kg indenter), ms; '≥ 100' when the search hit its ceiling."""
    if s.get("dt_body") is None:
        return "–"
    return ("≥ " if s.get("dt_body_ceiling") else "") + fmt(1e3 * s["dt_body"], ".1f")


def pct(x, digits=1):
    return "–" if x is None or not math.isfinite(x) else f"{100 * x:+.{digits}f} %"


def pct_abs(x, digits=1):
    return "–" if x is None or not math.isfinite(x) else f"{100 * x:.{digits}f} %"


def summary(run):
    """One flat dict per run: the sweep summary and the stable step."""
    v, s = run.get("verify"), run.get("stable")
    out = {"study": run["study"], "label": run["label"], "per_edge": per_edge(run)}
    if v:
        rows = v["rows"]
        statuses = [r["status"] for r in rows]
        out.update(particles=v["particles"], fixed=v["fixed_particles"], regularized=v["regularized_particles"],
                   neighbors=v["neighbors"], support_factor=v["support_factor"], integrator=v["integrator"],
                   dt=v["dt"], total_volume=v["total_volume"], box_volume=v["box_volume"],
                   l2_hertz=v["l2_error_hertz"], l2_layer=v["l2_error_finite_layer"],
                   all_at_rest=v["all_at_rest"], diverged=statuses.count("diverged"),
                   not_at_rest=statuses.count("not at rest"), forces=len(rows),
                   steps=sum(r["steps"] for r in rows), sim_time=sum(r["sim_time"] for r in rows),
                   wall=sum(r["wall_seconds"] for r in rows))
    else:
        out.update(particles=s["particles"] if s else None, l2_hertz=None, l2_layer=None)
    out["volumes"] = run["params"].get("mls.volumes", SCENE["mls"]["volumes"])
    out["hourglass"] = float(run["params"].get("mls.hourglass", 0))
    if s:
        for key, field in [("neighbors", "neighbors"), ("support_factor", "support_factor"),
                           ("integrator", "integrator"), ("particles", "particles")]:
            out.setdefault(key, s[field])
        out.update(indenter_mass=s.get("indenter_mass"))
        out.update(dt_max=s["dt_max_stable_s"], dt_unstable=s["dt_min_unstable_s"], dt_estimate=s["dt_estimate_s"],
                   courant=s["courant"], unstable_because=s["unstable_because"], stable_force=s["force"],
                   min_spacing=s["min_spacing"], wave_speed=s["wave_speed"], stable_trials=s["trials"],
                   stable_wall=s["wall_seconds"])
    b = run.get("stable_body")
    if b:
        out.update(dt_body=b["dt_max_stable_s"], courant_body=b["courant"], body_because=b["unstable_because"],
                   dt_body_ceiling=b["dt_min_unstable_s"] is None)
    return out


def write_csv(name, records, fields):
    with open(OUT / name, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields, extrasaction="ignore")
        w.writeheader()
        for r in records:
            w.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in fields})


def md_table(header, rows, align=None):
    align = align or ["---:"] * len(header)
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(align) + "|"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def force_rows(run):
    for r in run["verify"]["rows"]:
        yield dict(r, study=run["study"], label=run["label"], per_edge=per_edge(run),
                   particles=run["verify"]["particles"])


# ---------------------------------------------------------------------------
def main():
    runs = load_runs()
    for run in runs:
        if run.get("verify"):
            check_references(run)
    by_study = {}
    for run in runs:
        by_study.setdefault(run["study"], []).append(run)
    md = ["<!-- generated by scripts/plot_verification.py from raw/runs.tsv; do not edit -->\n"]
    plt.rcParams.update({"figure.dpi": 110, "font.size": 9, "axes.grid": True, "grid.alpha": 0.3})
    F_fine = np.linspace(1.0, 340.0, 300)
    d_hertz_fine = np.array([hertz_depth(F) for F in F_fine])
    d_layer_fine = np.array([layer_depth(F) for F in F_fine])

    row_fields = ["study", "label", "per_edge", "particles", "force", "d_sim", "d_hertz", "d_finite_layer",
                  "error_hertz", "error_finite_layer", "contact_force", "steps", "sim_time", "wall_seconds", "status"]
    write_csv("rows.csv", [r for run in runs if run.get("verify") for r in force_rows(run)], row_fields)
    summary_fields = ["study", "label", "per_edge", "particles", "fixed", "regularized", "neighbors", "support_factor",
                      "volumes", "hourglass", "integrator", "dt", "total_volume", "box_volume", "l2_hertz", "l2_layer",
                      "forces", "all_at_rest", "diverged", "not_at_rest", "steps", "sim_time", "wall", "stable_force",
                      "dt_max", "dt_unstable", "unstable_because", "dt_estimate", "courant", "min_spacing",
                      "wave_speed", "stable_trials", "stable_wall", "dt_body", "courant_body", "body_because"]

    # ---- a. resolution ----------------------------------------------------
    res = sorted(by_study.get("resolution", []), key=per_edge)
    if res:
        sums = [summary(r) for r in res]
        write_csv("resolution.csv", sums, summary_fields)
        write_csv("resolution_rows.csv", [r for run in res for r in force_rows(run)], row_fields)
        md.append("## a. Resolution (k = 16, α = 1, lattice volumes, RK4 at 1 ms)\n")
        md.append(md_table(
            ["per edge", "particles", "spacing [m]", "L2 vs Hertz", "L2 vs finite layer", "steps (sweep)",
             "wall [s] (sweep)", "stable dt [ms]", "c = dt·c_p/Δx", "body-only dt [ms]", "c body",
             "sinking δ [mm]"],
            [[s["per_edge"], s["particles"], fmt(EDGE / (s["per_edge"] - 1), ".4f"), pct_abs(s["l2_hertz"]),
              pct_abs(s["l2_layer"]), s["steps"], fmt(s["wall"], ".1f"), fmt(ms(s.get("dt_max")), ".1f"),
              fmt(s["courant"], ".2f"), body_dt(s), fmt(s.get("courant_body"), ".2f"),
              fmt(1e3 * sinking(s["per_edge"]), ".2f")] for s in sums]))
        forces = [r["force"] for r in res[0]["verify"]["rows"]]
        header = ["F [N]", "d_Hertz [mm]", "d_layer [mm]", "a [m]"] + [f"{per_edge(r)}³" for r in res]
        rows = []
        for k, F in enumerate(forces):
            dh = hertz_depth(F)
            rows.append([fmt(F, ".2f"), fmt(1e3 * dh, ".2f"), fmt(1e3 * layer_depth(F), ".2f"),
                         fmt(math.sqrt(R * dh), ".3f")]
                        + [pct(run["verify"]["rows"][k]["error_hertz"]) for run in res])
        md.append("\nError against plain Hertz, (d_sim − d_Hertz)/d_Hertz, per force:\n\n" + md_table(header, rows))
        rows = []
        for k, F in enumerate(forces):
            rows.append([fmt(F, ".2f"), fmt(1e3 * hertz_depth(F), ".2f"), fmt(1e3 * layer_depth(F), ".2f"),
                         fmt(math.sqrt(R * hertz_depth(F)), ".3f")]
                        + [pct(run["verify"]["rows"][k]["error_finite_layer"]) for run in res])
        md.append("\nError against the finite-layer Hertz, (d_sim − d_layer)/d_layer, per force:\n\n"
                  + md_table(header, rows))
        rows = []
        for k, F in enumerate(forces):
            rows.append([fmt(F, ".2f"), fmt(1e3 * hertz_depth(F), ".2f"), fmt(1e3 * layer_depth(F), ".2f"),
                         fmt(math.sqrt(R * hertz_depth(F)), ".3f")]
                        + [pct((run["verify"]["rows"][k]["d_sim"] + sinking(per_edge(run))) / hertz_depth(F) - 1)
                           if run["verify"]["rows"][k]["d_sim"] is not None else "–" for run in res])
        md.append("\nThe same against plain Hertz with d measured from the flat top face instead "
                  "(d_sim + δ, δ the sinking between the top particles, column δ above):\n\n"
                  + md_table(header, rows))
        rows = []
        for k, F in enumerate(forces):
            rows.append([fmt(F, ".2f")] + [f'{run["verify"]["rows"][k]["steps"]} / '
                                            f'{run["verify"]["rows"][k]["wall_seconds"]:.2f} s'
                                            + ("" if run["verify"]["rows"][k]["status"] == "ok"
                                               else " " + run["verify"]["rows"][k]["status"])
                                            for run in res])
        md.append("\nSteps to rest / wall time per force (each force starts from the previous rest state):\n\n"
                  + md_table(["F [N]"] + [f"{per_edge(r)}³" for r in res], rows))

        cmap = plt.get_cmap("viridis")
        colors = [cmap(i / max(1, len(res) - 1)) for i in range(len(res))]
        fig, ax = plt.subplots(figsize=(6.4, 4.6))
        ax.plot(F_fine, 1e3 * d_hertz_fine, "k-", lw=1.5, label="Hertz (half-space)")
        ax.plot(F_fine, 1e3 * d_layer_fine, "k--", lw=1.5, label=f"Hertz, finite layer L = {L:g} m")
        for run, c in zip(res, colors):
            rr = run["verify"]["rows"]
            ax.plot([r["force"] for r in rr], [1e3 * r["d_sim"] if r["d_sim"] is not None else np.nan for r in rr],
                    "o-", color=c, ms=3.5, lw=1, label=f'{per_edge(run)}³ = {run["verify"]["particles"]}')
        ax.set_xlabel("force F [N]")
        ax.set_ylabel("indentation d [mm]")
        ax.set_title("Indentation against force, uniform lattices (k = 16, α = 1)")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(OUT / "resolution_curves.png")
        plt.close(fig)

        fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
        for ax, key, title in zip(axes, ["error_hertz", "error_finite_layer"],
                                  ["against plain Hertz", f"against finite-layer Hertz (L = {L:g} m)"]):
            for run, c in zip(res, colors):
                rr = run["verify"]["rows"]
                ax.plot([r["force"] for r in rr], [100 * r[key] if r[key] is not None else np.nan for r in rr],
                        "o-", color=c, ms=3.5, lw=1, label=f"{per_edge(run)}³")
            ax.axhline(0, color="k", lw=0.8)
            ax.set_xlabel("force F [N]")
            ax.set_title("relative error " + title)
        axes[0].set_ylabel("(d_sim − d_ref) / d_ref [%]")
        axes[1].legend(fontsize=8, ncol=2)
        fig.tight_layout()
        fig.savefig(OUT / "resolution_errors.png")
        plt.close(fig)

        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        n = [s["particles"] for s in sums]
        ax.semilogx(n, [100 * s["l2_hertz"] for s in sums], "o-", label="L2 error vs Hertz")
        ax.semilogx(n, [100 * s["l2_layer"] for s in sums], "s--", label="L2 error vs finite-layer Hertz")
        for s in sums:
            ax.annotate(f'{s["per_edge"]}³', (s["particles"], 100 * s["l2_hertz"]), textcoords="offset points",
                        xytext=(0, 6), ha="center", fontsize=7)
        ax.set_xlabel("particles")
        ax.set_ylabel("L2 error over the sweep [%]")
        ax.set_ylim(bottom=0)
        ax.set_title("L2 error ‖d − d_ref‖/‖d_ref‖ against particle count")
        ax.legend()
        fig.tight_layout()
        fig.savefig(OUT / "resolution_l2.png")
        plt.close(fig)

    # ---- b. volumes ---------------------------------------------------------
    vol = sorted(by_study.get("volumes", []), key=lambda r: (per_edge(r), r["label"]))
    if vol:
        sums = [summary(r) for r in vol]
        write_csv("volumes.csv", sums, summary_fields)
        md.append("\n## b. Kernel (A-2, A-3) against lattice volumes (k = 16, α = 1)\n")
        md.append(md_table(["per edge", "volumes", "Σ v_i [m³]", "Σ v_i / box", "L2 vs Hertz", "L2 vs finite layer",
                            "stable dt [ms]", "c"],
                           [[s["per_edge"], s["volumes"], fmt(s["total_volume"], ".4f"),
                             fmt(s["total_volume"] / s["box_volume"], ".4f"), pct_abs(s["l2_hertz"]),
                             pct_abs(s["l2_layer"]), fmt(ms(s.get("dt_max")), ".1f"), fmt(s["courant"], ".2f")]
                            for s in sums], ["---:", ":---"] + ["---:"] * 6))
        forces = [r["force"] for r in vol[0]["verify"]["rows"]]
        rows = [[fmt(F, ".2f")] + [pct(run["verify"]["rows"][k]["error_finite_layer"]) for run in vol]
                for k, F in enumerate(forces)]
        md.append("\nError against the finite-layer Hertz per force:\n\n"
                  + md_table(["F [N]"] + [f'{per_edge(r)}³ {summary(r)["volumes"]}' for r in vol], rows))
        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        for run in vol:
            rr = run["verify"]["rows"]
            s = summary(run)
            ax.plot([r["force"] for r in rr], [100 * r["error_finite_layer"] if r["d_sim"] is not None else np.nan
                                               for r in rr],
                    "o-" if s["volumes"] == "lattice" else "s--", ms=3.5, lw=1,
                    label=f'{s["per_edge"]}³ {s["volumes"]} (Σv = {s["total_volume"]:.3f} m³)')
        ax.axhline(0, color="k", lw=0.8)
        ax.set_xlabel("force F [N]")
        ax.set_ylabel("error vs finite-layer Hertz [%]")
        ax.set_title("Kernel against lattice volumes")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(OUT / "volumes.png")
        plt.close(fig)

    # ---- c. k and alpha -----------------------------------------------------
    ka = by_study.get("k_alpha", [])
    if ka:
        sums = sorted((summary(r) for r in ka), key=lambda s: (s["neighbors"], s["support_factor"]))
        write_csv("k_alpha.csv", sums, summary_fields)
        ks = sorted({s["neighbors"] for s in sums})
        alphas = sorted({s["support_factor"] for s in sums})
        edge = sums[0]["per_edge"]
        forces = [r["force"] for r in ka[0]["verify"]["rows"]]

        def status(s):
            if s["diverged"]:
                return f'diverged ({s["diverged"]}/{s["forces"]})'
            if s["not_at_rest"]:
                return f'not at rest ({s["not_at_rest"]}/{s["forces"]})'
            return "at rest"

        md.append(f"\n## c. Neighbours k and support factor α at {edge}³ (forces {', '.join(f'{F:g}' for F in forces)} N; "
                  "at most 20 s per force)\n")
        run_of = {(summary(r)["neighbors"], summary(r)["support_factor"]): r for r in ka}
        rows = []
        for s in sums:
            rr = run_of[(s["neighbors"], s["support_factor"])]["verify"]["rows"]
            rows.append([s["neighbors"], f'{s["support_factor"]:g}', s["regularized"], pct_abs(s["l2_hertz"]),
                         pct_abs(s["l2_layer"])] + [pct(r["error_finite_layer"]) for r in rr]
                        + [status(s), s["steps"], fmt(ms(s.get("dt_max")), ".1f") if s.get("dt_max") else "none",
                           body_dt(s), fmt(s.get("courant_body"), ".2f")])
        md.append(md_table(["k", "α", "regularised", "L2 vs Hertz", "L2 vs layer"]
                           + [f"err layer {F:g} N" for F in forces]
                           + ["sweep", "steps", "stable dt [ms]", "body-only dt [ms]", "c body"], rows,
                           ["---:"] * (5 + len(forces)) + [":---", "---:", "---:", "---:", "---:"]))

        fig, axes = plt.subplots(1, 2, figsize=(11, 4.4))
        grid_l2 = np.full((len(ks), len(alphas)), np.nan)
        grid_dt = np.full((len(ks), len(alphas)), np.nan)
        notes = {}
        for s in sums:
            i, j = ks.index(s["neighbors"]), alphas.index(s["support_factor"])
            if s["l2_layer"] is not None:
                grid_l2[i, j] = 100 * s["l2_layer"]
            if s.get("dt_body"):
                grid_dt[i, j] = 1e3 * s["dt_body"]
            notes[i, j] = ("D" if s["diverged"] else "") + ("N" if s["not_at_rest"] else "") + \
                          ("R" if s["regularized"] else "")
        for ax, grid, title, cm, unit in [
                (axes[0], grid_l2, "L2 error vs finite-layer Hertz [%]", "magma_r", "%"),
                (axes[1], grid_dt, "largest stable dt of the body (100 kg indenter), RK4 [ms]", "viridis", "ms")]:
            shown = np.clip(grid, None, 100) if unit == "%" else grid
            im = ax.imshow(shown, cmap=cm, aspect="auto", origin="lower")
            fig.colorbar(im, ax=ax)
            ax.set_xticks(range(len(alphas)), [f"{a:g}" for a in alphas])
            ax.set_yticks(range(len(ks)), [str(k) for k in ks])
            ax.set_xlabel("support factor α (h = α · mean neighbour distance)")
            ax.set_ylabel("neighbours k")
            ax.set_title(title)
            ax.grid(False)
            for (i, j), note in notes.items():
                val = grid[i, j]
                text = ("–" if not math.isfinite(val) else f"{val:.3g}") + (f"\n{note}" if note else "")
                ax.text(j, i, text, ha="center", va="center", fontsize=7,
                        color="w" if (unit == "%" and math.isfinite(val) and val > 50) else "k",
                        bbox=dict(boxstyle="round,pad=0.15", fc="w", alpha=0.6, lw=0))
        fig.suptitle(f"k and α at {edge}³ (D: a force diverged, N: not at rest in 20 s, "
                     "R: regularised moment matrices)", fontsize=9)
        fig.tight_layout()
        fig.savefig(OUT / "k_alpha.png")
        plt.close(fig)

    # ---- d. hourglass -------------------------------------------------------
    hg = sorted(by_study.get("hourglass", []), key=lambda r: summary(r)["hourglass"])
    if hg:
        sums = [summary(r) for r in hg]
        write_csv("hourglass.csv", sums, summary_fields)
        edge = sums[0]["per_edge"]
        md.append(f"\n## d. Hourglass control at {edge}³ (k = 16, α = 1, RK4 at 1 ms)\n")
        md.append(md_table(["hourglass", "L2 vs Hertz", "L2 vs finite layer", "all at rest", "steps (sweep)",
                            "wall [s] (sweep)", "ms per step", "stable dt [ms]", "c", "body-only dt [ms]", "c body"],
                           [[f'{s["hourglass"]:g}', pct_abs(s["l2_hertz"]), pct_abs(s["l2_layer"]),
                             "yes" if s["all_at_rest"] else "no", s["steps"], fmt(s["wall"], ".1f"),
                             fmt(1e3 * s["wall"] / s["steps"], ".3f"),
                             fmt(ms(s.get("dt_max")), ".1f"), fmt(s["courant"], ".2f"), body_dt(s),
                             fmt(s.get("courant_body"), ".2f")] for s in sums]))
        forces = [r["force"] for r in hg[0]["verify"]["rows"]]
        rows = [[fmt(F, ".2f")] + [pct(run["verify"]["rows"][k]["error_finite_layer"]) for run in hg]
                for k, F in enumerate(forces)]
        md.append("\nError against the finite-layer Hertz per force:\n\n"
                  + md_table(["F [N]"] + [f'hourglass {s["hourglass"]:g}' for s in sums], rows))
        fig, axes = plt.subplots(1, 2, figsize=(10, 4))
        for run, s in zip(hg, sums):
            rr = run["verify"]["rows"]
            axes[0].plot([r["force"] for r in rr], [100 * r["error_finite_layer"] if r["d_sim"] is not None
                                                    else np.nan for r in rr], "o-", ms=3.5, lw=1,
                         label=f'hourglass {s["hourglass"]:g}')
        axes[0].axhline(0, color="k", lw=0.8)
        axes[0].set_xlabel("force F [N]")
        axes[0].set_ylabel("error vs finite-layer Hertz [%]")
        axes[0].legend(fontsize=8)
        axes[0].set_title(f"Hourglass control at {edge}³: error per force")
        x = np.arange(len(sums))
        axes[1].bar(x - 0.2, [1e3 * (s["dt_max"] or np.nan) for s in sums], 0.4, label="stable dt [ms]")
        axes[1].bar(x + 0.2, [1e3 * (s.get("dt_body") or np.nan) for s in sums], 0.4,
                    label="body only (100 kg indenter) [ms]")
        ax2 = axes[1].twinx()
        ax2.plot(x, [100 * (s["l2_layer"] if s["l2_layer"] is not None else np.nan) for s in sums], "ro-",
                 label="L2 vs finite layer [%]")
        ax2.plot(x, [100 * (s["l2_hertz"] if s["l2_hertz"] is not None else np.nan) for s in sums], "r^--",
                 label="L2 vs Hertz [%]")
        ax2.set_ylim(bottom=0)
        ax2.set_ylabel("L2 error [%]")
        axes[1].set_xticks(x, [f'{s["hourglass"]:g}' for s in sums])
        axes[1].set_xlabel("mls.hourglass")
        axes[1].set_ylabel("largest stable dt, RK4 [ms]")
        axes[1].set_title("stable step and L2 error")
        h1, l1 = axes[1].get_legend_handles_labels()
        h2, l2 = ax2.get_legend_handles_labels()
        axes[1].legend(h1 + h2, l1 + l2, fontsize=8, loc="lower left")
        fig.tight_layout()
        fig.savefig(OUT / "hourglass.png")
        plt.close(fig)

    # ---- e. integrators -----------------------------------------------------
    it = by_study.get("integrators", [])
    if it:
        order = ["rk4_dt0.001", "rk4_dt0.01", "symplectic_euler_dt0.001", "symplectic_euler_dt0.01",
                 "implicit_euler_dt0.01"]
        it.sort(key=lambda r: order.index(r["label"]) if r["label"] in order else 99)
        sums = [summary(r) for r in it]
        write_csv("integrators.csv", sums, summary_fields)
        edge = sums[0]["per_edge"]
        ref = next((r for r in it if r["label"] == "rk4_dt0.001"), it[0])
        ref_d = [r["d_sim"] for r in ref["verify"]["rows"]]
        records = []
        for run in it:
            for k, r in enumerate(run["verify"]["rows"]):
                diff = (r["d_sim"] / ref_d[k] - 1) if r["d_sim"] is not None and ref_d[k] else None
                records.append(dict(r, label=run["label"], integrator=run["verify"]["integrator"],
                                    dt=run["verify"]["dt"], diff_from_rk4_1ms=diff))
        write_csv("integrators_rows.csv", records,
                  ["label", "integrator", "dt", "force", "d_sim", "d_hertz", "d_finite_layer", "error_hertz",
                   "error_finite_layer", "diff_from_rk4_1ms", "steps", "sim_time", "wall_seconds", "status"])
        md.append(f"\n## e. Integrators at {edge}³ (k = 16, α = 1)\n")
        rows = []
        for run, s in zip(it, sums):
            diffs = [abs(r["d_sim"] / ref_d[k] - 1) for k, r in enumerate(run["verify"]["rows"])
                     if r["d_sim"] is not None]
            rows.append([s["integrator"], fmt(1e3 * s["dt"], "g"), pct_abs(s["l2_hertz"]), pct_abs(s["l2_layer"]),
                         fmt(100 * max(diffs), ".3f") + " %" if diffs else "–", "yes" if s["all_at_rest"] else "no",
                         s["steps"], fmt(s["sim_time"], ".1f"), fmt(s["wall"], ".1f"),
                         fmt(1e3 * s["wall"] / s["steps"], ".3f"),
                         fmt(ms(s.get("dt_max")), ".1f") if s.get("dt_max") else "",
                         fmt(s.get("courant"), ".2f") if s.get("dt_max") else ""])
        md.append(md_table(["integrator", "dt [ms]", "L2 vs Hertz", "L2 vs layer", "max |d/d_rk4,1ms − 1|",
                            "all at rest", "steps (sweep)", "simulated [s]", "wall [s]", "ms per step",
                            "stable dt [ms]", "c"], rows, [":---"] + ["---:"] * 11))
        forces = [r["force"] for r in ref["verify"]["rows"]]
        rows = [[fmt(F, ".2f")] + [f'{1e3 * run["verify"]["rows"][k]["d_sim"]:.3f} / '
                                   f'{run["verify"]["rows"][k]["steps"]}' if run["verify"]["rows"][k]["d_sim"]
                                   is not None else run["verify"]["rows"][k]["status"] for run in it]
                for k, F in enumerate(forces)]
        md.append("\nd_sim [mm] / steps to rest per force:\n\n"
                  + md_table(["F [N]"] + [f'{s["integrator"]} {1e3 * s["dt"]:g} ms' for s in sums], rows))
        fig, axes = plt.subplots(1, 2, figsize=(10, 4))
        for run, s in zip(it, sums):
            rr = run["verify"]["rows"]
            lab = f'{s["integrator"]} {1e3 * s["dt"]:g} ms'
            axes[0].plot([r["force"] for r in rr], [1e3 * r["d_sim"] if r["d_sim"] is not None else np.nan
                                                    for r in rr], "o-", ms=3, lw=1, label=lab)
            axes[1].semilogy([r["force"] for r in rr],
                             [abs(r["d_sim"] / ref_d[k] - 1) * 100 if r["d_sim"] is not None and run is not ref
                              else np.nan for k, r in enumerate(rr)], "o-", ms=3, lw=1, label=lab)
        axes[0].plot(F_fine, 1e3 * d_hertz_fine, "k-", lw=1, label="Hertz")
        axes[0].plot(F_fine, 1e3 * d_layer_fine, "k--", lw=1, label="finite layer")
        axes[0].set_xlabel("force F [N]")
        axes[0].set_ylabel("indentation d [mm]")
        axes[0].set_title(f"Integrators at {edge}³")
        axes[0].legend(fontsize=7)
        axes[1].set_xlabel("force F [N]")
        axes[1].set_ylabel("|d / d(RK4, 1 ms) − 1| [%]")
        axes[1].set_title("difference from RK4 at 1 ms")
        axes[1].legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(OUT / "integrators.png")
        plt.close(fig)

    # ---- f. strain level -----------------------------------------------------
    strain = sorted(by_study.get("strain", []), key=per_edge)
    res_of = {per_edge(r): r for r in by_study.get("resolution", [])}
    if strain:
        md.append("\n## f. Strain level: the same contact radii with R = 0.5 m and R = 5 m\n")
        md.append("Error against the finite-layer Hertz per contact radius a = √(R·d_Hertz) "
                  "(R = 5 m: a tenth of the force, strains a/R ten times smaller):\n\n")
        pairs = [(n, res_of.get(n), run) for n, run in ((per_edge(r), r) for r in strain)]
        header = ["a [m]", "a/R (R = 0.5)", "a/R (R = 5)"]
        for n, big, small in pairs:
            header += [f"{n}³ R = 0.5", f"{n}³ R = 5"]
        rows = []
        for k, row in enumerate(strain[0]["verify"]["rows"]):
            a = math.sqrt(radius(strain[0]) * row["d_hertz"])
            cells = [fmt(a, ".3f"), fmt(a / R, ".3f"), fmt(a / radius(strain[0]), ".4f")]
            for n, big, small in pairs:
                b = big["verify"]["rows"][k] if big and k < len(big["verify"]["rows"]) else None
                cells += [pct(b["error_finite_layer"]) if b else "–", pct(small["verify"]["rows"][k]["error_finite_layer"])]
            rows.append(cells)
        md.append(md_table(header, rows))
        md.append("\n" + md_table(["per edge", "R [m]", "L2 vs Hertz", "L2 vs finite layer"],
                                  [[n, f"{radius(run):g}", pct_abs(run["verify"]["l2_error_hertz"]),
                                    pct_abs(run["verify"]["l2_error_finite_layer"])]
                                   for n, big, small in pairs for run in (big, small) if run]))
        write_csv("strain.csv", [summary(r) | {"radius": radius(r)} for r in strain],
                  ["label", "per_edge", "particles", "radius", "l2_hertz", "l2_layer", "all_at_rest", "steps", "wall"])
        write_csv("strain_rows.csv", [r | {"radius": radius(run)} for run in strain for r in force_rows(run)],
                  row_fields + ["radius"])
        fig, ax = plt.subplots(figsize=(6.4, 4.4))
        cmap = plt.get_cmap("viridis")
        for i, (n, big, small) in enumerate(pairs):
            c = cmap(i / max(1, len(pairs) - 1))
            for run, style, lab in ((big, "o-", "R = 0.5 m"), (small, "s--", "R = 5 m")):
                if not run:
                    continue
                rr = run["verify"]["rows"]
                ax.plot([math.sqrt(radius(run) * r["d_hertz"]) for r in rr],
                        [100 * r["error_finite_layer"] if r["d_sim"] is not None else np.nan for r in rr],
                        style, color=c, ms=3.5, lw=1, label=f"{n}³, {lab}")
        ax.axhline(0, color="k", lw=0.8)
        ax.set_xlabel("Hertz contact radius a = √(R d_Hertz) [m]")
        ax.set_ylabel("error vs finite-layer Hertz [%]")
        ax.set_title("Same contact radii, strains ×1 (R = 0.5 m) and ×0.1 (R = 5 m)")
        ax.legend(fontsize=7, ncol=2)
        fig.tight_layout()
        fig.savefig(OUT / "strain.png")
        plt.close(fig)

    # ---- what limits the stable step ---------------------------------------
    lim = by_study.get("dt_limits", [])
    if lim:
        sums = [summary(r) for r in lim]
        sums.sort(key=lambda s: (["rk4", "symplectic_euler", "implicit_euler"].index(s["integrator"]),
                                 -s["stable_force"], s["indenter_mass"]))
        write_csv("dt_limits.csv", sums, ["label", "per_edge", "particles", "integrator", "indenter_mass",
                                          "stable_force", "dt_max", "dt_unstable", "unstable_because",
                                          "dt_estimate", "courant", "stable_trials", "stable_wall"])
        md.append(f'\n## What limits the stable step ({sums[0]["per_edge"]}³, k = 16, α = 1)\n')
        md.append(md_table(["integrator", "F [N]", "indenter mass [kg]", "stable dt [ms]", "c", "first failure"],
                           [[s["integrator"], fmt(s["stable_force"], "g"), fmt(s["indenter_mass"], "g"),
                             fmt(ms(s.get("dt_max")), ".1f") + ("" if s.get("dt_unstable") else " (ceiling)"),
                             fmt(s.get("courant"), ".2f"), s["unstable_because"] or "none up to 100 ms"]
                            for s in sums], [":---", "---:", "---:", "---:", "---:", ":---"]))

    # ---- all stable steps ---------------------------------------------------
    st = [summary(r) for r in runs if r.get("stable")]
    for r in runs:
        if r.get("stable_body"):
            st.append(summary({**r, "stable": r["stable_body"], "label": r["label"] + " (100 kg indenter)"}))
    write_csv("stable_dt.csv", st, ["study", "label", "per_edge", "particles", "integrator", "neighbors",
                                    "support_factor", "volumes", "hourglass", "indenter_mass", "stable_force", "dt_max", "dt_unstable",
                                    "unstable_because", "dt_estimate", "courant", "min_spacing", "wave_speed",
                                    "stable_trials", "stable_wall"])
    missing = [f'{r["study"]}/{r["label"]}' for r in runs
               if any(f"{k}_exit" in r and r.get(k) is None for k in ("verify", "stable", "stable_body"))]
    if missing:
        md.append("\nRuns that printed no JSON (crashed or refused): " + ", ".join(missing) + "\n")
    (OUT / "tables.md").write_text("\n".join(md))
    print(f"plot_verification.py: wrote {OUT}/tables.md, CSV and PNG files", file=sys.stderr)


if __name__ == "__main__":
    main()
