#!/usr/bin/env bash
# The verification study of docs/verification.md: Hertz indentation sweeps
# (palpate-verify --json), stable time steps (palpate-stable-dt --json) and step
# timings (palpate-bench-step --json) over
#   a. resolution      MLS (the default scene: kernel volumes, k = 16, alpha = 1, RK4 at
#                      1 ms) on uniform lattices 10 ... 34 per edge; also symplectic Euler
#                      at 1 ms and implicit Euler at 10 ms at most of them
#   g. hex FEM         linear, exact static solve, 10 ... 34 per edge; linear and
#                      corotational, implicit Euler at 10 ms (dynamic settle), 10 ... 18
#   h. fixed force     indentation at 82.88 and 152.3 N against the particle count,
#                      MLS 8 ... 38 per edge, linear FEM (static) 8 ... 50 per edge
#   i. run time        palpate-bench-step per model and resolution (step times)
#   b. volumes         kernel (A-2, A-3) against lattice volumes at 14^3 and 18^3
#   c. k and alpha     neighbours x support factor at 14^3, reduced force list
#   d. hourglass       mls.hourglass 0 ... 0.5 at 18^3, reduced force list
#   e. integrators     rk4, symplectic_euler, implicit_euler at 18^3
#   f. strain level    the same contact radii with R = 5 m (strains ten times smaller)
#   and what limits the stable step (force, indenter mass)
# Errors are against plain Hertz, the finite-layer Hertz and the finite-block
# reference (scenes/references/hertz_cube.json, found by palpate-verify).
# Then scripts/plot_verification.py turns the JSON into CSV tables, PNG plots and
# Markdown tables. Runs one job at a time (single thread); the full study takes
# about 45 minutes on a 2-core AMD EPYC, --quick about two.
#
# usage: scripts/verification_study.sh [--quick] [--out DIR] [--raw DIR]
#   --quick    a small subset (a minute or two), to check the pipeline
#   --out DIR  tables, plots and tables.md (default docs/verification)
#   --raw DIR  every run's JSON, in STUDY/ subfolders, and their list runs.tsv
#              (default data/verification; with --out alone, DIR/raw, so that a trial
#              run elsewhere leaves the stored data alone)
# BUILD_DIR (default build) holds bin/palpate-verify, bin/palpate-stable-dt and
# bin/palpate-bench-step; they are built there (Release) if missing.
# shellcheck source=SCRIPTDIR/lib/study_common.sh
source "$(dirname "$0")/lib/study_common.sh"
set +e  # a failed run is recorded in runs.tsv and the study goes on

quick=0
out=docs/verification
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

if [[ -z $raw ]]; then
  if [[ ${out%/} == docs/verification ]]; then raw=data/verification; else raw=$out/raw; fi
fi

verify="$BUILD_DIR/bin/palpate-verify"
stable_dt="$BUILD_DIR/bin/palpate-stable-dt"
bench="$BUILD_DIR/bin/palpate-bench-step"
scene=scenes/hertz_cube.json        # MLS
fem_scene=scenes/hertz_cube_fem.json  # hex FEM, same block, material, indenter and reference

echo "== building palpate-verify, palpate-stable-dt and palpate-bench-step (Release) in $BUILD_DIR, if stale" >&2
study_build palpate-verify palpate-stable-dt palpate-bench-step || exit 1

mkdir -p "$out" "$raw"
manifest="$raw/runs.tsv"
printf 'study\tlabel\tkind\tfile\texit\twall_s\targs\tscene\n' >"$manifest"
started=$(date +%s)

log() { printf '[%5ds] %s\n' "$(($(date +%s) - started))" "$*" >&2; }

# run STUDY LABEL KIND ARGS...: one palpate-verify (KIND=verify), palpate-stable-dt
# (KIND=stable, or stable_body for the body's own limit measured with a 100 kg indenter)
# or palpate-bench-step (KIND=bench) run on the scene with ARGS, JSON to
# $raw/STUDY/LABEL.KIND.json (runs.tsv lists it relative to $raw). The scene is $scene
# unless run_scene=FILE is set for the call.
run() {
  local study=$1 label=$2 kind=$3
  shift 3
  local file="$study/$label.$kind.json" exe quiet=(--quiet) scene_file=${run_scene:-$scene}
  mkdir -p "$raw/$study"
  case $kind in
    verify) exe=$verify ;;
    bench) exe=$bench; quiet=() ;;
    *) exe=$stable_dt ;;
  esac
  [[ $kind == stable_body ]] && set -- "$@" --set indenter.mass=100
  local t0 t1 code
  t0=$(date +%s.%N)
  "$exe" --scene "$scene_file" --json "${quiet[@]}" "$@" >"$raw/$file"
  code=$?
  t1=$(date +%s.%N)
  local wall
  wall=$(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.2f", b - a }')
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$study" "$label" "$kind" "$file" "$code" "$wall" "$*" "$scene_file" >>"$manifest"
  log "$study/$label $kind: exit $code, ${wall} s"
}

fixed_forces=82.88,152.3  # section h
if ((quick)); then
  resolutions=(10 14)
  forces=10.36,82.88,327.6
  se_resolutions=(10); ie_resolutions=(10)
  fem_resolutions=(10 14); fem_dynamic_resolutions=(10)
  mls_fixed=(8 9 12); fem_fixed=(8 9 12 16)
  bench_resolutions=(10); fem_bench_resolutions=(10)
  bench_repeats=30; ka_max_time=10
  limit_cases=(327.6:1)  volume_resolutions=(10)
  ka_edge=10; ka_k=(10 18); ka_alpha=(1.0 2.0)
  ka_forces=53.83,279.7
  hg_edge=10; hg_values=(0 0.1); hg_forces=$forces
  int_edge=10
  strain_resolutions=(10)
  small_strain_forces=1.036,8.288,32.76
else
  resolutions=(10 14 18 22 26 30 34)
  forces=  # the scene's sweep: Hertz depths 0.01 ... 0.1 m
  # symplectic / implicit Euler sweeps for the run time against error (18^3 is section e)
  se_resolutions=(10 14 22 26 30 34); ie_resolutions=(10 14 22 26)
  fem_resolutions=(10 14 18 22 26 30 34); fem_dynamic_resolutions=(10 14 18)
  # section h: the resolutions of sections a and g are reused
  mls_fixed=(8 9 12 13 16 17 20 21 24 25 28 29 32 33 36 37 38); fem_fixed=(8 9 12 13 16 17 20 21 24 25 28 29 33 38 42 46 50)
  bench_resolutions=(10 14 18 22 26 30 34); fem_bench_resolutions=(10 14 18 22 26 30 34)
  bench_repeats=100  # 300 (the tool's default) for the 18^3 comparison with the paper
  ka_max_time=10     # simulated seconds per force before "not at rest" (was 20: trimmed for time)
  limit_cases=(327.6:1 327.6:100)  volume_resolutions=(14 18)
  ka_edge=14; ka_k=(6 10 16 18 26); ka_alpha=(1.0 1.2 1.5 2.0 3.0)
  ka_forces=53.83,152.3,279.7
  # hourglass control makes a step ~10x dearer: every other force of the sweep
  hg_edge=18; hg_values=(0 0.02 0.1 0.5); hg_forces=10.36,53.83,115.8,191.9,279.7
  int_edge=18
  strain_resolutions=(18 26 34)
  small_strain_forces=1.036,2.930,5.383,8.288,11.58,15.23,19.19,23.44,27.97,32.76
fi
sweep=()
[[ -n $forces ]] && sweep=(--forces "$forces")

log "study in $out ($([[ $quick == 1 ]] && echo quick || echo full)), $verify, $stable_dt, $bench"

# i. Step times first, while the machine is as quiet as it will be: one palpate-bench-step
# per model and resolution (RK4 and symplectic Euler at the scene's dt = 1 ms, implicit
# Euler at 10 ms). The 18^3 runs are the comparison with the paper (tool defaults: 300
# repetitions, 10 of the implicit step).
for n in "${bench_resolutions[@]}"; do
  reps=(--repeats "$bench_repeats" --ie-repeats 5)
  [[ $n == 18 ]] && reps=()
  run bench "mls_n$n" bench --per-edge "$n" --ie-dt 0.01 "${reps[@]}"
done
for n in "${fem_bench_resolutions[@]}"; do
  reps=(--repeats "$bench_repeats" --ie-repeats 5)
  [[ $n == 18 ]] && reps=()
  run_scene=$fem_scene run bench "fem_linear_n$n" bench --per-edge "$n" --ie-dt 0.01 --set integrator.dt=0.001 "${reps[@]}"
done
for n in "${fem_dynamic_resolutions[@]}"; do
  run_scene=$fem_scene run bench "fem_corotational_n$n" bench --per-edge "$n" --ie-dt 0.01 --set integrator.dt=0.001 \
    --set hex_fem.formulation=corotational --repeats "$bench_repeats" --ie-repeats 5
done

# a. Resolution: the default scene (kernel volumes, k = 16, alpha = 1, RK4 at 1 ms).
for n in "${resolutions[@]}"; do
  run resolution "n$n" verify --per-edge "$n" "${sweep[@]}"
  run resolution "n$n" stable --set "body.distribution.per_edge=$n"
done
# The same sweep with the cheaper integrators (18^3: section e).
for n in "${se_resolutions[@]}"; do
  run mls_integrators "symplectic_euler_dt0.001_n$n" verify --per-edge "$n" "${sweep[@]}" \
    --set integrator.type=symplectic_euler --set integrator.dt=0.001
done
for n in "${ie_resolutions[@]}"; do
  run mls_integrators "implicit_euler_dt0.01_n$n" verify --per-edge "$n" "${sweep[@]}" \
    --set integrator.type=implicit_euler --set integrator.dt=0.01
done

# g. Hexahedral FEM by resolution: the linear FEM by the exact static solve, and the
# dynamic settle with implicit Euler at 10 ms of the linear and the corotational FEM.
for n in "${fem_resolutions[@]}"; do
  run_scene=$fem_scene run fem "linear_static_n$n" verify --per-edge "$n" --solve static "${sweep[@]}"
done
for n in "${fem_dynamic_resolutions[@]}"; do
  run_scene=$fem_scene run fem "linear_implicit_euler_dt0.01_n$n" verify --per-edge "$n" "${sweep[@]}"
  run_scene=$fem_scene run fem "corotational_implicit_euler_dt0.01_n$n" verify --per-edge "$n" "${sweep[@]}" \
    --set hex_fem.formulation=corotational
done

# h. Indentation at fixed forces against the particle count (both parities: with an odd
# count per edge a particle sits under the sphere's axis, with an even count four).
for n in "${mls_fixed[@]}"; do
  run fixed_force "mls_n$n" verify --per-edge "$n" --forces "$fixed_forces"
done
for n in "${fem_fixed[@]}"; do
  run_scene=$fem_scene run fixed_force "fem_linear_static_n$n" verify --per-edge "$n" --solve static --forces "$fixed_forces"
done

# b. Volumes: kernel sums (A-2, A-3) against lattice cell volumes.
for n in "${volume_resolutions[@]}"; do
  for v in kernel lattice; do
    run volumes "n${n}_$v" verify --per-edge "$n" --set "mls.volumes=$v" "${sweep[@]}"
    run volumes "n${n}_$v" stable --set "body.distribution.per_edge=$n" --set "mls.volumes=$v"
  done
done

# c. k and alpha, reduced sweep, at most ka_max_time s of simulated time per force.
last_force=${ka_forces##*,}
for k in "${ka_k[@]}"; do
  for a in "${ka_alpha[@]}"; do
    common=(--set "body.distribution.per_edge=$ka_edge" --set "mls.neighbors=$k" --set "mls.support_factor=$a")
    run k_alpha "k${k}_a$a" verify "${common[@]}" --forces "$ka_forces" --set "verify.rest.max_time=$ka_max_time"
    run k_alpha "k${k}_a$a" stable "${common[@]}" --force "$last_force"
  done
done

# d. Hourglass control (RK4, 1 ms).
for h in "${hg_values[@]}"; do
  common=(--set "body.distribution.per_edge=$hg_edge" --set "mls.hourglass=$h")
  run hourglass "h$h" verify "${common[@]}" --forces "$hg_forces"
  run hourglass "h$h" stable "${common[@]}"
done

# e. Integrators: the paper's RK4 at 1 ms, explicit steps at 10 ms, implicit Euler at 10 ms.
for spec in rk4:0.001 rk4:0.01 symplectic_euler:0.001 symplectic_euler:0.01 implicit_euler:0.01; do
  type=${spec%%:*} dt=${spec##*:}
  common=(--set "body.distribution.per_edge=$int_edge" --set "integrator.type=$type" --set "integrator.dt=$dt")
  run integrators "${type}_dt$dt" verify "${common[@]}" "${sweep[@]}"
  # The stable step depends on the integrator, not on the dt the search starts from: once per type.
  if [[ $type == implicit_euler || $dt == 0.001 ]]; then
    run integrators "${type}_dt$dt" stable "${common[@]}"
  fi
done

# f. Strain level: the same contact radii a = sqrt(R d) (so the same a / spacing and a / L)
# with a sphere ten times larger, R = 5 m, and a tenth of the force: strains ~ a / R ten times
# smaller. What changes between the two is material and geometric nonlinearity, not resolution.
for n in "${strain_resolutions[@]}"; do
  run strain "n${n}_R5" verify --per-edge "$n" --set indenter.radius=5 --forces "$small_strain_forces"
done

# What limits the stable step: the body (wave speed over spacing) or the indenter-contact
# loop (a 1 kg sphere on the contact stiffness, which grows with the force)? The stable_body
# runs above answer it for the body alone: the same search with a 100 kg indenter.
for type in rk4 symplectic_euler implicit_euler; do
  for case in "${limit_cases[@]}"; do
    f=${case%%:*} m=${case##*:}
    run dt_limits "${type}_F${f}_M$m" stable --set "body.distribution.per_edge=$int_edge" \
      --set "integrator.type=$type" --set integrator.dt=0.001 --set "indenter.mass=$m" --force "$f"
  done
done

log "tables and plots"
"$python" scripts/plot_verification.py "$out" "$raw" || exit 1
{
  echo "date: $(date -u '+%Y-%m-%d %H:%M UTC')"
  echo "mode: $([[ $quick == 1 ]] && echo quick || echo full)"
  echo "git: $(git rev-parse --short HEAD 2>/dev/null) (working tree $(git status --porcelain 2>/dev/null | wc -l) changed files)"
  echo "core sources (cat core/*.h core/*.cpp | sha1sum): $(cat core/*.h core/*.cpp | sha1sum | cut -c1-12)"
  echo "binaries: $(ls -l --time-style='+%Y-%m-%d %H:%M' "$verify" "$stable_dt" "$bench" | awk '{print $6, $7, $8}' | paste -sd';')"
  echo "load average at the end: $(cut -d' ' -f1-3 /proc/loadavg) (other jobs on the machine slow the timings)"
  echo "total wall: $(($(date +%s) - started)) s"
  lscpu | head -20
} >"$out/machine.txt"
log "done: $out/tables.md, $out/*.csv, $out/*.png"
