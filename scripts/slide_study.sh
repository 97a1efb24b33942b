#!/usr/bin/env bash
# The sliding study (docs/physics.md §4, "The sliding test"; tools/sliding.h): the tool,
# free, pressed with a constant normal force and dragged across the middle of the top
# face by the virtual coupling (a target moving at v along x, its z following the tool)
# at speeds decades apart; palpate-slide prints |mean F_x| / |mean F_z| of the contact
# force over the window x in [-0.1, 0.1] m and the depth at the middle against the static
# indentation there. Then scripts/plot_slide.py draws the ratio and the depth error
# against the speed (PNG).
#
# usage: scripts/slide_study.sh [--quick] [--out DIR] [--raw RAW]
#   --quick    the coarse 8^3 scene of tests/sliding_test.cpp only (seconds)
#   --out DIR  output folder (default docs/verification/sliding)
#   --raw RAW  the runs' JSON (default data/verification/sliding; with --out alone, DIR/raw)
# BUILD_DIR (default build) holds bin/palpate-slide; it is built there (Release) if missing.
# The full study (the haptic scene and the paper's 18^3 scene, 1 m/s ... 1 mm/s at 82.88 N)
# takes about five minutes on one core.
# shellcheck source=SCRIPTDIR/lib/study_common.sh
source "$(dirname "$0")/lib/study_common.sh"

quick=0
out=docs/verification/sliding
raw=
while [[ $# -gt 0 ]]; do
  case "$1" in
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
slide="$BUILD_DIR/bin/palpate-slide"
study_build palpate-slide
mkdir -p "$out" "$raw"
force=82.88
speeds=1,0.1,0.01,0.001

run() {  # name, then palpate-slide arguments
  local name=$1; shift
  echo "slide_study.sh: $name" >&2
  "$slide" "$@" --force "$force" --speeds "$speeds" --json --csv "$out/$name.csv" > "$raw/$name.json"
}

if [[ $quick == 1 ]]; then
  run coarse_8 --scene scenes/hertz_cube.json --per-edge 8 --set integrator.type=symplectic_euler
else
  run haptic --scene scenes/hertz_cube_haptic.json
  run uniform_18 --scene scenes/hertz_cube.json
fi
"$python" scripts/plot_slide.py "$out" "$raw"
