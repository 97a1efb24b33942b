#!/usr/bin/env bash
# Small strain against finite deformation, for one material and radius (issue #6,
# docs/verification.md "Other materials and radii"). The finite-cube reference is a
# linear (small-strain) FEM; at the top of the sweep the sphere presses 15-37 % of its
# radius in, where the geometrically nonlinear continuum departs from it. This runs,
# against the reference recomputed for the material and radius:
#   - the MLS scenes with the small-strain law (material.law linear): the discretisation
#     error, like against like;
#   - the same with the scenes' corotational law;
#   - the hex FEM on the 33^3 member of the reference's lattice family, linear and
#     corotational, pressed dynamically like the MLS: how far finite deformation moves
#     the answer in an independent discretisation.
#
#   scripts/finite_deformation_study.sh [--out DIR] [--set KEY=VALUE ...]
#   e.g. scripts/finite_deformation_study.sh --set material.poisson_ratio=0.45
#
# Writes DIR/reference.json, one palpate-verify JSON per run and DIR/summary.csv
# (default DIR build/finite_deformation). About 12 min on one core (the reference 2.5,
# the two 33^3 FEM runs 3 min each). BUILD_DIR (default build).
# shellcheck source=SCRIPTDIR/lib/study_common.sh
source "$(dirname "$0")/lib/study_common.sh"
out=$BUILD_DIR/finite_deformation
sets=()
while [ $# -gt 0 ]; do
  case "$1" in
    --out) out=$2; shift 2 ;;
    --set) sets+=(--set "$2"); shift 2 ;;
    -h|--help) study_help ;;
    *) study_unknown_option "$1" ;;
  esac
done
bin=$BUILD_DIR/bin
study_require "$bin/palpate-verify"
mkdir -p "$out"
echo "== reference" >&2
"$bin/palpate-reference" --scene scenes/hertz_cube_graded.json "${sets[@]}" --out "$out/reference.json"
verify=("$bin/palpate-verify" --reference "$out/reference.json" --json --quiet "${sets[@]}")
# The 33^3 member of the reference family (its first spacing read from the reference's
# levels), symplectic Euler at 1 ms (stable there for nu <= 0.45).
first33=$("$python" -c 'import json, sys
print(next(l["first_spacing"] for l in json.load(open(sys.argv[1]))["levels"] if l["per_edge"] == 33))' "$out/reference.json")
fem33=(--scene scenes/hertz_cube_graded_fem.json --per-edge 33 --set body.distribution.first_spacing=$first33
       --set integrator.type=symplectic_euler --set integrator.dt=0.001)
run() {
  local name=$1; shift
  echo "== $name" >&2
  "${verify[@]}" "$@" > "$out/$name.json" || echo "   $name failed" >&2
}
run mls_graded_linear --scene scenes/hertz_cube_graded.json --set material.law=linear
run mls_graded_corotational --scene scenes/hertz_cube_graded.json
run mls_tet_linear --scene scenes/hertz_cube_tet.json --set integrator.dt=0.003 --set material.law=linear
run mls_tet_corotational --scene scenes/hertz_cube_tet.json --set integrator.dt=0.003
run fem33_linear "${fem33[@]}"
run fem33_corotational "${fem33[@]}" --set hex_fem.formulation=corotational
"$python" - "$out" <<'PY'
import json, os, sys
out = sys.argv[1]
names = ["mls_graded_linear", "mls_graded_corotational", "mls_tet_linear", "mls_tet_corotational",
         "fem33_linear", "fem33_corotational"]
runs = {}
for n in names:
    try: runs[n] = json.load(open(os.path.join(out, n + ".json")))
    except Exception: pass
if not runs: sys.exit("no run finished")
forces = [r["force"] for r in next(iter(runs.values()))["rows"]]
def err(n, i):
    r = runs.get(n, {}).get("rows", [])
    return r[i]["error_reference"] if i < len(r) and r[i]["error_reference"] is not None else None
with open(os.path.join(out, "summary.csv"), "w") as f:
    f.write("force," + ",".join(names) + ",mls_graded_corotational_vs_fem33_corotational,mls_tet_corotational_vs_fem33_corotational\n")
    for i, F in enumerate(forces):
        e = [err(n, i) for n in names]
        rel = []
        for mls in ("mls_graded_corotational", "mls_tet_corotational"):
            a, b = err(mls, i), err("fem33_corotational", i)
            rel.append(None if a is None or b is None else (1 + a) / (1 + b) - 1)
        f.write(f"{F}," + ",".join("" if x is None else f"{x:.5f}" for x in e + rel) + "\n")
print(f"errors against the small-strain reference (%), {out}/summary.csv")
print(f"{'F [N]':>8} " + " ".join(f"{n[:24]:>24}" for n in names))
for line in open(os.path.join(out, "summary.csv")).read().splitlines()[1:]:
    v = line.split(",")
    print(f"{float(v[0]):8.2f} " + " ".join(f"{(100 * float(x)):+24.2f}" if x else f"{'':>24}" for x in v[1:7]))
PY
