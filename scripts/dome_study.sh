#!/usr/bin/env bash
# The dome against a converged reference of its own shape (issue #14, docs/verification.md
# "A curved body: the dome against its converged reference").
#
#   1. The reference (analysis/tet_reference.h): the dome's body as linear tetrahedra on gmsh
#      meshes refined self-similarly toward the pole (every size, and the growth's excess over
#      1, scaled by s: focus 1 mm x s, skin 3 mm x s, far 8 mm x s, growth 1 + 0.25 s; the lump's
#      ball 1.17 mm x s), each pressed with the exact static solve, Richardson in the focus size:
#        without the lump  s = 0.5, 0.397, 0.315, 0.25, 0.2   (17k ... 271k nodes)
#        with the lump     s = 0.5, 0.397, 0.315, 0.25        (37k ... 260k nodes)
#      written to scenes/references/palpation_dome_homogeneous.json and palpation_dome.json
#      (--only reference; about 13 and 12 min on one core and 15 GB of memory at the finest).
#   2. The MLS scene against them (--only mls): the shipped mesh, the grading of its first
#      version (growth 1.25) and its self-similar refinements s = 0.8, 0.63 (dt scaled with s,
#      and by 0.8 more with the lump), without and with the lump (about 2 min).
#
#   scripts/dome_study.sh [--out DIR] [--only reference|mls]
#
# Writes DIR/*.msh, one palpate-verify JSON per run and DIR/summary.md (default DIR
# build/dome_study). Resumes: a run whose output exists is skipped (FRESH=1 starts over).
# BUILD_DIR (default build).
# shellcheck source=SCRIPTDIR/lib/study_common.sh
source "$(dirname "$0")/lib/study_common.sh"
out=$BUILD_DIR/dome_study
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
study_require "$bin/palpate-verify" "$bin/palpate-reference"
[ "${FRESH:-0}" = 1 ] && rm -rf "$out"
mkdir -p "$out"
scene=scenes/palpation_dome.json
homogeneous=(--set 'material.inclusions=[]')
lump_ball=(0 0 0.032 0.007)  # the scene's lump: centre (m) and radius (m)

# mesh NAME S [extra make_mesh options]: the self-similar member s of the family.
mesh() {
  local name=$1 s=$2
  shift 2
  [ -f "$out/$name.msh" ] && return
  local h g
  h=$(awk -v s="$s" 'BEGIN { print 0.001 * s }')
  g=$(awk -v s="$s" 'BEGIN { print 1 + 0.25 * s }')
  scripts/make_mesh.sh --dome 0.05 --focus-size "$h" --growth "$g" --top-size "$(awk -v h="$h" 'BEGIN { print 3 * h }')" \
    --far-size "$(awk -v h="$h" 'BEGIN { print 8 * h }')" "$@" --out "$out/$name.msh" >&2
}
lump_refine() { echo --refine "${lump_ball[@]}" "$(awk -v s="$1" 'BEGIN { print 0.00117 * s }')"; }

if [ "$only" = all ] || [ "$only" = reference ]; then
  # reference NAME FILE S...: the family's meshes, then palpate-reference on them.
  reference() {
    local target=$1 with_lump=$2
    shift 2
    [ -f "$target" ] && [ "${FRESH:-0}" != 1 ] && { echo "dome_study.sh: $target exists (FRESH=1 recomputes)" >&2; return; }
    local levels=() s name
    for s in "$@"; do
      name=ref_$with_lump$s
      if [ "$with_lump" = lump ]; then mesh "$name" "$s" $(lump_refine "$s"); else mesh "$name" "$s"; fi
      levels+=("$out/$name.msh:$(awk -v s="$s" 'BEGIN { print 0.001 * s }')")
    done
    local set=()
    [ "$with_lump" = lump ] || set=("${homogeneous[@]}")
    "$bin/palpate-reference" --scene $scene "${set[@]}" --tet-meshes "$(IFS=,; echo "${levels[*]}")" --out "$target"
  }
  reference scenes/references/palpation_dome_homogeneous.json none 0.5 0.397 0.315 0.25 0.2
  reference scenes/references/palpation_dome.json lump 0.5 0.397 0.315 0.25
fi

if [ "$only" = all ] || [ "$only" = mls ]; then
  # verify NAME MESH DT [--set ...]: palpate-verify against the stored reference (found by its key).
  verify() {
    local name=$1 file=$2 dt=$3
    shift 3
    [ -f "$out/$name.json" ] && return
    echo "dome_study.sh: $name" >&2
    "$bin/palpate-verify" --scene $scene --set "body.distribution.file=$file" --set "integrator.dt=$dt" "$@" --json \
      > "$out/$name.json.part"
    mv "$out/$name.json.part" "$out/$name.json"
  }
  [ -f "$out/first.msh" ] || scripts/make_mesh.sh --dome 0.05 --focus-size 0.001 --growth 1.25 --top-size 0.003 \
    --far-size 0.008 $(lump_refine 1) --node-order morton --out "$out/first.msh" >&2
  for s in 0.8 0.63; do mesh "mls_$s" "$s" $(lump_refine "$s") --node-order morton; done
  for variant in homogeneous lump; do
    set=()
    [ "$variant" = lump ] || set=("${homogeneous[@]}")
    verify "${variant}_shipped" "$(realpath scenes/meshes/palpation_dome.msh)" 0.001 "${set[@]}"
    verify "${variant}_first" "$(realpath "$out/first.msh")" 0.001 "${set[@]}"
    # dt scaled with s (the lump's wave speed, sqrt(3) times the matrix's, asks for 0.8 of that)
    factor=1
    [ "$variant" = lump ] && factor=0.8
    verify "${variant}_s0.8" "$(realpath "$out/mls_0.8.msh")" "$(awk -v f=$factor 'BEGIN { print 0.0008 * f }')" "${set[@]}"
    verify "${variant}_s0.63" "$(realpath "$out/mls_0.63.msh")" "$(awk -v f=$factor 'BEGIN { print 0.00063 * f }')" "${set[@]}"
  done
  "$python" - "$out" <<'EOF'
import json, os, sys
out = sys.argv[1]
forces = [r["force"] for r in json.load(open(os.path.join(out, "homogeneous_shipped.json")))["rows"]]
lines = ["| run | particles | dt (ms) | " + " | ".join("%g N" % f for f in forces) + " | L2 |"]
lines.append("|---" * (len(lines[0].split("|")) - 2) + "|")
for variant in ("homogeneous", "lump"):
    for mesh in ("first", "shipped", "s0.8", "s0.63"):
        path = os.path.join(out, "%s_%s.json" % (variant, mesh))
        if not os.path.exists(path):
            continue
        j = json.load(open(path))
        errors = " | ".join("%+.2f %%" % (100 * r["error_reference"]) for r in j["rows"])
        lines.append("| %s, %s | %d | %g | %s | %.2f %% |" % (variant, mesh, j["particles"], 1e3 * j["dt"], errors,
                                                          100 * j["l2_error_reference"]))
open(os.path.join(out, "summary.md"), "w").write("\n".join(lines) + "\n")
print("\n".join(lines))
EOF
fi
