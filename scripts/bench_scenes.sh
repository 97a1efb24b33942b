#!/usr/bin/env bash
# Step cost of every default scene in one run (issue #6: the graded scenes against
# the uniform 18^3): palpate-bench-step on each scene, one after the other on the
# same build and machine, then one table (medians; ms per step; the ratio to the
# uniform MLS scene; whether a step fits the 1 kHz budget of 1 ms; the force evaluation
# in ns per weighted neighbour pair and as a fraction of the core's double-precision FMA
# peak, measured in the same run by palpate-bench-step, and the floor its pair loop's
# memory work sets).
#
#   scripts/bench_scenes.sh [--repeats N] [SCENE ...]   # default: scenes/hertz_cube*.json
#
# Environment: BUILD_DIR (default build). Writes the raw JSON lines to
# $BUILD_DIR/bench_scenes.jsonl. Timing on a shared machine is noisy: compare
# within one run.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${BUILD_DIR:-build}
REPEATS=100
if [[ "${1:-}" == "--repeats" ]]; then REPEATS=$2; shift 2; fi
SCENES=("$@")
[[ ${#SCENES[@]} -gt 0 ]] || SCENES=(scenes/hertz_cube.json scenes/hertz_cube_haptic.json scenes/hertz_cube_graded.json scenes/hertz_cube_tet.json
                                      scenes/hertz_cube_fem.json scenes/hertz_cube_graded_fem.json)
OUT="$BUILD_DIR/bench_scenes.jsonl"
: > "$OUT"
for scene in "${SCENES[@]}"; do
  [[ -f "$scene" ]] || { echo "bench_scenes: no scene $scene" >&2; exit 2; }
  echo "== $scene" >&2
  "$BUILD_DIR/bin/palpate-bench-step" --scene "$scene" --repeats "$REPEATS" --ie-repeats 3 --json |
    /usr/bin/python3 -c 'import json,sys; d=json.load(sys.stdin); d["scene_file"]=sys.argv[1]; print(json.dumps(d))' "$scene" >> "$OUT"
done
/usr/bin/python3 - "$OUT" <<'PY'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
base = next((r for r in rows if r["scene_file"].endswith("/hertz_cube.json")), rows[0])
print(f"{'scene':36} {'model':8} {'particles':>9} {'RK4 ms':>8} {'SE ms':>8} {'IE ms':>9} {'force ms':>9} {'ns/pair':>8} {'% peak':>7} {'floor ns/pair':>14} {'ceiling':>8} {'RK4/uniform':>12} {'1 kHz with':>12}")
def opt(r, key, scale, fmt):
    v = r.get(key)
    return format(v * scale, fmt) if v is not None else "-"
for r in rows:
    fits = [name for name, key in (("RK4", "rk4_step_ms"), ("SE", "symplectic_euler_step_ms")) if r[key] < 1.0]
    print(f"{r['scene_file']:36} {r['model']:8} {r['particles']:>9} {r['rk4_step_ms']:8.3f} {r['symplectic_euler_step_ms']:8.3f} "
          f"{r['implicit_euler_step_ms']:9.2f} {r['force_eval_ms']:9.3f} {opt(r, 'force_eval_ns_per_pair', 1, '.2f'):>8} "
          f"{opt(r, 'force_eval_fraction_of_peak', 100, '.0f'):>7} {opt(r, 'pair_loop_floor_ns_per_pair', 1, '.2f'):>14} "
          f"{opt(r, 'force_eval_ceiling_fraction_of_peak', 100, '.0f'):>8} {r['rk4_step_ms'] / base['rk4_step_ms']:12.2f} "
          f"{', '.join(fits) or 'neither':>12}")
peaks = [r["peak_double_gflops"] for r in rows if r.get("peak_double_gflops")]
if peaks:
    print(f"\nFMA peak of one core (AVX2, double), measured with each scene: {min(peaks):.1f} ... {max(peaks):.1f} GFLOP/s")
print("medians of one run, single thread; implicit Euler at dt = 0.01 s (3 repetitions); health checks included")
print("floor: the force loop's gathers, F and scatters alone (P = F); ceiling: the % of peak the evaluation's flops reach at the floor's time")
PY
