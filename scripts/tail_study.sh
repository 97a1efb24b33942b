#!/usr/bin/env bash
# The real-time tail over many runs (issue #17 item 5): palpate-bench-server, --runs times
# for --seconds each, on the 18^3 default (hertz_cube, RK4, 1 kHz) and on the haptic scene
# (hertz_cube_haptic, 1 kHz), alternating; one JSON per run in --raw, then a table of
# every run's deadline misses (by cause), tick lateness p99, step p99 and the host's
# steal, and the median of each. A single run says little on a shared machine: its tail
# swings by ten times from run to run.
#
# usage: scripts/tail_study.sh [--runs N] [--seconds S] [--out DIR] [--raw RAW]
#   --runs N     runs per scene (default 10)
#   --seconds S  length of each run (default 60)
#   --out DIR    output folder (default docs/verification/tail)
#   --raw RAW    the runs' JSON (default data/verification/tail; with --out alone, DIR/raw)
# LOCK (optional): a file each run holds with flock(1) while it measures, so that builds
# that take the same lock wait (the project's helpers build through /tmp/palpate-build.lock).
# BUILD_DIR (default build) holds the programs; they are built there (Release) if missing.
# shellcheck source=SCRIPTDIR/lib/study_common.sh
source "$(dirname "$0")/lib/study_common.sh"

runs=10
seconds=60
out=docs/verification/tail
raw=
while [[ $# -gt 0 ]]; do
  case "$1" in
    --runs) runs=${2:?--runs needs a number}; shift ;;
    --seconds) seconds=${2:?--seconds needs a number}; shift ;;
    --out) out=${2:?--out needs a folder}; shift ;;
    --raw) raw=${2:?--raw needs a folder}; shift ;;
    -h|--help) study_help ;;
    *) study_unknown_option "$1" ;;
  esac
  shift
done

# The runs' JSON (data/README.md): under data/ for an output under docs/, else DIR/raw.
[[ -n $raw ]] || { [[ $out == docs/* ]] && raw=data/${out#docs/} || raw=$out/raw; }
build=$BUILD_DIR
study_build palpate-server palpate-bench-server
mkdir -p "$out" "$raw"
measure() {  # output file, then the benchmark's arguments
  local file=$1
  shift
  if [[ -n "${LOCK:-}" ]]; then
    flock "$LOCK" "$build/bin/palpate-bench-server" "$@" --json > "$file"
  else
    "$build/bin/palpate-bench-server" "$@" --json > "$file"
  fi
}
for ((k = 1; k <= runs; ++k)); do
  for scene in hertz_cube hertz_cube_haptic; do
    echo "== $scene run $k of $runs ($seconds s)" >&2
    measure "$raw/${scene}_$k.json" --scene "scenes/$scene.json" --seconds "$seconds"
  done
done
"$python" - "$out" "$raw" <<'PY'
import glob, json, os, re, statistics, sys
folder, raw = sys.argv[1], sys.argv[2]
lines = ["| scene | run | ticks | misses (%) | late starts / long steps | skipped | lateness p99 (us) | step p50 / p99 (us) | steal (s) |",
         "|---|---:|---:|---:|---|---:|---:|---|---:|"]
for scene in ("hertz_cube", "hertz_cube_haptic"):
    rows = []
    for path in glob.glob(os.path.join(raw, "*.json")):
        m = re.fullmatch(re.escape(scene) + r"_(\d+)\.json", os.path.basename(path))
        if not m:
            continue
        with open(path) as f:
            d = json.load(f)
        rows.append((int(m.group(1)), d))
    rows.sort(key=lambda r: r[0])
    for k, d in rows:
        lines.append(f"| {scene} | {k} | {d['ticks']} | {d['deadline_misses']} ({100 * d['deadline_miss_ratio']:.2f}) | "
                     f"{d['misses_late_start']} / {d['misses_long_step']} | {d['skipped_ticks']} | "
                     f"{d['lateness_p99_us']:.0f} | {d['step_p50_us']:.0f} / {d['step_p99_us']:.0f} | {d['host_steal_s']:.2f} |")
    if rows:
        med = lambda key: statistics.median(d[key] for _, d in rows)
        lines.append(f"| {scene} | median | {med('ticks'):.0f} | {med('deadline_misses'):.0f} "
                     f"({100 * med('deadline_miss_ratio'):.2f}) | {med('misses_late_start'):.0f} / "
                     f"{med('misses_long_step'):.0f} | {med('skipped_ticks'):.0f} | {med('lateness_p99_us'):.0f} | "
                     f"{med('step_p50_us'):.0f} / {med('step_p99_us'):.0f} | {med('host_steal_s'):.2f} |")
with open(os.path.join(folder, "tail.md"), "w") as f:
    f.write("\n".join(lines) + "\n")
print("\n".join(lines))
PY
