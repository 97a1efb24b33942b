#!/usr/bin/env bash
# The palpation signal (docs/verification.md, "The lateral scan"): the force sweep of
# scenes/palpation_lump.json at sites along y = 0 across the lump (centre (0.01, 0, -0.01) m,
# radius 6 mm, 3x the matrix), each against the finite-block reference computed at that
# site (palpate-reference --site: the linear hex FEM on lattices graded toward the site,
# the lump blended per element, Richardson-extrapolated; stored in scenes/references/,
# recomputed with --references), and the same sweep of the homogeneous
# scenes/palpation_block.json (the tissue without the lump) for contrast.
# From each force-depth curve the force at a fixed depth D follows by interpolation
# (log F against log d, monotone): F(x) at depth D, the signal a palpating finger feels.
# Writes RAW/<scene>_<x>.json (palpate-verify --json), DIR/lateral_scan.csv (one row
# per site and force), DIR/lateral_scan.md (the tables) and DIR/lateral_scan.png.
#
# With --follow the scenes are palpation_lump_follow and palpation_block_follow (their
# clouds refined in-process at each site, docs/physics.md §7) against the same references,
# and a third run: palpation_lump_follow without its lump (--set material.inclusions=[]),
# the tissue without the lump on the lump scene's own cloud (raw name
# palpation_block_lump_cloud_follow), so that the signal is also the ratio of two runs of one
# cloud, whose discretisation errors cancel in it, against the references' ratio.
#
# usage: scripts/lateral_scan_study.sh [--references] [--follow] [--depth D] [--out DIR] [--raw RAW]
#   --references  recompute the references at every site (about a minute each)
#   --depth D     the fixed depth of the signal, m (default 0.0012)
#   --sites LIST  x of the sites, m, comma-separated (default -0.02,-0.015,...,0.02)
#   --follow      the refined-at-the-tool scenes (output default docs/verification/lateral_scan_follow)
#   --out DIR     output folder (default docs/verification/lateral_scan)
#   --raw RAW     the runs' JSON (default data/verification/lateral_scan, or _follow; with
#                 --out alone, DIR/raw, so that a trial run leaves the stored data alone)
# BUILD_DIR (default build) holds bin/palpate-verify and bin/palpate-reference; they are
# built there (Release) when stale, through scripts/build.sh.
# shellcheck source=SCRIPTDIR/lib/study_common.sh
source "$(dirname "$0")/lib/study_common.sh"

references=0
depth=0.0012
sites_list="-0.02,-0.015,-0.01,-0.005,0,0.005,0.01,0.015,0.02"
out=
raw=
suffix=
while [[ $# -gt 0 ]]; do
  case "$1" in
    --references) references=1 ;;
    --follow) suffix=_follow ;;
    --depth) depth=${2:?--depth needs a value in m}; shift ;;
    --sites) sites_list=${2:?--sites needs a list}; shift ;;
    --out) out=${2:?--out needs a folder}; shift ;;
    --raw) raw=${2:?--raw needs a folder}; shift ;;
    -h|--help) study_help ;;
    *) study_unknown_option "$1" ;;
  esac
  shift
done

[[ -n $out ]] || out=docs/verification/lateral_scan$suffix
# The runs' JSON (data/README.md): under data/ for an output under docs/, else DIR/raw.
[[ -n $raw ]] || { [[ $out == docs/* ]] && raw=data/${out#docs/} || raw=$out/raw; }
verify="$BUILD_DIR/bin/palpate-verify"
reference="$BUILD_DIR/bin/palpate-reference"
study_build palpate-verify palpate-reference
mkdir -p "$out" "$raw"
IFS=, read -r -a sites <<< "$sites_list"

# name:scene:physics (the reference's scene) of each run; the --set of a run by its name.
runs=("palpation_lump$suffix:palpation_lump$suffix:palpation_lump" "palpation_block$suffix:palpation_block$suffix:palpation_block")
[[ -n $suffix ]] && runs+=("palpation_block_lump_cloud$suffix:palpation_lump$suffix:palpation_block")
declare -A run_set=([palpation_block_lump_cloud$suffix]="material.inclusions=[]")
for x in "${sites[@]}"; do
  for run in "${runs[@]}"; do
    IFS=: read -r name scene physics <<< "$run"
    set_args=()
    [[ -n ${run_set[$name]:-} ]] && set_args=(--set "${run_set[$name]}")
    # The block's reference at the centre is stored already; off-centre ones are computed
    # like the lump's (the key names the site, so verify finds each by itself).
    file="scenes/references/${physics}_site_${x}_0.json"
    [[ $x == 0 ]] && file=scenes/references/$physics.json
    if [[ $references == 1 || ! -f "$file" ]]; then
      echo "lateral_scan_study.sh: palpate-reference --scene scenes/$physics.json --site $x,0" >&2
      start=$SECONDS
      "$reference" --scene "scenes/$physics.json" --site "$x,0" --out "$file" --quiet > /dev/null
      echo "lateral_scan_study.sh: reference of $physics at x = $x: $((SECONDS - start)) s" >&2
    fi
    echo "lateral_scan_study.sh: palpate-verify --scene scenes/$scene.json ${set_args[*]} --site $x,0" >&2
    start=$SECONDS
    "$verify" --scene "scenes/$scene.json" "${set_args[@]}" --site "$x,0" --reference "$file" --json --quiet \
      > "$raw/${name}_$x.json" || true
    echo "lateral_scan_study.sh: $name at x = $x: $((SECONDS - start)) s" >&2
  done
done

"$python" scripts/plot_lateral_scan.py "$out" "$depth" "$raw"
