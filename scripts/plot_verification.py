#!/usr/bin/python3
"""Tables and plots of the verification study (scripts/verification_study.sh).

usage: /usr/bin/python3 scripts/plot_verification.py [OUT [RAW]]
  OUT  default docs/verification
  RAW  default data/verification when OUT is the default, else OUT/raw

Reads RAW/runs.tsv and the JSON it lists, relative to RAW (palpate-verify --json,
palpate-stable-dt --json, palpate-bench-step --json) and writes into OUT:
  rows.csv                    every force of every sweep
  resolution_rows.csv         the resolution study, one row per force
  resolution.csv, fem.csv, volumes.csv, k_alpha.csv, hourglass.csv, integrators.csv
                              one row per run (sweep summary + stable time step)
  curves_18.csv, convergence.csv, fixed_force.csv, pareto.csv, step_times.csv
                              the data of the figures (i) ... (iv) and of the step timings
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
from matplotlib.ticker import FormatStrFormatter  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
OUT = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs" / "verification"
# The runs' JSON (scripts/verification_study.sh --raw): kept out of docs/, in data/verification.
if len(sys.argv) > 2:
    RAW = Path(sys.argv[2])
elif OUT.resolve() == (ROOT / "docs" / "verification").resolve():
    RAW = ROOT / "data" / "verification"
else:
    RAW = OUT / "raw"
SCENE = json.loads((ROOT / "scenes" / "hertz_cube.json").read_text())
# The finite-block reference of the default scene (palpate-reference; docs/physics.md §3).
REFERENCE = json.loads((ROOT / "scenes" / "references" / "hertz_cube.json").read_text())
# The paper's per-step times (Aras et al., Core i5 2.67 GHz, docs/physics.md §4), ms.
PAPER_MESHLESS_MS, PAPER_SOFA_HEX_MS = 20.11, 195.0

# ---------------------------------------------------------------------------
# Hertz references (the same formulas as core/hertz.cpp, docs/physics.md §3)
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
    with open(RAW / "runs.tsv") as f:
        for r in csv.DictReader(f, delimiter="\t"):
            entry = runs.setdefault((r["study"], r["label"]), {"study": r["study"], "label": r["label"], "params": {}})
            try:
                data = json.loads((RAW / r["file"]).read_text())
            except (OSError, json.JSONDecodeError):
                data = None  # the run failed before printing (it is reported as missing)
            entry[r["kind"]] = data
            entry[r["kind"] + "_exit"] = int(r["exit"])
            entry[r["kind"] + "_wall"] = float(r["wall_s"])
            entry["params"].update(parse_args(r["args"]))
            entry["scene"] = r.get("scene") or "scenes/hertz_cube.json"
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
    src = run.get("verify") or run.get("stable") or run.get("bench")
    return int(n) if n else round(src["particles"] ** (1 / 3))


def sinking(n):
    """Strain-free sinking of the centred sphere between the top particles of an n^3 lattice:
    the sphere first touches the particles nearest its axis (at s/sqrt(2) for even n, on the
    axis for odd n), R - sqrt(R^2 - r^2) below the height at which it would touch the flat face."""
    s = EDGE / (n - 1)
    r = s / math.sqrt(2) if n % 2 == 0 else 0.0
    return R - math.sqrt(R * R - r * r)


def ref_depth(F):
    """The reference indentation at a reference force (palpate-verify interpolates between them)."""
    k = min(range(len(REFERENCE["forces"])), key=lambda i: abs(REFERENCE["forces"][i] - F))
    assert abs(REFERENCE["forces"][k] / F - 1) < 1e-6, F
    return REFERENCE["indentation"][k]


def ref_unc(F):
    k = min(range(len(REFERENCE["forces"])), key=lambda i: abs(REFERENCE["forces"][i] - F))
    return REFERENCE["uncertainty"][k]


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
                   l2_ref=v.get("l2_error_reference"), solve=v.get("solve", "dynamic"),
                   all_at_rest=v["all_at_rest"], diverged=statuses.count("diverged"),
                   not_at_rest=statuses.count("not at rest"), forces=len(rows),
                   steps=sum(r["steps"] for r in rows), sim_time=sum(r["sim_time"] for r in rows),
                   wall=sum(r["wall_seconds"] for r in rows))
    else:
        out.update(particles=s["particles"] if s else None, l2_hertz=None, l2_layer=None, l2_ref=None)
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
# g. hex FEM, figures (i) ... (iv) and the step times
# ---------------------------------------------------------------------------
def classify(run):
    """(model, integrator-or-solve, dt) of a sweep: model 'MLS', 'FEM linear' or 'FEM corotational'."""
    v = run["verify"]
    if "fem" in run.get("scene", "") or v["scene"].endswith("_fem"):
        model = "FEM " + run["params"].get("hex_fem.formulation", "linear")
    else:
        model = "MLS"
    if v.get("solve") == "static":
        return model, "static", None
    return model, v["integrator"], v["dt"]


def config_name(model, integ, dt):
    integ = {"rk4": "RK4", "implicit_euler": "implicit Euler", "symplectic_euler": "symplectic Euler"}.get(integ, integ)
    return f"{model}, {integ}" + (f" {1e3 * dt:g} ms" if dt else " solve")


def plain_log_ticks(ax, axis="y"):
    """Log axis with plain numbers (2, 5, 10 %) instead of 2×10⁰."""
    a = ax.yaxis if axis == "y" else ax.xaxis
    a.set_major_formatter(FormatStrFormatter("%g"))
    a.set_minor_formatter(FormatStrFormatter("%g"))
    a.set_tick_params(which="minor", labelsize=7)


def pareto_front(points):
    """Indices of the points not dominated in (x, y), both smaller-is-better; errors within
    0.1 % (relative) of each other count as equal (the same rest state reached by different
    integrators differs in the fifth digit)."""
    front = []
    for i, (x, y) in enumerate(points):
        if not any((x2 <= x and y2 <= y * 1.001) and (x2 < x or y2 < y / 1.001)
                   for j, (x2, y2) in enumerate(points) if j != i):
            front.append(i)
    return sorted(front, key=lambda i: points[i][0])


def fit_order(dofs, errs):
    """Slope of log(err) against log(DOF) over the finer half of the points, and the order in h
    (DOF ~ h^-3). None when fewer than two points."""
    pts = sorted((d, e) for d, e in zip(dofs, errs) if e and e > 0)
    fine = pts[len(pts) // 2:] if len(pts) >= 4 else pts
    if len(fine) < 2:
        return None, None
    slope = np.polyfit(np.log([d for d, _ in fine]), np.log([e for _, e in fine]), 1)[0]
    return slope, -3 * slope


def fem_and_figures(runs, by_study, md, row_fields, summary_fields):
    ref_F = np.array(REFERENCE["forces"])
    ref_d = np.array(REFERENCE["indentation"])
    ref_u = np.array(REFERENCE["uncertainty"])
    F_fine = np.linspace(ref_F[0], ref_F[-1], 300)
    ref_levels = ", ".join(f'{lv["per_edge"]}' for lv in REFERENCE["levels"])
    md.append(f"\nReference: scenes/references/hertz_cube.json, linear hex FEM on graded lattices of "
              f"{ref_levels} nodes per edge, uncertainty {100 * min(ref_u / ref_d):.2f} … "
              f"{100 * max(ref_u / ref_d):.2f} % of d_ref; Richardson extrapolation was used at "
              f"{sum(1 for p in REFERENCE['order'] if p)} of {len(ref_F)} forces (elsewhere d_ref is the finest level).\n")
    md.append("\nThe analytic curves against the reference:\n\n" + md_table(
        ["F [N]", "d_ref [mm]", "u_ref [mm]", "u_ref / d_ref", "d_Hertz [mm]", "d_Hertz / d_ref − 1",
         "d_layer [mm]", "d_layer / d_ref − 1"],
        [[fmt(F, ".2f"), fmt(1e3 * d, ".3f"), fmt(1e3 * u, ".3f"), pct_abs(u / d, 2), fmt(1e3 * hertz_depth(F), ".3f"),
          pct(hertz_depth(F) / d - 1), fmt(1e3 * layer_depth(F), ".3f"), pct(layer_depth(F) / d - 1)]
         for F, d, u in zip(ref_F, ref_d, ref_u)]))

    # ---- g. hex FEM by resolution ------------------------------------------
    fem = by_study.get("fem", [])
    fem_of = {}
    if fem:
        order = {"linear_static": 0, "linear_implicit_euler": 1, "corotational_implicit_euler": 2}
        fem.sort(key=lambda r: (min((v for k, v in order.items() if r["label"].startswith(k)), default=9), per_edge(r)))
        sums = []
        for run in fem:
            s = summary(run)
            model, integ, dt = classify(run)
            s.update(model=model, config=config_name(model, integ, dt), process_wall=run.get("verify_wall"))
            sums.append(s)
            fem_of[run["label"]] = run
        write_csv("fem.csv", sums, ["label", "model", "config", "per_edge", "particles", "l2_hertz", "l2_layer",
                                    "l2_ref", "all_at_rest", "steps", "sim_time", "wall", "process_wall"])
        md.append("\n## g. Hexahedral FEM by resolution (same block, material, fixed faces and sphere)\n")
        md.append("Static: the exact quasi-static solve of the linear FEM (linearised vertical contact, "
                  "one sparse Cholesky factorisation per resolution); implicit Euler: the dynamic settle at dt = 10 ms "
                  "(damping 10 s⁻¹) until rest, contact in the deformed configuration. Wall per force: "
                  "the sweep's wall time over its forces; for the static solve the whole process "
                  "(assembly and factorisation included) over its forces.\n\n")
        md.append(md_table(["model", "per edge", "nodes", "L2 vs Hertz", "L2 vs finite layer", "L2 vs reference",
                            "all at rest", "steps / iterations (sweep)", "wall per force [s]"],
                           [[s["config"], s["per_edge"], s["particles"], pct_abs(s["l2_hertz"]),
                             pct_abs(s["l2_layer"]), pct_abs(s["l2_ref"]), "yes" if s["all_at_rest"] else "no",
                             s["steps"], fmt((s["process_wall"] if s["solve"] == "static" else s["wall"]) / s["forces"], ".3f")]
                            for s in sums], [":---"] + ["---:"] * 8))
        forces = [r["force"] for r in fem[0]["verify"]["rows"]]
        short = {"linear_static": "lin. static", "linear_implicit_euler": "lin. IE", "corotational_implicit_euler": "corot. IE"}
        names = [next((v for k, v in short.items() if r["label"].startswith(k)), r["label"]) + f" {per_edge(r)}³"
                 for r in fem]
        md.append("\nError against the finite-block reference per force:\n\n"
                  + md_table(["F [N]", "u_ref"] + names,
                             [[fmt(F, ".2f"), pct_abs(ref_unc(F) / ref_depth(F))]
                              + [pct(r["verify"]["rows"][k]["error_reference"]) if k < len(r["verify"]["rows"]) else "–"
                                 for r in fem] for k, F in enumerate(forces)]))
        md.append("\nError against plain Hertz per force:\n\n"
                  + md_table(["F [N]"] + names,
                             [[fmt(F, ".2f")] + [pct(r["verify"]["rows"][k]["error_hertz"])
                                                 if k < len(r["verify"]["rows"]) else "–" for r in fem]
                              for k, F in enumerate(forces)]))

    # ---- the sweeps of the default configurations, by model x integrator x resolution
    sweeps = {}  # (model, integ, dt, n) -> run
    for study in ("resolution", "fem", "mls_integrators", "integrators"):
        for run in by_study.get(study, []):
            if not run.get("verify"):
                continue
            model, integ, dt = classify(run)
            sweeps.setdefault((model, integ, dt, per_edge(run)), run)
    mls18 = sweeps.get(("MLS", "rk4", 0.001, 18))
    fem18 = sweeps.get(("FEM linear", "static", None, 18))
    fem18_ie = sweeps.get(("FEM linear", "implicit_euler", 0.01, 18))
    cor18 = sweeps.get(("FEM corotational", "implicit_euler", 0.01, 18))

    # ---- (i) force-indentation at 18^3 --------------------------------------
    if mls18 or fem18:
        curves = [(r, lab, sty) for r, lab, sty in [
            (mls18, "MLS, RK4 1 ms", "o-"), (fem18, "hex FEM linear, static", "s-"),
            (fem18_ie, "hex FEM linear, implicit Euler 10 ms", "x:"),
            (cor18, "hex FEM corotational, implicit Euler 10 ms", "^--")] if r]
        records = []
        for k, F in enumerate(ref_F):
            rec = {"force": F, "d_hertz": hertz_depth(F), "d_finite_layer": layer_depth(F), "d_reference": ref_d[k],
                   "d_reference_uncertainty": ref_u[k]}
            for r, lab, _ in curves:
                row = next((x for x in r["verify"]["rows"] if abs(x["force"] / F - 1) < 1e-6), None)
                rec[lab] = row["d_sim"] if row else None
            records.append(rec)
        write_csv("curves_18.csv", records, list(records[0].keys()))
        fig, axes = plt.subplots(1, 2, figsize=(11, 4.6))
        ax = axes[0]
        ax.plot(F_fine, [1e3 * hertz_depth(F) for F in F_fine], "k-", lw=1.2, label="Hertz (half-space)")
        ax.plot(F_fine, [1e3 * layer_depth(F) for F in F_fine], "k--", lw=1.2, label=f"finite-layer Hertz (L = {L:g} m)")
        ax.fill_between(ref_F, 1e3 * (ref_d - ref_u), 1e3 * (ref_d + ref_u), color="tab:red", alpha=0.3, lw=0)
        ax.plot(ref_F, 1e3 * ref_d, "-", color="tab:red", lw=1.2, label="finite-block reference ± uncertainty")
        for r, lab, sty in curves:
            rr = r["verify"]["rows"]
            ax.plot([x["force"] for x in rr], [1e3 * x["d_sim"] if x["d_sim"] is not None else np.nan for x in rr],
                    sty, ms=4, lw=1, label=lab + f' ({r["verify"]["particles"]})')
        ax.set_xlabel("force F [N]")
        ax.set_ylabel("indentation d [mm]")
        ax.set_title("Force-indentation at 18³ (cf. paper Fig. 1/4)")
        ax.legend(fontsize=7)
        ax = axes[1]
        ax.fill_between(ref_F, -100 * ref_u / ref_d, 100 * ref_u / ref_d, color="tab:red", alpha=0.3, lw=0,
                        label="reference uncertainty")
        ax.plot(ref_F, [100 * (hertz_depth(F) / d - 1) for F, d in zip(ref_F, ref_d)], "k-", lw=1.2, label="Hertz")
        ax.plot(ref_F, [100 * (layer_depth(F) / d - 1) for F, d in zip(ref_F, ref_d)], "k--", lw=1.2,
                label="finite-layer Hertz")
        for r, lab, sty in curves:
            rr = r["verify"]["rows"]
            ax.plot([x["force"] for x in rr], [100 * x["error_reference"] if x["error_reference"] is not None
                                               else np.nan for x in rr], sty, ms=4, lw=1, label=lab)
        ax.axhline(0, color="tab:red", lw=0.8)
        ax.set_xlabel("force F [N]")
        ax.set_ylabel("(d − d_ref) / d_ref [%]")
        ax.set_title("Relative to the finite-block reference")
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(OUT / "curves_18.png")
        plt.close(fig)

    # ---- (ii) L2 error against degrees of freedom ---------------------------
    series = [("MLS", "rk4", 0.001, "MLS, RK4 1 ms", "tab:blue", "o"),
              ("FEM linear", "static", None, "hex FEM linear, static", "tab:orange", "s"),
              ("FEM corotational", "implicit_euler", 0.01, "hex FEM corotational, IE 10 ms", "tab:green", "^")]
    conv_records, conv_rows = [], []
    fig, ax = plt.subplots(figsize=(7.2, 5))
    for model, integ, dt, lab, c, mk in series:
        pts = sorted((n, r) for (m, i, d, n), r in sweeps.items() if (m, i, d) == (model, integ, dt))
        if not pts:
            continue
        dofs = [3 * r["verify"]["particles"] for _, r in pts]
        for key, ls, what in (("l2_error_reference", "-", "vs reference"), ("l2_error_hertz", "--", "vs Hertz")):
            errs = [r["verify"][key] for _, r in pts]
            slope, order = fit_order(dofs, errs)
            fit_txt = f", slope {slope:+.2f} (order {order:.2f} in h)" if slope is not None else ""
            ax.loglog(dofs, [100 * e if e else np.nan for e in errs], mk + ls, color=c, ms=5,
                      mfc=c if ls == "-" else "none", lw=1.2, label=f"{lab} {what}{fit_txt}")
            conv_rows.append([lab, what, len(pts), fmt(slope, "+.2f") if slope is not None else "–",
                              fmt(order, ".2f") if order is not None else "–"])
        for (n, r), dof in zip(pts, dofs):
            conv_records.append({"config": lab, "per_edge": n, "particles": r["verify"]["particles"], "dof": dof,
                                 "l2_reference": r["verify"]["l2_error_reference"],
                                 "l2_hertz": r["verify"]["l2_error_hertz"],
                                 "l2_finite_layer": r["verify"]["l2_error_finite_layer"]})
    u_l2 = float(np.sqrt(np.sum(ref_u ** 2) / np.sum(ref_d ** 2)))
    ax.axhline(100 * u_l2, color="tab:red", ls=":", lw=1.2,
               label=f"reference uncertainty ‖u_ref‖/‖d_ref‖ = {100 * u_l2:.2f} %")
    ax.set_xlabel("degrees of freedom (3 × particles)")
    ax.set_ylabel("L2 error over the sweep [%]")
    ax.set_title("Convergence (cf. paper Fig. 3): solid = vs reference, dashed = vs plain Hertz\n"
                 "fits over the finer half of each series", fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(True, which="both", alpha=0.3)
    plain_log_ticks(ax)
    fig.tight_layout()
    fig.savefig(OUT / "convergence.png")
    plt.close(fig)
    if conv_records:
        write_csv("convergence.csv", conv_records, list(conv_records[0].keys()))
        md.append("\n## Convergence: L2 error against degrees of freedom\n")
        md.append(md_table(["series", "error", "resolutions", "slope d log e / d log DOF (finer half)",
                            "observed order in h (= −3 × slope)"], conv_rows, [":---", ":---", "---:", "---:", "---:"]))

    # ---- (iii) indentation at a fixed force against particle count ---------
    fixed_forces = [82.88, 152.3]
    pts = {}  # (model, force) -> [(particles, per_edge, d)]
    for study in ("resolution", "fixed_force", "fem"):
        for run in by_study.get(study, []):
            if not run.get("verify"):
                continue
            model, integ, dt = classify(run)
            if not ((model == "MLS" and integ == "rk4" and dt == 0.001) or (model == "FEM linear" and integ == "static")):
                continue
            for row in run["verify"]["rows"]:
                for F in fixed_forces:
                    if abs(row["force"] / F - 1) < 1e-6 and row["d_sim"] is not None:
                        pts.setdefault((model, F), {})[per_edge(run)] = (run["verify"]["particles"], row["d_sim"])
    if pts:
        records = []
        fig, axes = plt.subplots(1, len(fixed_forces), figsize=(11, 4.6))
        for ax, F in zip(axes, fixed_forces):
            dr, ur = ref_depth(F), ref_unc(F)
            xs = [p for m in ("MLS", "FEM linear") for p, _ in pts.get((m, F), {}).values()]
            if not xs:
                continue
            lo, hi = min(xs) / 1.3, max(xs) * 1.3
            ax.fill_between([lo, hi], 1e3 * (dr - ur), 1e3 * (dr + ur), color="tab:red", alpha=0.3, lw=0,
                            label="finite-block reference ± uncertainty")
            ax.axhline(1e3 * dr, color="tab:red", lw=1)
            ax.axhline(1e3 * hertz_depth(F), color="k", lw=1, label="Hertz")
            ax.axhline(1e3 * layer_depth(F), color="k", ls="--", lw=1, label="finite-layer Hertz")
            for m, c, lab in (("MLS", "tab:blue", "MLS, RK4 1 ms"), ("FEM linear", "tab:orange", "hex FEM linear, static")):
                data = sorted(pts.get((m, F), {}).items())
                for parity, mk, ptxt in ((0, "o", "even n"), (1, "D", "odd n")):
                    sel = [(p, d) for n, (p, d) in data if n % 2 == parity]
                    if sel:
                        ax.semilogx([p for p, _ in sel], [1e3 * d for _, d in sel], mk + "-", color=c, ms=4, lw=0.8,
                                    mfc=c if parity == 0 else "none", label=f"{lab}, {ptxt}")
                for n, (p, d) in data:
                    records.append({"force": F, "model": m, "per_edge": n, "particles": p, "d_sim": d,
                                    "d_reference": dr, "d_reference_uncertainty": ur, "error_reference": d / dr - 1,
                                    "d_hertz": hertz_depth(F), "d_finite_layer": layer_depth(F)})
            ax.set_xscale("log")
            ax.set_xlim(lo, hi)
            ax.set_xlabel("particles / nodes (n³)")
            ax.set_ylabel("indentation d [mm]")
            ax.set_title(f"F = {F:g} N (cf. paper Fig. 5)")
            ax.legend(fontsize=7)
            ax.grid(True, which="both", alpha=0.3)
        fig.tight_layout()
        fig.savefig(OUT / "fixed_force.png")
        plt.close(fig)
        write_csv("fixed_force.csv", records, list(records[0].keys()))
        md.append("\n## Indentation at a fixed force against the particle count\n")
        ns = sorted({r["per_edge"] for r in records})
        cols = [(m, F) for F in fixed_forces for m in ("MLS", "FEM linear")]
        rows = []
        for n in ns:
            cells = [n, n ** 3]
            for m, F in cols:
                rec = next((r for r in records if r["per_edge"] == n and r["model"] == m and r["force"] == F), None)
                cells.append(f'{1e3 * rec["d_sim"]:.2f} ({pct(rec["error_reference"])})' if rec else "")
            rows.append(cells)
        md.append("d_sim [mm] (error against the reference); reference "
                  + ", ".join(f"{1e3 * ref_depth(F):.2f} ± {1e3 * ref_unc(F):.2f} mm at {F:g} N" for F in fixed_forces)
                  + ":\n\n" + md_table(["per edge", "particles"] + [f"{'MLS RK4' if m == 'MLS' else 'FEM static'} {F:g} N"
                                                                    for m, F in cols], rows))

    # ---- step times (palpate-bench-step) and (iv) run time against error ---
    bench = {r["label"]: r["bench"] for r in by_study.get("bench", []) if r.get("bench")}
    if bench:
        recs = []
        for label, b in sorted(bench.items(), key=lambda kv: (kv[0].rsplit("_n", 1)[0], int(kv[0].rsplit("_n", 1)[1]))):
            recs.append({"label": label, "model": b.get("model", "mls"), "particles": b["particles"],
                         "contacts": b["contacts"], "force_eval_ms": b["force_eval_ms"], "rk4_step_ms": b["rk4_step_ms"],
                         "symplectic_euler_step_ms": b["symplectic_euler_step_ms"], "dt_explicit": b["dt"],
                         "implicit_euler_step_ms": b["implicit_euler_step_ms"], "implicit_euler_dt": b["implicit_euler_dt"],
                         "implicit_euler_cg_iterations": b["implicit_euler_cg_iterations"],
                         "implicit_euler_contact_solves": b["implicit_euler_contact_solves"],
                         "repeats": b["repeats"], "implicit_euler_repeats": b["implicit_euler_repeats"]})
        write_csv("step_times.csv", recs, list(recs[0].keys()))
        md.append("\n## Time per step (palpate-bench-step, single thread, indenter pressed in with 150 N)\n")
        m18, f18, c18 = bench.get("mls_n18"), bench.get("fem_linear_n18"), bench.get("fem_corotational_n18")
        rows = []
        if m18:
            rows += [["MLS 18³ (the paper's meshless model)", "RK4", "1", fmt(m18["rk4_step_ms"], ".3f"),
                      fmt(PAPER_MESHLESS_MS, ".2f"), fmt(PAPER_MESHLESS_MS / m18["rk4_step_ms"], ".0f") + "×"],
                     ["MLS 18³", "symplectic Euler", "1", fmt(m18["symplectic_euler_step_ms"], ".3f"), "", ""],
                     ["MLS 18³", "implicit Euler", "10", fmt(m18["implicit_euler_step_ms"], ".2f"), "", ""]]
        if f18:
            rows += [["hex FEM linear 18³", "implicit Euler", "10", fmt(f18["implicit_euler_step_ms"], ".2f"),
                      fmt(PAPER_SOFA_HEX_MS, ".0f") + " (SOFA)", fmt(PAPER_SOFA_HEX_MS / f18["implicit_euler_step_ms"], ".1f") + "×"],
                     ["hex FEM linear 18³", "RK4", "1", fmt(f18["rk4_step_ms"], ".3f"), "", ""]]
        if c18:
            rows += [["hex FEM corotational 18³", "implicit Euler", "10", fmt(c18["implicit_euler_step_ms"], ".2f"),
                      fmt(PAPER_SOFA_HEX_MS, ".0f") + " (SOFA)", fmt(PAPER_SOFA_HEX_MS / c18["implicit_euler_step_ms"], ".1f") + "×"]]
        md.append(md_table(["model", "integrator", "dt [ms]", "ms per step (here)", "ms per step (paper)", "paper / here"],
                           rows, [":---", ":---", "---:", "---:", "---:", "---:"]))
        md.append("\nAll resolutions (ms per step; implicit Euler: CG iterations of the free motion and contact "
                  "solves, one per contact candidate):\n\n"
                  + md_table(["run", "particles", "contacts", "force eval", "RK4", "symplectic Euler", "implicit Euler",
                              "IE CG it.", "IE contact solves"],
                             [[r["label"], r["particles"], r["contacts"], fmt(r["force_eval_ms"], ".3f"),
                               fmt(r["rk4_step_ms"], ".3f"), fmt(r["symplectic_euler_step_ms"], ".3f"),
                               fmt(r["implicit_euler_step_ms"], ".2f"), r["implicit_euler_cg_iterations"],
                               r["implicit_euler_contact_solves"]] for r in recs], [":---"] + ["---:"] * 8))

    # (iv) Pareto: one point per model x integrator x resolution with a sweep.
    step_key = {"rk4": "rk4_step_ms", "symplectic_euler": "symplectic_euler_step_ms", "implicit_euler": "implicit_euler_step_ms"}
    bench_prefix = {"MLS": "mls", "FEM linear": "fem_linear", "FEM corotational": "fem_corotational"}
    par = []
    for (model, integ, dt, n), run in sweeps.items():
        if integ not in step_key and integ != "static":
            continue
        if (integ in ("rk4", "symplectic_euler") and dt != 0.001) or (integ == "implicit_euler" and dt != 0.01):
            continue
        v = run["verify"]
        if v["l2_error_reference"] is None:
            continue
        rows_ = v["rows"]
        if v.get("solve") == "static":
            rest = (run.get("verify_wall") or sum(r["wall_seconds"] for r in rows_)) / len(rows_)
        else:
            rest = sum(r["wall_seconds"] for r in rows_) / len(rows_)
        b = bench.get(f"{bench_prefix[model]}_n{n}")
        rt = None
        if b and integ in step_key:
            bdt = b["implicit_euler_dt"] if integ == "implicit_euler" else b["dt"]
            if abs(bdt - dt) < 1e-12:
                rt = b[step_key[integ]] / (1e3 * dt)
        par.append({"config": config_name(model, integ, dt), "model": model, "integrator": integ, "dt": dt,
                    "per_edge": n, "particles": v["particles"], "l2_reference": v["l2_error_reference"],
                    "l2_hertz": v["l2_error_hertz"], "ms_per_simulated_ms": rt, "rest_seconds_per_force": rest,
                    "step_ms": None if rt is None else rt * 1e3 * dt, "all_at_rest": v["all_at_rest"]})
    if par:
        par.sort(key=lambda p: (p["config"], p["per_edge"]))
        for key in ("ms_per_simulated_ms", "rest_seconds_per_force"):
            sel = [i for i, p in enumerate(par) if p[key] is not None]
            front = pareto_front([(par[i][key], par[i]["l2_reference"]) for i in sel])
            for i in sel:
                par[i]["front_" + key] = False
            for k in front:
                par[sel[k]]["front_" + key] = True
        write_csv("pareto.csv", par, ["config", "model", "integrator", "dt", "per_edge", "particles", "l2_reference",
                                      "l2_hertz", "step_ms", "ms_per_simulated_ms", "rest_seconds_per_force",
                                      "front_ms_per_simulated_ms", "front_rest_seconds_per_force", "all_at_rest"])
        configs = sorted({p["config"] for p in par})
        colors = {c: plt.get_cmap("tab10")(i) for i, c in enumerate(configs)}
        markers = dict(zip(configs, "osD^v<>ph*"))
        fig, axes = plt.subplots(1, 2, figsize=(12, 5))
        for ax, key, xlabel, title in (
                (axes[0], "ms_per_simulated_ms", "wall ms per simulated ms (step time / dt)", "cost of simulated time"),
                (axes[1], "rest_seconds_per_force", "wall time to rest per force [s]", "cost of one quasi-static answer")):
            for c in configs:
                sel = sorted((p for p in par if p["config"] == c and p[key] is not None), key=lambda p: p["particles"])
                if not sel:
                    continue
                ax.loglog([p[key] for p in sel], [100 * p["l2_reference"] for p in sel], markers[c] + "-",
                          color=colors[c], ms=5, lw=0.8, label=c)
                for p in sel:
                    ax.annotate(str(p["per_edge"]), (p[key], 100 * p["l2_reference"]), textcoords="offset points",
                                xytext=(3, 3), fontsize=6, color=colors[c])
            front = sorted((p for p in par if p.get("front_" + key)), key=lambda p: p[key])
            if front:
                ax.step([p[key] for p in front], [100 * p["l2_reference"] for p in front], "k-", where="post",
                        lw=2, alpha=0.35, label="Pareto front")
            for lvl in (5, 2):
                ax.axhline(lvl, color="grey", ls=":", lw=1)
                ax.annotate(f"{lvl} %", (ax.get_xlim()[0], lvl), xytext=(2, 2), textcoords="offset points",
                            fontsize=7, color="grey")
            if key == "ms_per_simulated_ms":
                ax.axvline(1, color="tab:red", ls="--", lw=1, label="real time (1 ms per ms)")
            ax.set_xlabel(xlabel)
            ax.set_ylabel("L2 error vs finite-block reference [%]")
            ax.set_title(f"Run time against error: {title}\n(numbers: particles per edge)", fontsize=9)
            ax.grid(True, which="both", alpha=0.3)
            plain_log_ticks(ax)
            ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(OUT / "pareto.png")
        plt.close(fig)

        md.append("\n## Run time against error (Pareto)\n")
        md.append("ms per simulated ms = step time (palpate-bench-step) / dt; time to rest = the sweep's wall time per "
                  "force (static solve: the whole process per force). The same machine ran other jobs: absolute times "
                  "are upper bounds.\n\n")
        md.append(md_table(["configuration", "per edge", "particles", "L2 vs reference", "L2 vs Hertz", "step [ms]",
                            "ms per simulated ms", "front", "time to rest per force [s]", "front"],
                           [[p["config"], p["per_edge"], p["particles"], pct_abs(p["l2_reference"]),
                             pct_abs(p["l2_hertz"]), fmt(p["step_ms"], ".3f"), fmt(p["ms_per_simulated_ms"], ".3f"),
                             "★" if p.get("front_ms_per_simulated_ms") else "", fmt(p["rest_seconds_per_force"], ".3f"),
                             "★" if p.get("front_rest_seconds_per_force") else ""] for p in par],
                           [":---"] + ["---:"] * 9))
        lines = []
        for lvl in (0.05, 0.02):
            for key, unit, what in (("ms_per_simulated_ms", "ms per simulated ms", "per simulated time"),
                                    ("rest_seconds_per_force", "s to rest per force", "per answer at rest")):
                ok = [p for p in par if p[key] is not None and p["l2_reference"] <= lvl]
                if ok:
                    best = min(ok, key=lambda p: p[key])
                    lines.append(f"- L2 ≤ {100 * lvl:g} % cheapest {what}: {best['config']} at {best['per_edge']}³ "
                                 f"({pct_abs(best['l2_reference'])}, {best[key]:.3g} {unit})")
                else:
                    lines.append(f"- L2 ≤ {100 * lvl:g} % {what}: no configuration of the study reaches it")
        rt_ok = [p for p in par if p["ms_per_simulated_ms"] is not None and p["dt"] == 0.001
                 and p["step_ms"] is not None and p["step_ms"] <= 1.0]
        if rt_ok:
            parts = []
            for c in sorted({p["config"] for p in rt_ok}):
                mine = sorted((p for p in rt_ok if p["config"] == c), key=lambda p: p["per_edge"])
                best = min(mine, key=lambda p: p["l2_reference"])
                parts.append(f"{c} at {', '.join(str(p['per_edge']) + '³' for p in mine)} (largest: "
                             f"{mine[-1]['step_ms']:.3f} ms per step at {mine[-1]['per_edge']}³; lowest L2 "
                             f"{pct_abs(best['l2_reference'])} at {best['per_edge']}³)")
            lines.append("- at 1 kHz (dt = 1 ms, step ≤ 1 ms on one core): " + "; ".join(parts))
        else:
            lines.append("- at 1 kHz (dt = 1 ms, step ≤ 1 ms on one core): none")
        md.append("\n" + "\n".join(lines) + "\n")


# ---------------------------------------------------------------------------
def main():
    runs = load_runs()
    for run in runs:
        if run.get("verify"):
            check_references(run)
    by_study = {}
    for run in runs:
        by_study.setdefault(run["study"], []).append(run)
    try:
        manifest = (RAW / "runs.tsv").resolve().relative_to(ROOT)
    except ValueError:
        manifest = RAW / "runs.tsv"
    md = [f"<!-- generated by scripts/plot_verification.py from {manifest}; do not edit -->\n"]
    plt.rcParams.update({"figure.dpi": 110, "font.size": 9, "axes.grid": True, "grid.alpha": 0.3})
    F_fine = np.linspace(1.0, 340.0, 300)
    d_hertz_fine = np.array([hertz_depth(F) for F in F_fine])
    d_layer_fine = np.array([layer_depth(F) for F in F_fine])

    row_fields = ["study", "label", "per_edge", "particles", "force", "d_sim", "d_hertz", "d_finite_layer",
                  "d_reference", "d_reference_uncertainty", "error_hertz", "error_finite_layer", "error_reference",
                  "contact_force", "steps", "sim_time", "wall_seconds", "status"]
    write_csv("rows.csv", [r for run in runs if run.get("verify") for r in force_rows(run)], row_fields)
    summary_fields = ["study", "label", "per_edge", "particles", "fixed", "regularized", "neighbors", "support_factor",
                      "volumes", "hourglass", "integrator", "dt", "solve", "total_volume", "box_volume", "l2_hertz",
                      "l2_layer", "l2_ref",
                      "forces", "all_at_rest", "diverged", "not_at_rest", "steps", "sim_time", "wall", "stable_force",
                      "dt_max", "dt_unstable", "unstable_because", "dt_estimate", "courant", "min_spacing",
                      "wave_speed", "stable_trials", "stable_wall", "dt_body", "courant_body", "body_because"]

    # ---- a. resolution ----------------------------------------------------
    res = sorted(by_study.get("resolution", []), key=per_edge)
    if res:
        sums = [summary(r) for r in res]
        write_csv("resolution.csv", sums, summary_fields)
        write_csv("resolution_rows.csv", [r for run in res for r in force_rows(run)], row_fields)
        s0 = sums[0]
        md.append(f'## a. Resolution: MLS (k = {s0["neighbors"]}, α = {s0["support_factor"]:g}, {s0["volumes"]} volumes, '
                  f'{ {"rk4": "RK4"}.get(s0["integrator"], s0["integrator"])} at {1e3 * s0["dt"]:g} ms)\n')
        md.append(md_table(
            ["per edge", "particles", "spacing [m]", "L2 vs Hertz", "L2 vs finite layer", "L2 vs reference",
             "steps (sweep)", "wall [s] (sweep)", "stable dt [ms]", "c = dt·c_p/Δx", "sinking δ [mm]"],
            [[s["per_edge"], s["particles"], fmt(EDGE / (s["per_edge"] - 1), ".4f"), pct_abs(s["l2_hertz"]),
              pct_abs(s["l2_layer"]), pct_abs(s["l2_ref"]), s["steps"], fmt(s["wall"], ".1f"),
              fmt(ms(s.get("dt_max")), ".1f"), fmt(s.get("courant"), ".2f"),
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
        md.append("\nError against the finite-block reference, (d_sim − d_ref)/d_ref, per force "
                  "(reference uncertainty in the column u_ref):\n\n"
                  + md_table(["F [N]", "d_ref [mm]", "u_ref"] + [f"{per_edge(r)}³" for r in res],
                             [[fmt(F, ".2f"), fmt(1e3 * ref_depth(F), ".2f"), pct_abs(ref_unc(F) / ref_depth(F))]
                              + [pct(run["verify"]["rows"][k]["error_reference"]) for run in res]
                              for k, F in enumerate(forces)]))
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
        ax.set_title(f'MLS indentation against force, uniform lattices (k = {sums[0]["neighbors"]}, '
                     f'α = {sums[0]["support_factor"]:g}, {sums[0]["volumes"]} volumes)')
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(OUT / "resolution_curves.png")
        plt.close(fig)

        fig, axes = plt.subplots(1, 3, figsize=(14, 4.2), sharey=True)
        for ax, key, title in zip(axes, ["error_hertz", "error_finite_layer", "error_reference"],
                                  ["against plain Hertz", f"against finite-layer Hertz (L = {L:g} m)",
                                   "against the finite-block reference"]):
            for run, c in zip(res, colors):
                rr = run["verify"]["rows"]
                ax.plot([r["force"] for r in rr], [100 * r[key] if r[key] is not None else np.nan for r in rr],
                        "o-", color=c, ms=3.5, lw=1, label=f"{per_edge(run)}³")
            ax.axhline(0, color="k", lw=0.8)
            ax.set_ylim(-20, 30)
            ax.set_xlabel("force F [N]")
            ax.set_title("relative error " + title + "\n(the coarsest lattices leave the scale at small F)", fontsize=9)
        axes[0].set_ylabel("(d_sim − d_ref) / d_ref [%]")
        axes[2].legend(fontsize=8, ncol=2)
        fig.tight_layout()
        fig.savefig(OUT / "resolution_errors.png")
        plt.close(fig)

        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        n = [s["particles"] for s in sums]
        ax.semilogx(n, [100 * s["l2_hertz"] for s in sums], "o-", label="L2 error vs Hertz")
        ax.semilogx(n, [100 * s["l2_layer"] for s in sums], "s--", label="L2 error vs finite-layer Hertz")
        ax.semilogx(n, [100 * s["l2_ref"] if s["l2_ref"] is not None else np.nan for s in sums], "^-",
                    label="L2 error vs finite-block reference")
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

    fem_and_figures(runs, by_study, md, row_fields, summary_fields)

    # ---- b. volumes ---------------------------------------------------------
    vol = sorted(by_study.get("volumes", []), key=lambda r: (per_edge(r), r["label"]))
    if vol:
        sums = [summary(r) for r in vol]
        write_csv("volumes.csv", sums, summary_fields)
        md.append("\n## b. Kernel (A-2, A-3) against lattice volumes (k = 16, α = 1)\n")
        md.append(md_table(["per edge", "volumes", "Σ v_i [m³]", "Σ v_i / box", "L2 vs Hertz", "L2 vs finite layer",
                            "L2 vs reference", "stable dt [ms]", "c"],
                           [[s["per_edge"], s["volumes"], fmt(s["total_volume"], ".4f"),
                             fmt(s["total_volume"] / s["box_volume"], ".4f"), pct_abs(s["l2_hertz"]),
                             pct_abs(s["l2_layer"]), pct_abs(s["l2_ref"]), fmt(ms(s.get("dt_max")), ".1f"),
                             fmt(s.get("courant"), ".2f")]
                            for s in sums], ["---:", ":---"] + ["---:"] * 7))
        forces = [r["force"] for r in vol[0]["verify"]["rows"]]
        rows = [[fmt(F, ".2f")] + [pct(run["verify"]["rows"][k]["error_finite_layer"]) for run in vol]
                for k, F in enumerate(forces)]
        md.append("\nError against the finite-layer Hertz per force:\n\n"
                  + md_table(["F [N]"] + [f'{per_edge(r)}³ {summary(r)["volumes"]}' for r in vol], rows))
        rows = [[fmt(F, ".2f")] + [pct(run["verify"]["rows"][k]["error_reference"]) for run in vol]
                for k, F in enumerate(forces)]
        md.append("\nError against the finite-block reference per force:\n\n"
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
                  f'at most {ka[0]["params"].get("verify.rest.max_time", "60")} s of simulated time per force)\n')
        run_of = {(summary(r)["neighbors"], summary(r)["support_factor"]): r for r in ka}
        rows = []
        for s in sums:
            rr = run_of[(s["neighbors"], s["support_factor"])]["verify"]["rows"]
            rows.append([s["neighbors"], f'{s["support_factor"]:g}', s["regularized"],
                         fmt(s["total_volume"] / s["box_volume"], ".2f"), pct_abs(s["l2_hertz"]),
                         pct_abs(s["l2_layer"]), pct_abs(s["l2_ref"])] + [pct(r["error_reference"]) for r in rr]
                        + [status(s), s["steps"], fmt(ms(s.get("dt_max")), ".1f") if s.get("dt_max") else "none",
                           fmt(s.get("courant"), ".2f") if s.get("dt_max") else ""])
        md.append("Σ v_i / box: the kernel volumes (A-2, A-3) summed, over the box volume (1 would be exact).\n\n")
        md.append(md_table(["k", "α", "regularised", "Σ v_i / box", "L2 vs Hertz", "L2 vs layer", "L2 vs reference"]
                           + [f"err ref {F:g} N" for F in forces]
                           + ["sweep", "steps", "stable dt [ms] (RK4)", "c"], rows,
                           ["---:"] * (7 + len(forces)) + [":---", "---:", "---:", "---:"]))

        fig, axes = plt.subplots(1, 2, figsize=(11, 4.4))
        grid_l2 = np.full((len(ks), len(alphas)), np.nan)
        grid_dt = np.full((len(ks), len(alphas)), np.nan)
        notes = {}
        for s in sums:
            i, j = ks.index(s["neighbors"]), alphas.index(s["support_factor"])
            if s["l2_ref"] is not None:
                grid_l2[i, j] = 100 * s["l2_ref"]
            if s.get("dt_max"):
                grid_dt[i, j] = 1e3 * s["dt_max"]
            notes[i, j] = ("D" if s["diverged"] else "") + ("N" if s["not_at_rest"] else "") + \
                          ("R" if s["regularized"] else "")
        for ax, grid, title, cm, unit in [
                (axes[0], grid_l2, "L2 error vs the finite-block reference [%]", "magma_r", "%"),
                (axes[1], grid_dt, f"largest stable dt, RK4, at {forces[-1]:g} N [ms]", "viridis", "ms")]:
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
        fig.suptitle(f"k and α at {edge}³ (D: a force diverged, "
                     f'N: not at rest in {ka[0]["params"].get("verify.rest.max_time", "60")} s, '
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
        hg_forces = ", ".join(format(r["force"], "g") for r in hg[0]["verify"]["rows"])
        md.append(f"Forces {hg_forces} N.\n\n")
        md.append(md_table(["hourglass", "L2 vs Hertz", "L2 vs finite layer", "L2 vs reference", "all at rest",
                            "steps (sweep)", "wall [s] (sweep)", "ms per step", "stable dt [ms]", "c"],
                           [[f'{s["hourglass"]:g}', pct_abs(s["l2_hertz"]), pct_abs(s["l2_layer"]),
                             pct_abs(s["l2_ref"]), "yes" if s["all_at_rest"] else "no", s["steps"],
                             fmt(s["wall"], ".1f"), fmt(1e3 * s["wall"] / s["steps"], ".3f"),
                             fmt(ms(s.get("dt_max")), ".1f"), fmt(s.get("courant"), ".2f")] for s in sums]))
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
        axes[1].bar(x, [1e3 * (s.get("dt_max") or np.nan) for s in sums], 0.5, label="stable dt [ms]")
        ax2 = axes[1].twinx()
        ax2.plot(x, [100 * (s["l2_layer"] if s["l2_layer"] is not None else np.nan) for s in sums], "ro-",
                 label="L2 vs finite layer [%]")
        ax2.plot(x, [100 * (s["l2_hertz"] if s["l2_hertz"] is not None else np.nan) for s in sums], "r^--",
                 label="L2 vs Hertz [%]")
        ax2.plot(x, [100 * (s["l2_ref"] if s["l2_ref"] is not None else np.nan) for s in sums], "ks-",
                 label="L2 vs reference [%]")
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
                         pct_abs(s["l2_ref"]), fmt(100 * max(diffs), ".3f") + " %" if diffs else "–", "yes" if s["all_at_rest"] else "no",
                         s["steps"], fmt(s["sim_time"], ".1f"), fmt(s["wall"], ".1f"),
                         fmt(1e3 * s["wall"] / s["steps"], ".3f"),
                         fmt(ms(s.get("dt_max")), ".1f") if s.get("dt_max") else "",
                         fmt(s.get("courant"), ".2f") if s.get("dt_max") else ""])
        md.append(md_table(["integrator", "dt [ms]", "L2 vs Hertz", "L2 vs layer", "L2 vs reference",
                            "max |d/d_rk4,1ms − 1|", "all at rest", "steps (sweep)", "simulated [s]", "wall [s]",
                            "ms per step", "stable dt [ms]", "c"], rows, [":---"] + ["---:"] * 12))
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
