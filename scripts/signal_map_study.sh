#!/usr/bin/env bash
# The palpation signal over the palpable surface (issue #32, docs/verification/surface_map/
# method.md "The signal over the whole face"): the surface map (scripts/surface_map_study.sh)
# of a scene with a lump, the same map of the same scene without its inclusions (the tissue
# without the lump on the lump scene's own cloud, against the homogeneous block's references,
# reduced by the square's symmetry), and from the two the signal F(with) / F(without) at a
# fixed depth at every site, simulated and of the references (scripts/plot_signal_map.py).
# The map without the lump runs a copy of the scene with "material.inclusions" removed and
# the name NAME_without, written to a temporary folder beside links to the scene folder's
# meshes/ and references/.
#
# Writes (NAME = the scene's file name without .json), in DIR:
#   NAME.{csv,md,png}, NAME_rows.csv                   the map with the lump
#   NAME_without.{csv,md,png}, NAME_without_rows.csv   the map without it
#   NAME_signal.{csv,md,png}                           the signal at every site
# Time: the references as surface_map_study.sh says (with the lump, 24 besides a stored
# centre, 40-55 s each on 2 jobs; without, the block's octant sites, cached), then ~1 min.
#
# usage: scripts/signal_map_study.sh [options]
#   --scene FILE   the scene with the lump (default scenes/palpation_lump_follow.json)
#   --depth D      the fixed depth of the signal, m (default 0.0012)
#   --out DIR      output folder (default docs/verification/surface_map)
#   --raw RAW      the presses' JSON and the references' cache (surface_map_study.sh's --raw)
#   --jobs N       passed to surface_map_study.sh (default 2)
#   --set KEY=VALUE passed to surface_map_study.sh (repeatable; give --out)
# BUILD_DIR (default build) holds bin/palpate-verify and bin/palpate-reference (nothing is
# compiled). Paths are relative to the repository root.
# shellcheck source=SCRIPTDIR/lib/study_common.sh
source "$(dirname "$0")/lib/study_common.sh"

scene=scenes/palpation_lump_follow.json
depth=0.0012
out=docs/verification/surface_map
raw=
jobs=2
sets=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    --scene) scene=${2:?--scene needs a file}; shift ;;
    --depth) depth=${2:?--depth needs a value in m}; shift ;;
    --out) out=${2:?--out needs a folder}; shift ;;
    --raw) raw=${2:?--raw needs a folder}; shift ;;
    --jobs) jobs=${2:?--jobs needs a number}; shift ;;
    --set) sets+=(--set "${2:?--set needs KEY=VALUE}"); shift ;;
    -h|--help) study_help ;;
    *) study_unknown_option "$1" ;;
  esac
  shift
done
[[ -f $scene ]] || { echo "signal_map_study.sh: no scene $scene" >&2; exit 2; }
[[ -n $raw ]] || { [[ $out == docs/* ]] && raw=data/${out#docs/} || raw=$out/raw; }
name=$(basename "$scene" .json)
folder=$(cd "$(dirname "$scene")" && pwd)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

common=(--out "$out" --raw "$raw" --jobs "$jobs" "${sets[@]}")
scripts/surface_map_study.sh --scene "$scene" --no-symmetric "${common[@]}"

# The same scene without its inclusions, where its relative paths still resolve.
ln -s "$folder/meshes" "$tmp/meshes"
[[ -d $folder/references ]] && ln -s "$folder/references" "$tmp/references"
"$python" - "$scene" "$tmp/${name}_without.json" <<'PY'
import json, sys
scene = json.load(open(sys.argv[1]))
if not scene.get("material", {}).get("inclusions"):
    sys.exit("signal_map_study.sh: %s has no material.inclusions: no signal to map" % sys.argv[1])
del scene["material"]["inclusions"]
scene["name"] = scene.get("name", "scene") + "_without"
json.dump(scene, open(sys.argv[2], "w"), indent=1)
PY
scripts/surface_map_study.sh --scene "$tmp/${name}_without.json" --symmetric "${common[@]}"

"$python" scripts/plot_signal_map.py "$out/${name}_rows.csv" "$out/${name}_without_rows.csv" "$depth" \
  "$out/${name}_signal" --scene "$scene"
