#!/usr/bin/env bash
# Support study on the tetrahedralisation cloud (docs/verification.md, "Tetrahedralisation
# clouds"): scenes/hertz_cube_tet.json with k in {16, 20, 26, 32}, support_factor in
# {1.05, 1.2, 1.5}, support_rule kth_distance and mean_distance, each with nodal and
# consistent integration, at three forces of the sweep; every run's palpate-verify
# JSON goes to RAW/tet_cloud/, one CSV row per run to OUT/tet_cloud_study.csv.
#
#   scripts/tet_cloud_study.sh [--build DIR] [--out DIR] [--raw DIR] [--forces F1,F2,...] [--dt SECONDS]
#                              [--solve dynamic|static]
#
# Defaults: build-mesh (or $BUILD_DIR), docs/verification, RAW data/verification (with
# --out alone, OUT/raw), 10.36,82.88,279.7 N, the
# dynamic settle (RK4, damping 10 1/s) at dt = 5 ms (the rest states equal those at the
# scene's 1 ms to 5 digits; the quasi-static solve of the MLS takes minutes per force
# here). One job at a time, single thread: ~15 min on the shared 2-core machine.
BUILD_DIR=${BUILD_DIR:-build-mesh}  # this study's own default (before the common preamble)
# shellcheck source=SCRIPTDIR/lib/study_common.sh
source "$(dirname "$0")/lib/study_common.sh"
build=$BUILD_DIR
out=docs/verification
raw_root=
forces=10.36,82.88,279.7
dt=0.005
solve=dynamic
while [ $# -gt 0 ]; do
  case "$1" in
    --build) build=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --raw) raw_root=$2; shift 2 ;;
    --forces) forces=$2; shift 2 ;;
    --dt) dt=$2; shift 2 ;;
    --solve) solve=$2; shift 2 ;;
    -h|--help) study_help ;;
    *) study_unknown_option "$1" ;;
  esac
done
verify=$build/bin/palpate-verify
study_require "$verify"
if [ -z "$raw_root" ]; then
  if [ "${out%/}" = docs/verification ]; then raw_root=data/verification; else raw_root=$out/raw; fi
fi
raw=$raw_root/tet_cloud
mkdir -p "$raw" "$out"
csv=$out/tet_cloud_study.csv

echo "rule,k,alpha,integration,particles,worst_cond,regularized,residual_nodal,residual,total_volume,box_volume,forces,err_ref,l2_ref,l2_hertz,steps,wall_s,all_at_rest" > "$csv"
for rule in kth_distance mean_distance; do
  for k in 16 20 26 32; do
    for alpha in 1.05 1.2 1.5; do
      for integration in consistent nodal; do
        label=${rule}_k${k}_a${alpha}_${integration}
        start=$(date +%s.%N)
        "$verify" --scene scenes/hertz_cube_tet.json --solve "$solve" --forces "$forces" --json --quiet \
          --set mls.support_rule=$rule --set mls.neighbors=$k --set mls.support_factor=$alpha \
          --set mls.integration=$integration --set integrator.dt=$dt > "$raw/$label.json" || true
        end=$(date +%s.%N)
        "$python" - "$raw/$label.json" "$rule" "$k" "$alpha" "$integration" "$start" "$end" >> "$csv" <<'EOF'
import json, sys
path, rule, k, alpha, integration, start, end = sys.argv[1:]
try:
    d = json.load(open(path))
except Exception:
    print(f"{rule},{k},{alpha},{integration},,,,,,,,,,,,,{float(end) - float(start):.1f},failed")
    sys.exit()
rows = d["rows"]
f = lambda x: "" if x is None else f"{x:.6g}"
print(",".join([rule, k, alpha, integration, str(d["particles"]), f(d["worst_moment_condition"]),
                str(d["regularized_particles"]), f(d["integration_residual_nodal"]), f(d["integration_residual"]),
                f(d["total_volume"]), f(d["box_volume"]),
                " ".join(f"{r['force']:g}" for r in rows),
                " ".join(f(r["error_reference"]) for r in rows),
                f(d["l2_error_reference"]), f(d["l2_error_hertz"]),
                str(sum(r["steps"] for r in rows)), f"{float(end) - float(start):.1f}",
                str(d["all_at_rest"]).lower()]))
EOF
        tail -1 "$csv"
      done
    done
  done
done
