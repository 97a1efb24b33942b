#!/usr/bin/env bash
# The verification study of docs/verification.md: Hertz indentation sweeps
# (palpate-verify --json) and stable time steps (palpate-stable-dt --json) over
#   a. resolution      uniform lattices 10 ... 34 per edge
#   b. volumes         kernel (A-2, A-3) against lattice volumes at 14^3 and 18^3
#   c. k and alpha     neighbours x support factor at 14^3, reduced force list
#   d. hourglass       mls.hourglass 0 ... 0.5 at 18^3
#   e. integrators     rk4, symplectic_euler, implicit_euler at 18^3
#   f. strain level    the same contact radii with R = 5 m (strains ten times smaller)
#   and what limits the stable step (force, indenter mass)
# then scripts/plot_verification.py turns the JSON into CSV tables, PNG plots and
# Markdown tables. Runs one job at a time (single core).
#
# usage: scripts/verification_study.sh [--quick] [--out DIR]
#   --quick    a small subset (a minute or two), to check the pipeline
#   --out DIR  output folder (default docs/verification); raw JSON goes to DIR/raw
# BUILD_DIR (default build) holds bin/palpate-verify and bin/palpate-stable-dt;
# they are built there (Release) if missing.
set -uo pipefail
cd "$(dirname "$0")/.."

quick=0
out=docs/verification
while [[ $# -gt 0 ]]; do
  case "$1" in
    --quick) quick=1 ;;
    --out) out=${2:?--out needs a folder}; shift ;;
    -h|--help) sed -n '2,/^set /p' "$0" | grep '^#' | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "verification_study.sh: unknown option '$1'" >&2; exit 2 ;;
  esac
  shift
done

BUILD_DIR=${BUILD_DIR:-build}
verify="$BUILD_DIR/bin/palpate-verify"
stable_dt="$BUILD_DIR/bin/palpate-stable-dt"
python=/usr/bin/python3  # Debian's, which sees python3-numpy and python3-matplotlib
scene=scenes/hertz_cube.json

if [[ ! -x "$verify" || ! -x "$stable_dt" ]]; then
  echo "== building palpate-verify and palpate-stable-dt (Release) in $BUILD_DIR" >&2
  cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release >/dev/null &&
    cmake --build "$BUILD_DIR" -j1 --target palpate-verify palpate-stable-dt >/dev/null || exit 1
fi

mkdir -p "$out/raw"
manifest="$out/raw/runs.tsv"
printf 'study\tlabel\tkind\tfile\texit\twall_s\targs\n' >"$manifest"
started=$(date +%s)

log() { printf '[%5ds] %s\n' "$(($(date +%s) - started))" "$*" >&2; }

# run STUDY LABEL KIND ARGS...: one palpate-verify (KIND=verify) or palpate-stable-dt
# (KIND=stable, or stable_body for the body's own limit measured with a 100 kg indenter)
# run on the scene with ARGS, JSON to raw/STUDY/LABEL.KIND.json.
run() {
  local study=$1 label=$2 kind=$3
  shift 3
  local file="raw/$study/$label.$kind.json" exe
  mkdir -p "$out/raw/$study"
  if [[ $kind == verify ]]; then exe=$verify; else exe=$stable_dt; fi
  [[ $kind == stable_body ]] && set -- "$@" --set indenter.mass=100
  local t0 t1 code
  t0=$(date +%s.%N)
  "$exe" --scene "$scene" --json --quiet "$@" >"$out/$file"
  code=$?
  t1=$(date +%s.%N)
  local wall
  wall=$(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.2f", b - a }')
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$study" "$label" "$kind" "$file" "$code" "$wall" "$*" >>"$manifest"
  log "$study/$label $kind: exit $code, ${wall} s"
}

if ((quick)); then
  resolutions=(10 14)
  forces=10.36,82.88,327.6
  volume_resolutions=(10)
  ka_edge=10; ka_k=(10 18); ka_alpha=(1.0 2.0)
  ka_forces=53.83,279.7
  hg_edge=10; hg_values=(0 0.1)
  int_edge=10
  strain_resolutions=(10)
  small_strain_forces=1.036,8.288,32.76
else
  resolutions=(10 14 18 22 26 30 34)
  forces=  # the scene's sweep: Hertz depths 0.01 ... 0.1 m
  volume_resolutions=(14 18)
  ka_edge=14; ka_k=(6 10 16 18 26); ka_alpha=(1.0 1.2 1.5 2.0 3.0)
  ka_forces=53.83,152.3,279.7
  hg_edge=18; hg_values=(0 0.02 0.1 0.5)
  int_edge=18
  strain_resolutions=(18 26 34)
  small_strain_forces=1.036,2.930,5.383,8.288,11.58,15.23,19.19,23.44,27.97,32.76
fi
sweep=()
[[ -n $forces ]] && sweep=(--forces "$forces")

log "study in $out ($([[ $quick == 1 ]] && echo quick || echo full)), $verify, $stable_dt"

# a. Resolution: lattice volumes, k = 16, alpha = 1, RK4 at 1 ms (the scene).
for n in "${resolutions[@]}"; do
  run resolution "n$n" verify --per-edge "$n" "${sweep[@]}"
  run resolution "n$n" stable --set "body.distribution.per_edge=$n"
  run resolution "n$n" stable_body --set "body.distribution.per_edge=$n"
done

# b. Volumes: kernel sums (A-2, A-3) against lattice cell volumes.
for n in "${volume_resolutions[@]}"; do
  for v in kernel lattice; do
    run volumes "n${n}_$v" verify --per-edge "$n" --set "mls.volumes=$v" "${sweep[@]}"
    run volumes "n${n}_$v" stable --set "body.distribution.per_edge=$n" --set "mls.volumes=$v"
  done
done

# c. k and alpha, reduced sweep, at most 20 s of simulated time per force.
last_force=${ka_forces##*,}
for k in "${ka_k[@]}"; do
  for a in "${ka_alpha[@]}"; do
    common=(--set "body.distribution.per_edge=$ka_edge" --set "mls.neighbors=$k" --set "mls.support_factor=$a")
    run k_alpha "k${k}_a$a" verify "${common[@]}" --forces "$ka_forces" --set verify.rest.max_time=20
    run k_alpha "k${k}_a$a" stable "${common[@]}" --force "$last_force"
    run k_alpha "k${k}_a$a" stable_body "${common[@]}" --force "$last_force"
  done
done

# d. Hourglass control (RK4, 1 ms).
for h in "${hg_values[@]}"; do
  common=(--set "body.distribution.per_edge=$hg_edge" --set "mls.hourglass=$h")
  run hourglass "h$h" verify "${common[@]}" "${sweep[@]}"
  run hourglass "h$h" stable "${common[@]}"
  run hourglass "h$h" stable_body "${common[@]}"
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
  for case in 327.6:1 53.83:1 327.6:10 327.6:100; do
    f=${case%%:*} m=${case##*:}
    run dt_limits "${type}_F${f}_M$m" stable --set "body.distribution.per_edge=$int_edge" \
      --set "integrator.type=$type" --set integrator.dt=0.001 --set "indenter.mass=$m" --force "$f"
  done
done

log "tables and plots"
"$python" scripts/plot_verification.py "$out" || exit 1
{
  echo "date: $(date -u '+%Y-%m-%d %H:%M UTC')"
  echo "mode: $([[ $quick == 1 ]] && echo quick || echo full)"
  echo "git: $(git rev-parse --short HEAD 2>/dev/null) (working tree $(git status --porcelain 2>/dev/null | wc -l) changed files)"
  echo "core sources (cat core/*.h core/*.cpp | sha1sum): $(cat core/*.h core/*.cpp | sha1sum | cut -c1-12)"
  echo "binaries: $(ls -l --time-style='+%Y-%m-%d %H:%M' "$verify" "$stable_dt" | awk '{print $6, $7, $8}' | paste -sd';')"
  echo "total wall: $(($(date +%s) - started)) s"
  lscpu | head -20
} >"$out/machine.txt"
log "done: $out/tables.md, $out/*.csv, $out/*.png"
