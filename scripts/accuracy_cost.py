#!/usr/bin/python3
"""The accuracy-cost map of the default scenes (issue #6).

    /usr/bin/python3 scripts/accuracy_cost.py BENCH_JSONL VERIFY_JSON... --out DIR

BENCH_JSONL: scripts/bench_scenes.sh's output (one palpate-bench-step JSON per scene,
with "scene_file"); VERIFY_JSON: palpate-verify --json outputs (their "scene" names
match the bench rows' "scene"). Cost = wall ms per simulated ms with the scene's own
integrator and dt (the step time of that integrator / dt); error = the L2 and the
largest per-force error against the finite-cube reference, and the L2 against plain
Hertz. Writes DIR/accuracy_cost.csv and DIR/accuracy_cost.png (error against cost,
the Pareto front marked) and prints the table with the cheapest configuration that
reaches 5 % and 2 % at every force.
"""
import csv, json, os, sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt


def main(argv):
    out = argv[argv.index("--out") + 1] if "--out" in argv else "."
    args = [a for i, a in enumerate(argv) if a != "--out" and (i == 0 or argv[i - 1] != "--out")]
    bench = {}
    for line in open(args[0]):
        b = json.loads(line)
        scene = json.load(open(b["scene_file"]))
        b["integrator"] = scene.get("integrator", {}).get("type", "rk4")
        b["dt"] = scene.get("integrator", {}).get("dt", 0.001)
        bench[scene.get("name", os.path.splitext(os.path.basename(b["scene_file"]))[0])] = b
    rows = []
    for path in args[1:]:
        v = json.load(open(path))
        b = bench.get(v["scene"])
        if b is None:
            sys.exit(f"accuracy_cost: no benchmark row for scene {v['scene']} ({path})")
        step_ms = {"rk4": b["rk4_step_ms"], "symplectic_euler": b["symplectic_euler_step_ms"],
                   "implicit_euler": b["implicit_euler_step_ms"]}[b["integrator"]]
        if b["integrator"] == "implicit_euler" and abs(b.get("implicit_euler_dt", b["dt"]) - b["dt"]) > 1e-12:
            sys.exit(f"accuracy_cost: {v['scene']}: the benchmark's implicit dt differs from the scene's")
        errors = [abs(r["error_reference"]) for r in v["rows"] if r.get("error_reference") is not None]
        rows.append(dict(label=os.path.splitext(os.path.basename(path))[0], scene=v["scene"], model=v["model"],
                         particles=v["particles"], integrator=b["integrator"], dt_s=b["dt"], step_ms=step_ms,
                         ms_per_sim_ms=step_ms / (1000 * b["dt"]), l2_error_reference=v["l2_error_reference"],
                         max_error_reference=max(errors), l2_error_hertz=v["l2_error_hertz"]))
    rows.sort(key=lambda r: r["ms_per_sim_ms"])
    best = float("inf")
    for r in rows:  # Pareto front: nothing cheaper is as accurate
        r["pareto"] = r["max_error_reference"] < best
        best = min(best, r["max_error_reference"])
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "accuracy_cost.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        w.writeheader()
        w.writerows(rows)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for r in rows:
        ax.scatter(r["ms_per_sim_ms"], 100 * r["max_error_reference"], marker="o" if r["model"] == "mls" else "s",
                   color="C0" if r["pareto"] else "C7")
        ax.annotate(f"{r['label']} ({r['particles']})", (r["ms_per_sim_ms"], 100 * r["max_error_reference"]),
                    fontsize=7, xytext=(4, 3), textcoords="offset points")
    front = [r for r in rows if r["pareto"]]
    ax.plot([r["ms_per_sim_ms"] for r in front], [100 * r["max_error_reference"] for r in front], "C0--", lw=0.8)
    ax.axhline(5, color="C3", lw=0.6, ls=":")
    ax.axhline(2, color="C2", lw=0.6, ls=":")
    ax.axvline(1, color="k", lw=0.6, ls=":")
    ax.set_xscale("log")
    ax.set_xlabel("wall ms per simulated ms (1 = real time; the scene's integrator and dt, one core)")
    ax.set_ylabel("largest error vs finite-cube reference [%]")
    ax.set_title("accuracy against cost (circles MLS, squares hex FEM; blue: Pareto front)", fontsize=9)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "accuracy_cost.png"), dpi=130)
    print(f"{'configuration':28} {'particles':>9} {'integrator':>17} {'dt ms':>6} {'ms/sim ms':>10} {'L2 ref':>7} {'max ref':>8} {'L2 Hertz':>9} pareto")
    for r in rows:
        print(f"{r['label']:28} {r['particles']:>9} {r['integrator']:>17} {1000 * r['dt_s']:6.1f} {r['ms_per_sim_ms']:10.3f} "
              f"{100 * r['l2_error_reference']:6.2f}% {100 * r['max_error_reference']:7.2f}% {100 * r['l2_error_hertz']:8.2f}% {r['pareto']}")
    for target in (0.05, 0.02):
        ok = [r for r in rows if r["max_error_reference"] <= target]
        print(f"cheapest within {100 * target:.0f} % at every force: " +
              (f"{ok[0]['label']} ({ok[0]['ms_per_sim_ms']:.3f} ms per simulated ms)" if ok else "none"))


if __name__ == "__main__":
    main(sys.argv[1:])
