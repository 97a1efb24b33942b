#!/usr/bin/python3
"""Figures of palpate-stress --out DIR (docs/stability.md).

usage: /usr/bin/python3 scripts/plot_stability.py DIR

Reads DIR/envelope.csv, large_force.csv, inversion.csv, zero_energy_series.csv and
long_run.csv (whichever exist) and writes envelope.png, large_force.png,
inversion.png, zero_energy.png and long_run.png next to them. Needs Debian's
python3-matplotlib and python3-numpy (run it with /usr/bin/python3).
"""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def rows(path):
    if not os.path.exists(path):
        return None
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def num(text):
    try:
        return float(text)
    except (TypeError, ValueError):
        return float("nan")


def save(fig, d, name):
    """Writes the figure to d/name and closes it."""
    fig.tight_layout()
    fig.savefig(os.path.join(d, name), dpi=130)
    plt.close(fig)


def envelope(d):
    r = rows(os.path.join(d, "envelope.csv"))
    if not r:
        return
    fig, ax = plt.subplots(figsize=(10, 4.8))
    labels, values, colors, hatches = [], [], [], []
    palette = {"rk4": "tab:blue", "symplectic_euler": "tab:orange", "implicit_euler": "tab:green"}
    for row in r:
        labels.append(f"{row['model']}\n{row['cloud']}\n{row['integrator'].replace('_', ' ')}\nc={num(row['damping']):g}/s")
        values.append(num(row["dt_max_stable_s"]) * 1e3)
        colors.append(palette.get(row["integrator"], "grey"))
        hatches.append("//" if row["at_cap"] == "1" else "")
    x = np.arange(len(values))
    bars = ax.bar(x, values, color=colors)
    for b, h in zip(bars, hatches):
        b.set_hatch(h)
    est = [num(row["dt_estimate_s"]) * 1e3 for row in r]
    ax.plot(x, est, "k_", markersize=14, label="estimate 0.3 dx_min / c_p")
    ax.axhline(1.0, color="red", lw=0.8, ls="--", label="1 ms (explicit, paper)")
    ax.axhline(10.0, color="purple", lw=0.8, ls=":", label="10 ms (implicit, paper)")
    ax.set_yscale("log")
    ax.set_ylabel("largest stable dt [ms] (hatched: the cap, stable throughout)")
    ax.set_xticks(x)
    ax.set_xticklabels(labels, fontsize=5.5)
    ax.legend(fontsize=7)
    ax.set_title("Stable envelope (bisection; blue RK4, orange symplectic Euler, green implicit Euler)")
    save(fig, d, "envelope.png")


def large_force(d):
    r = rows(os.path.join(d, "large_force.csv"))
    if not r:
        return
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for model in sorted({row["model"] for row in r}):
        sel = [row for row in r if row["model"] == model]
        F = [num(row["force_n"]) for row in sel]
        axes[0].plot(F, [num(row["d_over_r"]) for row in sel], "o-", label=model)
        axes[1].plot(F, [max(num(row["max_inverted"]), 0.5) for row in sel], "o-", label=model)
        for row in sel:
            if row["recovered"] != "1":
                axes[0].plot(num(row["force_n"]), num(row["d_over_r"]), "rx", markersize=12)
    axes[0].set_xscale("log")
    axes[0].set_xlabel("commanded force step [N]")
    axes[0].set_ylabel("max indentation d / R")
    axes[0].set_title("red x: not recovered after the reversal")
    axes[1].set_xscale("log")
    axes[1].set_yscale("log")
    axes[1].set_xlabel("commanded force step [N]")
    axes[1].set_ylabel("max inverted particles / elements (0 drawn at 0.5)")
    for ax in axes:
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    save(fig, d, "large_force.png")


def inversion(d):
    r = rows(os.path.join(d, "inversion.csv"))
    if not r:
        return
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    kv = np.array([max(num(row["kv_over_e"]), 1e-3) for row in r])
    inv = np.array([num(row["release_final_inverted"]) for row in r])
    pressed = np.array([num(row["pressed_max_inverted"]) for row in r])
    axes[0].plot(kv, np.maximum(inv, 0.5), "o-", label="inverted after the release")
    axes[0].plot(kv, np.maximum(pressed, 0.5), "s--", label="inverted while pressed")
    axes[0].set_xscale("log")
    axes[0].set_yscale("log")
    axes[0].set_xlabel("k_v / E (k_v = 0 drawn at 1e-3)")
    axes[0].set_ylabel("particles with det F <= 0 (0 drawn at 0.5)")
    axes[0].legend(fontsize=8)
    dtm = np.array([num(row["dt_max_stable_s"]) for row in r]) * 1e3
    dtp = np.array([num(row["dt_predicted_s"]) for row in r]) * 1e3
    axes[1].plot(kv, dtm, "o-", label="largest stable dt (bisection)")
    axes[1].plot(kv, dtp, "k:", label="dt_max(0) sqrt(M / (M + k_v))")
    axes[1].axhline(num(r[0]["scene_dt_s"]) * 1e3 if "scene_dt_s" in r[0] else 1.0, color="red", ls="--", lw=0.8,
                    label="the scene's dt")
    axes[1].set_xscale("log")
    axes[1].set_yscale("log")
    axes[1].set_xlabel("k_v / E (k_v = 0 drawn at 1e-3)")
    axes[1].set_ylabel("dt [ms]")
    axes[1].legend(fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    save(fig, d, "inversion.png")


def zero_energy(d):
    r = rows(os.path.join(d, "zero_energy_series.csv"))
    if not r:
        return
    runs = {}
    for row in r:
        key = (row["cloud"], row["perturbation"], num(row["hourglass"]), num(row["damping"]))
        runs.setdefault(key, ([], []))
        runs[key][0].append(num(row["t_s"]))
        runs[key][1].append(num(row["a_m"]))
    clouds = sorted({k[0] for k in runs})
    perts = ["checkerboard", "noise"]
    fig, axes = plt.subplots(len(clouds), 2, figsize=(10, 3.6 * len(clouds)), squeeze=False)
    for ci, cloud in enumerate(clouds):
        for pi, pert in enumerate(perts):
            ax = axes[ci][pi]
            for key, (t, a) in sorted(runs.items()):
                if key[0] != cloud or key[1] != pert:
                    continue
                style = "-" if key[2] > 0 else "--"
                ax.plot(t, np.maximum(a, 1e-16), style, label=f"hourglass {key[2]:g}, damping {key[3]:g}/s")
            ax.set_yscale("log")
            ax.set_xlabel("t [s]")
            ax.set_ylabel("checkerboard amplitude [m]")
            ax.set_title(f"{cloud}: {pert}", fontsize=9)
            ax.legend(fontsize=7)
            ax.grid(alpha=0.3)
    save(fig, d, "zero_energy.png")


def long_run(d):
    r = rows(os.path.join(d, "long_run.csv"))
    if not r:
        return
    t = np.array([num(row["t_s"]) for row in r])
    e = np.array([num(row["energy_j"]) for row in r])
    dd = np.array([num(row["indentation_m"]) for row in r])
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    axes[0].plot(t, e, ".", markersize=2)
    axes[0].set_xlabel("t [s]")
    axes[0].set_ylabel("total energy at phase 0 [J]")
    axes[1].plot(t, dd, ".", markersize=2)
    axes[1].set_xlabel("t [s]")
    axes[1].set_ylabel("indentation at phase 0 [m]")
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.suptitle("Long run: periodic command, stroboscopic samples (one per period)", fontsize=10)
    save(fig, d, "long_run.png")


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    d = sys.argv[1]
    for f in (envelope, large_force, inversion, zero_energy, long_run):
        f(d)
    print("figures written to", d)


if __name__ == "__main__":
    main()
