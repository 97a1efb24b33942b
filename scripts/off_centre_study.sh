#!/usr/bin/env bash
# The off-centre table (docs/physics.md §4, "Off-centre sites"): the Hertz sweep at the
# centre of the top face, at (0.4, 0.3) and near a wall at (0.5, 0) (R = 0.5 m from the
# side x = 1, the closest site palpate-verify accepts), each against the finite-block
# reference computed at that site (palpate-reference --site; stored in scenes/references/,
# recomputed with --references) and against Hertz. Three clouds per site:
#   haptic          scenes/hertz_cube_haptic.json as shipped (its mesh is refined at the centre)
#   haptic_at_site  the same recipe (scripts/make_mesh.sh --focus-size 0.03 --far-size 0.3
#                   --growth 1.15) with the focus at the site (needs gmsh)
#   graded          scenes/hertz_cube_graded.json, whose lattice is graded toward the site
# Writes RAW/<cloud>_<site>.json (palpate-verify --json), DIR/off_centre.csv and
# DIR/off_centre.md (the table).
#
# usage: scripts/off_centre_study.sh [--references] [--quick] [--out DIR] [--raw RAW]
#   --references  recompute the references at the off-centre sites (about a minute each)
#                 into scenes/references/
#   --quick       three forces and the haptic clouds only (seconds)
#   --out DIR     output folder (default docs/verification/off_centre)
#   --raw RAW     the runs' JSON (default data/verification/off_centre; with --out alone,
#                 DIR/raw)
# BUILD_DIR (default build) holds bin/palpate-verify and bin/palpate-reference; they are
# built there (Release) when stale, through scripts/build.sh.
# shellcheck source=SCRIPTDIR/lib/study_common.sh
source "$(dirname "$0")/lib/study_common.sh"

references=0
quick=0
out=docs/verification/off_centre
raw=
while [[ $# -gt 0 ]]; do
  case "$1" in
    --references) references=1 ;;
    --quick) quick=1 ;;
    --out) out=${2:?--out needs a folder}; shift ;;
    --raw) raw=${2:?--raw needs a folder}; shift ;;
    -h|--help) study_help ;;
    *) study_unknown_option "$1" ;;
  esac
  shift
done

# The runs' JSON (data/README.md): under data/ for an output under docs/, else DIR/raw.
[[ -n $raw ]] || { [[ $out == docs/* ]] && raw=data/${out#docs/} || raw=$out/raw; }
verify="$BUILD_DIR/bin/palpate-verify"
reference="$BUILD_DIR/bin/palpate-reference"
study_build palpate-verify palpate-reference
mkdir -p "$out" "$raw"
sites=("0,0" "0.4,0.3" "0.5,0")
forces=()
[[ $quick == 1 ]] && forces=(--forces 29.3,82.88,191.9)

# The references at the off-centre sites (the centre's is scenes/references/hertz_cube.json).
for site in "${sites[@]:1}"; do
  file="scenes/references/hertz_cube_site_${site/,/_}.json"
  if [[ $references == 1 || ! -f "$file" ]]; then
    echo "off_centre_study.sh: palpate-reference --site $site" >&2
    start=$SECONDS
    "$reference" --scene scenes/hertz_cube.json --site "$site" --out "$file" --quiet > /dev/null
    echo "off_centre_study.sh: reference at ($site): $((SECONDS - start)) s" >&2
  fi
done

have_gmsh=0
command -v gmsh > /dev/null && have_gmsh=1
meshes=$(mktemp -d)
trap 'rm -rf "$meshes"' EXIT
for site in "${sites[@]}"; do
  tag=${site/,/_}
  echo "off_centre_study.sh: site ($site)" >&2
  "$verify" --scene scenes/hertz_cube_haptic.json --site "$site" "${forces[@]}" --json --quiet > "$raw/haptic_$tag.json" || true
  if [[ $have_gmsh == 1 ]]; then
    mesh="$meshes/haptic_at_site_$tag.msh"
    scripts/make_mesh.sh --focus-size 0.03 --far-size 0.3 --growth 1.15 --focus "${site%,*}" "${site#*,}" 0 --out "$mesh" > /dev/null
    "$verify" --scene scenes/hertz_cube_haptic.json --set "body.distribution.file=$(realpath "$mesh")" --site "$site" "${forces[@]}" \
      --json --quiet > "$raw/haptic_at_site_$tag.json" || true
  else
    echo "off_centre_study.sh: no gmsh: the haptic_at_site clouds are skipped" >&2
  fi
  if [[ $quick == 0 ]]; then
    "$verify" --scene scenes/hertz_cube_graded.json --site "$site" --json --quiet > "$raw/graded_$tag.json" || true
  fi
done

"$python" - "$out" "$raw" <<'PY'
import glob, json, os, sys
out, raw = sys.argv[1], sys.argv[2]
rows, md = [], []
order = {"haptic": 0, "haptic_at_site": 1, "graded": 2}
site_order = {"0_0": 0, "0.4_0.3": 1, "0.5_0": 2}
def sort_key(p):
    cloud, x, y = os.path.splitext(os.path.basename(p))[0].rsplit("_", 2)
    return (order.get(cloud, 9), site_order.get(x + "_" + y, 9), p)
files = sorted(glob.glob(os.path.join(raw, "*.json")), key=sort_key)
for path in files:
    j = json.load(open(path))
    cloud = os.path.basename(path).rsplit("_", 2)[0]
    site = "(%g, %g)" % tuple(j["site"])
    e_ref = [r["error_reference"] for r in j["rows"]]
    e_h = [r["error_hertz"] for r in j["rows"]]
    def pc(v):
        return "-" if v is None else "%+.1f" % (100 * v)
    worst = max((abs(v) for v in e_ref if v is not None), default=None)
    md.append("| %s | %s | %d | %s | %s | %s | %s |" % (
        cloud, site, j["particles"], " / ".join(pc(v) for v in e_ref),
        "-" if worst is None else "%.1f %%" % (100 * worst),
        "-" if j["l2_error_reference"] is None else "%.2f %%" % (100 * j["l2_error_reference"]),
        " / ".join(pc(v) for v in e_h)))
    for r in j["rows"]:
        rows.append([cloud, j["site"][0], j["site"][1], j["particles"], r["force"], r["d_sim"], r["d_reference"],
                     r["d_reference_uncertainty"], r["error_reference"], r["d_hertz"], r["error_hertz"], r["status"]])
forces = ", ".join("%g" % r["force"] for r in json.load(open(files[0]))["rows"]) if files else ""
head = ["Errors in depth, per cent, at F = %s N" % forces, "",
        "| cloud | site [m] | particles | error against the reference at the site [%] | worst | L2 | error against Hertz [%] |",
        "|---|---|---:|---|---:|---:|---|"]
open(os.path.join(out, "off_centre.md"), "w").write("\n".join(head + md) + "\n")
with open(os.path.join(out, "off_centre.csv"), "w") as f:
    f.write("cloud,site_x_m,site_y_m,particles,force_N,d_sim_m,d_ref_m,d_ref_uncertainty_m,err_ref,d_hertz_m,err_hertz,status\n")
    for r in rows:
        f.write(",".join("" if v is None else str(v) for v in r) + "\n")
print("\n".join(head + md))
PY
