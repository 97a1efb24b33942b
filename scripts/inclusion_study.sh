#!/usr/bin/env bash
# The inclusion under the indenter under refinement (issue #14, docs/verification.md
# "Inclusions under the indenter: refinement and finite deformation").
#
# The 2 m cube with a sphere of radius 0.25 m, 0.5 m below the contact point, 3x and 10x
# the matrix modulus, against the linear finite-block reference of the same body
# (scenes/references/hertz_cube_inclusion{,_10x}.json). It runs:
#   - the MLS scene (scenes/hertz_cube_inclusion.json, corotational) on a family of gmsh
#     meshes refined about the contact and the inclusion (focus and inclusion size
#     shrinking together), 3x and 10x;
#   - the hex FEM on the 33^3 and 41^3 members of the reference's own lattice family with
#     the same inclusion (bricks blended by volume fraction), corotational and linear,
#     pressed dynamically like the MLS: an independent discretisation of the
#     finite-deformation continuum the MLS simulates, and of the small-strain one.
#
#   - (--only family) the MLS on 18 meshes of the shipped mesh's resolution (far size 0.2 and
#     0.3 m, growth 1.12-1.13, focus 0.028-0.032 m, inclusion 0.04 m): how far the result
#     moves from mesh to mesh at one resolution.
#
#   scripts/inclusion_study.sh [--out DIR] [--only mls|fem|family]
#
# Writes DIR/<mesh>.msh, one palpate-verify JSON per run and DIR/summary.md (default DIR
# build/inclusion_study). Resumes: a run whose JSON exists is skipped (FRESH=1 starts
# over). About 10 min for the MLS, 25 for the FEM and 6 for the family on one core.
# BUILD_DIR (default build).
# shellcheck source=SCRIPTDIR/lib/study_common.sh
source "$(dirname "$0")/lib/study_common.sh"
out=$BUILD_DIR/inclusion_study
only=all
while [ $# -gt 0 ]; do
  case "$1" in
    --out) out=$2; shift 2 ;;
    --only) only=$2; shift 2 ;;
    -h|--help) study_help ;;
    *) study_unknown_option "$1" ;;
  esac
done
bin=$BUILD_DIR/bin
study_require "$bin/palpate-verify"
[ "${FRESH:-0}" = 1 ] && rm -rf "$out"
mkdir -p "$out"
inc10='material.inclusions=[{"sphere":{"center":[0,0,-0.5],"radius":0.25},"young_modulus":1e5,"poisson_ratio":0.3}]'
ref3=scenes/references/hertz_cube_inclusion.json
ref10=scenes/references/hertz_cube_inclusion_10x.json

run() {  # run NAME ARGS...: one palpate-verify run, skipped when its JSON exists
  local name=$1; shift
  [ -s "$out/$name.json" ] && return 0
  echo "== $name" >&2
  local t0=$SECONDS
  if "$bin/palpate-verify" --json --quiet "$@" > "$out/$name.json.tmp"; then
    mv "$out/$name.json.tmp" "$out/$name.json"
    echo "   $((SECONDS - t0)) s" >&2
  else
    echo "   $name failed" >&2; rm -f "$out/$name.json.tmp"
  fi
}

# The mesh family: NAME FOCUS_SIZE INCLUSION_SIZE GROWTH FAR_SIZE. "g115" is the first
# shipped mesh (5134 particles), "g1125" the shipped one; the rest halve the spacing
# about the inclusion in two steps at the growth of the finer shipped mesh.
meshes=(
  "g115   0.03   0.04    1.15  0.3"
  "g1125  0.03   0.04    1.125 0.3"
  "r1     0.024  0.032   1.125 0.3"
  "r2     0.02   0.0267  1.12  0.25"
  "r3     0.015  0.02    1.12  0.25"
)
if [ "$only" = family ]; then
  meshes=()
  for far in 0.2 0.3; do
    for growth in 1.12 1.125 1.13; do
      for h0 in 0.028 0.03 0.032; do meshes+=("f_${far}_${growth}_${h0} $h0 0.04 $growth $far"); done
    done
  done
fi
if [ "$only" != fem ]; then
  for m in "${meshes[@]}"; do
    read -r name h0 hinc growth far <<< "$m"
    msh=$out/$name.msh
    [ -s "$msh" ] || scripts/make_mesh.sh --focus-size "$h0" --far-size "$far" --growth "$growth" \
      --refine 0 0 -0.5 0.25 "$hinc" --node-order morton --out "$msh" > /dev/null
    # dt: 1 ms, the scene's; the finest cloud at 0.5 ms as a precaution (palpate-stable-dt
    # at 10x and 327.6 N finds r2 stable up to 4.3 ms and r3 up to 3.2 ms).
    dt=0.001
    case "$name" in r3) dt=0.0005 ;; esac
    mls=(--scene scenes/hertz_cube_inclusion.json --set "body.distribution.file=$(realpath "$msh")"
         --set integrator.dt=$dt)
    run "mls_${name}_3x" "${mls[@]}" --reference $ref3
    run "mls_${name}_10x" "${mls[@]}" --set "$inc10" --reference $ref10
  done
fi
if [ "$only" = all ] || [ "$only" = fem ]; then
  for f in corotational linear; do
    for n in 33 41; do
      first=$("$python" -c 'import json, sys
print(next(l["first_spacing"] for l in json.load(open(sys.argv[1]))["levels"] if l["per_edge"] == int(sys.argv[2])))' $ref3 $n)
      # Symplectic Euler at 1 ms: inside the envelope at 10x down to 41^3 (1.13 ms there).
      fem=(--scene scenes/hertz_cube_graded_fem.json --per-edge $n --set body.distribution.first_spacing=$first
           --set integrator.type=symplectic_euler --set integrator.dt=0.001 --set hex_fem.formulation=$f
           --set 'material.inclusions=[{"sphere":{"center":[0,0,-0.5],"radius":0.25},"young_modulus":3e4,"poisson_ratio":0.3}]')
      run "fem${n}_${f}_3x" "${fem[@]}" --reference $ref3
      run "fem${n}_${f}_10x" "${fem[@]}" --set "$inc10" --reference $ref10
    done
  done
fi

"$python" - "$out" <<'PY'
import glob, json, os, sys
out = sys.argv[1]
runs = {}
for path in sorted(glob.glob(os.path.join(out, "*.json"))):
    try: runs[os.path.basename(path)[:-5]] = json.load(open(path))
    except Exception: pass
if not runs: sys.exit("no run finished")
def errors(r): return [row["error_reference"] for row in r["rows"]]
lines = []
for case in ("3x", "10x"):
    names = [n for n in runs if n.endswith("_" + case) and not n.startswith("mls_f_")]
    if not names: continue
    forces = [row["force"] for row in runs[names[0]]["rows"]]
    lines.append(f"\n{case}: error against the linear finite-block reference (%)\n")
    lines.append("| run | particles | " + " | ".join(f"{F:g} N" for F in forces) + " | worst | L2 |")
    lines.append("|---|---:|" + "---:|" * (len(forces) + 2))
    for n in names:
        r = runs[n]; e = errors(r)
        worst = max((x for x in e if x is not None), key=abs)
        lines.append(f"| {n} | {r.get('particles', '')} | " + " | ".join("" if x is None else f"{100*x:+.2f}" for x in e)
                     + f" | {100*worst:+.2f} | {100*r['l2_error_reference']:.2f} |")
    # Each MLS run against the finest corotational FEM of the same case, force by force.
    fem = next((runs[n] for n in (f"fem41_corotational_{case}", f"fem33_corotational_{case}") if n in runs), None)
    if fem:
        fem_name = next(n for n in (f"fem41_corotational_{case}", f"fem33_corotational_{case}") if n in runs)
        lines.append(f"\n{case}: MLS depth against {fem_name} (%)\n")
        lines.append("| run | " + " | ".join(f"{F:g} N" for F in forces) + " | worst |")
        lines.append("|---|" + "---:|" * (len(forces) + 1))
        for n in names:
            if not n.startswith("mls_"): continue
            rel = [a["d_sim"] / b["d_sim"] - 1 for a, b in zip(runs[n]["rows"], fem["rows"])]
            lines.append(f"| {n} | " + " | ".join(f"{100*x:+.2f}" for x in rel) + f" | {100*max(rel, key=abs):+.2f} |")
family = sorted({n[len("mls_f_"):].rsplit("_", 1)[0] for n in runs if n.startswith("mls_f_")})
if family:
    lines.append("\nThe shipped resolution, mesh to mesh: worst error against the reference (%), L2 (%)\n")
    lines.append("| far size, growth, focus | particles | 3x worst | 3x L2 | 10x worst | 10x L2 | within 2 % |")
    lines.append("|---|---:|---:|---:|---:|---:|---|")
    passed = 0
    for f in family:
        cells, ok = [], True
        for case in ("3x", "10x"):
            r = runs.get(f"mls_f_{f}_{case}")
            if r is None: cells += ["", ""]; ok = False; continue
            e = [x for x in errors(r) if x is not None]
            worst = max(e, key=abs); ok = ok and abs(worst) <= 0.02
            cells += [f"{100*worst:+.2f}", f"{100*r['l2_error_reference']:.2f}"]
        passed += ok
        particles = next((runs[n].get("particles", "") for n in runs if n.startswith(f"mls_f_{f}_")), "")
        lines.append(f"| {f.replace('_', ', ')} | {particles} | " + " | ".join(cells) + f" | {'yes' if ok else 'no'} |")
    lines.append(f"\n{passed} of {len(family)} meshes within 2 % at every force, 3x and 10x.")
text = "\n".join(lines) + "\n"
open(os.path.join(out, "summary.md"), "w").write(text)
print(text)
PY
