#!/usr/bin/env bash
# Support study on the graded lattice (issue #6, item 3): k (neighbours) and the
# support radius rule/factor against the error vs the finite-cube reference at
# three forces of the sweep, the integration residual, the worst moment-matrix
# condition number and the largest stable symplectic-Euler step.
#
#   scripts/graded_support_study.sh [SCENE]    # default scenes/hertz_cube_graded.json
#
# Writes docs/verification/graded_supports.csv (BUILD_DIR, default build); about 3 min
# per cell on one core. Cells already in the CSV are kept and skipped, so an
# interrupted study resumes; FRESH=1 starts the CSV over.
# shellcheck source=SCRIPTDIR/lib/study_common.sh
source "$(dirname "$0")/lib/study_common.sh"
[[ ${1:-} == -h || ${1:-} == --help ]] && study_help
SCENE=${1:-scenes/hertz_cube_graded.json}
OUT=docs/verification/graded_supports.csv
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
HEADER="k,max_neighbors,support_rule,support_factor,particles,regularized,worst_condition,integration_residual,err_10N,err_115N,err_327N,l2_error_reference,dt_max_se_s"
if [[ ${FRESH:-0} == 1 || ! -s $OUT ]] || [[ $(head -1 "$OUT") != "$HEADER" ]]; then echo "$HEADER" > "$OUT"; fi
for rule in kth_distance mean_distance; do
  for k in 16 26 32; do
    for alpha in 1.05 1.3; do
      [[ $rule == mean_distance && $alpha == 1.05 ]] && alpha=1.5   # mean-distance supports need reach
      if grep -q "^$k,64,$rule,$alpha," "$OUT"; then echo "== k=$k rule=$rule alpha=$alpha: in $OUT" >&2; continue; fi
      set_args=(--set mls.neighbors=$k --set mls.max_neighbors=64 --set mls.support_rule=$rule --set mls.support_factor=$alpha)
      echo "== k=$k rule=$rule alpha=$alpha" >&2
      if ! "$BUILD_DIR/bin/palpate-verify" --scene "$SCENE" "${set_args[@]}" --forces 10.36,115.8,327.6 --json --quiet > "$TMP/v.json" 2> "$TMP/err"; then
        echo "   failed: $(tail -1 "$TMP/err")" >&2
      fi
      "$BUILD_DIR/bin/palpate-stable-dt" --scene "$SCENE" "${set_args[@]}" --json --quiet > "$TMP/s.json" 2>/dev/null || echo '{}' > "$TMP/s.json"
      "$python" - "$TMP/v.json" "$TMP/s.json" "$k" "$rule" "$alpha" >> "$OUT" <<'PY'
import json, sys
try: v = json.load(open(sys.argv[1]))
except Exception: v = {"rows": []}
try: s = json.load(open(sys.argv[2]))
except Exception: s = {}
err = {round(r["force"]): r.get("error_reference") for r in v.get("rows", [])}
f = lambda x: "" if x is None else f"{x:.5g}"
print(",".join([sys.argv[3], "64", sys.argv[4], sys.argv[5], f(v.get("particles")), f(v.get("regularized_particles")),
                f(v.get("worst_moment_condition")), f(v.get("integration_residual")), f(err.get(10)), f(err.get(116)),
                f(err.get(328)), f(v.get("l2_error_reference")), f(s.get("dt_max_stable_s"))]))
PY
      tail -1 "$OUT" >&2
    done
  done
done
