# shellcheck shell=bash disable=SC2034  # (study, python: for the scripts that source this)
# The preamble the study scripts (scripts/*_study.sh) share, sourced right after their header
# comment, which is their --help:
#
#   source "$(dirname "$0")/lib/study_common.sh"
#
# Sets bash's strict mode (set -euo pipefail: a script that must go on past a failed run
# turns -e off after this line) and moves to the repository root. Then:
#   study                    the script's name, for messages ("dome_study.sh")
#   BUILD_DIR                the build folder (from the environment; default build; a script
#                            with another default sets it before sourcing this)
#   python                   Debian's /usr/bin/python3, which sees python3-numpy and
#                            python3-matplotlib
#   study_help               prints the header comment (lines 2 ... up to the first line that
#                            is not a comment, shellcheck directives left out) and exits 0:
#                            for -h and --help
#   study_unknown_option OPT says so on stderr and exits 2
#   study_build TOOL...      builds the programs in $BUILD_DIR (Release) when they are stale,
#                            through scripts/build.sh (its compiler output hidden)
#   study_require PATH...    exits 2 naming the first program not built (for the scripts
#                            that build nothing themselves)
set -euo pipefail
cd "$(dirname "$0")/.."

study=$(basename "$0")
BUILD_DIR=${BUILD_DIR:-build}
python=/usr/bin/python3

study_help() {
  awk 'NR > 1 && !/^#/ { exit } NR > 1 && !/^# shellcheck / { sub(/^# ?/, ""); print }' "$0"
  exit 0
}

study_unknown_option() {
  echo "$study: unknown option '$1'" >&2
  exit 2
}

study_build() {
  BUILD_DIR=$BUILD_DIR scripts/build.sh "$@" >/dev/null
}

study_require() {
  local program
  for program in "$@"; do
    [[ -x $program ]] || { echo "$study: $program not built" >&2; exit 2; }
  done
}
