#!/usr/bin/env bash
# The error over the whole palpable surface (issue #32, docs/verification.md "The error over
# the whole palpable surface"): the MLS scene pressed at a 5 x 5 grid of sites over its top
# face, each at the scene's verification forces (verify.forces), against the converged
# finite-block reference computed at that site (palpate-reference --site: the linear hex FEM
# on lattices graded toward the site, Richardson/finest level with an uncertainty).
# The grid spans the palpable surface, the top face up to 1.5 R from the side walls: for
# scenes/palpation_block.json (box [-0.05, 0.05]^2, R = 0.01 m) x, y in
# {-0.035, -0.0175, 0, 0.0175, 0.035} m.
#
# Symmetry (--symmetric; on by default for palpation_block only): the continuous problem of a
# homogeneous block with a square top face, fixed on its bottom and four sides, pressed by a
# sphere at (x, y), is mapped onto itself by the reflections x -> -x, y -> -y (about the centre
# of the face) and by the swap x <-> y, so its depth-force curve at (x, y) is the one at
# (|x|, |y|) ordered so that the first is >= the second. The reference's lattices are graded
# toward the site, so they are mirrored and swapped with it and the discrete reference is too
# (the stored references at x = +-0.005, +-0.01, ... m agree to 4e-15; (0.0175, 0) and
# (0, 0.0175) give the same depths to rounding). Only the distinct sites
# of the octant are computed (6 of 25 on the 5 x 5 grid, the centre being stored already); each
# other site gets a copy of its octant site's reference with the key naming the site (a
# temporary file; the copy records "mirrored_from"). The MLS cloud is NOT symmetric (a gmsh
# mesh), so every one of the 25 sites is pressed. Without --symmetric (a lump, any body whose
# symmetry is not that of the square) every site's reference is computed.
#
# References are looked up by key (palpate-reference's, which names the site) in the scene
# folder's references/ (the stored ones, e.g. scenes/references/palpation_block.json at the
# centre) and in the cache (RAW/references/), and only the missing ones are computed, into the
# cache. The cache is in the repository's data/, not the build tree: a reference costs 50-100 s
# of one core and is a small JSON file, so keeping it beside the presses of the map it produced
# makes the map reproducible from the repository alone and a re-run cheap (~1 min: the presses
# only).
#
# A dome (--dome RB: a scene whose body is the hemisphere of `scripts/make_mesh.sh --dome RB`
# centred at the origin, no box): the grid is the square |x|, |y| <= A (--half-width, default
# RB / 2: the corners 45 degrees down the flank), and each site is pressed along the skin's
# normal there, as a finger palpates: the body is rotated about the origin so that the site is
# its top (scripts/lib/rotate_to_top.py: a rotated copy of the scene's mesh, the inclusions'
# centres rotated with it, the fixed base group moving with its nodes) and pressed straight
# down at (0, 0). (Pressed straight down, the flank would also be pushed along its slope, and a
# linear reference with vertical gaps is then another problem: 20 % apart at 45 degrees.) The
# reference at a site is palpate-reference --tet-meshes (linear tetrahedra, exact static
# solve, Richardson in the size at the site) on gmsh meshes of the hemisphere refined toward
# the site's point of the skin, rotated the same way, self-similar in s (--tet-levels,
# default 0.5 0.397 0.315; as scripts/dome_study.sh: focus 1 mm x s, skin 3 mm x s, far
# 8 mm x s, growth 1 + 0.25 s, each spherical inclusion a ball of its radius / 6 x s).
# Symmetry (--symmetric, the default when every inclusion is a sphere on the axis x = y = 0):
# the hemisphere fixed on its base is mapped onto itself by every rotation about its axis, so
# the reference at (x, y) is the one at (sqrt(x^2 + y^2), 0) ("rotated"): the 25 sites of the
# 5 x 5 grid need 6. Each takes 4-6 min of one core and up to 9 GB at s = 0.315 with a lump,
# about 14 min and 20 GB with s = 0.25 as well (then --jobs 1).
#
# Time: 50-100 s per new reference (one core each, --jobs at a time), ~2 s per pressed site.
# palpation_block from scratch on a 2-core machine (nice -n 10): 3 min 54 s (the 5 references
# in 192 s on 2 jobs, the 25 presses in 39 s); again with the cache: 49 s. Without --symmetric
# (24 references besides a stored centre) expect ~15-20 min on 2 jobs.
#
# Writes (NAME = the scene's file name without .json):
#   RAW/sites/NAME_X_Y.json            palpate-verify --json at each site
#   RAW/references/NAME_site_X_Y.json  the computed references (the cache)
#   DIR/NAME.csv                       one row per site: x, y, the error at each force, the worst
#                                      |error|, the L2 error, the reference used
#   DIR/NAME_rows.csv                  one row per site and force (d_sim, d_ref, its uncertainty)
#   DIR/NAME.md                        the table
#   DIR/NAME.png                       the map (scripts/plot_surface_map.py)
#
# usage: scripts/surface_map_study.sh [options]
#   --build DIR       build folder holding bin/palpate-verify and bin/palpate-reference
#                     (default build; BUILD_DIR is honoured too). Nothing is compiled.
#   --scene FILE      the scene (default scenes/palpation_block.json); it must have a
#                     body.box (palpate-reference computes the block's reference)
#   --symmetric       reduce the references by the square's symmetry (default for
#                     palpation_block only)
#   --no-symmetric    compute the reference at every site
#   --jobs N          references (and presses) run N at a time (default 2)
#   --out DIR         output folder (default docs/verification/surface_map)
#   --raw RAW         the presses' JSON and the references' cache (default
#                     data/verification/surface_map; with --out alone, DIR/raw)
#   --per-axis N      sites per axis of the grid (default 5)
#   --sites LIST      explicit sites instead of the grid, 'X,Y X,Y ...' (m)
#   --cache DIR       the references' cache (default RAW/references)
#   --references      recompute the references into the cache even when one is found
#   --dome RB         the body is the hemisphere of radius RB (m) of make_mesh.sh --dome
#   --half-width A    with --dome: the grid's half-width (m; default RB / 2)
#   --tet-levels LIST with --dome: the reference meshes' scale factors s, coarse to fine
#                     (default '0.5 0.397 0.315'; at least three)
#   --set KEY=VALUE   override a scene field in every press and reference (palpate-verify
#                     and palpate-reference --set; repeatable), e.g. mls.neighbors=20; the
#                     grid is still placed from the scene file's box and tool radius, and the
#                     outputs keep the scene's name: give --out
# Paths are relative to the repository root.
# shellcheck source=SCRIPTDIR/lib/study_common.sh
source "$(dirname "$0")/lib/study_common.sh"

build=$BUILD_DIR
scene=scenes/palpation_block.json
symmetric=
jobs=2
out=docs/verification/surface_map
raw=
per_axis=5
sites_list=
references=0
cache=
dome=
half_width=
tet_levels="0.5 0.397 0.315"
sets=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    --build) build=${2:?--build needs a folder}; shift ;;
    --scene) scene=${2:?--scene needs a file}; shift ;;
    --symmetric) symmetric=1 ;;
    --no-symmetric) symmetric=0 ;;
    --jobs) jobs=${2:?--jobs needs a number}; shift ;;
    --out) out=${2:?--out needs a folder}; shift ;;
    --raw) raw=${2:?--raw needs a folder}; shift ;;
    --per-axis) per_axis=${2:?--per-axis needs a number}; shift ;;
    --sites) sites_list=${2:?--sites needs a list}; shift ;;
    --cache) cache=${2:?--cache needs a folder}; shift ;;
    --references) references=1 ;;
    --dome) dome=${2:?--dome needs a radius}; shift ;;
    --half-width) half_width=${2:?--half-width needs a length}; shift ;;
    --tet-levels) tet_levels=${2:?--tet-levels needs a list}; shift ;;
    --set) sets+=(--set "${2:?--set needs KEY=VALUE}"); shift ;;
    -h|--help) study_help ;;
    *) study_unknown_option "$1" ;;
  esac
  shift
done
[[ $jobs =~ ^[1-9][0-9]*$ ]] || { echo "surface_map_study.sh: --jobs: expected a positive integer" >&2; exit 2; }
[[ $per_axis =~ ^[1-9][0-9]*$ ]] || { echo "surface_map_study.sh: --per-axis: expected a positive integer" >&2; exit 2; }
[[ -f $scene ]] || { echo "surface_map_study.sh: no scene $scene" >&2; exit 2; }
verify="$build/bin/palpate-verify"
reference="$build/bin/palpate-reference"
study_require "$verify" "$reference"  # this script compiles nothing
name=$(basename "$scene" .json)
[[ -z $symmetric && -z $dome ]] && { [[ $name == palpation_block ]] && symmetric=1 || symmetric=0; }
# The runs' JSON (data/README.md): under data/ for an output under docs/, else DIR/raw.
[[ -n $raw ]] || { [[ $out == docs/* ]] && raw=data/${out#docs/} || raw=$out/raw; }
cache=${cache:-$raw/references}
stored="$(dirname "$scene")/references"
mkdir -p "$out" "$raw/sites" "$cache"
tmp=$(mktemp -d)
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$tmp"' EXIT

# The sites, and per site its octant site under the symmetry (itself without it). The grid
# is the top face less 1.5 R from every side wall; coordinates are printed with %.10g so
# that a site's text is the same everywhere (file names, --site, the reference's key).
"$python" - "$scene" "$symmetric" "$per_axis" "$sites_list" "$dome" "$half_width" > "$tmp/sites.txt" <<'PY'
import json, math, sys
scene_file, symmetric, per_axis, sites_list, dome, half_width = sys.argv[1:7]
per_axis = int(per_axis)
scene = json.load(open(scene_file))
box = scene.get("body", {}).get("box")
t = lambda v: "%.10g" % (0.0 if abs(v) < 1e-15 else v)
if dome:
    if box is not None:
        sys.exit("surface_map_study.sh: --dome, but %s has a body.box" % scene_file)
    RB = float(dome)
    a = float(half_width) if half_width else 0.5 * RB
    inclusions = scene.get("material", {}).get("inclusions", [])
    on_axis = all("sphere" in i and abs(i["sphere"]["center"][0]) < 1e-12 and abs(i["sphere"]["center"][1]) < 1e-12
                  for i in inclusions)
    if symmetric == "1" and not on_axis:
        sys.exit("surface_map_study.sh: --symmetric, but an inclusion is not a sphere on the axis: use --no-symmetric")
    axisymmetric = on_axis if symmetric == "" else symmetric == "1"
    if sites_list:
        sites = [tuple(float(v) for v in s.split(",")) for s in sites_list.split()]
    else:
        axis = [-a + 2 * a * k / max(per_axis - 1, 1) for k in range(per_axis)] if per_axis > 1 else [0.0]
        sites = [(x, y) for y in axis for x in axis]
    for x, y in sites:
        if math.hypot(x, y) > RB - scene["indenter"]["radius"]:
            sys.exit("surface_map_study.sh: the site (%g, %g) is within R of the dome's rim" % (x, y))
        ox, oy = (math.hypot(x, y), 0.0) if axisymmetric else (x, y)
        print(t(x), t(y), t(ox), t(oy))
    sys.exit(0)
if box is None:
    sys.exit("surface_map_study.sh: %s has no body.box: palpate-reference --site computes the finite *block*'s "
             "reference; for a hemisphere give --dome RB (references on tetrahedral meshes refined at each site)" %
             scene_file)
lo, hi, R = box["min"], box["max"], scene["indenter"]["radius"]
cx, cy = 0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])
symmetric = symmetric == "1"  # "0" with --no-symmetric (and for any block but palpation_block)
if symmetric:
    why = []
    if abs((hi[0] - lo[0]) - (hi[1] - lo[1])) > 1e-12 * (hi[0] - lo[0]): why.append("the top face is not square")
    if scene.get("material", {}).get("inclusions"): why.append("the body has inclusions")
    fixed = scene.get("fixed", [])
    if any(not isinstance(f, str) or f not in ("bottom", "top", "sides") for f in fixed):
        why.append("its fixed regions are not whole faces (bottom, sides)")
    if why:
        sys.exit("surface_map_study.sh: --symmetric, but " + " and ".join(why) + ": use --no-symmetric")
if sites_list:
    sites = [tuple(float(v) for v in s.split(",")) for s in sites_list.split()]
else:
    m = 1.5 * R
    axis = lambda a, b: [a + m + (b - a - 2 * m) * k / max(per_axis - 1, 1) for k in range(per_axis)] if per_axis > 1 else [0.5 * (a + b)]
    xs, ys = axis(lo[0], hi[0]), axis(lo[1], hi[1])
    sites = [(x, y) for y in ys for x in xs]
for x, y in sites:
    if symmetric:
        u, v = sorted((abs(x - cx), abs(y - cy)), reverse=True)
        ox, oy = cx + u, cy + v
    else:
        ox, oy = x, y
    print(t(x), t(y), t(ox), t(oy))
PY

# site_args X Y: sets `args`, what puts the tool at site (X, Y): --site X,Y; on a dome, the
# scene's mesh and inclusions rotated so that the site is the top, and --site 0,0 (made once
# per site into $tmp, read back by the background jobs).
if [[ -n $dome ]]; then
  base_mesh=$("$python" -c 'import json, os, sys; s = json.load(open(sys.argv[1]))
print(os.path.join(os.path.dirname(sys.argv[1]), s["body"]["distribution"]["file"]))' "$scene")
fi
skin_z() { awk -v r="$dome" -v x="$1" -v y="$2" 'BEGIN { printf "%.10g", sqrt(r * r - x * x - y * y) }'; }
site_args() {
  local x=$1 y=$2 file="$tmp/site_${1}_${2}.args"
  if [[ ! -f $file ]]; then
    if [[ -z $dome ]]; then
      printf '%s\n' --site "$x,$y" > "$file"
    else
      local z mesh inclusions
      z=$(skin_z "$x" "$y")
      mesh="$tmp/$(basename "$base_mesh" .msh)_site_${x}_${y}.msh"
      "$python" scripts/lib/rotate_to_top.py mesh "$base_mesh" "$mesh" "$x" "$y" "$z"
      inclusions=$("$python" - "$scene" "$x" "$y" "$z" <<'PY'
import json, sys
sys.path.insert(0, "scripts/lib")
from rotate_to_top import apply, rotation
Q = rotation([float(v) for v in sys.argv[2:5]])
inclusions = json.load(open(sys.argv[1])).get("material", {}).get("inclusions", [])
for i in inclusions:
    if "box" in i:
        sys.exit("surface_map_study.sh: --dome: a box inclusion does not rotate into a box")
    if "sphere" in i:
        i["sphere"]["center"] = [float("%.12g" % v) for v in apply(Q, i["sphere"]["center"])]
print(json.dumps(inclusions))
PY
)
      printf '%s\n' --set "body.distribution.file=$mesh" --set "material.inclusions=$inclusions" --site 0,0 > "$file"
    fi
  fi
  mapfile -t args < "$file"
  args=("${sets[@]}" "${args[@]}")
}
# key X Y: the reference key palpate-verify expects at a site (palpate-reference --key; it
# also refuses a site off the face or closer than R to a wall).
key() {
  site_args "$1" "$2"
  "$reference" --scene "$scene" "${args[@]}" --key ||
    { echo "surface_map_study.sh: no reference key at ($1, $2) (palpate-reference refused the site)" >&2; exit 2; }
}
# The stored and cached references by key.
index_references() {
  "$python" - "$@" <<'PY'
import glob, json, os, sys
for folder in sys.argv[1:]:
    for path in sorted(glob.glob(os.path.join(folder, "*.json"))):
        try:
            j = json.load(open(path))
            if {"key", "forces", "indentation", "uncertainty"} <= j.keys() and "mirrored_from" not in j:
                print(j["key"] + "\t" + path)
        except Exception:
            pass
PY
}
index_references "$cache" "$stored" > "$tmp/index.tsv"
lookup() { awk -F'\t' -v k="$1" '$1 == k { print $2; exit }' "$tmp/index.tsv"; }

# The octant sites whose reference is missing.
declare -A site_key octant_file
todo=()
while read -r x y ox oy; do
  site_key[$x,$y]=$(key "$x" "$y")
  if [[ -z ${site_key[$ox,$oy]:-} ]]; then site_key[$ox,$oy]=$(key "$ox" "$oy"); fi
  [[ -n ${octant_file[$ox,$oy]:-} ]] && continue
  file=$(lookup "${site_key[$ox,$oy]}")
  if [[ $references == 1 || -z $file ]]; then
    file="$cache/${name}_site_${ox}_${oy}.json"
    todo+=("$ox,$oy")
  fi
  octant_file[$ox,$oy]=$file
  echo "surface_map_study.sh: reference at ($ox, $oy): $file$([[ $references == 1 || ! -f $file ]] && echo ' (to compute)')" >&2
done < "$tmp/sites.txt"

# throttle: wait until fewer than --jobs background jobs run.
throttle() { while (( $(jobs -rp | wc -l) >= jobs )); do wait -n || true; done; }
# tet_meshes X Y: with --dome, the gmsh family refined toward the site's point of the skin and
# rotated as site_args rotates the scene's mesh (into $tmp), printed as palpate-reference
# --tet-meshes wants it.
tet_meshes() {
  local x=$1 y=$2 s list=() z
  z=$(skin_z "$x" "$y")
  for s in $tet_levels; do
    local file="$tmp/tet_${x}_${y}_$s.msh" refine=()
    while read -r cx cy cz rad; do
      refine+=(--refine "$cx" "$cy" "$cz" "$rad" "$(awk -v r="$rad" -v s="$s" 'BEGIN { print r / 6 * s }')")
    done < "$tmp/inclusions.txt"
    scripts/make_mesh.sh --dome "$dome" --focus "$x" "$y" "$z" \
      --focus-size "$(awk -v s="$s" 'BEGIN { print 0.001 * s }')" --growth "$(awk -v s="$s" 'BEGIN { print 1 + 0.25 * s }')" \
      --top-size "$(awk -v s="$s" 'BEGIN { print 0.003 * s }')" --far-size "$(awk -v s="$s" 'BEGIN { print 0.008 * s }')" \
      "${refine[@]}" --out "$file.unrotated" >&2 || return 1
    "$python" scripts/lib/rotate_to_top.py mesh "$file.unrotated" "$file" "$x" "$y" "$z" || return 1
    rm -f "$file.unrotated"
    list+=("$file:$(awk -v s="$s" 'BEGIN { print 0.001 * s }')")
  done
  (IFS=,; echo "${list[*]}")
}
if [[ -n $dome ]]; then
  (( $(wc -w <<< "$tet_levels") >= 3 )) || { echo "surface_map_study.sh: --tet-levels: at least three" >&2; exit 2; }
  "$python" - "$scene" > "$tmp/inclusions.txt" <<'PY'
import json, sys
for i in json.load(open(sys.argv[1])).get("material", {}).get("inclusions", []):
    if "sphere" not in i:
        sys.exit("surface_map_study.sh: --dome: only spherical inclusions get a refined ball in the reference meshes")
    print(*i["sphere"]["center"], i["sphere"]["radius"])
PY
fi
compute_reference() {
  local x=$1 y=$2 file=$3 start=$SECONDS family=() args
  site_args "$x" "$y"
  if [[ -n $dome ]]; then
    family=(--tet-meshes "$(tet_meshes "$x" "$y" 2> "$tmp/mesh_${x}_${y}.log")") ||
      { echo "surface_map_study.sh: the reference meshes at ($x, $y) FAILED:" >&2; cat "$tmp/mesh_${x}_${y}.log" >&2; return; }
  fi
  if "$reference" --scene "$scene" "${args[@]}" "${family[@]}" --out "$file.part" > "$tmp/ref_${x}_${y}.log" 2>&1; then
    rm -f "$tmp"/tet_"${x}"_"${y}"_*.msh
    mv "$file.part" "$file"
    echo "surface_map_study.sh: reference at ($x, $y): $((SECONDS - start)) s" >&2
  else
    echo "surface_map_study.sh: palpate-reference --site $x,$y FAILED:" >&2
    cat "$tmp/ref_${x}_${y}.log" >&2
    rm -f "$file.part"
  fi
}
start_all=$SECONDS
for site in "${todo[@]}"; do
  throttle
  echo "surface_map_study.sh: palpate-reference --scene $scene --site $site" >&2
  compute_reference "${site%,*}" "${site#*,}" "${octant_file[$site]}" &
done
wait
echo "surface_map_study.sh: references: ${#todo[@]} computed in $((SECONDS - start_all)) s" >&2
for site in "${todo[@]}"; do
  [[ -f ${octant_file[$site]} ]] || { echo "surface_map_study.sh: no reference at ($site)" >&2; exit 1; }
done

# The reference at each site: its octant site's, under the site's own key.
site_reference() {
  local x=$1 y=$2 ox=$3 oy=$4
  local src=${octant_file[$ox,$oy]}
  if [[ ${site_key[$x,$y]} == "${site_key[$ox,$oy]}" ]]; then echo "$src"; return; fi
  local file="$tmp/mirrored_${x}_${y}.json"
  "$python" - "$src" "${site_key[$x,$y]}" "$file" <<'PY'
import json, sys
src, key, dst = sys.argv[1:4]
j = json.load(open(src))
j["mirrored_from"] = {"key": j["key"], "file": src}
j["key"] = key
json.dump(j, open(dst, "w"), indent=1)
PY
  echo "$file"
}

press() {
  local x=$1 y=$2 ref=$3 rc=0 args
  local json="$raw/sites/${name}_${x}_${y}.json"
  site_args "$x" "$y"
  "$verify" --scene "$scene" "${args[@]}" --reference "$ref" --json --quiet > "$json.part" 2> "$tmp/verify_${x}_${y}.log" || rc=$?
  if [[ $rc == 0 || $rc == 3 ]]; then  # 3: some force did not come to rest (its row says so)
    mv "$json.part" "$json"
  else
    echo "surface_map_study.sh: palpate-verify --site $x,$y FAILED (exit $rc):" >&2
    cat "$tmp/verify_${x}_${y}.log" >&2
    rm -f "$json.part"
  fi
}
start_all=$SECONDS
: > "$tmp/pressed.txt"
while read -r x y ox oy; do
  ref=$(site_reference "$x" "$y" "$ox" "$oy")
  printf '%s %s %s %s %s\n' "$x" "$y" "$ox" "$oy" "${octant_file[$ox,$oy]}" >> "$tmp/pressed.txt"
  rm -f "$raw/sites/${name}_${x}_${y}.json"
  throttle
  echo "surface_map_study.sh: palpate-verify --scene $scene --site $x,$y" >&2
  press "$x" "$y" "$ref" &
done < "$tmp/sites.txt"
wait
echo "surface_map_study.sh: $(wc -l < "$tmp/pressed.txt") sites pressed in $((SECONDS - start_all)) s" >&2

# The tables.
"$python" - "$out" "$name" "$tmp/pressed.txt" "$raw" "$([[ -n $dome ]] && echo rotated || echo mirrored)" <<'PY'
import json, math, os, sys
out, name, pressed, raw, moved = sys.argv[1:6]
sites = [line.split() for line in open(pressed)]
rows, long_rows, forces = [], [], None
missing = []
for x, y, ox, oy, ref_file in sites:
    path = os.path.join(raw, "sites", "%s_%s_%s.json" % (name, x, y))
    if not os.path.exists(path):
        missing.append((x, y))
        continue
    j = json.load(open(path))
    f = [r["force"] for r in j["rows"]]
    forces = forces or f
    if f != forces:
        sys.exit("surface_map_study.sh: the sites were pressed at different forces")
    err = [r["error_reference"] for r in j["rows"]]
    unc = [r["d_reference_uncertainty"] / r["d_reference"] if r["d_reference_uncertainty"] is not None else None
           for r in j["rows"]]
    finite = [abs(e) for e in err if e is not None]
    mirrored = (x, y) != (ox, oy)
    rows.append(dict(x=float(x), y=float(y), r=math.hypot(float(x), float(y)), err=err,
                     worst=max(finite) if len(finite) == len(err) else None, l2=j["l2_error_reference"],
                     unc=max((u for u in unc if u is not None), default=None), particles=j["particles"],
                     status="ok" if all(r["status"] == "ok" for r in j["rows"]) else
                     ";".join(sorted({r["status"] for r in j["rows"]} - {"ok"})),
                     reference=os.path.relpath(ref_file), octant=(float(ox), float(oy)), mirrored=mirrored))
    for r in j["rows"]:
        long_rows.append([x, y, r["force"], r["d_sim"], r["d_reference"], r["d_reference_uncertainty"],
                          r["error_reference"], r["status"], r["steps"]])
if not rows:
    sys.exit("surface_map_study.sh: no site was pressed")
fmt = lambda v: "" if v is None else repr(v)
with open(os.path.join(out, name + ".csv"), "w") as f:
    f.write("x_m,y_m,r_m," + ",".join("err_%gN" % F for F in forces) +
            ",worst_abs_err,l2_err,ref_uncertainty_max,status,particles,reference,octant_x_m,octant_y_m\n")
    for s in rows:
        f.write(",".join([repr(s["x"]), repr(s["y"]), repr(s["r"])] + [fmt(e) for e in s["err"]] +
                         [fmt(s["worst"]), fmt(s["l2"]), fmt(s["unc"]), s["status"], str(s["particles"]),
                          s["reference"], repr(s["octant"][0]), repr(s["octant"][1])]) + "\n")
with open(os.path.join(out, name + "_rows.csv"), "w") as f:
    f.write("x_m,y_m,force_N,d_sim_m,d_ref_m,d_ref_uncertainty_m,err_ref,status,steps\n")
    for r in long_rows:
        f.write(",".join("" if v is None else str(v) for v in r) + "\n")
pc = lambda v: "–" if v is None else ("%+.1f" % (100 * v)).replace("-", "−")
ok2 = [s for s in rows if s["worst"] is not None and s["worst"] <= 0.02]
ok1 = [s for s in rows if s["worst"] is not None and s["worst"] <= 0.01]
worst = max(rows, key=lambda s: -1 if s["worst"] is None else s["worst"])
md = ["Depth error of `%s` against the converged reference at each site, per cent, at F = %s N; worst = the "
      "largest |error| over the forces; L2 = ||d_sim − d_ref|| / ||d_ref|| over the sweep; ref ± = the "
      "reference's largest relative uncertainty; reference: the site whose reference was used "
      "(%s when it is not the site itself). Written by scripts/surface_map_study.sh." %
      (name, ", ".join("%g" % F for F in forces), moved), "",
      "| x (mm) | y (mm) | " + " | ".join("%g N" % F for F in forces) + " | worst | L2 | ref ± | reference |",
      "|---:|---:|" + "---:|" * len(forces) + "---:|---:|---:|---|"]
for s in sorted(rows, key=lambda s: (-s["y"], s["x"])):
    w = "–" if s["worst"] is None else "%.1f" % (100 * s["worst"])
    if s["worst"] is not None and s["worst"] > 0.02: w = "**" + w + "**"
    md.append("| %g | %g | %s | %s | %s | %s | %s |" % (
        1000 * s["x"], 1000 * s["y"], " | ".join(pc(e) for e in s["err"]), w,
        "–" if s["l2"] is None else "%.1f" % (100 * s["l2"]),
        "–" if s["unc"] is None else "%.1f" % (100 * s["unc"]),
        "(%g, %g)%s%s" % (1000 * s["octant"][0], 1000 * s["octant"][1], " " + moved if s["mirrored"] else "",
                          "" if s["status"] == "ok" else ", " + s["status"])))
md += ["", "%d of %d sites within 2 %% at every force, %d within 1 %%; the worst: (%g, %g) mm, %.1f %%." % (
    len(ok2), len(rows), len(ok1), 1000 * worst["x"], 1000 * worst["y"], 100 * (worst["worst"] or float("nan")))]
if missing:
    md += ["", "Not pressed (palpate-verify failed): " + ", ".join("(%s, %s)" % m for m in missing)]
open(os.path.join(out, name + ".md"), "w").write("\n".join(md) + "\n")
print("\n".join(md))
PY

"$python" scripts/plot_surface_map.py "$out/$name.csv" "$scene" "$out/$name.png" ${dome:+--dome "$dome"}
