#!/usr/bin/env bash
# The multirate verification (docs/verification.md, "Multirate haptics"; bench/multirate_study.h):
# the force a device gets along the palpation path when the full model steps at 4 ms and
# the server renders at 1 kHz from the newest step's local model, against the same scene
# stepped at 1 ms, and against the zero-order hold of the 4 ms steps' forces.
# palpate-bench-multirate writes a CSV (DIR) and a JSON (RAW) per scene; scripts/plot_multirate.py
# draws the forces and the errors over the path (PNG).
#
# usage: scripts/multirate_study.sh [--quick] [--out DIR] [--raw RAW]
#   --quick    the 8^3 cube of tests/multirate_test.cpp only (seconds)
#   --out DIR  output folder (default docs/verification/multirate)
#   --raw RAW  the runs' JSON (default data/verification/multirate; with --out alone, DIR/raw)
# BUILD_DIR (default build) holds bin/palpate-bench-multirate; it is built there if missing.
# The full study (the graded 9261-particle cube at its own 4 ms, and the haptic scene run
# at 4 ms) takes about ten minutes on one core: most of it is the contact stiffness of
# every coarse step, which a headless run computes at every step.
# shellcheck source=SCRIPTDIR/lib/study_common.sh
source "$(dirname "$0")/lib/study_common.sh"

quick=0
out=docs/verification/multirate
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
study_build palpate-bench-multirate
bin="$BUILD_DIR/bin/palpate-bench-multirate"
mkdir -p "$out" "$raw"

run() {  # name, then the program's arguments
  local name=$1
  shift
  echo "== $name" >&2
  "$bin" "$@" --csv "$out/$name.csv" --json > "$raw/$name.json"
}

if (( quick )); then
  run cube8 --scene scenes/hertz_cube.json --set body.distribution.per_edge=8 \
    --set integrator.type=symplectic_euler --model-dt 0.004 --seconds 12
else
  run graded --scene scenes/hertz_cube_graded.json --seconds 12
  run haptic_at_4ms --scene scenes/hertz_cube_haptic.json --model-dt 0.004 --seconds 12
fi
"$python" scripts/plot_multirate.py "$out" "$raw"
