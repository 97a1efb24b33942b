#!/usr/bin/env bash
# A tetrahedral mesh of the body's box, graded toward a focus point, with Debian's
# gmsh; its vertices are a node cloud for the "mesh" distribution
# (docs/scene-format.md). Writes gmsh .msh 4.1 ASCII.
#
#   scripts/make_mesh.sh [options]
#     --out FILE        output .msh (default scenes/meshes/graded_cube.msh)
#     --focus-size H0   element size at the focus, m (default 0.03)
#     --far-size H1     largest element size, m (default 0.25)
#     --growth G        size growth: h(r) = min(H1, H0 + (G - 1) r) at distance r from
#                       the focus, i.e. neighbouring elements grow by about a factor G
#                       (default 1.25)
#     --box XMIN YMIN ZMIN XMAX YMAX ZMAX   the box, m (default -1 -1 -2 1 1 0: the
#                       2 m cube with its top face at z = 0)
#     --focus X Y Z     the focus, m (default the centre of the top face, the indenter's site)
#     --focus-top       grade from the whole top face instead: r is the depth below it
#                       (a palpation block, fine wherever the tool may touch it)
#     --top-size H2     with a focus point or a --patch: also at most H2 + (G - 1) x depth
#                       below the top face (the skin of a --dome), so the whole top face is
#                       at most H2 (the focus stays finer)
#     --patch A         with --focus-top: only the square |x - fx|, |y - fy| <= A of the top
#                       face (fx, fy: the centre of the top face) is the focus; r is the
#                       distance to it (the palpable part of the face, coarser toward walls)
#     --seed N          gmsh's Mesh.RandomSeed (default 1); the mesh is deterministic
#                       for a given gmsh version, seed and options
#     --format F        msh41 (default) or msh22
#     --node-order O    file (default: gmsh's) or morton: the nodes of each gmsh entity
#                       block rewritten in Morton (Z-curve) order of their positions, so
#                       that neighbouring particles lie near each other in memory (the force
#                       loop's gathers and scatters; about 7 % of its time on a 6416-node
#                       block, docs/verification.md); the tetrahedra are unchanged
#     --refine X Y Z R H  also at most H inside the ball of radius R about (X, Y, Z), growing
#                       by G away from it: H + (G - 1) x (distance - R) (an inclusion;
#                       repeatable)
#     --focus-line X0 Y0 X1 Y1 H  also at most H on the segment (X0, Y0)-(X1, Y1) of the
#                       top face (a scan path), growing by G away from it: H + (G - 1) x
#                       (distance to the segment) (repeatable; not with --dome)
#     --dome RB         the body is a hemisphere of radius RB on the plane z = 0 (its
#                       centre at the origin, its pole at (0, 0, RB)) instead of the box, with
#                       the physical groups "base" (the flat face, to fix), "skin" (the curved
#                       face) and "tissue" (the volume); the focus defaults to the pole, and
#                       --focus-top grades from the whole skin (r = depth below it)
#     --scene FILE      size the mesh for a scene (core/resolution.h): the focus size is the
#                       spacing its smallest sweep force asks for (three spacings across the
#                       Hertz contact radius), every inclusion gets a --refine with six
#                       spacings across its radius, and the box and focus are the scene's
#                       (options after --scene override them); a mesh body without a box
#                       (any shape) gives neither, unless it names a focus: the body is
#                       then this command's (--box, --dome). Needs palpate-resolution:
#                       $PALPATE_BIN (default build/bin) or on PATH. Prints what it chose.
#
# scenes/meshes/palpation_block.msh (the hand-scale block) is
#   scripts/make_mesh.sh --box -0.05 -0.05 -0.05 0.05 0.05 0 --focus-size 0.001 --growth 1.2 \
#     --top-size 0.0025 --far-size 0.015 --out scenes/meshes/palpation_block.msh
#
# gmsh is not needed by the build or the tests. If it is missing the script installs
# Debian's package when run as root, else says how.
set -euo pipefail

out=scenes/meshes/graded_cube.msh
h0=0.03
h1=0.25
growth=1.25
box=(-1 -1 -2 1 1 0)
focus=()
focus_top=0
top_size=
patch=
seed=1
format=msh41
node_order=file
refines=()
lines=()
dome=

die() { echo "make_mesh.sh: $*" >&2; exit 2; }
number() { [[ "$2" =~ ^[-+]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][-+]?[0-9]+)?$ ]] || die "$1: expected a number, got '$2'"; }

while [ $# -gt 0 ]; do
  case "$1" in
    --out) out=${2:?--out needs a file}; shift 2 ;;
    --focus-size) number "$1" "${2:-}"; h0=$2; shift 2 ;;
    --far-size) number "$1" "${2:-}"; h1=$2; shift 2 ;;
    --growth) number "$1" "${2:-}"; growth=$2; shift 2 ;;
    --box) [ $# -ge 7 ] || die "--box needs 6 numbers"
           for v in "${@:2:6}"; do number --box "$v"; done
           box=("${@:2:6}"); shift 7 ;;
    --focus) [ $# -ge 4 ] || die "--focus needs 3 numbers"
             for v in "${@:2:3}"; do number --focus "$v"; done
             focus=("${@:2:3}"); shift 4 ;;
    --focus-top) focus_top=1; shift ;;
    --top-size) number "$1" "${2:-}"; top_size=$2; shift 2 ;;
    --patch) number "$1" "${2:-}"; patch=$2; shift 2 ;;
    --seed) [[ "${2:-}" =~ ^[0-9]+$ ]] || die "--seed: expected a non-negative integer"; seed=$2; shift 2 ;;
    --format) case "${2:-}" in msh41|msh22) format=$2 ;; *) die "--format: msh41 or msh22, got '${2:-}'" ;; esac; shift 2 ;;
    --node-order) case "${2:-}" in file|morton) node_order=$2 ;; *) die "--node-order: file or morton, got '${2:-}'" ;; esac; shift 2 ;;
    --refine) [ $# -ge 6 ] || die "--refine needs 5 numbers (X Y Z R H)"
              for v in "${@:2:5}"; do number --refine "$v"; done
              awk -v r="$5" -v h="$6" 'BEGIN { exit !(r > 0 && h > 0) }' || die "--refine: R and H must be positive"
              refines+=("${*:2:5}"); shift 6 ;;
    --focus-line) [ $# -ge 6 ] || die "--focus-line needs 5 numbers (X0 Y0 X1 Y1 H)"
                  for v in "${@:2:5}"; do number --focus-line "$v"; done
                  awk -v h="$6" 'BEGIN { exit !(h > 0) }' || die "--focus-line: H must be positive"
                  lines+=("${*:2:5}"); shift 6 ;;
    --dome) number "$1" "${2:-}"; dome=$2; shift 2 ;;
    --scene) scene=${2:?--scene needs a file}
             tool=${PALPATE_BIN:-build/bin}/palpate-resolution
             [ -x "$tool" ] || tool=$(command -v palpate-resolution) ||
               die "--scene needs palpate-resolution (build it, or set PALPATE_BIN to the folder holding it)"
             values=$("$tool" --scene "$scene" --shell) || die "--scene: palpate-resolution could not read '$scene'"
             # Its KEY=VALUE lines as scene_KEY (box and focus are this script's arrays): no
             # box line for a mesh body of any shape, no focus line unless it is known.
             unset scene_box scene_focus
             eval "$(sed 's/^/scene_/' <<< "$values")"
             h0=$scene_focus_size
             [ -z "${scene_box:-}" ] || read -r -a box <<< "$scene_box"
             [ -z "${scene_focus:-}" ] || read -r -a focus <<< "$scene_focus"
             for ((k = 0; k < scene_refine_count; ++k)) { v=scene_refine_$k; refines+=("${!v}"); }
             echo "make_mesh.sh: $scene asks for $h0 m under the tool at (${focus[*]:-the default focus})," \
                  "${scene_refine_count} inclusion(s)${scene_box:+, box (${box[*]})}" >&2
             [ -n "${scene_box:-}" ] ||
               echo "make_mesh.sh: $scene is a mesh body without a box: the body is this command's (--box, --dome)" >&2
             shift 2 ;;
    -h|--help) sed -n '2,50p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) die "unknown option '$1' (--help)" ;;
  esac
done

awk -v h0="$h0" -v h1="$h1" -v g="$growth" 'BEGIN { exit !(h0 > 0 && h1 >= h0 && g > 1) }' ||
  die "need 0 < --focus-size <= --far-size and --growth > 1 (got $h0, $h1, $growth)"
awk -v a="${box[0]}" -v b="${box[1]}" -v c="${box[2]}" -v d="${box[3]}" -v e="${box[4]}" -v f="${box[5]}" \
  'BEGIN { exit !(d > a && e > b && f > c) }' || die "--box: max must exceed min on every axis"
[ $focus_top -eq 0 ] || [ ${#focus[@]} -eq 0 ] || die "--focus and --focus-top exclude each other"
if [ -n "$dome" ]; then
  awk -v r="$dome" 'BEGIN { exit !(r > 0) }' || die "--dome: the radius must be positive"
  [ -z "$patch" ] || die "--patch goes with the box, not --dome"
  [ ${#lines[@]} -eq 0 ] || die "--focus-line goes with the box, not --dome"
  box=(-$dome -$dome 0 $dome $dome $dome)
  [ ${#focus[@]} -gt 0 ] || [ $focus_top -eq 1 ] || focus=(0 0 $dome)
fi
if [ ${#focus[@]} -eq 0 ]; then
  focus=($(awk -v a="${box[0]}" -v b="${box[1]}" -v d="${box[3]}" -v e="${box[4]}" -v f="${box[5]}" \
    'BEGIN { printf "%.17g %.17g %.17g", (a + d) / 2, (b + e) / 2, f }'))
fi

if ! command -v gmsh >/dev/null; then
  if [ "$(id -u)" -eq 0 ]; then
    echo "make_mesh.sh: installing Debian's gmsh" >&2
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq gmsh >/dev/null
  else
    die "gmsh not found: sudo apt-get install -y gmsh"
  fi
fi

[ -z "$patch" ] || [ $focus_top -eq 1 ] || die "--patch goes with --focus-top"
# The depth below the top face (the skin of a dome), for --focus-top and --top-size.
if [ -n "$dome" ]; then
  depth="($dome - Sqrt(x^2 + y^2 + z^2))"
  top_name="the skin of the dome"
else
  depth="((${box[5]}) - z)"
  top_name="the top face z = ${box[5]}"
fi
if [ $focus_top -eq 1 ] && [ -n "$patch" ]; then
  distance="Sqrt(Max(Fabs(x - (${focus[0]})) - $patch, 0)^2 + Max(Fabs(y - (${focus[1]})) - $patch, 0)^2 + ((${box[5]}) - z)^2)"
  where="the top face within $patch m of (${focus[0]}, ${focus[1]})"
elif [ $focus_top -eq 1 ]; then
  distance=$depth
  where=$top_name
else
  distance="Sqrt((x - (${focus[0]}))^2 + (y - (${focus[1]}))^2 + (z - (${focus[2]}))^2)"
  where="(${focus[*]})"
fi
size="Min($h1, $h0 + ($growth - 1) * $distance)"
if [ -n "$top_size" ]; then
  [ $focus_top -eq 0 ] || [ -n "$patch" ] || die "--top-size goes with a focus point or a --patch"
  size="Min($size, $top_size + ($growth - 1) * $depth)"
  where="$where, at most $top_size m on $top_name"
fi
for r in "${refines[@]}"; do
  read -r rx ry rz rr rh <<< "$r"
  size="Min($size, $rh + ($growth - 1) * Max(Sqrt((x - ($rx))^2 + (y - ($ry))^2 + (z - ($rz))^2) - $rr, 0))"
  where="$where, at most $rh m within $rr m of ($rx, $ry, $rz)"
done

for l in "${lines[@]}"; do
  read -r ax ay bx by lh <<< "$l"
  # t: the parameter of the point of the segment nearest to (x, y), clamped to [0, 1].
  ll=$(awk -v a="$ax" -v b="$ay" -v c="$bx" -v d="$by" 'BEGIN { printf "%.17g", (c - a)^2 + (d - b)^2 }')
  if awk -v l="$ll" 'BEGIN { exit !(l > 0) }'; then
    t="Min(Max(((x - ($ax)) * (($bx) - ($ax)) + (y - ($ay)) * (($by) - ($ay))) / $ll, 0), 1)"
  else
    t="0"
  fi
  segment="Sqrt((x - ($ax) - $t * (($bx) - ($ax)))^2 + (y - ($ay) - $t * (($by) - ($ay)))^2 + ((${box[5]}) - z)^2)"
  size="Min($size, $lh + ($growth - 1) * $segment)"
  where="$where, at most $lh m along ($ax, $ay)-($bx, $by) on the top face"
done

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
geo=$work/box.geo
if [ -n "$dome" ]; then
  body="Sphere(1) = {0, 0, 0, $dome, 0, Pi / 2, 2 * Pi};
eps = 1e-3 * $dome;  // (OpenCASCADE's bounding boxes carry its tolerance: not tighter)
base() = Surface In BoundingBox{-$dome - eps, -$dome - eps, -eps, $dome + eps, $dome + eps, eps};
skin() = Abs(Boundary{ Volume{1}; });
skin() -= base();
Physical Surface(\"base\", 1) = {base()};
Physical Surface(\"skin\", 2) = {skin()};
Physical Volume(\"tissue\", 3) = {1};"
else
  body="Box(1) = {${box[0]}, ${box[1]}, ${box[2]}, ${box[3]} - (${box[0]}), ${box[4]} - (${box[1]}), ${box[5]} - (${box[2]})};"
fi
cat > "$geo" <<EOF
// Written by scripts/make_mesh.sh
SetFactory("OpenCASCADE");
$body
// Element size: h(r) = min(H1, H0 + (G - 1) r), r the distance to the focus (or the depth
// below the top face), with --top-size also at most H2 + (G - 1) x depth.
Field[1] = MathEval;
Field[1].F = "$size";
Background Field = 1;
Mesh.MeshSizeExtendFromBoundary = 0;
Mesh.MeshSizeFromPoints = 0;
Mesh.MeshSizeFromCurvature = 0;
Mesh.Algorithm = 6;      // Frontal-Delaunay on the faces
Mesh.Algorithm3D = 1;    // Delaunay
Mesh.Optimize = 1;
Mesh.ElementOrder = 1;
Mesh.RandomSeed = $seed;
Mesh.Binary = 0;
EOF

mkdir -p "$(dirname "$out")"
gmsh -3 -nt 1 -format "$format" -o "$out" "$geo" > "$work/gmsh.log" 2>&1 || { cat "$work/gmsh.log" >&2; die "gmsh failed"; }
grep -E "Warning|Error" "$work/gmsh.log" >&2 || true
if [ "$node_order" = morton ]; then
  # Each $Nodes block's (tag, coordinates) entries sorted by the Morton code of the position
  # in the box of all nodes (21 bits per axis); tags, blocks and elements unchanged, so the
  # mesh is the same and only the order of its nodes (the particles' numbering) changes.
  /usr/bin/python3 - "$out" <<'PY' || die "--node-order morton: could not rewrite $out"
import sys
path = sys.argv[1]
lines = open(path).read().split("\n")
start = lines.index("$Nodes")
end = lines.index("$EndNodes")
v41 = lines[lines.index("$MeshFormat") + 1].startswith("4")
def spread(v):
    code = 0
    for bit in range(21):
        code |= ((v >> bit) & 1) << (3 * bit)
    return code
blocks = []  # (header, [(tag line, coordinate line)])
if v41:
    k = start + 2
    while k < end:
        header = lines[k]
        count = int(header.split()[3])
        tags = lines[k + 1:k + 1 + count]
        coords = lines[k + 1 + count:k + 1 + 2 * count]
        blocks.append((header, list(zip(tags, coords))))
        k += 1 + 2 * count
else:
    blocks.append((None, [(l, None) for l in lines[start + 2:end]]))
def position(entry):
    tag, coords = entry
    values = (coords if coords is not None else tag.split(None, 1)[1]).split()
    return [float(v) for v in values[:3]]
points = [position(e) for _, entries in blocks for e in entries]
low = [min(p[c] for p in points) for c in range(3)]
span = [max(max(p[c] for p in points) - low[c], 1e-300) for c in range(3)]
def morton(entry):
    p = position(entry)
    q = [min(int((p[c] - low[c]) / span[c] * 2097151), 2097151) for c in range(3)]
    return spread(q[0]) | (spread(q[1]) << 1) | (spread(q[2]) << 2)
body = []
for header, entries in blocks:
    entries = sorted(entries, key=morton)
    if v41:
        body.append(header)
        body += [t for t, _ in entries]
        body += [c for _, c in entries]
    else:
        body += [t for t, _ in entries]
lines[start + 2:end] = body
open(path, "w").write("\n".join(lines))
PY
fi
nodes=$(awk '/^\$Nodes/ { getline; print (NF == 4 ? $2 : $1); exit }' "$out")
tets=$(grep -E "^Info *: .*tetrahedra" "$work/gmsh.log" | tail -1 | sed 's/^Info *: *//' || true)
echo "make_mesh.sh: $out: $nodes nodes; focus size $h0 m at $where, far size $h1 m, growth $growth, node order $node_order${tets:+; $tets}"
