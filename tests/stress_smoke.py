#!/usr/bin/python3
"""ctest stress_smoke (tests/CMakeLists.txt): `palpate-stress --smoke --json` (a few seconds,
6^3 and 7^3 clouds of the 2 m cube, docs/stability.md) and its figures held to bounds that
follow from the physics, each stated beside its check: the wave speed, spacing and estimate
from their definitions; the stable step against the integrators' stability intervals and the
element eigenvalue bound; the zero-energy ratios against what a zero-energy mode and a
quadratic energy must give; the dynamics against energy conservation. Also the JSON keys
that other tools rely on (the former stress_smoke.cmake).

usage: /usr/bin/python3 tests/stress_smoke.py PALPATE_STRESS SCENES_DIR
Exit status 1 with every failed check listed; each check printed with its figure.
"""
import json
import math
import subprocess
import sys

stress_bin, scenes = sys.argv[1], sys.argv[2]
run = subprocess.run([stress_bin, "--smoke", "--json", "--quiet"], capture_output=True, text=True, timeout=110)
if run.returncode != 0:
    sys.exit(f"palpate-stress --smoke --json exited with {run.returncode}: {run.stderr}")
out = json.loads(run.stdout)
failures = []


def check(ok, what):
    print(("ok    " if ok else "FAIL  ") + what)
    if not ok:
        failures.append(what)


def close(a, b, rel):
    return abs(a - b) <= rel * abs(b)


# --- The keys other tools rely on -----------------------------------------------------------
for key in ("envelope", "large_force", "inversion", "zero_energy", "zero_energy_ratios", "long_run", "definitions"):
    if key not in out:
        sys.exit(f"no '{key}' in the output")
envelope = out["envelope"]
# 2 models (MLS, hex FEM) x 3 integrators x 2 clouds (uniform, graded).
check(len(envelope) >= 12, f"envelope has {len(envelope)} rows (2 models x 3 integrators x 2 clouds)")
for i, row in enumerate(envelope):
    for key in ("model", "integrator", "particles", "dt_max_stable_s", "dt_estimate_s", "cloud", "damping", "c"):
        if key not in row:
            sys.exit(f"envelope row {i} has no '{key}'")
check(out["definitions"]["envelope_definition"].startswith("stable: "), "the envelope's definition of stable is given")

# --- The material and the clouds, from the scenes the smoke run loads (tools/stress/harness.cpp)
scene = json.load(open(f"{scenes}/hertz_cube.json"))
graded_scene = json.load(open(f"{scenes}/hertz_cube_graded.json"))
mat = scene["material"]
E, nu, rho = mat["young_modulus"], mat["poisson_ratio"], mat["density"]
for s in (graded_scene, json.load(open(f"{scenes}/hertz_cube_fem.json")), json.load(open(f"{scenes}/hertz_cube_graded_fem.json"))):
    assert (s["material"]["young_modulus"], s["material"]["poisson_ratio"], s["material"]["density"]) == (E, nu, rho)
lam = E * nu / ((1 + nu) * (1 - 2 * nu))
mu = E / (2 * (1 + nu))
c_p = math.sqrt((lam + 2 * mu) / rho)  # the P-wave speed, the fastest signal in the solid
box = scene["body"]["box"]
edge = box["max"][0] - box["min"][0]
dx_expected = {"uniform 6^3": edge / 5,  # 6 nodes per edge of the 2 m cube: 5 intervals
               "graded 7^3": graded_scene["body"]["distribution"]["first_spacing"]}  # the lattice's first spacing
search = out["definitions"]["envelope_search"]
tolerance = search["tolerance"]  # the bisection's bracket: dt_min_unstable <= (1 + tolerance) dt_max_stable

# --- Envelope ---------------------------------------------------------------------------------
rows = {(r["model"], r["cloud"], r["integrator"]): r for r in envelope if r.get("scene_damping", True)}
for (model, cloud, integrator), r in sorted(rows.items()):
    name = f"{model}, {cloud}, {integrator}"
    # Definitions (docs/stability.md): c_p = sqrt((lambda + 2 mu) / rho), the estimate 0.3 dx_min / c_p,
    # c = dt_max c_p / dx_min, and the lattice's smallest spacing.
    check(close(r["wave_speed_m_s"], c_p, 1e-12), f"{name}: c_p = {r['wave_speed_m_s']:.12g} m/s = sqrt((lambda+2mu)/rho) = {c_p:.12g}")
    check(close(r["dx_min_m"], dx_expected[cloud], 1e-12), f"{name}: dx_min = {r['dx_min_m']:.12g} m, the cloud's {dx_expected[cloud]}")
    check(close(r["dt_estimate_s"], 0.3 * r["dx_min_m"] / c_p, 1e-12), f"{name}: estimate {r['dt_estimate_s']:.6g} s = 0.3 dx_min / c_p")
    check(close(r["c"], r["dt_max_stable_s"] * c_p / r["dx_min_m"], 1e-12), f"{name}: c = {r['c']:.4g} = dt_max c_p / dx_min")
    # The bisection brackets the limit within its tolerance (below the cap: none reaches 0.1 s here).
    if not r["at_cap"]:
        ratio = r["dt_min_unstable_s"] / r["dt_max_stable_s"]
        check(1 < ratio <= 1 + tolerance + 1e-12, f"{name}: unstable/stable bracket {ratio:.4f} in (1, {1 + tolerance}]")
    # The paper's step (1 ms explicit, 10 ms implicit) lies below the stable limit found, so it must be stable.
    if r["paper_dt_s"] <= r["dt_max_stable_s"]:
        check(r["stable_at_paper_dt"], f"{name}: stable at the paper's {r['paper_dt_s']} s (below dt_max {r['dt_max_stable_s']:.4g} s)")
    # Symplectic Euler: the tool (mass m, force F) starts at rest just touching the surface, where the
    # contact force is zero, so its first step moves it F/m dt^2 down whatever the body does; beyond
    # dt = sqrt(R m / F) that is deeper than R, outside the envelope's [-R, R]: no stable step beyond it.
    if integrator == "symplectic_euler":
        tool = scene["indenter"]
        fall = math.sqrt(tool["radius"] * tool["mass"] / r["force_n"])
        check(r["dt_max_stable_s"] < fall, f"{name}: dt_max {r['dt_max_stable_s']:.4g} s < sqrt(R m / F) = {fall:.4g} s")

# On the graded cloud the elastic stability limit binds (the failures are "particle speed above
# 10 m/s", not the tool): the explicit integrators' stable step follows the model's highest
# frequency omega_max.
for model in ("mls", "hex_fem"):
    se, rk, ie = (rows[(model, "graded 7^3", i)] for i in ("symplectic_euler", "rk4", "implicit_euler"))
    # Symplectic Euler is stable for dt < 2 / omega_max, RK4 for dt < 2 sqrt(2) / omega_max (its stability
    # interval on the imaginary axis): the ratio of their limits is sqrt(2), to the bisection's tolerance.
    ratio = rk["dt_max_stable_s"] / se["dt_max_stable_s"]
    check(math.sqrt(2) / (1 + tolerance) <= ratio <= math.sqrt(2) * (1 + tolerance),
          f"{model}, graded: dt_max(RK4) / dt_max(symplectic Euler) = {ratio:.4f}, sqrt(2) = 1.4142 within the bisection's {tolerance}")
    # Lower bound: omega_max is at most the largest element frequency (the element eigenvalue theorem);
    # a brick of side dx_min with lumped mass has omega_e <= 2 sqrt(3) c_p / dx_min, so symplectic Euler is
    # stable at least to c = 1 / sqrt(3) = 0.577, RK4 to sqrt(2) / sqrt(3) = 0.816, less the bisection's
    # tolerance. (MLS: the same elasticity with a wider stencil, whose omega_max is lower still.)
    # Upper bound: c at most 3 (symplectic Euler), 3 sqrt(2) (RK4): a P wave crossing more than three of
    # the finest spacings in one step outruns an explicit step, which couples a particle only to its
    # neighbours (support radius about two spacings here) per force evaluation (the CFL condition;
    # docs/stability.md measures c = 0.6 ... 1.8 on the full clouds).
    for r, factor in ((se, 1.0), (rk, math.sqrt(2))):
        low, high = factor / math.sqrt(3) / (1 + tolerance), 3 * factor
        check(low <= r["c"] <= high, f"{model}, graded, {r['integrator']}: c = {r['c']:.3f} in [{low:.3f}, {high:.3f}]")
    # Implicit Euler is A-stable: the elastic limit that stops the explicit integrators does not stop it.
    check(ie["dt_max_stable_s"] > rk["dt_max_stable_s"],
          f"{model}, graded: implicit Euler's dt_max {ie['dt_max_stable_s']:.4g} s beyond the explicit ones' ({rk['dt_max_stable_s']:.4g} s)")

# --- Zero-energy ratios ---------------------------------------------------------------------------
ratios = out["zero_energy_ratios"]
for r in ratios:
    name = f"{r['model']}, {r['cloud']}, hourglass {r['hourglass']}"
    # A linear-range field (A = 1e-3 dx_min): the energy is quadratic in u, so -f.u = u.K.u = 2U and the
    # force ratio equals the energy ratio; geometric nonlinearity enters at relative order A/dx ~ 1e-3
    # squared, 1e-6.
    check(close(r["force_ratio"], r["energy_ratio"], 1e-6), f"{name}: force ratio {r['force_ratio']:.10g} = energy ratio {r['energy_ratio']:.10g}")
mls = sorted((r for r in ratios if r["model"] == "mls"), key=lambda r: r["hourglass"])
hex_fem = [r for r in ratios if r["model"] == "hex_fem"]
zero = mls[0]
assert zero["hourglass"] == 0
# MLS without hourglass control on the uniform lattice: the symmetric support's gradient does not see the
# checkerboard (-1)^(a+b+c), so the enveloped checkerboard costs exactly its envelope: ratio 1, the
# zero-energy mode, to round-off.
check(abs(zero["energy_ratio"] - 1) <= 1e-9, f"MLS, hourglass 0: energy ratio {zero['energy_ratio']:.15g} = 1 (a zero-energy mode)")
# The hourglass term is a quadratic form times its coefficient: both energies are affine in it, so every
# coefficient gives the same slope (U(hg) - U(0)) / hg, to round-off.
for key in ("energy_checkerboard_j", "energy_smooth_j"):
    slopes = [(r[key] - zero[key]) / r["hourglass"] for r in mls[1:]]
    check(max(slopes) - min(slopes) <= 1e-6 * max(abs(s) for s in slopes),
          f"MLS: {key} affine in the hourglass coefficient (slopes {', '.join(f'{s:.9g}' for s in slopes)} J)")
    if key == "energy_checkerboard_j":
        check(min(slopes) > 0, "MLS: the hourglass term makes the checkerboard cost more")
# So the ratio grows with the coefficient (the smooth field costs the hourglass term far less).
check(all(a["energy_ratio"] < b["energy_ratio"] for a, b in zip(mls, mls[1:])),
      "MLS: energy ratio increasing with the coefficient (" + ", ".join(f"{r['energy_ratio']:.4g}" for r in mls) + ")")
# The hex FEM (full 2x2x2 integration, no zero-energy mode) sees the checkerboard's strain: above 1 by
# more than round-off; and below the ratio of the checkerboard's strain (~2A/dx per axis) to the smooth
# field's (~pi A / L per axis) squared, 3 (2 L / (pi dx))^2 with L the 2 m edge.
for r in hex_fem:
    dx = dx_expected[r["cloud"]]
    high = 3 * (2 * edge / (math.pi * dx)) ** 2
    check(1.1 < r["energy_ratio"] < high, f"hex FEM, {r['cloud']}: energy ratio {r['energy_ratio']:.4f} in (1.1, {high:.1f})")

# --- Zero-energy dynamics (0.1 s in --smoke) ---------------------------------------------------------
for r in out["zero_energy"]:
    name = f"{r['cloud']}, hourglass {r['hourglass']}, damping {r['damping']}, {r['perturbation']}"
    check(r["finite"], f"{name}: finite")
    # Started at rest from the checkerboard, no force: the motion cannot gain energy, so the
    # checkerboard's amplitude cannot grow (ratio_end = a(T)/a(0) <= 1; the symplectic step at 1 ms,
    # omega dt << 1, conserves a modified energy within O((omega dt)^2)).
    # From velocity noise: a mode with any stiffness moves less than one without (ratio_end = a(T) /
    # a_free(T) <= 1; sin(w T) / (w T) <= 1 per mode).
    check(0 <= r["ratio_end"] <= 1.0 + 1e-3, f"{name}: ratio_end {r['ratio_end']:.4f} in [0, 1]")

# --- Long run and large force -------------------------------------------------------------------------
lr = out["long_run"]
check(lr["finite"] and lr["rest_reached"], "long run: finite, rest reached")
# Elastic and path-independent: the rest after the periodic load equals a fresh press to the same force,
# to the rest criterion's residual motion (speeds ~1e-4 m/s: 1e-3 of the indentation allows for it).
check(abs(lr["rest_indentation_difference_m"]) <= 1e-3 * lr["fresh_rest_indentation_m"],
      f"long run: rest indentation {lr['rest_indentation_m']:.6g} m, a fresh press {lr['fresh_rest_indentation_m']:.6g} m")
for r in out["large_force"]:
    check(r["finite"], f"large force {r['force_n']} N, {r['model']}, {r['cloud']}: finite")

print(f"palpate-stress --smoke: {len(envelope)} envelope rows; {len(failures)} of the checks failed")
sys.exit(1 if failures else 0)
